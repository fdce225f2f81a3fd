"""Exceedance probabilities: P(a realisation's maximum |error| over a window exceeds a limit).

An event ``QUANTITY:DIRECTIONS > LIMIT UNIT[/WINDOW]`` (for example ``displacement:z>0.1mm``,
``velocity:x>2mm/s/steady`` or ``displacement:x,y,z>0.05mm``) holds for a realisation when its
``max_abs_error`` of that quantity over the window (default whole) exceeds the limit in at least one of
the directions (one unit family: translations or rotations).  From n independent realisations
of which k exceed, the estimate is k / n and the interval is the exact Clopper-Pearson one (beta
quantiles; at least the stated confidence for every true probability, two-sided, or one-sided for
each bound of a requirement: coverage measured in tests/test_exceedance.py).  A randomised QMC
file is refused: its points are not independent, so the binomial interval does not hold.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..vocabulary import CONFIDENCE, WINDOWS, window_words
from .estimators import clopper_pearson
from .spec import _NUMBER, SpecError, _limit, _subject, _unit_factor, missing_value

__all__ = ["Event", "Exceedance", "EventError", "parse_event", "exceedance", "format_exceedance", "exceedance_json",
           "union_words"]

_PER_SECOND = {"s", "s^2", "s2", "s**2"}   # unit tails after '/' that are no window


class EventError(SpecError):
    """An event that cannot be parsed; one line naming the bad token."""


@dataclass(frozen=True)
class Event:
    """``max |error|`` of ``quantity`` in any of ``directions`` (one unit family) over ``window``
    exceeds ``limit`` (SI; the user's ``unit`` is ``factor`` SI units): the union of the directions'
    events, so that "the platform leaves its 0.05 mm box" is one event."""

    text: str
    quantity: str
    directions: tuple[str, ...]
    limit: float
    unit: str
    factor: float
    window: str = "whole"

    def exceeds(self, values: np.ndarray) -> np.ndarray:
        """Whether each maximum |error| (SI; over the event's directions) is in the event."""
        return np.asarray(values) > self.limit

    @property
    def direction_words(self) -> str:
        """'z', or 'any of x, y, z'."""
        return self.directions[0] if len(self.directions) == 1 else "any of " + ", ".join(self.directions)


def union_words(directions) -> str:
    """What a printed P(...) line adds for an event over several directions: ' (any of x, y, z)'; ''
    for one."""
    return f" (any of {', '.join(directions)})" if len(directions) > 1 else ""


def _fail(text: str, what: str, flag: str) -> EventError:
    return EventError(f"{flag} {text!r}: {what}")


def _window(text: str, flag: str) -> tuple[str, str]:
    """(the event without its window, the window); a trailing '/NAME' that is no unit tail names one."""
    head, slash, tail = text.rpartition("/")
    if not slash or tail.strip() in _PER_SECOND or not re.fullmatch(r"\s*[A-Za-z_]\w*\s*", tail):
        return text, "whole"
    if tail.strip() not in WINDOWS:
        raise _fail(text, f"unknown window {tail.strip()!r} (choose from {', '.join(WINDOWS)})", flag)
    return head, tail.strip()


def parse_event(text: str, flag: str = "--event") -> Event:
    """Parse ``QUANTITY:DIRECTION > VALUE UNIT[/WINDOW]``; EventError (one line, naming ``flag``) on
    an unknown quantity, direction or window, a missing operator, value or unit."""
    if "@" in text:
        raise _fail(text, "an event has no @statistic: it is each realisation's max |error| above the limit "
                          "(a limit on a statistic is a --require spec, e.g. 'displacement:z<=0.5mm@q95')", flag)
    body, window = _window(text, flag)
    subject, op, rest = body.partition(">")
    if not op or rest.startswith("="):
        raise _fail(text, "an event reads QUANTITY:DIRECTION>LIMIT (e.g. displacement:z>0.1mm)", flag)
    try:
        quantity, directions = _subject(text, subject)
        m = _NUMBER.match(rest)
        if m is None:
            raise _fail(text, missing_value(rest, ">", "0.1mm"), flag)
        limit = _limit(text, m)
        factor = _unit_factor(text, m.group(2).strip(), quantity, directions)
    except EventError:
        raise
    except SpecError as exc:       # the spec grammar's message, under this flag
        raise EventError(str(exc).replace("--require", flag, 1)) from None
    return Event(text, quantity, tuple(directions), limit * factor, m.group(2).strip(), factor, window)


ONE_RUN_METHOD = "exact: every realisation is the same run (nothing drawn), so P is 0 or 1"


@dataclass(frozen=True)
class Exceedance:
    """The estimate k / n of an event's probability over the n finished realisations and its two-sided
    Clopper-Pearson interval at ``confidence`` over all n + ``n_failed`` draws, whose failed ones may or
    may not be in the event (counted out on the lower side, in on the upper)."""

    event: str
    exceeding: int
    n: int
    n_failed: int
    estimate: float
    lower: float
    upper: float
    confidence: float
    window: str = "whole"   # the part of the run whose maxima the event reads (startup, steady, whole)
    directions: tuple[str, ...] = ()   # the event holds where any of them exceeds
    method: str = "Clopper-Pearson exact binomial interval (coverage >= confidence for every p)"


def event_values(ds, event: Event) -> np.ndarray:
    """The event's maxima |error| (SI; the largest over its directions) over the finished realisations
    of an ensemble Dataset; ValueError for a QMC file or a window the file lacks."""
    from .stats import check_window_samples, finished_values
    if ds.attrs.get("sampler") == "qmc":
        raise ValueError(f"{event.text!r}: an exceedance probability needs independent realisations; "
                         "a scrambled Sobol' (QMC) file's points are not, so its Clopper-Pearson "
                         "interval would not hold (use a Monte Carlo ensemble, --sampler mc)")
    if event.window != "whole" and "window" not in ds.dims:
        raise ValueError(f"{event.text!r}: the file has no analysis windows; drop '/{event.window}'")
    try:
        check_window_samples(ds, event.window)
    except ValueError as exc:
        raise ValueError(f"{event.text!r}: {exc}") from None
    values = finished_values(ds, "max_abs_error", event.window)
    return values.sel(quantity=event.quantity, direction=list(event.directions)).max("direction").values


def exceedance(ds, event: Event, confidence: float = CONFIDENCE) -> Exceedance:
    """The event's probability estimate and two-sided interval from an ensemble Dataset."""
    values = event_values(ds, event)
    n, k = len(values), int(np.count_nonzero(event.exceeds(values)))
    failed = int(ds["status"].size - n) if "status" in ds else 0
    if n == 0:
        return Exceedance(event.text, 0, 0, failed, float("nan"), float("nan"), float("nan"), confidence,
                          event.window, event.directions)
    from .stats import one_run_repeated
    if one_run_repeated(ds):   # the gate's exact rule: every realisation is the same run, so P is k / n, 0 or 1
        p = k / n
        return Exceedance(event.text, k, n, failed, p, p, p, confidence, event.window, event.directions,
                          ONE_RUN_METHOD)
    # a failed realisation may or may not be in the event: the interval takes it as neither on the lower
    # side and as in it on the upper one, so it covers the probability over every draw
    lower = clopper_pearson(k, n + failed, confidence)[0]
    upper = clopper_pearson(k + failed, n + failed, confidence)[1]
    return Exceedance(event.text, k, n, failed, k / n, float(lower), float(upper), confidence, event.window,
                      event.directions)


def format_exceedance(results: list[Exceedance]) -> str:
    """One line per event: P = k/n over the part of the run it reads, and its interval with the
    confidence it reaches."""
    lines = []
    for r in results:
        failed = (f"; the estimate leaves the {r.n_failed} failed realisations out, the interval counts them "
                  "out on its lower side and in on its upper one") if r.n_failed else ""
        how = (r.method if r.method == ONE_RUN_METHOD else
               f"Clopper-Pearson, exact: covers with at least {100 * r.confidence:g} % for every true P{failed}")
        lines.append(f"P({r.event}){union_words(r.directions)} over the {window_words(r.window)} = "
                     f"{r.exceeding}/{r.n} = {r.estimate:.4g}, "
                     f"{100 * r.confidence:g} % interval [{r.lower:.4g}, {r.upper:.4g}] ({how})")
    return "\n".join(lines)


def exceedance_json(results: list[Exceedance]) -> list[dict]:
    """Plain dicts for ``--json`` (NaN as None)."""
    from .stats import json_record
    return [json_record(r) for r in results]
