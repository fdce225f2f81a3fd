"""``rss6 reliability``: the probability that a level's maximum |error| exceeds a limit, by subset
simulation (pipeline.analysis.subset) or plain Monte Carlo, in the standard normal space of the
realisation's random inputs.

A realisation of a level is a function of a vector of uniforms u (the clearance draw's
``uniform_dimension`` eccentricity and size uniforms, then the [uncertain.*] inputs' ones); the
space of the estimators is z = Phi^-1(u) of that whole vector, so u = Phi(z) (clipped below 1).
A realisation that fails numerically counts as exceeding the limit (its response is +inf), the
conservative reading.  Batches of rows are evaluated in this process, or in chunks on the dask
workers of pipeline.ensemble.cluster when a batch is large.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
import xarray as xr
from scipy import stats as sps

from rss6core import (FINISHED, SIZE_UNIFORMS, UNIFORM_BLOCKS, clearances_from_named_uniforms, clearances_from_uniforms,
                      inputs_from_uniforms, model_level, prepare_level, size_band, uniform_dimension)

from ..analysis.estimators import clopper_pearson
from ..analysis.exceedance import Event
from ..analysis.spec import si_unit
from ..analysis.subset import SubsetSettings, check_estimate_end, subset_simulation
from ..ensemble.cluster import WORKER_TIMEOUT_S, optional_client, results_as_finished
from ..files.records import window_summaries
from ..files.writing import sigint_deferred
from ..vocabulary import CONFIDENCE, DIRECTIONS, QUANTITIES, UNMEASURED_LEVEL, WINDOWS, UserError, at_measured_level

__all__ = ["ReliabilityError", "Estimate", "input_dimension", "input_labels", "physical_inputs", "what_fails",
           "evaluate", "reliability", "check_subset_budget", "subset_levels_within", "estimate_from_dataset",
           "largest_response",
           "reliability_dataset", "coverage_note", "METHODS", "MC_BLOCK", "IN_PROCESS_ROWS"]

METHODS = ("subset", "mc")
MC_BLOCK = 1000          # plain Monte Carlo draws block b of z from SeedSequence([seed, MC_TAG, b])
MC_TAG = 40404040
IN_PROCESS_ROWS = 64     # batches up to this many rows of a cheap level are evaluated here, larger ones on the workers
DEFAULT_BUDGET = {"subset": 20_000, "mc": 200_000}   # evaluations at most with a CoV target (--budget)
_ONE_BELOW = np.nextafter(1.0, 0.0)


class ReliabilityError(UserError):
    """A reliability request that cannot be answered (no random inputs at that level)."""


@dataclass(frozen=True)
class Estimate:
    """P of the event, its CoV estimate, interval at ``confidence`` and how it was obtained; every
    evaluation's z (E, d), level (E,) and maxima |error| (E, quantity, direction) in the event's window."""

    method: str
    pf: float
    lower: float
    upper: float
    confidence: float
    cov: float
    interval: str
    evaluations_per_level: tuple[int, ...]
    thresholds: tuple[float, ...]
    status: str
    message: str
    z: np.ndarray
    level: np.ndarray
    maxima: np.ndarray

    def __post_init__(self):
        check_estimate_end(self.status)   # vocabulary.ESTIMATE_ENDS

    def summary(self) -> dict:
        """The JSON fields (SI thresholds)."""
        return {"method": self.method, "pf": self.pf, "lower": self.lower, "upper": self.upper,
                "confidence": self.confidence, "cov": self.cov, "evaluations": int(self.level.size),
                "evaluations_per_level": list(self.evaluations_per_level), "thresholds": list(self.thresholds),
                "interval": self.interval, "status": self.status, "message": self.message}


def coverage_note(est: Estimate) -> str | None:
    """Why a subset interval at a label other than 95 % has no measured coverage: its log-normal interval and the
    floor of MIN_N_INTERVAL draws per level were measured with 95 % intervals only (docs/reliability.md,
    benchmarks/subset_verification.py); None at 95 % and for the exact binomial (Clopper-Pearson) intervals of
    plain Monte Carlo and of a level 0 that decides, which hold at any level."""
    from ..analysis.subset import MIN_N_INTERVAL
    if est.method != "subset" or est.interval.startswith("exact binomial") or at_measured_level(est.confidence):
        return None
    return (f"{100 * est.confidence:g} % interval: {UNMEASURED_LEVEL} (docs/reliability.md, python "
            f"benchmarks/subset_verification.py; so is its floor of {MIN_N_INTERVAL} draws per level); --method mc's "
            "exact interval holds at any level")


def input_dimension(scene, model: str, source: str = "") -> int:
    """How many standard normal inputs a realisation of ``model`` on ``scene`` takes; ReliabilityError
    for a level that draws none (or redraws its clearances every step, an unbounded dimension)."""
    kind = model_level(model)
    if kind.redraws_every_step:
        raise ReliabilityError(f"--model {model}: the level redraws its clearances every step, so its "
                               "random inputs grow with the steps; use quasi-static or contact")
    if scene.uncertain:   # the core reads them after a clearance draw's uniforms, at every level
        return uniform_dimension(None, scene)
    if not kind.draws_clearances:
        raise ReliabilityError(f"{source or scene.name}: a scene with no uncertain input at the {model} level "
                               "(it draws no clearances and has no [uncertain.*] table): nothing to be probable")
    return uniform_dimension(None)


def input_labels(scene, model: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(label, family) of every standard normal input of a realisation, in the order of
    :func:`input_dimension`: the clearance draw's blocks of six uniforms (legs 1-6; the four size
    blocks, then the eccentricity blocks the draw takes), then the [uncertain.*] draws (family: the
    input's name); inputs that no draw takes, and the size uniforms of a family whose sizes are nominal
    (taken but not used), are in family 'unused': their shift shows the noise of the estimate."""
    labels, families = [], []
    if model_level(model).draws_clearances:
        nominal = {block for block, family in zip(UNIFORM_BLOCKS, CLEARANCE_FAMILIES)
                   if size_band(scene, family) is None}
        for block in UNIFORM_BLOCKS[:SIZE_UNIFORMS // 6] + _eccentricity_blocks(scene):
            labels += [f"{block}[leg {i}]" for i in range(1, 7)]
            families += ["unused" if block in nominal else block] * 6
    _pad(labels, families, uniform_dimension(None) if scene.uncertain else len(labels))
    if scene.uncertain:
        labels += list(scene.uncertain.labels())
        families += list(scene.uncertain.columns(lambda i: i.name))
    _pad(labels, families, input_dimension(scene, model))
    return tuple(labels), tuple(families)


# the joint families of the four size blocks, in their order (rss6core.clearance.FAMILIES, not exported)
CLEARANCE_FAMILIES = ("revolute_radial", "revolute_axial", "spherical_C", "spherical_B")


def _pad(labels: list, families: list, size: int) -> None:
    labels += [f"unused[{k}]" for k in range(len(labels), size)]
    families += ["unused"] * (size - len(families))


def _eccentricity_blocks(scene) -> tuple[str, ...]:
    """The eccentricity blocks of UNIFORM_BLOCKS a clearance draw of ``scene`` takes, in its order (a
    point law takes none): asked of rss6core's draw by name, one missing block at a time."""
    given, order = {block: np.full(6, 0.5) for block in UNIFORM_BLOCKS[:SIZE_UNIFORMS // 6]}, []
    for _ in UNIFORM_BLOCKS:
        try:
            clearances_from_named_uniforms(scene, given)
            return tuple(order)
        except ValueError as exc:
            missing = re.search(r"uniforms '(\w+)'", str(exc))
            if missing is None or missing.group(1) in given:
                raise
            given[missing.group(1)] = np.full(6, 0.5)
            order.append(missing.group(1))
    raise ValueError("the clearance draw asks for more blocks than UNIFORM_BLOCKS holds")


def physical_inputs(scene, model: str, z: np.ndarray) -> list[tuple[str, tuple[float, ...], str]]:
    """(name, values, unit) of the realisation at z: its clearance sizes and eccentricity magnitudes,
    legs 1-6 (m), and each [uncertain.*] input's draws (its units: SI deviations, or factors)."""
    u = np.minimum(sps.norm.cdf(np.asarray(z, float)), _ONE_BELOW)
    rows, offset = [], uniform_dimension(None)
    if model_level(model).draws_clearances:
        d = clearances_from_uniforms(scene, u[:offset])
        for name, values in (("A_radial_size", d.radial_size), ("A_axial_size", d.axial_size), ("C_size", d.size_C),
                             ("B_size", d.size_B), ("|e_A|", np.linalg.norm(d.e_A, axis=1)),
                             ("|e_C|", np.linalg.norm(d.e_C, axis=1)), ("|e_B|", np.linalg.norm(d.e_B, axis=1))):
            rows.append((f"{name} (legs 1-6)", tuple(map(float, values)), "m"))
    if scene.uncertain and u.size >= offset + scene.uncertain.dimension:
        drawn = inputs_from_uniforms(scene.uncertain, u[offset:offset + scene.uncertain.dimension])
        rows += [(i.name, tuple(map(float, drawn.of(i.name))), i.draw_units) for i in scene.uncertain.inputs]
    return rows


def what_fails(est: "Estimate", event: Event, scene, model: str):
    """The failure domain of a reliability estimate (pipeline.analysis.failure_domain) and the
    physical inputs of its most probable failing realisation; None when no evaluation failed."""
    from ..analysis.failure_domain import failure_domain
    failing = _response(event, est.maxima) > event.limit
    if not failing.any():
        return None, []
    labels, families = input_labels(scene, model)
    fd = failure_domain(est.z, est.level, failing, labels, families)
    return fd, physical_inputs(scene, model, fd.most_probable_z)


def _evaluate_rows(spec, window: str, z: np.ndarray) -> np.ndarray:
    """Maxima |error| (rows, quantity, direction), SI, over ``window`` of the level at rows z; NaN
    for a realisation that failed."""
    scene = spec.scene()
    sim = scene.simulation
    level = prepare_level(scene, spec.model, spec.integrator, spec.dt, spec.elements)
    u = np.minimum(sps.norm.cdf(z), _ONE_BELOW)
    results = level.simulate(0, range(len(u)), lambda r, dim: u[r][:dim])
    k = WINDOWS.index(window)
    return np.stack([window_summaries(r, sim.settle_time, sim.steady_after)[0][k] if r.status == FINISHED
                     else np.full((len(QUANTITIES), len(DIRECTIONS)), np.nan) for r in results])


def evaluate(spec, window: str, z: np.ndarray, client=None) -> np.ndarray:
    """:func:`_evaluate_rows` of a batch, in chunks on ``client``'s workers when it is large, or
    always for a level that integrates the links (a second or so per row at the contact level:
    a subset level's chains, a few dozen rows a step, would otherwise run one by one here)."""
    dear = model_level(spec.model).elastic_links
    if client is None or (len(z) <= IN_PROCESS_ROWS and not dear):
        return _evaluate_rows(spec, window, z)
    workers = max(1, len(client.nthreads()))
    chunk = -(-len(z) // workers) if dear else max(IN_PROCESS_ROWS // 4, -(-len(z) // (4 * workers)))
    parts = [slice(i, min(i + chunk, len(z))) for i in range(0, len(z), chunk)]
    with sigint_deferred() as interrupted:   # Ctrl-C acted on between waits, never inside dask's client
        # the rows go with each task, not scattered: a worker that dies takes scattered rows with it and
        # its dependants are cancelled, while a task that carries its rows is simply run again
        futures = [client.submit(_evaluate_part, spec, window, z[p], k, pure=False) for k, p in enumerate(parts)]
        got = {part["index"]: part["maxima"]
               for part in results_as_finished(client, futures, None, WORKER_TIMEOUT_S, interrupted)}
    return np.concatenate([got[k] for k in range(len(parts))])


def _evaluate_part(spec, window: str, rows: np.ndarray, index: int) -> dict:
    """One task of :func:`evaluate`: the maxima of its rows, with the part's index (results come back in
    the order they finish)."""
    return {"index": index, "maxima": _evaluate_rows(spec, window, rows)}


def _response(event: Event, maxima: np.ndarray) -> np.ndarray:
    """The event's maximum |error| per row (SI; the largest over its directions); +inf where the
    realisation failed."""
    r = maxima[:, QUANTITIES.index(event.quantity), [DIRECTIONS.index(d) for d in event.directions]]
    return np.where(np.isnan(r).any(axis=-1), np.inf, r.max(axis=-1))


def largest_response(est: "Estimate", event: Event) -> float:
    """The largest response the estimate's evaluations reached (SI; +inf when a realisation failed): against the
    limit, whether the event was ever approached."""
    return float(_response(event, est.maxima).max()) if est.level.size else float("nan")


def _batches(spec, window: str, client, checkpoint):
    """The function evaluating a batch of rows z: through ``checkpoint`` (a
    reliability_checkpoint.Checkpoint: stored batches replayed, new ones stored) when given."""
    def compute(z):
        return evaluate(spec, window, z, client)
    return compute if checkpoint is None else (lambda z: checkpoint.evaluate(z, compute))


def _subset(spec, event: Event, dimension: int, settings: SubsetSettings, client, checkpoint=None) -> Estimate:
    collected, batch = [], _batches(spec, event.window, client, checkpoint)

    def response(z):
        collected.append(batch(z))
        return _response(event, collected[-1])

    res = subset_simulation(response, dimension, event.limit, settings, (event.unit, event.factor))
    e = res.evaluations
    return Estimate("subset", res.pf, res.lower, res.upper, res.confidence, res.cov, res.interval,
                    tuple(rec.evaluations for rec in res.levels), tuple(rec.threshold for rec in res.levels),
                    res.status, res.message, e.z, e.level, np.concatenate(collected))


def _mc_cov(k: int, n: int) -> float:
    """The CoV of the Monte Carlo estimate k / n: sqrt((1 - P) / (n P)); infinite for k = 0, undefined (NaN)
    for k = n, where the plug-in 0 would claim a certainty no n reaches."""
    return float(np.sqrt((1 - k / n) / k)) if 0 < k < n else float("inf") if k == 0 else float("nan")


def _cov_met(k: int, n: int, cov_target: float) -> bool:
    """Whether k of n meets a CoV target; k = n stops the rule as the plug-in CoV 0 did (the exact interval then
    says how close to 1 P is)."""
    return k == n or _mc_cov(k, n) <= cov_target


def _monte_carlo(spec, event: Event, dimension: int, n: int, seed: int, confidence: float, client,
                 checkpoint=None, cov_target: float | None = None) -> Estimate:
    """Plain Monte Carlo of n draws, block b of MC_BLOCK from SeedSequence([seed, MC_TAG, b]); with
    ``cov_target``, stopped after the first block at which the CoV is at most the target (n the cap)."""
    batch = _batches(spec, event.window, client, checkpoint)   # a block at a time: an interrupt loses one
    zs, maxima, k = [], [], 0
    for b in range(-(-n // MC_BLOCK)):
        rng = np.random.default_rng(np.random.SeedSequence([seed, MC_TAG, b]))
        zs.append(rng.standard_normal((MC_BLOCK, dimension))[:n - b * MC_BLOCK])
        maxima.append(batch(zs[-1]))
        k += int(np.count_nonzero(_response(event, maxima[-1]) > event.limit))
        if cov_target is not None and _cov_met(k, b * MC_BLOCK + len(zs[-1]), cov_target):
            break
    z, maxima = np.concatenate(zs), np.concatenate(maxima)
    m = len(z)
    lower, upper = (float(v) for v in clopper_pearson(k, m, confidence))
    status, message = "finished", f"{k} of {m} realisations exceed the limit"   # n asked for: no convergence claimed
    if cov_target is not None:
        met = _cov_met(k, m, cov_target)
        status = "converged" if met else "budget"
        message += (f"; CoV target {cov_target:g} met" if met else
                    f"; CoV target {cov_target:g} not met within the budget of {n} realisations")
    return Estimate("mc", k / m, lower, upper, confidence, _mc_cov(k, m), "Clopper-Pearson exact binomial interval",
                    (m,), (event.limit,), status, message, z, np.zeros(m, int), maxima)


def subset_levels_within(settings: SubsetSettings, left: int) -> int:
    """The most levels a subset run of ``settings`` can take within ``left`` evaluations: N at level 0, then
    (1 - p0) N new ones per level; at most its ``max_levels``."""
    return int(min(settings.max_levels, (left - settings.n_per_level) // ((settings.steps - 1) * settings.chains)))


def check_subset_budget(settings: SubsetSettings, budget: int) -> None:
    """ReliabilityError (before any work) when the first run of a CoV target cannot take even one level within
    ``budget``: N + (1 - p0) N evaluations."""
    if subset_levels_within(settings, budget) < 1:
        one = settings.n_per_level + (settings.steps - 1) * settings.chains
        raise ReliabilityError(f"--budget {budget}: the first subset run, N = {settings.n_per_level}, needs {one} "
                               f"evaluations for its first level (N, then {one - settings.n_per_level}); give "
                               f"--budget {one} or more, or a smaller -n")


def _subset_to_cov(spec, event: Event, dimension: int, settings: SubsetSettings, client, checkpoint,
                   cov_target: float, budget: int) -> Estimate:
    """Subset simulation with N doubled (a fresh run each time, its own seed schedule) until its CoV is
    at most ``cov_target``; each run takes at most the levels that fit in what is left of ``budget``
    (:func:`subset_levels_within`), so the runs never spend more. The last estimate and file, the runs
    and evaluations spent in its message; status 'budget' where the budget, not the event, ended them."""
    from dataclasses import replace
    check_subset_budget(settings, budget)
    spent, runs, last, done = 0, 0, None, ""
    while True:
        levels = subset_levels_within(settings, budget - spent)
        if levels < 1:
            return replace(last, status="budget", message=f"{last.message}; CoV target {cov_target:g} not met: the "
                           f"next run (N = {settings.n_per_level}) cannot take a level within what is left of the "
                           f"budget of {budget} ({done})")
        est = _subset(spec, event, dimension, replace(settings, max_levels=levels), client, checkpoint)
        spent, runs = spent + est.level.size, runs + 1
        done = f"{runs} run(s) up to N = {settings.n_per_level}, {spent} evaluations in all"
        if est.status == "max_levels" and levels < settings.max_levels:   # the budget ran out, not the levels
            ended = last or est
            return replace(ended, status="budget", message=f"{ended.message}; CoV target {cov_target:g} not met: "
                           f"the run at N = {settings.n_per_level} needed more than the {levels} levels left in the "
                           f"budget of {budget} ({done})")
        if est.status in ("certain", "impossible") or est.cov <= cov_target or not math.isfinite(est.pf):
            return replace(est, message=f"{est.message}; CoV target {cov_target:g} met ({done})"
                           if est.cov <= cov_target else est.message)
        last, settings = est, replace(settings, n_per_level=2 * settings.n_per_level)


def reliability(spec, event: Event, method: str = "subset", n: int | None = None, p0: float = 0.1,
                confidence: float = CONFIDENCE, workers: int = 1, checkpoint=None, cov_target: float | None = None,
                budget: int | None = None) -> Estimate:
    """P(event) at the level of ``spec`` (pipeline.ensemble.run.EnsembleSpec) by ``method``: subset
    simulation with N = ``n`` (default 1000) per level, or plain Monte Carlo of ``n`` (default 20000);
    every batch through ``checkpoint`` (pipeline.studies.reliability_checkpoint) when given. With
    ``cov_target``: Monte Carlo adds blocks, subset simulation doubles N, until the CoV is at most the
    target or the ``budget`` of evaluations (default DEFAULT_BUDGET) would be exceeded."""
    dimension = input_dimension(spec.scene(), spec.model, spec.source)
    budget = budget or DEFAULT_BUDGET[method]
    with optional_client(workers) as client:
        if method == "mc":
            return _monte_carlo(spec, event, dimension, budget if cov_target else n or 20000, spec.seed, confidence,
                                client, checkpoint, cov_target)
        settings = SubsetSettings(n or 1000, p0, spec.seed, confidence)
        if cov_target is not None:
            return _subset_to_cov(spec, event, dimension, settings, client, checkpoint, cov_target, budget)
        return _subset(spec, event, dimension, settings, client, checkpoint)


def estimate_from_dataset(ds: xr.Dataset) -> Estimate:
    """The Estimate a reliability file holds (:func:`reliability_dataset`: its ``estimate`` attribute, null read
    back as NaN, and every evaluation), so that a rerun of the same request answers from the file."""
    import json
    s = {k: float("nan") if v is None else v for k, v in json.loads(ds.attrs["estimate"]).items()}
    thresholds = tuple(float("nan") if t is None else t for t in s["thresholds"])
    return Estimate(s["method"], s["pf"], s["lower"], s["upper"], s["confidence"], s["cov"], s["interval"],
                    tuple(s["evaluations_per_level"]), thresholds, s["status"], s["message"], ds["z"].values,
                    ds["level"].values, ds["max_abs_error"].values)


def reliability_dataset(est: Estimate, event: Event, spec, options: str = "") -> xr.Dataset:
    """The CF netCDF content: every evaluation's inputs, level and maxima, and the estimate in attributes."""
    import json

    from ..analysis.stats import json_number
    from ..files.schema import MIXED_UNITS, _unit_table, command_line
    scene = spec.scene()
    history = command_line("reliability", scene, model=spec.model, integrator=spec.integrator, dt=spec.dt,
                           elements=spec.elements, options=options)
    attrs = {"Conventions": "CF-1.10", "title": f"rss6 reliability of {event.text} at the {spec.model} level, "
             f"scene {scene.name!r}", "history": history, "event": event.text, "event_limit": event.limit,
             "event_limit_unit": si_unit(event.quantity, event.directions[0]),
             "event_window": event.window, "seed": spec.seed,
             "interval_coverage": coverage_note(est) or "measured at this level (docs/reliability.md)",
             "estimate": json.dumps({k: json_number(v) if isinstance(v, float) else v
                                     for k, v in est.summary().items()}, allow_nan=False)}
    data = {"z": (("evaluation", "input"), est.z, {"long_name": "standard normal input, Phi^-1 of the "
                                                   "realisation's uniform", "units": "1"}),
            "level": ("evaluation", est.level.astype(np.int32), {"long_name": "subset level of the evaluation "
                                                                 "(0: independent draws)", "units": "1"}),
            "max_abs_error": (("evaluation", "quantity", "direction"), est.maxima,
                              {"long_name": f"maximum over the {event.window} window of |error|",
                               "units": MIXED_UNITS, "cell_methods": "time: maximum"})}
    coords = {"quantity": list(QUANTITIES), "direction": list(DIRECTIONS),
              "unit": (("quantity", "direction"), _unit_table(), {"long_name": "SI unit of each element"})}
    return xr.Dataset(data, coords=coords, attrs=attrs)
