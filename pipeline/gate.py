"""Pass, fail or undecided: requirement specs judged from the statistics Dataset's intervals.

A spec holds with the file's confidence when the statistic's whole confidence
interval meets the limit (pass), is refuted when the whole interval violates it
(fail), and is undecided when the interval straddles the limit or no interval
exists at this sample size. The intervals describe the finished realisations
only: where any realisation failed, a spec they meet is undecided, not passed
(the failed draws, which often diverged on the largest errors, are in the
population the requirement is about). Each direction of a spec is judged on its own
interval; the spec's verdict is the worst of them. For an undecided verdict the
sample size that would likely decide is estimated from the interval's 1/sqrt(n)
shrinkage about an unchanged estimate (and, for quantiles, never below the
smallest n at which a distribution-free interval exists).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .spec import Spec
from .stats import interval_floor

__all__ = ["OUTCOMES", "Verdict", "exit_code", "format_verdicts", "overall", "judge", "judge_all",
           "verdicts_json"]

OUTCOMES = ("pass", "undecided", "fail")


@dataclass(frozen=True)
class Verdict:
    """One direction of one spec: the interval (SI), its outcome, and the n that would likely decide."""

    spec: str
    quantity: str
    direction: str
    statistic: str
    measure: str
    window: str | None
    op: str
    limit: float
    unit: str
    factor: float
    estimate: float
    lower: float | None
    upper: float | None
    confidence: float
    n: int
    n_failed: int
    outcome: str
    n_needed: int | None
    reason: str


def _n_needed(spec: Spec, est: float, lo: float, hi: float, n: int, confidence: float,
              replicates: int | None = None):
    """(n, reason) that would likely decide an undecided spec (see module doc); ``replicates``: R
    of a randomised QMC file, whose intervals start at other n."""
    floor = interval_floor(spec.statistic, confidence, replicates)
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return max(floor, n + 1), f"no {100 * confidence:g} % interval exists at n = {n}"
    margin = abs(est - spec.limit)
    if margin == 0:
        return None, "the estimate equals the limit: no sample size is expected to decide"
    side = hi - est if est < spec.limit else est - lo
    return max(floor, n + 1, math.ceil(n * (side / margin) ** 2)), "the interval straddles the limit"


def _outcome(spec: Spec, lo: float, hi: float) -> str:
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return "undecided"
    if spec.holds(lo) and spec.holds(hi):
        return "pass"
    if not spec.holds(lo) and not spec.holds(hi):
        return "fail"
    return "undecided"


def _select(stats, spec: Spec, window: str = "whole"):
    """The spec's (bound,) slice per direction, in the spec's window or else ``window`` (statistics
    with a window dimension); EnsembleFileError-style ValueError if a window is absent."""
    da = stats[spec.variable].sel(statistic=spec.statistic, quantity=spec.quantity)
    if spec.window is None and "window" in da.dims:
        da = da.sel(window=window)
    if spec.window is not None:
        if "window" not in da.dims:
            raise ValueError(f"--require {spec.text!r}: the statistics have no analysis windows "
                             f"(no 'window' dimension); drop '/{spec.window}'")
        windows = [str(w) for w in da["window"].values]
        if spec.window not in windows:
            raise ValueError(f"--require {spec.text!r}: unknown window {spec.window!r} "
                             f"(the file has {', '.join(windows)})")
        da = da.sel(window=spec.window)
    return da


def judge(spec: Spec, stats) -> list[Verdict]:
    """Verdicts of one spec, one per direction, from a statistics Dataset (``pipeline.stats``)."""
    da = _select(spec=spec, stats=stats)
    n, confidence = int(stats.attrs["n_finished"]), float(stats.attrs["confidence"])
    failed = int(stats.attrs.get("n_failed", 0))
    replicates = stats.attrs.get("qmc_replicates")
    replicates = None if replicates is None else int(replicates)
    out = []
    for d in spec.directions:
        est, lo, hi = (float(da.sel(direction=d, bound=b)) for b in ("estimate", "lower", "upper"))
        outcome = _outcome(spec, lo, hi)
        if outcome == "pass" and failed:
            outcome, need, reason = "undecided", None, (
                f"the whole interval meets the limit, but {failed} of {n + failed} realisations failed "
                "and are not in it")
        elif outcome == "undecided":
            need, reason = _n_needed(spec, est, lo, hi, n, confidence, replicates)
        else:
            need, reason = None, "the whole interval " + ("meets" if outcome == "pass"
                                                          else "violates") + " the limit"
        out.append(Verdict(spec.text, spec.quantity, d, spec.statistic, spec.measure, spec.window,
                           spec.op, spec.limit, spec.unit, spec.factor, est,
                           lo if np.isfinite(lo) else None, hi if np.isfinite(hi) else None,
                           confidence, n, failed, outcome, need, reason))
    return out


def judge_all(specs: list[Spec], stats) -> list[Verdict]:
    """Every spec's verdicts, in the order given."""
    return [v for s in specs for v in judge(s, stats)]


def exit_code(verdicts: list[Verdict], undecided: str = "fail") -> int:
    """0 when every verdict passes (undecided ones too with ``undecided='pass'``), else 1."""
    allowed = ("pass", "undecided") if undecided == "pass" else ("pass",)
    return 0 if all(v.outcome in allowed for v in verdicts) else 1


def _num(value: float | None, factor: float) -> str:
    return "-" if value is None else f"{value / factor:.4g}"


def format_verdicts(verdicts: list[Verdict]) -> str:
    """A table in each spec's own unit: spec, direction, interval, limit, verdict, n to decide."""
    if not verdicts:
        return ""
    conf = f"{100 * verdicts[0].confidence:g} %"
    failed = verdicts[0].n_failed
    lines = [f"requirements ({conf} intervals, n = {verdicts[0].n} finished realisations"
             + (f"; {failed} failed, so a limit they meet is undecided" if failed else "")
             + "; estimate and interval in the unit of the spec's limit)",
             f"{'spec':<40s}{'dir':<4s}{'estimate':>11s}{'interval':>24s}{'limit':>14s}  "
             f"{'verdict':<10s}n to decide"]
    for v in verdicts:
        interval = f"[{_num(v.lower, v.factor)}, {_num(v.upper, v.factor)}]"
        need = "" if v.outcome != "undecided" else (str(v.n_needed) if v.n_needed else "-")
        lines.append(f"{v.spec:<40.40s}{v.direction:<4s}{_num(v.estimate, v.factor):>11s}"
                     f"{interval:>24s}{v.op + ' ' + _num(v.limit, v.factor) + ' ' + v.unit:>14s}  "
                     f"{v.outcome:<10s}{need}")
    counts = ", ".join(f"{sum(v.outcome == o for v in verdicts)} {o}" for o in OUTCOMES)
    lines.append(f"verdict: {overall(verdicts)} ({counts})")
    return "\n".join(lines)


def overall(verdicts: list[Verdict]) -> str:
    """The worst outcome of all verdicts (fail over undecided over pass)."""
    return max((v.outcome for v in verdicts), key=OUTCOMES.index)


def verdicts_json(verdicts: list[Verdict]) -> list[dict]:
    """Plain dicts (SI values; None where a bound does not exist) for ``--json`` and file attributes."""
    return [asdict(v) for v in verdicts]
