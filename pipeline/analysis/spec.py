"""Requirement specs on ensemble statistics: ``QUANTITY:DIRECTIONS OP VALUE UNIT @ STATISTIC``.

One grammar serves every command that states a limit (``rss6 run --require``,
``rss6 stats --require``), for example ``displacement:x,y<=0.05mm@q95`` or
``acceleration:z <= 50 m/s^2 @ q50``:

- QUANTITY: displacement, velocity or acceleration;
- DIRECTIONS: a comma list of x, y, z, rx, ry, rz, or ``all``; one spec bounds
  translations or rotations, not both (its unit is a length or an angle);
- OP: ``<=``, ``<``, ``>=`` or ``>``;
- VALUE UNIT: a number and a unit of the quantity: lengths m, cm, mm, um;
  angles rad, mrad, urad, deg; per second ``/s`` (or UDUNITS ``m s-1``),
  per second squared ``/s^2`` (``/s2``, ``m s-2``), and ``g`` (9.80665 m/s^2);
- STATISTIC: ``pf<=P`` (or ``pf<P``), P in (0, 1): the probability that a realisation's maximum
  |error| violates the limit is at most P (an upper limit OP only; per direction; decided on
  one-sided Clopper-Pearson bounds, pipeline.analysis.exceedance), for example
  ``displacement:z<=0.1mm@pf<=1e-3``; or one of the statistics Dataset's labels that carry an interval
  (mean, std, q05, q50, q95, q99; not max, which has none), of the per-realisation maximum |error| by default or of the
  per-realisation mean |error| with ``:mean`` (``@q50:mean``), and optionally
  an analysis window of the file (``@q95/steady``).

A malformed spec raises :class:`SpecError` with one line naming the bad token
and what would be valid, before any work starts.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from ..vocabulary import FAMILIES, QUANTITIES, REQUIRABLE, SUMMARIES, UserError

__all__ = ["OPERATORS", "PF", "Spec", "SpecError", "parse_spec", "parse_specs", "si_unit"]

TRANSLATIONS, ROTATIONS = FAMILIES["translation"], FAMILIES["rotation"]
MEASURES = dict(zip(("max", "mean"), SUMMARIES))   # the summary a spec's ":max" or ":mean" names
OPERATORS = ("<=", "<", ">=", ">")
PF = "pf"   # the statistic of a probability-of-exceedance requirement
STANDARD_GRAVITY = 9.80665  # m/s^2

_LENGTHS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "μm": 1e-6}
_ANGLES = {"rad": 1.0, "mrad": 1e-3, "urad": 1e-6, "µrad": 1e-6, "deg": math.pi / 180}
_POWER = {"displacement": 0, "velocity": 1, "acceleration": 2}
_PER_TIME = ("", "/s", "/s^2")   # by _POWER


def si_unit(quantity: str, direction: str) -> str:
    """The SI unit a spec's values are held in: m or rad, per s or s^2 by ``quantity``."""
    return ("rad" if direction in ROTATIONS else "m") + _PER_TIME[_POWER[quantity]]
_NUMBER = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*)$")
_OPERATOR = re.compile(r"<=|>=|=<|=>|==|!=|<|>|=")


class SpecError(UserError):
    """A requirement spec that cannot be parsed; the message is one line naming the bad token."""


@dataclass(frozen=True)
class Spec:
    """One parsed requirement: ``statistic`` of ``measure`` |error| of ``quantity`` in ``directions``
    compared by ``op`` with ``limit`` (SI: m or rad, per s or s^2); ``unit`` and ``factor`` give the
    user's unit (value_in_unit = value_SI / factor)."""

    text: str
    quantity: str
    directions: tuple[str, ...]
    op: str
    limit: float
    unit: str
    factor: float
    statistic: str
    measure: str = "max"
    window: str | None = None
    pf_op: str | None = None       # pf requirements: "<=" or "<" on the exceedance probability
    pf_limit: float | None = None  # pf requirements: the largest allowed exceedance probability

    @property
    def variable(self) -> str:
        """The statistics Dataset variable the spec reads."""
        return MEASURES[self.measure]

    def holds(self, value):
        """Whether ``value`` (SI; a number, or an array judged elementwise) meets the limit."""
        return {"<=": value <= self.limit, "<": value < self.limit,
                ">=": value >= self.limit, ">": value > self.limit}[self.op]


def _fail(text: str, what: str) -> SpecError:
    return SpecError(f"--require {text!r}: {what}")


def _directions(text: str, token: str) -> tuple[str, ...]:
    if token.strip() in ("all", "*"):
        return TRANSLATIONS + ROTATIONS
    names = [d.strip() for d in token.split(",")]
    for d in names:
        if d not in TRANSLATIONS + ROTATIONS:
            raise _fail(text, f"unknown direction {d!r} (choose from x, y, z, rx, ry, rz or all)")
    if len(set(names)) != len(names):
        raise _fail(text, f"direction listed twice in {token.strip()!r}")
    return tuple(names)


def _split_unit(unit: str) -> tuple[str, int]:
    """``'mm/s^2'`` -> (``'mm'``, 2); also ``'m s-2'``, ``'m/s2'``, ``'m/s**2'``."""
    u = unit.replace("**", "^").replace(" ", "")
    m = re.fullmatch(r"(.+?)s-(\d)", unit.replace(" ", "")) if " s-" in unit else None
    if m:
        return m.group(1), int(m.group(2))
    if "/" not in u:
        return u, 0
    base, _, per = u.partition("/")
    powers = {"s": 1, "s^2": 2, "s2": 2}
    return base, powers.get(per, -1)


def _unit_factor(text: str, unit: str, quantity: str, directions: tuple[str, ...]) -> float:
    """SI factor of ``unit`` for ``quantity`` in ``directions``; SpecError naming what fits."""
    if not unit:
        raise _fail(text, "missing unit after the value (e.g. mm, rad, m/s, m/s^2)")
    rotation = directions[0] in ROTATIONS
    if any((d in ROTATIONS) != rotation for d in directions):
        raise _fail(text, "directions mix translations and rotations; one unit cannot bound both "
                          "(write two specs)")
    need = _POWER[quantity]
    if unit == "g" and quantity == "acceleration" and not rotation:
        return STANDARD_GRAVITY
    base, power = _split_unit(unit)
    table = _ANGLES if rotation else _LENGTHS
    suffix = _PER_TIME[need]
    names = ("rad", "mrad", "deg") if rotation else ("m", "mm", "um")
    valid = ", ".join(f"{b}{suffix}" for b in names) + (", g" if need == 2 and not rotation else "")
    if base not in table or power != need:
        kind = "a rotation" if rotation else "a translation"
        raise _fail(text, f"unknown unit {unit!r} for the {quantity} of {kind} (valid: {valid})")
    return table[base]


def _statistic(text: str, token: str) -> tuple[str, str, str | None]:
    stat, _, window = token.strip().partition("/")
    stat, _, measure = stat.partition(":")
    stat, measure, window = stat.strip(), (measure.strip() or "max"), window.strip() or None
    if stat == "max":
        raise _fail(text, "statistic 'max' has no confidence interval (the sample maximum estimates "
                          "no population parameter); bound a quantile such as q99 instead")
    if stat not in REQUIRABLE:
        raise _fail(text, f"unknown statistic {stat!r} (choose from {', '.join(REQUIRABLE)}, or pf<=P for the "
                          "probability of exceeding the limit)")
    if measure not in MEASURES:
        raise _fail(text, f"unknown measure {measure!r} after ':' (choose from max, mean)")
    if "/" in token and window is None:
        raise _fail(text, "missing window name after '/' (e.g. @q95/steady)")
    return stat, measure, window


def _pf(text: str, op: str, token: str) -> tuple[str, float, str | None]:
    """``'pf<=1e-3/steady'`` -> (op, probability, window); SpecError names what is wrong."""
    body, _, window = token.strip().partition("/")
    m = re.fullmatch(r"pf\s*(<=|<|=<)\s*(.*)", body.strip())
    if m is None:
        raise _fail(text, "a pf requirement reads pf<=P or pf<P (e.g. @pf<=1e-3)")
    if op not in ("<=", "<"):
        raise _fail(text, "a pf requirement bounds the probability that the error exceeds an upper "
                          f"limit: use <= or < before the limit, not {op!r}")
    try:
        value = float(m.group(2))
    except ValueError:
        raise _fail(text, f"pf value {m.group(2)!r} is not a number") from None
    if not 0 < value < 1:
        raise _fail(text, f"pf value {m.group(2)} must lie strictly between 0 and 1")
    if "/" in token and not window.strip():
        raise _fail(text, "missing window name after '/' (e.g. @pf<=1e-3/steady)")
    return {"=<": "<="}.get(m.group(1), m.group(1)), value, window.strip() or None


def _subject(text: str, subject: str) -> tuple[str, tuple[str, ...]]:
    """``'displacement:x,y'`` -> (quantity, directions)."""
    quantity, colon, dirs = subject.partition(":")
    quantity = quantity.strip()
    if quantity not in QUANTITIES:
        raise _fail(text, f"unknown quantity {quantity!r} (choose from {', '.join(QUANTITIES)})")
    if not colon or not dirs.strip():
        raise _fail(text, "missing directions after the quantity (e.g. displacement:x,y)")
    return quantity, _directions(text, dirs)


def _comparison(text: str, left: str) -> tuple[str, str, str]:
    """``'displacement:x<=0.05mm'`` -> (subject, op, value-and-unit)."""
    m = _OPERATOR.search(left)
    if m is None:
        raise _fail(text, "missing operator (use <=, <, >= or >)")
    op = {"=<": "<=", "=>": ">="}.get(m.group(0), m.group(0))
    if op not in OPERATORS:
        raise _fail(text, f"unknown operator {m.group(0)!r} (use <=, <, >= or >)")
    return left[:m.start()], op, left[m.end():]


def _limit(text: str, m) -> float:
    """The limit a spec's or an event's number match ``m`` gives (in its unit): |error| is never
    negative, so only a positive finite one means anything."""
    value = float(m.group(1))
    if not math.isfinite(value) or value <= 0:
        raise _fail(text, f"value {m.group(1)!r} is not a positive finite number (a limit on |error|)")
    return value


def missing_value(rest: str, op: str, example: str) -> str:
    """What is wrong where no number follows ``op``: a nan or inf written as the limit, or no value at all."""
    word = re.match(r"\s*([-+]?(?:nan|inf(?:inity)?))", rest, re.IGNORECASE)
    if word:
        return f"value {word.group(1)!r} is not a positive finite number (a limit on |error|)"
    return f"missing value after {op!r} (e.g. {example})"


def parse_spec(text: str) -> Spec:
    """Parse one spec (see module doc); raises SpecError with one line on any malformed token."""
    left, at, right = text.partition("@")
    if not at:
        raise _fail(text, "missing '@STATISTIC' (e.g. @q95)")
    subject, op, rest = _comparison(text, left)
    quantity, directions = _subject(text, subject)
    m = _NUMBER.match(rest)
    if m is None:
        raise _fail(text, missing_value(rest, op, "0.05mm"))
    value, unit = _limit(text, m), m.group(2).strip()
    factor = _unit_factor(text, unit, quantity, directions)
    if right.strip().startswith(PF):
        pf_op, pf_limit, window = _pf(text, op, right)
        return Spec(text, quantity, directions, op, value * factor, unit, factor, PF, "max", window,
                    pf_op, pf_limit)
    stat, measure, window = _statistic(text, right)
    return Spec(text, quantity, directions, op, value * factor, unit, factor, stat, measure, window)


def parse_specs(texts: list[str] | None) -> list[Spec]:
    """Parse every spec of a repeated flag (none given: an empty list)."""
    return [parse_spec(t) for t in texts or []]
