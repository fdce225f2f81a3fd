"""``rss6 run --until``: add realisations until stated confidence-interval half-widths are reached.

A target reads ``QUANTITY:DIRECTIONS@STATISTIC <= HALF-WIDTH``, with the pieces
of pipeline/analysis/spec.py (quantity, directions, statistic with ``:mean`` measure
and ``/window``), for example ``displacement:x,y,z,rx,ry,rz@q95<=5%``:

- HALF-WIDTH ``N%``: half the interval's width, (upper - lower) / 2, relative to
  the statistic's estimate, in every listed direction;
- HALF-WIDTH ``VALUE UNIT`` (``0.002mm``, ``1e-4rad``): the same in absolute
  terms, in a unit of the quantity as in spec.py.

Stopping rule: the ensemble is checked only at the fixed sample sizes of
:func:`checkpoints` (a function of the targets, the cap ``-n`` and the sampler;
never of timing), and stops at the first one where every target is met.  A
statistic without an interval at that n (below its minimum n) is not met.  The
intervals are those of pipeline/analysis/estimators.py at the run's confidence (95 %), the
quantiles' (with ``--sampler qmc`` every statistic's) taken at the widened level LEVEL (97.5 %):
choosing n by an interval's own width costs it coverage (:func:`pipeline.analysis.stats.until_note`), and
every later statistic of the file is taken the same way.  The file at the final n is the file of a plain ``-n FINAL``
run plus the ``until_*`` attributes.  A file that already holds realisations (a resumed
run) is checked at its own n first.
"""
from __future__ import annotations

import contextlib
import json
import math
import re
import sys
from dataclasses import dataclass

import numpy as np

from ..vocabulary import CONFIDENCE, UserError
from .estimators import bound_level, stopped_level
from .spec import SpecError, _statistic, _subject, _unit_factor

__all__ = ["Target", "UntilError", "parse_target", "parse_targets", "checkpoints", "widths",
           "run_until", "GROWTH", "CONFIDENCE"]

GROWTH = 1.25        # mc: each checked n is the previous one times this, rounded up
LEVEL = stopped_level(CONFIDENCE, stopped_by_width=True)   # the quantiles' bounds the rule checks
_WIDTH = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:nan|inf))\s*(%?)\s*(.*)$", re.I)


class UntilError(UserError):
    """A malformed ``--until`` target or an impossible stopping rule; one line naming the token."""


@dataclass(frozen=True)
class Target:
    """One target: the half-width of ``statistic``'s interval for ``quantity`` in each direction is at
    most ``relative`` times the estimate, or ``absolute`` (SI; ``unit`` and ``factor`` the user's)."""
    text: str
    quantity: str
    directions: tuple[str, ...]
    statistic: str
    measure: str
    window: str | None
    relative: float | None
    absolute: float | None
    unit: str
    factor: float

    @property
    def variable(self) -> str:
        return {"max": "max_abs_error", "mean": "mean_abs_error"}[self.measure]

    def target_text(self) -> str:
        return (f"{100 * self.relative:g} %" if self.relative is not None
                else f"{self.absolute / self.factor:g} {self.unit}")


def _fail(text: str, what: str) -> UntilError:
    return UntilError(f"--until {text!r}: {what}")


def _spec_piece(text: str, parse, *args):
    """A parser piece of spec.py, its error message naming --until."""
    try:
        return parse(*args)
    except SpecError as exc:
        raise UntilError(str(exc).replace("--require", "--until", 1)) from None


def parse_target(text: str) -> Target:
    """Parse one target (see module doc); UntilError with one line on any malformed token."""
    subject, at, right = text.partition("@")
    if not at:
        raise _fail(text, "missing '@STATISTIC<=HALF-WIDTH' (e.g. displacement:x,y@q95<=5%)")
    quantity, directions = _spec_piece(text, _subject, text, subject)
    m = re.search(r"<=|<", right)
    if m is None:
        raise _fail(text, "missing '<=' and the half-width after the statistic (e.g. @q95<=5%)")
    statistic, measure, window = _spec_piece(text, _statistic, text, right[:m.start()])
    w = _WIDTH.match(right[m.end():])
    if w is None:
        raise _fail(text, "missing half-width after '<=' (e.g. 5% or 0.002mm)")
    value, percent, unit = float(w.group(1)), w.group(2), w.group(3).strip()
    if not value > 0 or not math.isfinite(value):
        raise _fail(text, f"half-width {w.group(1)!r} must be a positive number")
    if percent:
        if unit:
            raise _fail(text, f"unexpected {unit!r} after the percentage")
        return Target(text, quantity, directions, statistic, measure, window, value / 100, None,
                      "%", 1.0)
    factor = _spec_piece(text, _unit_factor, text, unit, quantity, directions)
    return Target(text, quantity, directions, statistic, measure, window, None, value * factor,
                  unit, factor)


def parse_targets(texts: list[str] | None) -> list[Target]:
    """Every target of the repeated flag (none given: an empty list)."""
    return [parse_target(t) for t in texts or []]


def check_cap(targets: list[Target], cap: int, replicates: int | None = None) -> None:
    """UntilError, before any work, for a target whose statistic has no interval at the cap ``-n``:
    no check could meet it (as ``rss6 budget`` refuses the same request)."""
    from .estimators import interval_floor
    for t in targets:
        floor = interval_floor(t.statistic, bound_level(t.statistic, CONFIDENCE, True), replicates)
        if cap < floor:
            raise _fail(t.text, f"{t.statistic} has no {100 * CONFIDENCE:g} % interval after --until below "
                                f"n = {floor} (-n {cap}; docs/ensembles.md); raise -n")


def checkpoints(targets: list[Target], cap: int, replicates: int | None = None) -> list[int]:
    """The sample sizes at which the rule is checked, ascending, ending at ``cap``.

    mc: from the largest minimum n of the targets' statistics, times GROWTH (rounded up) each
    time.  qmc (R ``replicates``): R m with m doubling from the largest minimum points per
    replicate, so each replicate stays a power-of-two prefix of its Sobol' sequence."""
    from .estimators import interval_floor
    first = max(interval_floor(t.statistic, bound_level(t.statistic, CONFIDENCE, True), replicates)
                for t in targets)
    out, n = [], first
    while n < cap:
        out.append(n)
        n = 2 * n if replicates is not None else max(n + 1, math.ceil(n * GROWTH))
    return out + [cap]


@dataclass(frozen=True)
class Width:
    """The interval half-width of one target in one direction at n (SI), and whether it is met."""
    target: str
    direction: str
    estimate: float
    half_width: float | None   # None: no interval at this n
    relative: float | None
    met: bool


def widths(targets: list[Target], sds) -> list[Width]:
    """The half-widths of every target and direction in a statistics Dataset (pipeline.analysis.stats)."""
    out = []
    for t in targets:
        da = sds[t.variable].sel(statistic=t.statistic, quantity=t.quantity)
        if "window" in da.dims:                     # statistics of every window of the file
            da = da.sel(window=t.window or "whole")
        for d in t.directions:
            est, lo, hi = (float(da.sel(direction=d, bound=b)) for b in ("estimate", "lower", "upper"))
            half = (hi - lo) / 2 if np.isfinite(lo) and np.isfinite(hi) else None
            rel = half / abs(est) if half is not None and est != 0 else None
            met = (half is not None and (half <= t.absolute if t.absolute is not None
                                         else rel is not None and rel <= t.relative))
            out.append(Width(t.text, d, est, half, rel, met))
    return out


def _width_text(t: Target, w: Width) -> str:
    if w.half_width is None:
        return f"{w.direction} no interval"
    value = (f"{100 * w.relative:.3g} %" if t.relative is not None and w.relative is not None
             else f"{w.half_width / t.factor:.3g} {t.unit}")
    return f"{w.direction} {value}{'' if w.met else ' (not yet)'}"


def format_widths(targets: list[Target], found: list[Width], n: int) -> str:
    """One line: the half-widths reached at n against each target, each one not met yet saying so."""
    parts = []
    for t in targets:
        mine = [w for w in found if w.target == t.text]
        parts.append(f"{t.quantity} {t.statistic} half-width <= {t.target_text()}: "
                     + ", ".join(_width_text(t, w) for w in mine))
    return f"n = {n}: " + "; ".join(parts)


def until_attrs(targets: list[Target], found: list[Width], n: int, points: list[int],
                cap: int) -> dict:
    """File attributes: the rule, whether it was met, the widths reached (SI JSON) and the final n."""
    from .stats import json_record
    met = all(w.met for w in found)
    shown = points if len(points) <= 12 else points[:6] + ["..."] + points[-3:]
    return {"until_rule": ("stop at the first checked n where every target holds: "
                           + "; ".join(t.text for t in targets)
                           + f" (interval half-widths at {100 * CONFIDENCE:g} % confidence, the quantiles' bounds at "
                           f"{100 * LEVEL:g} %; "
                           f"checked at n = {', '.join(map(str, shown))}; cap -n {cap})"),
            "until_met": "met" if met else "not met",
            "until_n": n,
            "until_widths": json.dumps([json_record(w) for w in found], allow_nan=False)}


@dataclass(frozen=True)
class UntilOutcome:
    """What ``run_until`` did: the last ensemble call's outcome, the n it stopped at, whether every
    target was met there, and the half-widths reached."""
    ensemble: object
    n: int
    met: bool
    widths: list


def _stored(output, spec):
    """The ensemble already in ``output`` (identity checked), or None."""
    from pathlib import Path

    from ..ensemble.run import _check_identity
    from ..files.opening import open_ensemble
    if not Path(output).exists():
        return None
    ds = open_ensemble(output)
    _check_identity(output, ds.attrs, spec)
    return ds


def run_until(spec, targets: list[Target], cap: int, output, workers: int = 2,
              scheduler: str | None = None, chunk: int | None = None, progress: bool = True,
              annotate=None, worker_timeout: float | None = None, stream=None) -> UntilOutcome:
    """Extend ``output`` through :func:`checkpoints` until every target is met or ``cap`` is reached;
    each check's widths are printed to ``stream`` and written into the file (``until_*``)."""
    from ..ensemble.cluster import WORKER_TIMEOUT_S, dask_client
    from ..ensemble.progress import cluster_label
    from ..ensemble.run import default_chunk, ensemble
    from .stats import ensemble_stats
    stream = stream or sys.stderr
    points = checkpoints(targets, cap, spec.qmc_replicates)
    found: dict = {}
    stored = _stored(output, spec)
    done = 0 if stored is None else stored.sizes["realization"]
    checked = sorted(set(points) | ({done} if done else set()))   # a stored file is checked first

    def judge(ds) -> dict:
        n = ds.sizes["realization"]
        found.update(n=n, widths=widths(targets, ensemble_stats(ds, CONFIDENCE, window=None, stopped_by_width=True)))
        extra = until_attrs(targets, found["widths"], n, checked, cap)
        return extra | (annotate(ds) if annotate else {})

    if stored is not None:
        judge(stored)
        stream.write(f"rss6 run --until: {output} holds {done} realisations; checked there first\n"
                     + format_widths(targets, found["widths"], done) + "\n")
    plan = ([done] if done and all(w.met for w in found["widths"]) else []) \
        + [n for n in points if n > done]
    outcome, computed = None, 0
    if plan and progress:   # said once: the batches' own first lines do not repeat it
        batches = (f"1 batch (a check at n = {plan[0]})" if len(plan) == 1 else
                   f"{len(plan)} batches (checks at n = {plan[0]} to {plan[-1]})")
        stream.write(f"rss6 run --until: at most {batches} on "
                     f"{cluster_label(workers, scheduler)}; starting workers\n")
        stream.flush()
    # one cluster (or client of the scheduler) for every batch: a cluster per batch would cost its
    # start-up every check
    with dask_client(workers, scheduler) if plan else contextlib.nullcontext() as client:
        for n in plan:
            if outcome is not None:   # judged: the next batch opens the file again
                outcome.dataset.close()
            size = default_chunk(max(n - done, 1), workers, spec.model) if chunk is None else chunk
            outcome = ensemble(spec, n, output, workers, scheduler, size, progress, judge,
                               worker_timeout or WORKER_TIMEOUT_S, client=client)
            computed, done = computed + outcome.computed, n
            met = all(w.met for w in found["widths"])
            stream.write(format_widths(targets, found["widths"], n)
                         + (" -> all met" if met else "") + "\n")
            stream.flush()
            if met:
                break
    if outcome is None:      # the stored file is beyond the cap and was checked as it is
        outcome = ensemble(spec, done, output, workers, scheduler, chunk, progress, judge,
                           worker_timeout or WORKER_TIMEOUT_S)
    from dataclasses import replace
    outcome = replace(outcome, computed=computed, written=outcome.written or computed > 0,
                      stored_before=0 if stored is None else stored.sizes["realization"])
    return UntilOutcome(outcome, found["n"], all(w.met for w in found["widths"]), found["widths"])

