"""``rss6 allocate``: the least-cost fit class per joint family such that every spec holds.

At the quasi-static level (the paper and contact levels: pipeline.studies.allocation_greedy), whose
error is linear in the eccentricities, which
scale with the joint's clearance size on the draw's own uniforms (docs/model.md section 4; with
``quasi_static_eccentricity = "reaction"`` along the rigid joint forces, which do not depend on the
sizes), so one realisation's error is d(t) = sum_j s_j U_j(t) with U_j the error per unit size of joint j.  A class
draws each joint's size uniformly in its band [lo, hi] from the draw's size uniform u_j, s_j = lo +
(hi - lo) u_j, so per family f the error is lo_f A_f(t) + (hi_f - lo_f) B_f(t), with A_f = sum_j U_j
and B_f = sum_j u_j U_j computed once from the seed's realisations (two given-draw runs per family).
Every class combination is then judged without an ensemble, on the same one-sided bounds as the
gate (pipeline.analysis.estimators.one_sided_bounds), in order of rising cost: the first that meets
every spec is the least-cost allocation (exhaustive, so exact for these draws).  A verification
ensemble at the answer (same seed and n, so the same draws) is judged by the gate.
"""
from __future__ import annotations

import itertools
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rss6core import ClearanceDraw, model_level, models_with, parse_scene, prepare_level, stored_draw, toml_spelling

from ..analysis.estimators import one_sided_bounds
from ..analysis.gate import Verdict, allowed_exceedances, upper_limits_problem
from ..analysis.spec import PF, Spec
from ..ensemble.run import EnsembleSpec
from ..files.records import window_masks
from ..scenes.variant import dump_scene_toml
from ..vocabulary import DIRECTIONS, QUANTITIES, STATISTICS, WINDOWS, UserError
from .fits import COST_LAW, DEFAULT_FITS, FitError, fit_limits, parse_fit
from .trial import run_trial

__all__ = ["ALLOCATED", "DEFAULT_FITS", "ClassOption", "Allocation", "AllocationError", "class_options",
           "Responses", "responses", "spec_uppers", "error_uppers", "search", "allocate", "allocated_scene",
           "check_request",
           "cost_of", "cheapest_uniform", "unit_eccentricity", "family_draw", "fixed_draw", "cells_history",
           "probe_scene", "PROBE_LOW", "PROBE_HIGH", "allowed_exceedances", "pf_order_statistic", "out_of_reach",
           "Search", "unreachable"]

ALLOCATED = ("revolute_radial", "spherical_C", "spherical_B")   # families given fit classes
RADII = {"revolute_radial": "journal_radius", "spherical_C": "sphere_radius", "spherical_B": "sphere_radius"}
PROBE_LOW, PROBE_HIGH = 1.0e-4, 2.0e-4   # m: the band the responses are drawn with (any band gives them)


class AllocationError(UserError):
    """A request no allocation can answer (unknown class, band too wide, spec out of reach, costs)."""


@dataclass(frozen=True)
class ClassOption:
    """One class offered to one family: its radial band (m, drawn uniformly) and cost per joint."""
    family: str
    name: str
    low: float    # m
    high: float   # m
    cost: float   # relative units per joint


@dataclass(frozen=True)
class Allocation:
    """The answer: a class per family (or per joint, ``joints``), its total cost (6 joints a family),
    the cheapest uniform choice (one class name for every family) and the verification's verdicts."""
    classes: tuple[ClassOption, ...]
    cost: float
    uniform: tuple[ClassOption, ...] | None
    uniform_cost: float | None
    combinations: int       # class combinations judged
    verdicts: tuple[Verdict, ...]
    predicted: dict         # spec text -> largest predicted upper bound over its directions (SI)
    ensemble_path: Path
    scene_path: Path | None  # None per joint: a scene's [tolerance] bands are per family
    method: str = "exact linear scaling"
    joints: tuple[str, ...] = ()   # per joint: the joint of each class (A1-A6, C1-C6, B1-B6); else per family


def _read_costs(path) -> dict:
    try:
        data = tomllib.loads(Path(path).read_text())
    except OSError as exc:
        raise AllocationError(f"--costs {path}: {exc.strerror or exc} (a TOML file of costs)") from None
    except tomllib.TOMLDecodeError as exc:
        raise AllocationError(f"--costs {path}: not TOML: {exc}") from None
    classes = data.get("classes", {})
    tables = {key: data[key] for key in (*ALLOCATED, "classes") if key in data}
    tables |= {f"classes.{family}": table for family, table in classes.items()} if isinstance(classes, dict) else {}
    for key, table in tables.items():
        if not isinstance(table, dict):
            raise AllocationError(f"--costs {path}: {key} must be a table ([{key}]), got {toml_spelling(table)}")
    unknown = sorted(set(data) - set(ALLOCATED) - {"classes"}) + sorted(set(classes) - set(ALLOCATED))
    if unknown:
        raise AllocationError(f"--costs {path}: unknown table {unknown[0]!r}; give [<family>] costs and "
                              f"[classes.<family>.<name>] classes for the families {', '.join(ALLOCATED)}")
    return data


def _cost(value, where: str) -> float:
    """A cost per joint from the costs file: a finite number above 0, else AllocationError naming
    ``where`` (a free class would make the cheapest allocation any set of free ones)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise AllocationError(f"{where}: the cost must be a number (per joint), got {toml_spelling(value)}")
    if not 0 < value < float("inf"):
        raise AllocationError(f"{where}: the cost must be positive and finite (per joint), got {value!r}")
    return float(value)


def _named_class(family: str, name: str, table, radius: float, where: str) -> ClassOption:
    """A class the costs file names ([classes.<family>.<name>] low_m, high_m, cost), checked."""
    keys = {"low_m", "high_m", "cost"}
    if not isinstance(table, dict) or set(table) != keys:
        raise AllocationError(f"{where}: give exactly low_m, high_m (radial play, m) and cost (per joint)")
    low, high, cost = table["low_m"], table["high_m"], _cost(table["cost"], where)
    if not all(isinstance(x, (int, float)) for x in (low, high)) or not 0 <= low < high:
        raise AllocationError(f"{where}: need 0 <= low_m < high_m, got {low!r}, {high!r}")
    if high >= radius:
        raise AllocationError(f"{where}: high_m = {high:g} m reaches the {family} joint's "
                              f"{RADII[family]}_m = {radius:g} m")
    return ClassOption(family, name, float(low), float(high), float(cost))


def _fit_class(family: str, name: str, radius: float, costs, costs_file) -> ClassOption:
    """An ISO 286 fit as a class of ``family`` (radial band: half the diametral clearance)."""
    try:
        lim = fit_limits(parse_fit(name), 2 * radius)
    except FitError as exc:
        raise AllocationError(f"--classes: {exc}") from None
    if lim.radial_high >= radius:
        raise AllocationError(f"--classes {name}: its radial band reaches {lim.radial_high * 1e3:g} mm, "
                              f"not below the {family} joint's {RADII[family]}_m = {radius * 1e3:g} mm")
    cost = COST_LAW.fit(lim)
    if costs is not None:
        where = f"--costs {costs_file}: [{family}] {name!r}"
        if name not in costs.get(family, {}):
            raise AllocationError(f"{where}: missing; give a cost per joint for every fit of --classes")
        cost = _cost(costs[family][name], where)
    return ClassOption(family, name, lim.radial_low, lim.radial_high, float(cost))


def class_options(scene, fits=DEFAULT_FITS, costs_file=None) -> dict[str, tuple[ClassOption, ...]]:
    """Each allocated family's classes: ISO 286 fits at the joint's diameter (2 x its [contact] radius),
    the radial band half the diametral clearance, costs from ``costs_file`` ([<family>] "<fit>" =
    cost per joint) or else the reciprocal-power law (pipeline.studies.fits); then the file's named
    classes ([classes.<family>.<name>] low_m, high_m, cost; e.g. ball-joint catalogue grades).
    AllocationError for an unknown fit, a band reaching the joint's radius, or a cost the file lacks."""
    costs = _read_costs(costs_file) if costs_file else None
    out = {}
    for family in ALLOCATED:
        radius = getattr(scene.contact, RADII[family])
        options = [_fit_class(family, name, radius, costs, costs_file) for name in fits]
        for name, table in ((costs or {}).get("classes", {}).get(family, {})).items():
            if name in fits:
                raise AllocationError(f"--costs {costs_file}: [classes.{family}.{name}] repeats a fit of --classes")
            options.append(_named_class(family, name, table, radius, f"--costs {costs_file}: "
                                                                     f"[classes.{family}.{name}]"))
        out[family] = tuple(options)
    return out


def allocated_scene(text: str, source: str, classes) -> str:
    """The scene text with each class's family drawn uniformly in its band ([tolerance.<family>]),
    its nominal [clearance] size the band's middle; checked by parsing."""
    data = tomllib.loads(text)
    tolerance = data.setdefault("tolerance", {})
    for c in classes:
        tolerance[c.family] = {"law": "uniform", "low_m": c.low, "high_m": c.high}
        data["clearance"][f"{c.family}_m"] = 0.5 * (c.low + c.high)
    note = ", ".join(f"{c.family} {c.name}" for c in classes)
    out = dump_scene_toml(data, f"rss6 allocate variant of {source}: {note}")
    parse_scene(out, source)
    return out


@dataclass(frozen=True)
class Responses:
    """Per allocated family f the error parts A_f, B_f (module doc) of the spec cells: (family, n, T,
    cell) in SI per metre of size; the error of the families left at the scene's sizes (the revolute
    axial play): (n, T, cell) in SI; the cells' (quantity, direction) and the times (s)."""
    offset: np.ndarray
    spread: np.ndarray
    fixed: np.ndarray
    cells: tuple[tuple[str, str], ...]
    t: np.ndarray


def unit_eccentricity(scene, draw: ClearanceDraw, family: str) -> tuple[np.ndarray, np.ndarray]:
    """(unit, u) of ``family`` in a probe draw: each joint's eccentricity per metre of its size (6, 3)
    (the revolute's radial part) and its size uniform in the probe band (6,) (module doc)."""
    if family == "revolute_radial":
        w = scene.geometry.w
        size = draw.radial_size
        radial = draw.e_A - np.einsum("li,li->l", draw.e_A, w)[:, None] * w
        unit = radial / size[:, None]
    else:
        size = draw.size_C if family == "spherical_C" else draw.size_B
        unit = (draw.e_C if family == "spherical_C" else draw.e_B) / size[:, None]
    return unit, (size - PROBE_LOW) / (PROBE_HIGH - PROBE_LOW)


def family_draw(family: str, sizes: np.ndarray, eccentricity: np.ndarray) -> ClearanceDraw:
    """A draw with ``family``'s sizes (6,) and eccentricities (6, 3) (m) and every other family at zero."""
    zero6, zero63 = np.zeros(6), np.zeros((6, 3))
    fields = dict(radial_size=zero6, axial_size=zero6, size_C=zero6, size_B=zero6, e_A=zero63, e_C=zero63,
                  e_B=zero63)
    key = {"revolute_radial": ("radial_size", "e_A"), "spherical_C": ("size_C", "e_C"),
           "spherical_B": ("size_B", "e_B")}[family]
    fields.update({key[0]: sizes, key[1]: eccentricity})
    return ClearanceDraw(**fields)


def _unit_draws(scene, draw: ClearanceDraw, family: str):
    """Two draws of ``family`` alone (others zero) at sizes 1 and u_j (module doc), scaled by PROBE_LOW
    so that no divergence check sees metre-sized clearances."""
    unit, u = unit_eccentricity(scene, draw, family)
    return [family_draw(family, PROBE_LOW * c, PROBE_LOW * c[:, None] * unit) for c in (np.ones(6), u)]


def fixed_draw(scene, draw: ClearanceDraw) -> ClearanceDraw:
    """The draw with the allocated families' eccentricities zeroed: the revolute axial part alone."""
    w = scene.geometry.w
    axial = np.einsum("li,li->l", draw.e_A, w)[:, None] * w
    zero6, zero63 = np.zeros(6), np.zeros((6, 3))
    return ClearanceDraw(radial_size=zero6, axial_size=draw.axial_size, size_C=zero6, size_B=zero6, e_A=axial,
                         e_C=zero63, e_B=zero63)


def cells_history(result, cells) -> np.ndarray:
    """(T, cell) of a result's error histories, SI."""
    q = [QUANTITIES.index(c[0]) for c in cells]
    d = [DIRECTIONS.index(c[1]) for c in cells]
    return np.stack([result.displacement, result.velocity, result.acceleration])[q, :, d].T


def probe_scene(spec: EnsembleSpec):
    """The scene with every allocated family drawn in the probe band (its draws give the responses)."""
    probe = [ClassOption(f, "probe", PROBE_LOW, PROBE_HIGH, 0.0) for f in ALLOCATED]
    return parse_scene(allocated_scene(spec.scene_text, spec.source, probe), spec.source)


def responses(spec: EnsembleSpec, specs: list[Spec], n: int) -> Responses:
    """A_f and B_f of realisations 0..n-1 of the seed, for the cells the specs read."""
    cells = tuple(dict.fromkeys((s.quantity, d) for s in specs for d in s.directions))
    scene = probe_scene(spec)
    level = prepare_level(scene, spec.model, dt=spec.dt)
    t = scene.times
    offset = np.empty((len(ALLOCATED), n, len(t), len(cells)))
    spread, fixed = np.empty_like(offset), np.empty((n, len(t), len(cells)))
    for r in range(n):
        draw = stored_draw(scene, spec.model, spec.seed, r, spec.dt)
        fixed[r] = cells_history(level.simulate_draws([fixed_draw(scene, draw)])[0], cells)
        for k, family in enumerate(ALLOCATED):
            one, u = level.simulate_draws(_unit_draws(scene, draw, family))
            offset[k, r] = cells_history(one, cells) / PROBE_LOW
            spread[k, r] = cells_history(u, cells) / PROBE_LOW
    return Responses(offset, spread, fixed, cells, t)


def spec_uppers(res: Responses, combo, specs: list[Spec], scene, confidence: float) -> list[np.ndarray]:
    """Per spec, the one-sided upper bound (SI) of its statistic per direction at class ``combo``
    (one ClassOption per ALLOCATED family), from the responses."""
    lows = np.array([c.low for c in combo])
    widths = np.array([c.high - c.low for c in combo])
    err = np.abs(np.tensordot(lows, res.offset, 1) + np.tensordot(widths, res.spread, 1) + res.fixed)  # (n, T, cell)
    return error_uppers(err, res.cells, res.t, specs, scene, confidence)


def error_uppers(err: np.ndarray, cells, t: np.ndarray, specs: list[Spec], scene, confidence: float) -> list:
    """Per spec, the one-sided upper bound (SI) of its statistic per direction, from the |error|
    histories ``err`` (n, T, cell) of the (quantity, direction) ``cells`` at times ``t`` (s)."""
    sim = scene.simulation
    masks = window_masks(t, sim.settle_time, sim.steady_after)
    out = []
    for s in specs:
        mask = masks[WINDOWS.index(s.window or "whole")]
        cols = [cells.index((s.quantity, d)) for d in s.directions]
        e = err[:, mask][:, :, cols]
        x = e.max(axis=1) if s.measure == "max" else e.mean(axis=1)
        out.append(pf_order_statistic(x, s, confidence) if s.statistic == PF else
                   one_sided_bounds(x, confidence)[STATISTICS.index(s.statistic), 1])
    return out


def pf_order_statistic(x: np.ndarray, spec: Spec, confidence: float) -> np.ndarray:
    """The (k+1)-th largest of the maxima x (n, directions) (SI), k = allowed_exceedances: the pf
    requirement holds exactly when this value meets the limit, so a pf spec is searched as an upper
    bound like the others."""
    k = allowed_exceedances(spec, x.shape[0], confidence)
    return np.sort(x, axis=0)[x.shape[0] - 1 - k] if k >= 0 else np.full(x.shape[1], np.inf)


def ordinal(k: int) -> str:
    """1st, 2nd, 3rd, 4th, ..., 11th, 12th, 13th, ..., 21st."""
    suffix = "th" if 10 <= k % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(k % 10, "th")
    return f"{k}{suffix}"


def out_of_reach(spec: Spec, best: float, n: int, confidence: float) -> AllocationError:
    """The error for a spec no combination meets, with the best attainable value (SI ``best``) and
    what could change that: tighter classes, the families allocate leaves alone, or the spec."""
    what = (f"{ordinal(allowed_exceedances(spec, n, confidence) + 1)} largest maximum |error| (pf {spec.pf_op} "
            f"{spec.pf_limit:g} allows {allowed_exceedances(spec, n, confidence)} of {n} above the limit)"
            if spec.statistic == PF else f"{spec.statistic} upper bound")
    return AllocationError(f"--spec {spec.text!r}: no class combination meets it; the best attainable "
                           f"{what} is {best / spec.factor:.4g} {spec.unit}; offer tighter fits (--classes), "
                           f"tighten what allocate keeps at the scene's sizes (the revolute axial play), "
                           f"or relax the spec")


def unreachable(specs: list[Spec], best: list, n: int, confidence: float) -> AllocationError:
    """:func:`out_of_reach` for the spec whose best attainable bound is farthest above its limit."""
    worst = max(range(len(specs)), key=lambda i: best[i] / specs[i].limit)
    return out_of_reach(specs[worst], best[worst], n, confidence)


def cost_of(combo) -> float:
    """Total cost of a class per family, six joints a family."""
    return 6.0 * sum(c.cost for c in combo)



@dataclass(frozen=True)
class Search:
    """What a class search found: the least-cost combo (None if none meets every spec), how many
    combinations it judged and the best attainable upper bound per spec (SI)."""
    combo: tuple | None
    judged: int
    best: list


def search(res: Responses, options: dict, specs: list[Spec], scene, confidence: float) -> Search:
    """The least-cost class per family by exhaustive search in rising cost (:class:`Search`)."""
    combos = sorted(itertools.product(*(options[f] for f in ALLOCATED)), key=cost_of)
    best = [np.inf] * len(specs)
    for k, combo in enumerate(combos, 1):
        uppers = spec_uppers(res, combo, specs, scene, confidence)
        best = [min(b, float(np.max(u))) for b, u in zip(best, uppers)]
        if all(bool(np.all(s.holds(u))) for s, u in zip(specs, uppers)):
            return Search(combo, k, best)
    return Search(None, len(combos), best)


def cheapest_uniform(res: Responses, options: dict, specs: list[Spec], scene, confidence: float):
    """The cheapest combo naming one class for every family that meets every spec, or None."""
    names = [c.name for c in options[ALLOCATED[0]]
             if all(any(o.name == c.name for o in options[f]) for f in ALLOCATED)]
    combos = [tuple(next(c for c in options[f] if c.name == name) for f in ALLOCATED) for name in names]
    for combo in sorted(combos, key=cost_of):
        if all(bool(np.all(s.holds(u))) for s, u in zip(specs, spec_uppers(res, combo, specs, scene, confidence))):
            return combo
    return None


def check_request(spec: EnsembleSpec, specs: list[Spec], n: int, confidence: float) -> None:
    """AllocationError for a request no allocation can answer, before any work."""
    if not model_level(spec.model).draws_clearances:
        raise AllocationError(f"--model {spec.model}: this level has no clearances, so no fit allocation; use "
                              f"{', '.join(models_with('draws_clearances'))}")
    scene = spec.scene()
    if scene.uncertain or scene.sampling.size_tolerance > 0:
        raise AllocationError(f"{spec.source}: allocate draws sizes from fit classes; give a scene without "
                              "[uncertain.*] tables and with [sampling] size_tolerance = 0")
    if why := upper_limits_problem(specs, confidence, n, "an allocation"):
        raise AllocationError(why)


def allocate(spec: EnsembleSpec, specs: list[Spec], n: int, folder, confidence: float, options: dict,
             workers: int = 2) -> Allocation:
    """The least-cost class per family meeting every spec, checked by an ensemble (module doc)."""
    check_request(spec, specs, n, confidence)
    if not model_level(spec.model).linear_in_clearances:
        raise ValueError(f"the {spec.model} level is not linear in the clearances: use greedy_allocate")
    scene = spec.scene()
    res = responses(spec, specs, n)
    found = search(res, options, specs, scene, confidence)
    combo = found.combo
    if combo is None:
        raise unreachable(specs, found.best, n, confidence)
    uniform = cheapest_uniform(res, options, specs, scene, confidence)
    predicted = {s.text: float(np.max(u)) for s, u in zip(specs, spec_uppers(res, combo, specs, scene, confidence))}
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    text = allocated_scene(spec.scene_text, spec.source, combo)
    scene_path = folder / f"{scene.name}_allocated.toml"
    scene_path.write_text(text)
    path = folder / f"{scene.name}_{spec.model}_allocated.nc"
    verdicts = run_trial(spec, text, combo, specs, n, path, confidence, workers).verdicts
    return Allocation(combo, cost_of(combo), uniform, None if uniform is None else cost_of(uniform), found.judged,
                      verdicts, predicted, path, scene_path)
