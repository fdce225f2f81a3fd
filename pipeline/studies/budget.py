"""``rss6 budget``: the largest common clearance scale factor for which requirement specs pass.

A spec passes at the run's confidence when its statistic's one-sided upper bound meets the
limit (pipeline.analysis.gate), so for an upper limit the answer is the largest scale s at which that
upper bound is within it, with every [clearance] size of the scene times s.

- quasi-static: exact scaling from one ensemble.  Every draw law scales with the clearance
  sizes on the same uniforms (truncated normals in units of the size, k times the size), so
  the eccentricities of each realisation are s times those at s = 1, and the linear closure
  (with the eccentricities drawn, or set by the sizes along the joint forces) makes its
  error s times as large.  Every per-realisation maximum and mean |error| is then s times
  as large, and so is every bound rss6 gives: quantile bounds are order statistics, and
  the mean and std bounds are location-scale equivariant (the skewness and kurtosis that
  enter them do not change).  Hence upper(s) = s upper(1) and s* = min(limit / upper(1)).
- other levels, a scene with [uncertain.*] inputs at any level (its realised robots' geometric
  error does not scale with the clearances), and pf specs (a count of exceedances, not a bound that
  scales): a measured sweep: ensembles of the same realisations (same seed) at
  scales doubled or halved from 1 until one passes and one does not, then bisection to the
  stated relative tolerance; the answer is the largest scale whose ensemble passed.  It
  assumes the verdict changes once along the scale (errors grow with the clearance).

The factor is rounded down to 4 significant digits, so a run at the printed clearances
passes too (the gate compares the upper bound with the limit, and a factor that equals
limit / upper up to rounding could land a hair above it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from rss6core import model_level, models_with

from ..analysis.gate import Verdict, upper_limits_problem
from ..ensemble.run import EnsembleSpec
from ..scenes.variant import scene_variant
from ..analysis.spec import PF, Spec
from ..vocabulary import CONFIDENCE, UserError, window_words
from .trial import SELECTION_NOTE, Trial, run_trial

__all__ = ["FAMILY_KEYS", "Budget", "scaled_scene", "exact_scale", "budget", "format_budget",
           "BudgetError"]

FAMILY_KEYS = ("revolute_radial_m", "revolute_axial_m", "spherical_C_m", "spherical_B_m")
DIGITS = 4            # significant digits the factor is rounded down to
MAX_DOUBLINGS = 12    # the sweep looks for a passing and a failing scale within 2^-12..2^12


class BudgetError(UserError):
    """A budget that cannot be computed (a lower-limit spec, no interval at this n, zero error)."""


@dataclass(frozen=True)
class Budget:
    """The answer: scale factor, how it was found, the clearances (m) it gives, and the trials
    (for exact scaling: the ensemble at scale 1 and the check at the answer)."""
    scale: float
    method: str
    clearances: dict
    confidence: float
    n: int
    trials: tuple[Trial, ...]
    limiting: str
    scene_path: Path


def round_down(x: float, digits: int = DIGITS) -> float:
    """x > 0 rounded towards zero to ``digits`` significant digits."""
    step = 10.0 ** (math.floor(math.log10(x)) - digits + 1)
    return math.floor(x / step * (1 + 1e-12)) * step


def scaled_scene(spec: EnsembleSpec, scale: float) -> tuple[str, dict]:
    """The scene text with every [clearance] size times ``scale``, and those sizes (m)."""
    cl = spec.scene().clearance
    sizes = {k: scale * getattr(cl, k.removesuffix("_m")) for k in FAMILY_KEYS}
    return scene_variant(spec.scene_text, {"clearance": sizes}, spec.source), sizes


def geometric_limit(scene) -> float:
    """The clearance scale at which the first clearance, or with a [sampling] size_tolerance its
    largest draw, would reach its joint's radius, which the scene check refuses
    (rss6core.CLEARANCE_RADII, RELATIVE_BAND_REACH); inf without clearances."""
    from rss6core import CLEARANCE_RADII, RELATIVE_BAND_REACH
    c, ct = scene.clearance, scene.contact
    reach = RELATIVE_BAND_REACH if scene.sampling.size_tolerance > 0 else 1.0
    return min((getattr(ct, r.removesuffix("_m")) / (reach * getattr(c, k.removesuffix("_m")))
                for k, r in CLEARANCE_RADII.items() if getattr(c, k.removesuffix("_m")) > 0), default=math.inf)


def _check_scene(spec: EnsembleSpec) -> None:
    """BudgetError for a scene whose sizes a [clearance] scale would not move: a family whose
    [tolerance.<family>] band (absolute limits, m) draws them. A relative [sampling] size_tolerance
    scales with the nominal size, so it does not stop a budget."""
    drawn = [i.name for i in spec.scene().uncertain.inputs if i.parameter.startswith("clearance.")]
    if drawn:
        raise BudgetError(f"{spec.source}: [uncertain.{drawn[0]}] draws clearance sizes about the [clearance] "
                          "values, which a clearance budget (a scale on those values) would not scale alike; "
                          "budget the scene without that table")
    tolerance = spec.scene().tolerance
    banded = [k.removesuffix("_m") for k in FAMILY_KEYS if getattr(tolerance, k.removesuffix("_m")) is not None]
    if banded:
        raise BudgetError(f"{spec.source}: [tolerance.{banded[0]}] draws its clearance sizes from a band "
                          "of fixed limits, which a clearance budget (a scale on the [clearance] sizes) "
                          "cannot move; budget the scene without its [tolerance.*] tables")


def _check_request(model: str, specs: list[Spec], n: int, confidence: float) -> None:
    """BudgetError for a request no budget can answer, before any ensemble runs."""
    if not model_level(model).draws_clearances:
        *others, last = models_with("draws_clearances")
        raise BudgetError(f"--model {model}: this level has no clearances, so no clearance budget; "
                          f"use {', '.join(others)} or {last}")
    if why := upper_limits_problem(specs, confidence, n, "a budget"):
        raise BudgetError(why)


def _trial(spec: EnsembleSpec, specs, scale: float, n: int, folder: Path, confidence: float,
           workers: int) -> Trial:
    """Run (or resume) the ensemble at ``scale`` and judge the specs on it (the trial's candidate: ``scale``)."""
    text, _ = scaled_scene(spec, scale)
    path = folder / f"{spec.scene().name}_{spec.model}_scale{scale:.6g}.nc"
    return run_trial(spec, text, scale, specs, n, path, confidence, workers)


def exact_scale(verdicts: list[Verdict]) -> tuple[float, str]:
    """(min over specs and directions of limit / upper bound, the limiting one) for a level whose
    error is proportional to the clearance scale (module doc)."""
    best = None
    for v in verdicts:
        if v.upper is None:
            raise BudgetError(f"--spec {v.spec!r}: no {100 * v.confidence:g} % upper bound of {v.statistic} "
                              f"at n = {v.n} ({v.reason}); raise -n")
        if not v.upper > 0:
            raise BudgetError(f"--spec {v.spec!r}: the {v.direction} error is zero at scale 1; any "
                              "clearance meets it")
        ratio = v.limit / v.upper
        if best is None or ratio < best[0]:
            statistic = v.statistic + (":mean" if v.measure == "mean" else "")   # of the mean |error|: as the spec
            best = (ratio, f"{v.quantity} {v.direction} {statistic} ({window_words(v.window)}): upper bound "
                           f"{v.upper / v.factor:.4g} {v.unit} at scale 1, limit {v.limit / v.factor:.4g} {v.unit}")
    return best


def _sweep(run, tolerance: float) -> list[Trial]:
    """Trials of a doubling/halving search from 1, then bisection until (hi - lo) / lo <= tolerance."""
    trials = [run(1.0)]
    factor = 2.0 if trials[0].passed else 0.5
    while all(t.passed for t in trials) or not any(t.passed for t in trials):
        if len(trials) > MAX_DOUBLINGS:
            kind = "passes" if trials[0].passed else "fails"
            raise BudgetError(f"the spec still {kind} at clearance scale {trials[-1].candidate:g}; "
                              "no budget in 2^-12..2^12" + ("" if trials[0].passed else
                                                            " (an error no clearance scale removes, such as a "
                                                            "realised robot's geometric error, exceeds it)"))
        trials.append(run(trials[-1].candidate * factor))
    lo = max(t.candidate for t in trials if t.passed)
    hi = min(t.candidate for t in trials if not t.passed and t.candidate > lo)
    while (hi - lo) / lo > tolerance:
        t = run(round_down(math.sqrt(lo * hi)))
        trials.append(t)
        lo, hi = (t.candidate, hi) if t.passed else (lo, t.candidate)
    return trials


def _not_passing(t: Trial) -> str:
    """How a trial that does not pass ended: it fails (a spec's bound violates its limit) or it is
    undecided at this n (no spec fails, one's interval straddles its limit)."""
    return "fails" if any(v.outcome == "fail" for v in t.verdicts) else "is undecided at this n"


def budget(spec: EnsembleSpec, specs: list[Spec], n: int, folder, confidence: float = CONFIDENCE,
           workers: int = 2, tolerance: float = 0.05) -> Budget:
    """The largest common clearance scale factor for which every spec passes (module doc)."""
    _check_request(spec.model, specs, n, confidence)
    _check_scene(spec)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)

    limit = geometric_limit(spec.scene())

    def run(scale: float) -> Trial:
        if scale >= limit:
            raise BudgetError(f"the specs pass beyond the joints' geometry: at clearance scale {scale:g} a "
                              f"clearance would reach its joint's [contact] radius (from scale {limit:.4g}), "
                              "so they set no clearance budget")
        return _trial(spec, specs, scale, n, folder, confidence, workers)

    if model_level(spec.model).linear_in_clearances and not spec.scene().uncertain and \
            not any(s.statistic == PF for s in specs):
        first = run(1.0)
        ratio, limiting = exact_scale(list(first.verdicts))
        scale = round_down(ratio)
        trials = (first, run(scale))
        if not trials[-1].passed:   # the scaling argument of the module doc failed
            raise RuntimeError(f"the ensemble at the exact scale {scale:g} does not pass: {trials[-1].path}")
        method = ("exact scaling from the ensemble at scale 1, the level being linear in the "
                  "clearance; checked by an ensemble at the answer on the same draws: a check of the "
                  "scaling, not a fresh sample")
    else:
        trials = tuple(_sweep(run, tolerance))
        scale = max(t.candidate for t in trials if t.passed)
        above = min((t for t in trials if not t.passed and t.candidate > scale), key=lambda t: t.candidate)
        limiting = f"scale {scale:.{DIGITS}g} passes, {above.candidate:.{DIGITS}g} {_not_passing(above)}"
        method = f"measured sweep (doubling, then bisection to {100 * tolerance:g} % in the scale)"
    text, sizes = scaled_scene(spec, scale)
    scene_path = folder / f"{spec.scene().name}_budget.toml"
    scene_path.write_text(text)
    return Budget(scale, method, sizes, confidence, n, trials, limiting, scene_path)


def format_budget(b: Budget, scene_name: str, model: str, fresh_check: str) -> str:
    """The answer as lines: factor, method, clearances per family, the trials' verdicts, and that the
    answer's pass is on the draws that chose it (:data:`.trial.SELECTION_NOTE`) with ``fresh_check``."""
    lines = [f"clearance budget: scene {scene_name}, {model} level, n = {b.n} realisations per "
             f"ensemble, one-sided {100 * b.confidence:g} % bounds (a spec passes when its upper "
             "bound is within the limit)",
             f"largest common clearance scale factor: {b.scale:.{DIGITS}g} ({b.method})",
             f"limiting: {b.limiting}",
             "clearances at this factor: " + ", ".join(f"{k.removesuffix('_m')} {v * 1e3:.6g} mm"
                                                       for k, v in b.clearances.items()),
             f"scene at these clearances: {b.scene_path}",
             "ensembles run (scale: verdict, file):"]
    for t in b.trials:
        worst = "pass" if t.passed else ("fail" if any(v.outcome == "fail" for v in t.verdicts)
                                         else "undecided")
        answer = " (the answer, on the draws that chose it)" if t.candidate == b.scale and t.passed else ""
        lines.append(f"  {t.candidate:.{DIGITS}g}: {worst}{answer}, {t.path}")
    lines.append(SELECTION_NOTE.format(what="pass at the answer") + f"{SELECTION_WHY[b.method.startswith('exact')]}; "
                 f"a fresh check: {fresh_check}")
    return "\n".join(lines)


# why the pass at the answer is optimistic: exact scaling puts the bound on the limit by construction,
# the sweep keeps the largest scale that passed on one seed
SELECTION_WHY = {True: " (exact scaling puts the limiting bound on the limit, so fresh draws often come back "
                       "undecided)",
                 False: " (the sweep keeps the largest scale that passed on this seed)"}
