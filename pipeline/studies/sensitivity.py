"""``rss6 sensitivity``: Sobol' indices of the error statistics by joint family (and by joint).

A clearance realisation is a function of independent U(0, 1) inputs: per joint
the uniforms that rss6core.clearance turns into sizes (with a size tolerance),
magnitudes, angles and axial offsets through the laws' inverse CDFs
(:func:`clearance_draws_from_uniforms`).  The inputs are grouped by joint family
(the scene's [clearance] keys: revolute_radial, revolute_axial, spherical_C,
spherical_B) or by joint (A1..A6 with their radial and axial parts, C1..C6,
B1..B6); a scene's [uncertain.*] inputs add their uniforms (one per draw, the core's
inputs_from_uniforms), grouped by input in the family design and as one group
``uncertain_inputs`` in the joint design.  SALib samples them with Saltelli's scheme on scrambled Sobol' points
(N base rows, N (G + 2) evaluations for G groups), the level is evaluated on
every row (dask workers, or in this process), and SALib's estimators give the
first-order (Saltelli 2010) and total (Jansen 1999) indices of each statistic
with bootstrap intervals: estimate +- z sd of the indices over resampled rows, z widened to
reach the label on a maximum over time (:func:`sobol_indices`).
Each finished chunk of rows is kept at once in OUT.parts (:class:`RowParts`), so
a rerun of the same command evaluates only the rows still missing.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import xarray as xr

from rss6core import (FINISHED, UNIFORM_BLOCKS, ClearanceDraw, clearances_from_named_uniforms,
                      inputs_from_uniforms, MODELS, model_level, models_with, prepare_level, realised_clearances,
                      size_band)

from ..ensemble.cluster import WORKER_TIMEOUT_S, optional_client, results_as_finished
from ..files.records import check_window, window_label, window_summaries
from ..files.schema import JOINTS, MIXED_UNITS, _provenance, _unit_table, command_line
from ..files.writing import sigint_deferred
from .sensitivity_parts import RowParts, parts_manifest
from ..vocabulary import (CONFIDENCE, DIRECTIONS, QUANTITIES, SUMMARIES, UNMEASURED_LEVEL, UserError, WINDOWS,
                          at_measured_level)
from ..analysis.resolution import resolutions

__all__ = ["JOINT_FAMILIES", "LEVELS", "INDICES", "ClearanceInputs", "clearance_inputs",
           "clearance_draws_from_uniforms", "Design", "designs", "sample_design",
           "evaluate_statistics", "SobolIndices", "sobol_indices", "sensitivity", "sensitivity_dataset",
           "SensitivityError", "RowParts", "parts_manifest", "coverage_caveat", "interval_coverage", "UNMEASURED"]

JOINT_FAMILIES = ("revolute_radial", "revolute_axial", "spherical_C", "spherical_B")
LEVELS = models_with("function_of_one_draw")   # the levels whose error is a function of one draw
INDICES = ("S1", "ST")
BOUNDS = ("estimate", "lower", "upper")
RESAMPLES = 500                          # bootstrap resamples of the rows per index (SALib default 100)
MIN_N = 64                               # smallest base sample whose interval coverage was measured
SOBOL_WIDENING = 0.1                     # the bootstrap's z at the level 1 - SOBOL_WIDENING (1 - confidence)
MAX_N = 2 ** 18                          # largest: 26 N evaluations with --per-joint stay below 10^7
COVERAGE_NOTE = ("95 % intervals, z at the level 1 - SOBOL_WIDENING (1 - confidence) (99.5 %): at the label's "
                 "own z they covered S1 88.8-93.2 %, ST 88.6-93.4 % at N = 64 on a maximum over time "
                 "(python benchmarks/sobol_coverage.py); widened, S1 98.0-99.2 %, ST 96.2-98.8 % at N = 64, "
                 "S1 97.4-99.2 %, ST 99.2-100 % at N = 256 there, and 99.1-99.3 % on the closed-form case "
                 "(quasi-static displacement at one instant, tests/test_sensitivity.py)")
SHORT_COVERAGE = "z widened: >= 96 % measured on a maximum over time, docs/ensembles.md"   # the table's caveat
UNMEASURED = UNMEASURED_LEVEL   # the caveat at any label but the one benchmarks/sobol_coverage.py measured
measured = at_measured_level


def coverage_caveat(confidence: float) -> str:
    """The table head's caveat of a ``confidence`` label: the coverage measured at 95 %, else that none was."""
    return SHORT_COVERAGE if measured(confidence) else f"z widened, {UNMEASURED} (docs/ensembles.md)"


def interval_coverage(confidence: float) -> str:
    """The file's ``interval_coverage``: COVERAGE_NOTE at 95 %; at another label, its widened level and that its
    coverage was not measured, then what was measured at 95 %."""
    if measured(confidence):
        return COVERAGE_NOTE
    return (f"{100 * confidence:g} % intervals, z at the level 1 - SOBOL_WIDENING (1 - confidence) "
            f"({100 * (1 - SOBOL_WIDENING * (1 - confidence)):g} %): {UNMEASURED}, not at this label. At 95 %: "
            + COVERAGE_NOTE)


class SensitivityError(UserError):
    """A sensitivity request that cannot be answered (level, sample size, failed evaluations)."""


# --- the inputs of one draw ------------------------------------------------------------------

@dataclass(frozen=True)
class ClearanceInputs:
    """The independent U(0, 1) inputs of one clearance draw, then of the scene's [uncertain.*] inputs
    (the last ``uncertain`` columns): name, joint and family of each column."""
    names: tuple[str, ...]
    joints: tuple[str, ...]
    families: tuple[str, ...]
    uncertain: int = 0


def clearance_inputs(scene) -> ClearanceInputs:
    """The scene's inputs: sizes only where they vary (size tolerance > 0 and a nonzero size)."""
    sized = {f: size_band(scene, f) is not None for f in JOINT_FAMILIES}
    rows = []
    for leg in range(1, 7):
        a = f"A{leg}"
        rows += [(a, "radial_size", "revolute_radial")] if sized["revolute_radial"] else []
        rows += [(a, "axial_size", "revolute_axial")] if sized["revolute_axial"] else []
        rows += [(a, "radial_magnitude", "revolute_radial"), (a, "radial_angle", "revolute_radial"),
                 (a, "axial", "revolute_axial")]
    for kind in "CB":
        family = f"spherical_{kind}"
        for leg in range(1, 7):
            j = f"{kind}{leg}"
            rows += [(j, "size", family)] if sized[family] else []
            rows += [(j, "magnitude", family), (j, "polar", family), (j, "azimuth", family)]
    drawn = scene.uncertain.inputs   # grouped by input name (families) or together (joints)
    rows += [(UNCERTAIN_GROUP, label, i.name) for i in drawn for label in i.labels()]
    return ClearanceInputs(tuple(w if j == UNCERTAIN_GROUP else f"{j}_{w}" for j, w, _ in rows),
                           tuple(j for j, _, _ in rows), tuple(f for _, _, f in rows),
                           sum(i.count for i in drawn))


UNCERTAIN_GROUP = "uncertain_inputs"   # the joint design's group of every [uncertain.*] input


def clearance_draws_from_uniforms(scene, inputs: ClearanceInputs, u: np.ndarray, given=None) -> list[ClearanceDraw]:
    """The clearance draws (one per row) of uniforms u (R, D) laid out as ``inputs``: the core's
    draw (rss6core.clearances_from_named_uniforms) with each block's six uniforms taken from the
    columns of its joints (block ``C_magnitude``: columns C1_magnitude .. C6_magnitude); with the
    rows' [uncertain.*] inputs ``given``, the clearance sizes they draw (rss6core.realised_clearances)."""
    u = np.atleast_2d(np.asarray(u, float))
    columns = {}
    for block in UNIFORM_BLOCKS:
        kind, what = block.split("_", 1)
        names = [f"{kind}{leg}_{what}" for leg in range(1, 7)]
        if all(n in inputs.names for n in names):
            columns[block] = [inputs.names.index(n) for n in names]
    scenes = [scene] * len(u) if given is None else [realised_clearances(scene, g) for g in given]
    return [clearances_from_named_uniforms(s, {b: row[c] for b, c in columns.items()}) for s, row in zip(scenes, u)]


# --- the sampling design ---------------------------------------------------------------------

@dataclass(frozen=True)
class Design:
    """One grouping of the inputs: its name (families or joints), group labels and SALib problem."""
    name: str
    groups: tuple[str, ...]
    problem: dict


def designs(inputs: ClearanceInputs, per_joint: bool) -> list[Design]:
    """The family design, and with ``per_joint`` the joint design (A_i radial and axial together)."""
    extra = tuple(dict.fromkeys(inputs.families[len(inputs.families) - inputs.uncertain:])) if inputs.uncertain else ()
    out = [("families", inputs.families, JOINT_FAMILIES + extra)]
    if per_joint:
        out.append(("joints", inputs.joints, JOINTS + ((UNCERTAIN_GROUP,) if extra else ())))
    return [Design(name, order, {"num_vars": len(inputs.names), "names": list(inputs.names),
                                 "bounds": [[0.0, 1.0]] * len(inputs.names), "groups": list(labels)})
            for name, labels, order in out]


_STREAMS = {("families", "sample"): 0, ("families", "bootstrap"): 1, ("joints", "sample"): 2,
            ("joints", "bootstrap"): 3}


def _salib_seed(seed: int, design: str, stage: str) -> int:
    """A positive integer seed per (seed, design, stage): SALib's analyser draws from numpy's
    global, unseeded state when given 0."""
    return int(np.random.SeedSequence([seed, _STREAMS[design, stage]]).generate_state(1)[0]) + 1


def sample_design(design: Design, n: int, seed: int) -> np.ndarray:
    """Saltelli's N (G + 2) rows of uniforms on scrambled Sobol' points, no second-order columns."""
    from SALib.sample import sobol
    return sobol.sample(design.problem, n, calc_second_order=False, scramble=True,
                        seed=_salib_seed(seed, design.name, "sample"))


# --- evaluation ------------------------------------------------------------------------------

def _evaluate_chunk(spec, inputs: ClearanceInputs, u: np.ndarray, window: str = "whole"):
    """(statistics (R, 2, 3, 6) max and mean |error| SI over the analysis ``window`` (WINDOWS), status
    messages ('' when finished))."""
    scene = spec.scene()
    sim = scene.simulation
    level = prepare_level(scene, spec.model, spec.integrator, spec.dt, spec.elements)
    given = None
    if inputs.uncertain:
        given = [inputs_from_uniforms(scene.uncertain, row[len(inputs.names) - inputs.uncertain:]) for row in u]
    results = level.simulate_draws(clearance_draws_from_uniforms(scene, inputs, u, given), given)
    k = WINDOWS.index(window)
    stats = np.stack([np.stack([w[k] for w in window_summaries(r, sim.settle_time, sim.steady_after)])
                      for r in results])
    return stats, [r.message or r.status if r.status != FINISHED else "" for r in results]


def _chunks(todo: np.ndarray, chunk: int) -> list[slice]:
    """The rows ``todo`` (sorted indices) as slices of at most ``chunk`` rows within their runs of
    consecutive rows (all rows: 0..chunk-1, chunk..2 chunk-1, ...)."""
    runs = np.split(todo, np.flatnonzero(np.diff(todo) != 1) + 1) if len(todo) else []
    ends = [(int(run[0]), int(run[-1]) + 1) for run in runs]
    return [slice(i, min(i + chunk, stop)) for first, stop in ends for i in range(first, stop, chunk)]


def evaluate_statistics(spec, inputs: ClearanceInputs, u: np.ndarray, client=None,
                        chunk: int | None = None, window: str = "whole", parts: RowParts | None = None) -> np.ndarray:
    """Per-row statistics (R, 2, 3, 6) of the level for uniforms u (R, D) over the analysis
    ``window``, in chunks (default: four per worker, at most 256 rows) on a dask ``client`` (None:
    in this process); with ``parts``, the rows stored there are read, not evaluated, and every
    chunk that finishes without a failed row is stored at once. SensitivityError if any row failed."""
    workers = max(1, len(client.nthreads())) if client is not None else 1
    chunk = chunk or max(1, min(256, -(-len(u) // (4 * workers))))
    out, failures = np.empty((len(u), len(SUMMARIES), len(QUANTITIES), len(DIRECTIONS))), []
    done = np.zeros(len(u), bool)
    for rows, stats in parts.stored() if parts else []:
        out[rows], done[rows] = stats, True
    for part, (stats, messages) in _run_chunks(spec, inputs, u, _chunks(np.flatnonzero(~done), chunk), client, window):
        out[part] = stats
        failures += [m for m in messages if m]
        if parts and not any(messages):   # a failed row is evaluated (and reported) again by a rerun
            parts.keep(part, stats)
    if failures:
        raise SensitivityError(f"{len(failures)} of {len(u)} evaluations of the {spec.model} level "
                               f"failed (first: {failures[0]}); Sobol' indices need every row")
    return out


def _run_chunks(spec, inputs, u, parts, client, window):
    """(slice, chunk result) pairs as they finish; on dask, a Ctrl-C is raised between waits, as
    ``rss6 run``'s (pipeline.ensemble.cluster.results_as_finished), never inside dask's client."""
    if client is None:
        for part in parts:
            yield part, _evaluate_chunk(spec, inputs, u[part], window)
        return
    futures = [client.submit(_evaluate_rows, spec, inputs, u[p], p, window, pure=False) for p in parts]
    with sigint_deferred() as interrupted:
        yield from results_as_finished(client, futures, None, WORKER_TIMEOUT_S, interrupted)


def _evaluate_rows(spec, inputs, u, rows: slice, window):   # a dask task: (rows, _evaluate_chunk)
    return rows, _evaluate_chunk(spec, inputs, u, window)


# --- analysis -----------------------------------------------------------------------------

@dataclass(frozen=True)
class SobolIndices:
    """Indices (index S1/ST, bound estimate/lower/upper, group, output) of one design."""
    design: Design
    values: np.ndarray


def sobol_indices(design: Design, y: np.ndarray, confidence: float, seed: int,
                  resamples: int = RESAMPLES, widening: float = SOBOL_WIDENING) -> SobolIndices:
    """SALib's first-order and total indices of every output column of y (rows, outputs), with
    estimate -+ z sd(bootstrap) bounds, z at the level 1 - ``widening`` (1 - confidence): at the
    label's own z (``widening`` 1) they covered 88.6-93.4 % on a maximum over time at N = 64
    (COVERAGE_NOTE); the bounds clipped to [0, 1], where every index lies (which keeps their coverage:
    an index is in the interval exactly when it is in the clipped one), the estimates not (their
    noise shows there, :func:`pipeline.studies.sensitivity_table._outside_note`); NaN for an output that
    does not vary."""
    from SALib.analyze import sobol
    groups = len(design.groups)
    out = np.full((len(INDICES), len(BOUNDS), groups, y.shape[1]), np.nan)
    for k in range(y.shape[1]):
        if not np.ptp(y[:, k]) > 0:
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            res = sobol.analyze(design.problem, y[:, k], calc_second_order=False,
                                num_resamples=resamples, conf_level=1.0 - widening * (1.0 - confidence),
                                seed=_salib_seed(seed, design.name, "bootstrap"))
        for i, name in enumerate(INDICES):
            est, half = np.asarray(res[name]), np.asarray(res[f"{name}_conf"])
            out[i, :, :, k] = np.stack([est, np.clip(est - half, 0, 1), np.clip(est + half, 0, 1)])
    return SobolIndices(design, out)


# --- the file ---------------------------------------------------------------------------------

def _group_inputs(inputs: ClearanceInputs, design: Design) -> list[str]:
    labels = inputs.families if design.name == "families" else inputs.joints
    return [" ".join(n for n, g in zip(inputs.names, labels) if g == group) for group in design.groups]


def sensitivity_dataset(scene, spec, inputs, results: list[SobolIndices], n: int, confidence: float,
                        window: str = "whole", stats: np.ndarray | None = None) -> xr.Dataset:
    """The indices of every design as one CF Dataset (index, bound, group, quantity, direction), of
    the statistics over the analysis ``window``; with every evaluated row's statistics ``stats`` (rows, 2,
    3, 6), also the outputs' spread over the rows and the level's resolution (:func:`_spread_variables`)."""
    groups = [g for r in results for g in r.design.groups]
    data = {}
    for s, name in enumerate(SUMMARIES):
        values = np.concatenate([r.values.reshape(r.values.shape[:3] + (2, 3, 6))[..., s, :, :]
                                 for r in results], axis=2)
        what = "maximum" if name == "max_abs_error" else "mean"
        data[f"{name}_sobol"] = (("index", "bound", "group", "quantity", "direction"), values, {
            "long_name": f"Sobol' index of the per-realisation {what} over time of |platform pose "
                         "error| with respect to an input group", "units": "1",
            "analysis_window": window_label(window, scene.simulation.steady_after,
                                             scene.simulation.settle_time)})
    design = [r.design.name for r in results for _ in r.design.groups]
    data["group_design"] = (("group",), np.array(design, dtype=object),
                            {"long_name": "grouping the index belongs to (families or joints)"})
    data["group_inputs"] = (("group",), np.array([t for r in results for t in _group_inputs(inputs, r.design)],
                                                 dtype=object),
                            {"long_name": "the U(0, 1) inputs of the draw in the group (clearances, uncertain inputs)"})
    coords = {"index": ("index", list(INDICES), {"long_name": "S1 first-order, ST total Sobol' index"}),
              "bound": ("bound", list(BOUNDS), {"long_name": "estimate and bootstrap interval bounds"}),
              "group": ("group", groups, {"long_name": "input group: joint family or joint"}),
              "quantity": ("quantity", list(QUANTITIES)),
              "direction": ("direction", list(DIRECTIONS),
                            {"long_name": "platform pose direction, base frame"}),
              "unit": (("quantity", "direction"), _unit_table(),
                       {"long_name": "SI unit of the statistic (the indices are dimensionless)"})}
    joints = " --per-joint" if any(r.design.name == "joints" for r in results) else ""
    history = command_line("sensitivity", scene, model=spec.model, integrator=spec.integrator, dt=spec.dt,
                           elements=spec.elements, options=f"--seed {spec.seed} -n {n} --confidence "
                                                            f"{confidence:g} --window {window}{joints}")
    attrs = _provenance(scene, f"rss6 Sobol' indices: {spec.model} level, scene {scene.name!r}",
                        model=spec.model, integrator=spec.integrator, dt=spec.dt, elements=spec.elements,
                        history=history)
    evaluations = {f"evaluations_{r.design.name}": n * (len(r.design.groups) + 2) for r in results}
    attrs |= {"seed": spec.seed, "n_base_samples": n, **evaluations, "confidence": confidence, "window": window,
              "sampler": "SALib sobol.sample: Saltelli's scheme on scrambled Sobol' points, "
                         "N (G + 2) rows for G groups, no second-order rows",
              "estimator": "SALib sobol.analyze: first order Saltelli et al. (2010), total Jansen "
                           "(1999), on the output standardised over all rows",
              "interval_method": f"bootstrap intervals: estimate -+ z sd, z the normal "
                                 f"{100 * (1 - SOBOL_WIDENING * (1 - confidence)):g} % two-sided quantile "
                                 f"for a {100 * confidence:g} % label (interval_coverage) and sd the standard "
                                 f"deviation of the index over {RESAMPLES} bootstrap resamples of the N base rows "
                                 "(SALib), clipped to [0, 1] where every index lies (which keeps the coverage); "
                                 "the estimates are not clipped",
              "interval_coverage": interval_coverage(confidence)}
    if stats is not None:
        data |= _spread_variables(attrs, stats)
    return xr.Dataset(data, coords=coords, attrs=attrs)


def _spread_variables(attrs: dict, stats: np.ndarray) -> dict:
    """Per statistic, the spread (max - min, SI) of each output over the evaluated rows ``stats`` (rows, 2, 3, 6)
    and the spread the level resolves there (pipeline.analysis.resolution, the test the ensemble plots make):
    where the spread is within it, the outputs differ by numerical noise and their indices rank that noise."""
    from types import SimpleNamespace
    file = SimpleNamespace(attrs=attrs)   # resolutions() reads a file's model and scene
    levels = [resolutions(file, q) for q in QUANTITIES]   # once per quantity: each parses the scene
    out = {}
    for s, name in enumerate(SUMMARIES):
        spread, top = np.ptp(stats[:, s], axis=0), np.max(stats[:, s], axis=0)
        limit = np.array([[levels[i][d].limit(top[i, j]) for j, d in enumerate(DIRECTIONS)]
                          for i in range(len(QUANTITIES))])
        cells = ("quantity", "direction")
        out[f"{name}_spread"] = (cells, spread, {"long_name": f"spread (max - min) of {name} over the evaluated "
                                                 "rows", "units": MIXED_UNITS})
        out[f"{name}_resolution"] = (cells, limit, {
            "long_name": f"spread of {name} below which the level does not resolve it (its indices then rank "
                         "numerical noise; pipeline/analysis/resolution.py)", "units": MIXED_UNITS})
    return out


def _outputs(stats: np.ndarray) -> np.ndarray:
    """(rows, 2 * 3 * 6) output columns of per-row statistics (rows, 2, 3, 6)."""
    return stats.reshape(stats.shape[0], -1)


def _check_window(scene, window: str) -> None:
    """SensitivityError unless ``window`` is one of WINDOWS and holds output samples of the scene."""
    try:
        check_window(scene, window)
    except ValueError as exc:
        raise SensitivityError(str(exc)) from None


def _check_level(model: str) -> None:
    """SensitivityError unless the error of ``model`` is a function of one clearance draw, saying
    (from the level table) why the other levels have no Sobol' indices."""
    if model in LEVELS:
        return
    redrawn = " and ".join(models_with("redraws_every_step"))
    without = " and ".join(name for name in MODELS if not model_level(name).draws_clearances)
    raise SensitivityError(f"--model {model}: Sobol' indices need a level whose error is a "
                           f"function of one clearance draw ({', '.join(LEVELS)}); the {redrawn} level "
                           f"redraws the clearances every step, {without} have none")


def sensitivity(spec, n: int, per_joint: bool = False, confidence: float = CONFIDENCE, workers: int = 2,
                announce=None, window: str = "whole", parts=None) -> xr.Dataset:
    """Sobol' indices of the level ``spec.model`` with N base rows per design (a power of 2), of the
    statistics over the analysis ``window`` (WINDOWS: whole run, startup or steady); with a ``parts``
    folder (OUT.parts), the finished chunks are kept there and the rows stored there are not evaluated."""
    _check_level(spec.model)
    if n < MIN_N or n & (n - 1):
        raise SensitivityError(f"-n {n}: the base sample must be a power of 2 of at least {MIN_N} "
                               "(Sobol' points are balanced in powers of 2; interval coverage was "
                               f"measured from {MIN_N})")
    scene = spec.scene()
    if scene.uncertain.correlations:
        raise SensitivityError(f"{spec.source}: [correlation.{scene.uncertain.correlations[0].name}]: Sobol' "
                               "indices need independent inputs; run the scene without its [correlation.*] tables")
    _check_window(scene, window)
    c = scene.clearance
    if not any((c.revolute_radial, c.revolute_axial, c.spherical_C, c.spherical_B)) and not scene.uncertain:
        raise SensitivityError(f"{spec.source}: every [clearance] size is 0, so no input varies and no "
                               "Sobol' index is defined")
    inputs = clearance_inputs(scene)
    manifest = parts_manifest(spec, n, per_joint, window, parts) if parts else None
    results, evaluated = [], []
    with optional_client(workers) as client:
        for design in designs(inputs, per_joint):
            u = sample_design(design, n, spec.seed)
            rows = RowParts(manifest, design.name) if manifest else None
            if announce:
                kept = f"; {stored} stored in {parts}" if rows and (stored := rows.count()) else ""
                announce(f"{design.name}: {len(u)} evaluations of the {spec.model} level "
                         f"({len(design.groups)} groups, N = {n}) on {workers} worker(s){kept}")
            stats = evaluate_statistics(spec, inputs, u, client, window=window, parts=rows)
            results.append(sobol_indices(design, _outputs(stats), confidence, spec.seed))
            evaluated.append(stats)
    return sensitivity_dataset(scene, spec, inputs, results, n, confidence, window, np.concatenate(evaluated))
