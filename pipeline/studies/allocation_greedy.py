"""``rss6 allocate`` at a level whose error is not linear in the clearances (paper, contact): a greedy
search of measured ensembles with a bound on their number.

It assumes a cheaper class errs at least as much (the verdict changes once along each family's class
order, as ``rss6 budget``'s sweep assumes).  First the uniform choices (one class name for every
family, in rising cost) are bisected: the dearest must pass (else the spec is out of reach), the
cheapest is tried next, then the middle of the bracket until the cheapest passing uniform class is
found (about log2 of the classes' number of ensembles), which is also the baseline the saving is
stated against.  From there, the one-step loosenings (a family moved to its next strictly cheaper
class) are tried in order of the cost they save, an ensemble each, and the first that passes every
spec at the gate is kept; a family whose loosening failed is not loosened again (by the assumption it would
fail with the others looser too).  It stops when no family can be loosened or the ensemble budget is
spent; it is greedy, so it may stop above the least cost, and says so.  The passing ensemble of the
answer is its verification.
"""
from __future__ import annotations

from pathlib import Path

from ..analysis.spec import Spec
from ..ensemble.run import EnsembleSpec
from .allocation import ALLOCATED, Allocation, AllocationError, allocated_scene, check_request, cost_of
from .trial import Trial, run_trial

__all__ = ["greedy_allocate"]


class _Runner:
    """Runs (or resumes) the ensemble of a class combination, counting them against the budget."""

    def __init__(self, spec: EnsembleSpec, specs, n: int, folder: Path, confidence: float, workers: int,
                 budget: int):
        self.spec, self.specs, self.n, self.folder = spec, specs, n, folder
        self.confidence, self.workers, self.budget = confidence, workers, budget
        self.trials: dict[tuple, Trial] = {}

    @property
    def left(self) -> int:
        return self.budget - len(self.trials)

    def __call__(self, combo) -> Trial:
        key = tuple(c.name for c in combo)
        if key not in self.trials:
            text = allocated_scene(self.spec.scene_text, self.spec.source, combo)
            name = "_".join(k.replace("/", "") for k in key)
            path = self.folder / f"{self.spec.scene().name}_{self.spec.model}_{name}.nc"
            self.trials[key] = run_trial(self.spec, text, combo, self.specs, self.n, path, self.confidence,
                                         self.workers)
        return self.trials[key]


def _loosenings(combo, ranked: dict, frozen: frozenset = frozenset()) -> list[tuple]:
    """The one-step cheaper combinations of the families not in ``frozen``, most cost saved first: each
    family to its next strictly cheaper class (a class costing the same as a tighter one saves nothing)."""
    out = []
    for k, family in enumerate(ALLOCATED):
        cheaper = [c for c in ranked[family] if c.cost < combo[k].cost]
        if family not in frozen and cheaper:
            out.append(combo[:k] + (cheaper[0],) + combo[k + 1:])
    return sorted(out, key=cost_of)


def _descend(run: _Runner, start: Trial, ranked: dict) -> Trial:
    """Greedy loosening from ``start`` while the budget lasts, freezing a family once its loosening fails."""
    best, frozen = start, set()
    while run.left > 0:
        for candidate in _loosenings(best.candidate, ranked, frozenset(frozen)):
            if run.left <= 0:
                break
            trial = run(candidate)
            if trial.passed:
                best = trial
                break
            frozen.add(ALLOCATED[next(k for k, c in enumerate(candidate) if c != best.candidate[k])])
        else:
            break
    return best


def uniform_combos(options: dict) -> list[tuple]:
    """The combinations naming one class for every family (a name every family offers), dearest first."""
    names = [c.name for c in options[ALLOCATED[0]]
             if all(any(o.name == c.name for o in options[f]) for f in ALLOCATED)]
    combos = [tuple(next(c for c in options[f] if c.name == n) for f in ALLOCATED) for n in names]
    return sorted(combos, key=lambda c: -cost_of(c))


def _bisect_uniform(run: _Runner, combos: list[tuple]) -> Trial | None:
    """The cheapest passing uniform trial: the dearest, the cheapest, then bisection of the bracket
    (module doc); None if the dearest fails or the budget ends before the bracket closes."""
    if not run(combos[0]).passed:
        return None
    good, bad = 0, len(combos)
    if len(combos) > 1 and run.left > 0:
        if run(combos[-1]).passed:
            return run(combos[-1])
        bad = len(combos) - 1
    while bad - good > 1 and run.left > 0:
        mid = (good + bad) // 2
        good, bad = (mid, bad) if run(combos[mid]).passed else (good, mid)
    return run(combos[good]) if bad - good == 1 else None


def _out_of_reach(spec: EnsembleSpec, start: Trial):
    """AllocationError: the dearest classes fail; name the worst direction's bound."""
    worst = max(start.verdicts, key=lambda v: (v.outcome != "pass", (v.upper or float("inf")) / v.limit))
    raise AllocationError(f"--spec {worst.spec!r}: the most expensive classes do not meet it at the {spec.model} "
                          f"level (the {worst.direction} {worst.statistic} bound is "
                          f"{'none' if worst.upper is None else f'{worst.upper / worst.factor:.4g}'} {worst.unit}, "
                          f"{worst.outcome}; {start.path})")


def greedy_allocate(spec: EnsembleSpec, specs: list[Spec], n: int, folder, confidence: float, options: dict,
                    workers: int = 2, max_ensembles: int = 12) -> Allocation:
    """The greedy allocation (module doc) with at most ``max_ensembles`` ensembles."""
    check_request(spec, specs, n, confidence)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    ranked = {f: sorted(options[f], key=lambda c: -c.cost) for f in ALLOCATED}
    run = _Runner(spec, specs, n, folder, confidence, workers, max_ensembles)
    start = run(tuple(ranked[f][0] for f in ALLOCATED))
    if not start.passed:
        _out_of_reach(spec, start)
    uniforms = uniform_combos(options)
    uniform = _bisect_uniform(run, uniforms) if uniforms else None
    cheapest = min((t for t in run.trials.values() if t.passed), key=lambda t: cost_of(t.candidate))
    best = _descend(run, uniform or cheapest, ranked)
    scene_path = folder / f"{spec.scene().name}_allocated.toml"
    scene_path.write_text(allocated_scene(spec.scene_text, spec.source, best.candidate))
    predicted = {s.text: max((v.upper for v in best.verdicts if v.spec == s.text and v.upper is not None),
                             default=float("nan")) for s in specs}
    uniform = None if uniform is None else uniform.candidate
    return Allocation(best.candidate, cost_of(best.candidate), uniform, None if uniform is None else cost_of(uniform),
                      len(run.trials), best.verdicts, predicted, best.path, scene_path,
                      method=f"greedy loosening, {len(run.trials)} of at most {max_ensembles} ensembles "
                             "(not proven least-cost)")
