"""Pass, fail or undecided: requirement specs decided on one-sided bounds of the ensemble's statistics.

A requirement is decided on whichever side the data already decide, at the stated
confidence c: it fails when the statistic's one-sided bound on the limit's side violates
the limit (for ``<=`` L: the lower bound exceeds L), passes when the one-sided bound on
the other side meets it (the upper bound is within L), and is undecided otherwise.  Each
decision errs with probability at most 1 - c (the bounds: pipeline.analysis.estimators,
one-sided bounds; error rates measured in tests/test_gate.py).  So a q95 limit that all of a few
realisations violate fails from n = 1 (were q95 <= L, all n would exceed L with
probability at most 0.05^n), while passing one needs n >= 59.

The bounds describe the finished realisations only: where any realisation failed, a spec
they meet is undecided, not passed (the failed draws, which often diverged on the largest
errors, are in the population the requirement is about); one they violate fails.  Each
direction of a spec is judged on its own; the spec's verdict is the worst of them.  For an
undecided verdict, the n that would likely decide: for a quantile of a plain Monte Carlo
ensemble, the smallest n at which the binomial bound decides if the share of violating
realisations stays as it is; otherwise from the bound's 1/sqrt(n) shrinkage about an
unchanged estimate (never below the smallest n at which the bound exists).

A limit within the level's numerical error of the estimate (half its resolution: the contact level's
accuracy against a converged reference, pipeline.analysis.resolution; for a std, that of the largest
value; none at levels resolved to round-off) is undecided with no n: any decision there would be on
numerical noise, which more realisations do not shrink.

Exit codes (:func:`exit_code`): 0 every verdict passes, 1 any fails, 3 none fails but
some are undecided ("needs more realisations"); 2 stays the CLI's for usage errors.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .exceedance import Event, event_values
from .spec import PF, Spec, si_unit
from ..vocabulary import CONFIDENCE, QUANTILES, WINDOWS
from .estimators import (QUANTILE_DECISION_CAP, bound_level, interval_floor, no_interval_at, one_sided_cp,
                         quantile_decision_n)
from .stats import check_window_samples, ensemble_stats, finished_values, json_number, json_record, one_run_repeated

__all__ = ["OUTCOMES", "EXIT_CODES", "Verdict", "check_confidence", "exit_code", "format_verdicts",
           "verdicts_with_note", "start_up_note", "allowed_exceedances", "overall", "judge", "judge_all",
           "verdicts_json"]

OUTCOMES = ("pass", "undecided", "fail")
EXIT_CODES = {"pass": 0, "fail": 1, "undecided": 3}
UPPER_LIMITS = ("<=", "<")
BOUND_METHODS = {"quantile": "exact binomial order statistics, distribution-free",
                 "mean": "union of Student t and Hall's skewness-corrected t, two-sided on the side the sample "
                         "skewness points to",
                 "std": "those of the two-sided (widened) Bonett interval",
                 "qmc": "Student t over the randomised-QMC replicates",
                 PF: "exact Clopper-Pearson binomial bounds"}


@dataclass(frozen=True)
class Verdict:
    """One direction of one spec: its one-sided bounds (SI; None where none exists at this n), its
    outcome, the n that would likely decide, and the rule it was decided by."""

    spec: str
    quantity: str
    direction: str
    statistic: str
    measure: str
    window: str             # the spec's window, "whole" when it names none
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
    rule: str


@dataclass(frozen=True)
class _Evidence:
    """What one direction of a spec is judged on: the bounds (SI, NaN where none) and the finished
    realisations' values of its cell."""

    estimate: float
    lower: float
    upper: float
    values: np.ndarray


def check_confidence(confidence: float) -> None:
    """ValueError unless ``confidence`` lies in (0.5, 1): one-sided bounds below 0.5 cross."""
    if not 0.5 < confidence < 1.0:
        raise ValueError(f"confidence {confidence:g}: a requirement is decided on one-sided bounds, "
                         "which need a confidence above 0.5 and below 1")


def upper_limits_problem(specs: list[Spec], confidence: float, n: int, study: str) -> str | None:
    """Why ``specs`` cannot serve a study (``study``: "a budget", "an allocation") that bounds the error
    from above with n realisations at ``confidence``, as a one-line message: the confidence, else the
    first spec that cannot (:func:`upper_limit_problem`); None if they can."""
    try:
        check_confidence(confidence)
    except ValueError as exc:
        return f"--{exc}"
    return next((why for spec in specs if (why := upper_limit_problem(spec, confidence, n, study))), None)


def upper_limit_problem(spec: Spec, confidence: float, n: int, study: str) -> str | None:
    """Why ``spec`` cannot serve a study (``study``: "a budget", "an allocation") that bounds the error
    from above with n realisations at ``confidence``, as a one-line message; None if it can."""
    if spec.op not in ("<=", "<"):   # the spec itself first, then what -n can show of it
        return f"--spec {spec.text!r}: {study} bounds the error from above; use <= or <"
    if spec.window is not None and spec.window not in WINDOWS:
        return f"--spec {spec.text!r}: unknown window {spec.window!r}; choose one of {', '.join(WINDOWS)}"
    if spec.statistic == PF and allowed_exceedances(spec, n, confidence) < 0:
        return (f"--spec {spec.text!r}: even with no realisation above the limit, n = {n} cannot show pf "
                f"{spec.pf_op} {spec.pf_limit:g} at {100 * confidence:g} % (raise -n)")
    if spec.statistic != PF and (why := no_interval_at(spec.statistic, confidence, n)):
        return f"--spec {spec.text!r}: {why}"
    return None


def allowed_exceedances(spec: Spec, n: int, confidence: float) -> int:
    """The most realisations of n whose maximum may violate ``spec``'s limit with its pf requirement
    still met: the largest k whose one-sided Clopper-Pearson upper bound of P meets pf (the gate's
    rule, pipeline.analysis.gate); -1 if not even k = 0 does at this n."""
    upper = one_sided_cp(np.arange(n + 1), n, confidence)[1]
    ok = upper <= spec.pf_limit if spec.pf_op == "<=" else upper < spec.pf_limit
    return int(np.flatnonzero(ok).max()) if ok.any() else -1


def _sides(spec: Spec) -> tuple[str, str]:
    """(the bound that can show a violation, the bound that can show the limit met)."""
    return ("lower", "upper") if spec.op in UPPER_LIMITS else ("upper", "lower")


def _rule(spec: Spec, confidence: float, replicates: int | None) -> str:
    """The decision rule of ``spec`` in words, with its confidence."""
    kind = "qmc" if replicates is not None and spec.statistic != PF else (
        "quantile" if spec.statistic in QUANTILES else spec.statistic)
    check, other = _sides(spec)
    return (f"one-sided {100 * confidence:g} % bounds of {spec.statistic} ({BOUND_METHODS[kind]}): "
            f"fail when the {check} bound violates the limit, pass when the {other} bound meets it")


def _outcome(spec: Spec, ev: _Evidence) -> str:
    """fail, pass or undecided from the one-sided bounds (module doc)."""
    check, other = (getattr(ev, side) for side in _sides(spec))
    if np.isfinite(check) and not spec.holds(check):
        return "fail"
    if np.isfinite(other) and spec.holds(other):
        return "pass"
    return "undecided"


def _quantile_needed(spec: Spec, ev: _Evidence, confidence: float):
    """(n, reason) for an undecided quantile of a plain Monte Carlo ensemble: the n at which the
    binomial bound decides if the share of violating realisations stays as it is."""
    n = len(ev.values)
    violating = int(np.count_nonzero(~spec.holds(ev.values)))
    p = QUANTILES[spec.statistic]
    allowed = 1 - p if spec.op in UPPER_LIMITS else p
    need = quantile_decision_n(n, violating, allowed, confidence)
    share = f"{violating} of {n} realisations violate the limit"
    if need is None:
        return None, (f"{share}, a share too close to the {allowed:g} the limit allows for any n up to "
                      f"{QUANTILE_DECISION_CAP:,} to decide")
    return need, f"{share}; at that share n = {need} decides"


def _shrinkage_needed(spec: Spec, ev: _Evidence, n: int, confidence: float,
                      replicates: int | None = None):
    """(n, reason) from the bound's 1/sqrt(n) shrinkage about an unchanged estimate; ``replicates``:
    R of a randomised QMC file, whose bounds start at other n."""
    floor = interval_floor(spec.statistic, confidence, replicates)
    if floor is None:
        return None, f"no {100 * confidence:g} % one-sided bound at any n (docs/ensembles.md)"
    bound = ev.upper if ev.estimate < spec.limit else ev.lower
    if not np.isfinite(bound):
        return max(floor, n + 1), f"no {100 * confidence:g} % one-sided bound that could decide at n = {n}"
    margin = abs(ev.estimate - spec.limit)
    if margin == 0:
        return None, "the estimate equals the limit: no sample size is expected to decide"
    side = abs(bound - ev.estimate)
    return (max(floor, n + 1, math.ceil(n * (side / margin) ** 2)),
            "the bounds lie on both sides of the limit")


def _decision(spec: Spec, ev: _Evidence, n: int, failed: int, confidence: float,
              replicates: int | None):
    """(outcome, n needed, reason) of one direction."""
    outcome = _outcome(spec, ev)
    check, other = _sides(spec)
    if outcome == "pass" and failed:
        return "undecided", None, (f"the {other} bound meets the limit, but {failed} of {n + failed} "
                                   "realisations failed and are not in it")
    if outcome == "pass":
        return outcome, None, f"the {other} bound meets the limit"
    if outcome == "fail":
        return outcome, None, f"the {check} bound violates the limit"
    if spec.statistic in QUANTILES and replicates is None and n > 0:
        return (outcome, *_quantile_needed(spec, ev, confidence))
    return (outcome, *_shrinkage_needed(spec, ev, n, confidence, replicates))


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


def _values(ds, spec: Spec):
    """The spec's variable over the finished realisations (realization, direction), in its window (SI)."""
    return finished_values(ds, spec.variable, spec.window or "whole").sel(quantity=spec.quantity)


def _level(spec: Spec, bounds, confidence: float, replicates: int | None) -> float:
    """The level ``spec``'s bounds were taken at (:func:`.estimators.bound_level`): widened for a file
    --until wrote, else the label ``confidence``."""
    return bound_level(spec.statistic, confidence, "interval_after_until" in bounds.attrs, replicates is not None)


def _resolutions(ds, quantity: str) -> dict:
    """The level's resolution per direction (:func:`.resolution.resolutions`; imported here: it draws on the
    plots' helpers)."""
    from .resolution import resolutions
    return resolutions(ds, quantity)


def _within_accuracy(spec: Spec, ev: _Evidence, res) -> str | None:
    """Why ``spec``'s limit cannot be decided at the level: it lies within the level's numerical error
    (:meth:`.resolution.Resolution.error`) of the estimate, that of the largest value for a std; else None.
    A level resolved to round-off leaves such limits (the estimate itself, to 1e-9) to the bounds' reasons."""
    if res.round_off:
        return None
    scale = float(np.max(np.abs(ev.values), initial=0.0)) if spec.statistic == "std" else ev.estimate
    band = res.error(scale)
    if not (np.isfinite(ev.estimate) and abs(spec.limit - ev.estimate) <= band):
        return None
    return (f"the limit lies within {_num(band, spec.factor)} {spec.unit} of the estimate, the level's numerical "
            f"error there (half of its resolution, {res.source}): no n decides on numerical noise")


def _judge(spec: Spec, ds, bounds) -> list[Verdict]:
    """Verdicts of one spec, one per direction, from the ensemble ``ds`` and its one-sided bounds."""
    da, values = _select(spec=spec, stats=bounds), _values(ds, spec)
    n, confidence = int(bounds.attrs["n_finished"]), float(bounds.attrs["confidence"])
    failed = int(bounds.attrs.get("n_failed", 0))
    replicates = bounds.attrs.get("qmc_replicates")
    replicates = None if replicates is None else int(replicates)
    at, res = _level(spec, bounds, confidence, replicates), _resolutions(ds, spec.quantity)
    rule = _rule(spec, at, replicates) + ("" if at == confidence else
                                          f" (for a {100 * confidence:g} % label: the run chose n by its widths)")
    out = []
    for d in spec.directions:
        ev = _Evidence(*(float(da.sel(direction=d, bound=b)) for b in ("estimate", "lower", "upper")),
                       values=values.sel(direction=d).values)
        outcome, need, reason = _decision(spec, ev, n, failed, at, replicates)
        if d in res and (noise := _within_accuracy(spec, ev, res[d])):
            outcome, need, reason = "undecided", None, noise
        out.append(Verdict(spec.text, spec.quantity, d, spec.statistic, spec.measure, spec.window or "whole",
                           spec.op, spec.limit, spec.unit, spec.factor, ev.estimate,
                           json_number(ev.lower), json_number(ev.upper),
                           confidence, n, failed, outcome, need, reason, rule))
    return out


def _pf_decision(spec: Spec, k: int, n: int, failed: int, lower: float, upper: float, confidence: float):
    """(outcome, n needed, reason) of a pf requirement from k of n exceeding and its one-sided bounds."""
    holds = (lambda p: p <= spec.pf_limit) if spec.pf_op == "<=" else (lambda p: p < spec.pf_limit)
    share = f"{k} of {n} realisations exceed the limit"
    if not holds(lower):
        return "fail", None, f"{share}: the lower bound of P violates pf {spec.pf_op} {spec.pf_limit:g}"
    if holds(upper) and failed:
        return "undecided", None, (f"the upper bound meets the limit, but {failed} of {n + failed} "
                                   "realisations failed and are not in it")
    if holds(upper):
        return "pass", None, f"{share}: the upper bound of P meets pf {spec.pf_op} {spec.pf_limit:g}"
    need = quantile_decision_n(max(n, 1), k, spec.pf_limit, confidence)
    if need is None:
        return "undecided", None, (f"{share}, a share too close to the {spec.pf_limit:g} allowed for any n "
                                   f"up to {QUANTILE_DECISION_CAP:,} to decide")
    return "undecided", need, f"{share}; at that share n = {need} decides"


def _judge_pf(spec: Spec, ds, confidence: float) -> list[Verdict]:
    """Verdicts of a pf requirement, one per direction: P(max |error| violates the limit) on
    one-sided Clopper-Pearson bounds at ``confidence``."""
    out = []
    for d in spec.directions:
        event = Event(spec.text, spec.quantity, (d,), spec.limit, spec.unit, spec.factor, spec.window or "whole")
        values = event_values(ds, event)
        n, k = len(values), int(np.count_nonzero(~spec.holds(values)))
        failed = int(ds["status"].size - n) if "status" in ds else 0
        lower, upper = (float(b) for b in one_sided_cp(k, n, confidence))
        outcome, need, reason = _pf_decision(spec, k, n, failed, lower, upper, confidence)
        out.append(Verdict(spec.text, spec.quantity, d, PF, "max", spec.window or "whole", spec.pf_op, spec.pf_limit,
                           "", 1.0, k / n if n else float("nan"), lower, upper, confidence, n, failed,
                           outcome, need, reason, _rule(spec, confidence, None)))
    return out


def judge_all(specs: list[Spec], ds, confidence: float = CONFIDENCE) -> list[Verdict]:
    """Every spec's verdicts, in the order given, on an ensemble (or single-run) Dataset at
    ``confidence``; ValueError names a window the file lacks, a confidence not above 0.5, or a pf
    requirement on a QMC file."""
    if not specs:
        return []
    check_confidence(confidence)
    for s in specs:
        try:
            check_window_samples(ds, s.window or "whole")
        except ValueError as exc:
            raise ValueError(f"--require {s.text!r}: {exc}") from None
    bounds = ensemble_stats(ds, confidence, window=None, one_sided=True)
    exact = one_run_repeated(ds)
    return [_exact(v, s, ds) if exact else v for s in specs
            for v in (_judge_pf(s, ds, confidence) if s.statistic == PF else _judge(s, ds, bounds))]


EXACT_RULE = "exact: the level draws nothing on this scene, so every realisation is the same run"


def _exact(v: Verdict, spec: Spec, ds) -> Verdict:
    """Verdict ``v`` of ``spec`` decided by the one run's value (the std of identical runs is 0; pf is 0
    or 1)."""
    from dataclasses import replace
    if v.statistic == PF:
        value, holds = v.estimate, (v.estimate <= v.limit if v.op == "<=" else v.estimate < v.limit)
    else:
        value = 0.0 if v.statistic == "std" else float(_values(ds, spec).sel(direction=v.direction).values[0])
        holds = bool(spec.holds(value))
    return replace(v, estimate=value, lower=value, upper=value, outcome="pass" if holds else "fail",
                   n_needed=None, reason="the one run's value meets the limit" if holds else
                   "the one run's value violates the limit", rule=EXACT_RULE)


def judge(spec: Spec, ds, confidence: float = CONFIDENCE) -> list[Verdict]:
    """Verdicts of one spec, one per direction (see :func:`judge_all`)."""
    return judge_all([spec], ds, confidence)


def exit_code(verdicts: list[Verdict], undecided: str | None = None) -> int:
    """0 when every verdict passes, 1 when any fails, else 3 (some undecided); ``undecided`` 'pass'
    or 'fail' counts undecided verdicts as that (exit 0 or 1)."""
    worst = overall(verdicts) if verdicts else "pass"
    if worst == "undecided" and undecided is not None:
        worst = undecided
    return EXIT_CODES[worst]


def _num(value: float | None, factor: float, limit: float | None = None) -> str:
    """``value`` in the spec's unit to 4 significant digits, or as many more (up to 12) as tell it from
    ``limit``: a bound of 1.0003 mm against a 1 mm limit must not read '1'."""
    if value is None:
        return "-"
    for digits in range(4, 13):
        text = f"{value / factor:.{digits}g}"
        if limit is None or value == limit or text != f"{limit / factor:.{digits}g}":
            return text
    return text


def start_up_note(verdicts: list[Verdict], ds) -> str | None:
    """A line for the verdicts judged over the whole run of a contact-level file: its maxima include the
    start-up window, where the joints settle onto their walls, not the robot in operation (None if none)."""
    from rss6core import model_level
    model = ds.attrs.get("model")
    whole = sorted({v.spec for v in verdicts if v.window == "whole"})
    if not whole or model is None or not model_level(str(model)).contact_joints:
        return None
    after = ds.attrs.get("steady_after_s")
    until = f"t < {float(after):g} s, " if after is not None else ""
    return (f"note: {', '.join(repr(s) for s in whole)} judged over the whole run, whose {model}-level maxima "
            f"include start-up ({until}the joints settling onto their walls); append '/steady' to judge the robot "
            "in operation")


def verdicts_with_note(verdicts: list[Verdict], ds) -> str:
    """The verdicts' table (:func:`format_verdicts`) and, for a contact-level file judged over the whole
    run, the :func:`start_up_note` below it: what ``rss6 run`` and ``rss6 stats`` print."""
    startup = start_up_note(verdicts, ds)
    return format_verdicts(verdicts) + (f"\n{startup}" if startup else "")


def format_verdicts(verdicts: list[Verdict]) -> str:
    """A table in each spec's own unit: spec, direction, window, bounds, limit, verdict, n to decide
    (the spec column as wide as the longest spec: a cut spec ran into its direction)."""
    if not verdicts:
        return ""
    width = max(40, 1 + max(len(v.spec) for v in verdicts))
    conf = f"{100 * verdicts[0].confidence:g} %"
    failed = verdicts[0].n_failed
    wider = any(v.statistic in ("mean", "std") for v in verdicts)
    rule = ("exact: every realisation is the same run, whose value decides" if all(v.rule == EXACT_RULE
            for v in verdicts) else f"one-sided {conf} bounds" + (
            " (a mean's or std's wider where a one-sided one falls short of its label: docs/ensembles.md)"
            if wider else "") + ": fail when the bound on the limit's side violates it, pass when the other "
            "bound meets it")
    lines = [f"requirements ({rule}; n = {verdicts[0].n} finished realisations"
             + (f"; {failed} failed, so a limit they meet is undecided" if failed else "")
             + "; estimate and bounds in the unit of the spec's limit)",
             f"{'spec':<{width}s}{'dir':<4s}{'window':<9s}{'estimate':>11s}{'bounds':>24s}  {'limit':>14s}  "
             f"{'verdict':<10s}n to decide"]
    for v in verdicts:
        bounds = f"[{_num(v.lower, v.factor, v.limit)}, {_num(v.upper, v.factor, v.limit)}]"
        estimate = _num(v.estimate, v.factor, v.limit)
        lines.append(f"{v.spec:<{width}s}{v.direction:<4s}{v.window or 'whole':<9s}{estimate:>11s}{bounds:>24s}  "
                     f"{v.op + ' ' + _num(v.limit, v.factor) + ' ' + v.unit:>14s}  {v.outcome:<10s}{_to_decide(v)}")
    counts = ", ".join(f"{sum(v.outcome == o for v in verdicts)} {o}" for o in OUTCOMES)
    lines.append(f"verdict: {overall(verdicts)} ({counts})")
    return "\n".join(lines)


def _to_decide(v: Verdict) -> str:
    """The 'n to decide' cell: empty for a decided verdict, the n that would likely decide, else '-' and why
    none is given (the reason the JSON carries)."""
    if v.outcome != "undecided":
        return ""
    return str(v.n_needed) if v.n_needed else f"- ({v.reason})"


def overall(verdicts: list[Verdict]) -> str:
    """The worst outcome of all verdicts (fail over undecided over pass)."""
    return max((v.outcome for v in verdicts), key=OUTCOMES.index)


def verdicts_json(verdicts: list[Verdict]) -> list[dict]:
    """Plain dicts (SI values, in ``si_unit``; None where a bound or the estimate does not exist) for ``--json``
    and file attributes; the spec's own unit is ``spec_unit``, ``factor`` SI units each."""
    records = []
    for v in verdicts:
        record = json_record(v)
        record["spec_unit"] = record.pop("unit")
        record["si_unit"] = si_unit(v.quantity, v.direction)
        records.append(record)
    return records
