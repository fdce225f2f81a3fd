"""``rss6 allocate --per-joint`` at the quasi-static level: the least-cost fit class per joint (the six
revolute journals A1-A6 and the twelve ball joints C1-C6, B1-B6).

The error is linear in each joint's eccentricity (pipeline.studies.allocation), so one run per joint
and realisation with that joint alone at unit size gives its response U_j(t); a class [lo_j, hi_j]
drawing s_j = lo_j + (hi_j - lo_j) u_j gives the error sum_j s_j U_j(t) + the revolute axial part.
Summed over a family's joints these are the family responses A_f, B_f, so the per-family optimum
comes first (exhaustive, exact) and is the start.  If the per-joint combinations number at most
EXHAUSTIVE_LIMIT, all are judged in rising cost (exact); otherwise a greedy descent loosens one joint
to its next strictly cheaper class at a time, the most cost saved first and, among equal savings,
the one that leaves the largest margin (the smallest worst ratio of upper bound to limit), until no
loosening meets every spec (not proven least-cost, and it says so).  Every judgement is a linear combination, so no
ensemble runs during the search.  The verification simulates the seed's realisations 0..n-1 at the
answer's per-joint sizes (the same uniforms: a scene's [tolerance] bands are per family, so no
scene can express a per-joint answer) and judges their Dataset with the gate.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rss6core import ClearanceDraw, prepare_level, stored_draw

from ..analysis.gate import judge_all
from ..analysis.spec import Spec
from ..ensemble.run import EnsembleSpec
from ..files.records import chunk_dataset, finish_ensemble
from ..files.writing import write_netcdf
from .allocation import (ALLOCATED, PROBE_LOW, Allocation, Responses,
                         cells_history, check_request, cheapest_uniform, cost_of, error_uppers, family_draw,
                         fixed_draw, probe_scene, search, unit_eccentricity, unreachable)

__all__ = ["EXHAUSTIVE_LIMIT", "JOINT_LETTERS", "JointResponses", "joint_labels", "joint_responses", "joint_uppers",
           "JointSearch", "joint_search", "verify_per_joint", "allocate_per_joint"]

EXHAUSTIVE_LIMIT = 4096          # per-joint combinations judged one by one at most
JOINT_LETTERS = {"revolute_radial": "A", "spherical_C": "C", "spherical_B": "B"}


def joint_labels() -> tuple[str, ...]:
    """The 18 allocated joints in order: A1-A6, C1-C6, B1-B6."""
    return tuple(f"{JOINT_LETTERS[f]}{leg}" for f in ALLOCATED for leg in range(1, 7))


@dataclass(frozen=True)
class JointResponses:
    """Per joint j (A1-A6, C1-C6, B1-B6) its error per metre of size U_j: (joint, n, T, cell), SI/m;
    its size uniform u_j in each realisation: (joint, n); the revolute axial part: (n, T, cell), SI;
    the cells' (quantity, direction) and the times (s)."""
    unit: np.ndarray
    u: np.ndarray
    fixed: np.ndarray
    cells: tuple[tuple[str, str], ...]
    t: np.ndarray

    def family(self) -> Responses:
        """The per-family responses A_f = sum_j U_j, B_f = sum_j u_j U_j over each family's six joints."""
        shape = (len(ALLOCATED), 6) + self.unit.shape[1:]
        spread = (self.u[:, :, None, None] * self.unit).reshape(shape).sum(axis=1)
        return Responses(self.unit.reshape(shape).sum(axis=1), spread, self.fixed, self.cells, self.t)


def _one_joint_draws(scene, draw) -> tuple[list, np.ndarray]:
    """18 draws, each one joint alone at size PROBE_LOW in its realisation's direction, and the
    joints' size uniforms (18,)."""
    draws, uniforms = [], []
    for family in ALLOCATED:
        unit, u = unit_eccentricity(scene, draw, family)
        uniforms.append(u)
        for leg in range(6):
            sizes = np.zeros(6)
            sizes[leg] = PROBE_LOW
            draws.append(family_draw(family, sizes, sizes[:, None] * unit))
    return draws, np.concatenate(uniforms)


def joint_responses(spec: EnsembleSpec, specs: list[Spec], n: int) -> JointResponses:
    """U_j and u_j of realisations 0..n-1 of the seed, for the cells the specs read (19 runs each)."""
    cells = tuple(dict.fromkeys((s.quantity, d) for s in specs for d in s.directions))
    scene = probe_scene(spec)
    level = prepare_level(scene, spec.model, dt=spec.dt)
    t = scene.times
    unit, u = np.empty((18, n, len(t), len(cells))), np.empty((18, n))
    fixed = np.empty((n, len(t), len(cells)))
    for r in range(n):
        draw = stored_draw(scene, spec.model, spec.seed, r, spec.dt)
        draws, u[:, r] = _one_joint_draws(scene, draw)
        results = level.simulate_draws([fixed_draw(scene, draw), *draws])
        fixed[r] = cells_history(results[0], cells)
        for j, result in enumerate(results[1:]):
            unit[j, r] = cells_history(result, cells) / PROBE_LOW
    return JointResponses(unit, u, fixed, cells, t)


def joint_uppers(res: JointResponses, combo, specs: list[Spec], scene, confidence: float) -> list[np.ndarray]:
    """Per spec, the one-sided upper bound (SI) per direction at ``combo`` (one ClassOption per joint)."""
    lows = np.array([c.low for c in combo])
    widths = np.array([c.high - c.low for c in combo])
    spread = np.einsum("jr,jrtc->rtc", widths[:, None] * res.u, res.unit)
    err = np.abs(np.tensordot(lows, res.unit, 1) + spread + res.fixed)   # (n, T, cell)
    return error_uppers(err, res.cells, res.t, specs, scene, confidence)


def _margin(uppers, specs) -> float | None:
    """The worst ratio of upper bound to limit if every spec holds, else None."""
    if not all(bool(np.all(s.holds(u))) for s, u in zip(specs, uppers)):
        return None
    return max(float(np.max(u)) / s.limit for s, u in zip(specs, uppers))


def _exhaustive(res, options, specs, scene, confidence):
    """The least-cost passing per-joint combination by judging all in rising cost; (combo, judged)."""
    per_joint = [options[f] for f in ALLOCATED for _ in range(6)]
    combos = sorted(itertools.product(*per_joint), key=lambda c: sum(x.cost for x in c))
    for k, combo in enumerate(combos, 1):
        if _margin(joint_uppers(res, combo, specs, scene, confidence), specs) is not None:
            return combo, k
    raise AssertionError("the per-family optimum is a per-joint combination that passes")


def _greedy(res, options, specs, scene, confidence, start):
    """Greedy one-joint loosening from ``start`` (module doc); (combo, combinations judged)."""
    ranked = {f: sorted(options[f], key=lambda c: -c.cost) for f in ALLOCATED}
    families = [f for f in ALLOCATED for _ in range(6)]
    combo, judged = tuple(start), 0
    while True:
        best = None
        for j, family in enumerate(families):
            cheaper = [c for c in ranked[family] if c.cost < combo[j].cost]   # strictly: a tie saves nothing
            if not cheaper:
                continue
            candidate = combo[:j] + (cheaper[0],) + combo[j + 1:]
            judged += 1
            margin = _margin(joint_uppers(res, candidate, specs, scene, confidence), specs)
            key = (combo[j].cost - cheaper[0].cost, -margin if margin is not None else 0.0)
            if margin is not None and (best is None or key > best[0]):
                best = (key, candidate)
        if best is None:
            return combo, judged
        combo = best[1]


@dataclass(frozen=True)
class JointSearch:
    """What the per-joint search found: the combo (a class per joint), the combinations judged (the
    per-family search's included), how (exhaustive or greedy) and the per-family optimum it began from."""
    combo: tuple
    judged: int
    method: str
    family_combo: tuple


def joint_search(res: JointResponses, options: dict, specs: list[Spec], scene, confidence: float) -> JointSearch:
    """The least-cost class per joint: exhaustive if at most EXHAUSTIVE_LIMIT combinations, else greedy
    from the per-family optimum (module doc; :class:`JointSearch`)."""
    family = search(res.family(), options, specs, scene, confidence)
    if family.combo is None:
        raise unreachable(specs, family.best, res.u.shape[1], confidence)
    if math.prod(len(options[f]) ** 6 for f in ALLOCATED) <= EXHAUSTIVE_LIMIT:
        combo, k = _exhaustive(res, options, specs, scene, confidence)
        return JointSearch(combo, family.judged + k, "exact linear scaling, per joint (exhaustive)", family.combo)
    start = tuple(c for c in family.combo for _ in range(6))
    combo, k = _greedy(res, options, specs, scene, confidence, start)
    return JointSearch(combo, family.judged + k, "linear scaling, per joint: greedy one-joint loosening from the "
                       "per-family optimum (not proven least-cost)", family.combo)


def _sized_draw(scene, draw: ClearanceDraw, combo) -> ClearanceDraw:
    """The probe draw at the per-joint classes: joint j's size lo_j + (hi_j - lo_j) u_j on its own
    uniform and direction; the revolute axial play as drawn."""
    w = scene.geometry.w
    parts = {}
    for k, family in enumerate(ALLOCATED):
        unit, u = unit_eccentricity(scene, draw, family)
        sizes = np.array([c.low + (c.high - c.low) * x for c, x in zip(combo[6 * k:6 * k + 6], u)])
        parts[family] = (sizes, sizes[:, None] * unit)
    axial = np.einsum("li,li->l", draw.e_A, w)[:, None] * w
    return ClearanceDraw(radial_size=parts["revolute_radial"][0], axial_size=draw.axial_size,
                         size_C=parts["spherical_C"][0], size_B=parts["spherical_B"][0],
                         e_A=parts["revolute_radial"][1] + axial, e_C=parts["spherical_C"][1],
                         e_B=parts["spherical_B"][1])


def verify_per_joint(spec: EnsembleSpec, specs: list[Spec], n: int, combo, path: Path, confidence: float):
    """The verdicts of the gate on realisations 0..n-1 simulated at the per-joint classes (module doc),
    their ensemble Dataset written to ``path``."""
    scene = probe_scene(spec)
    level = prepare_level(scene, spec.model, dt=spec.dt)
    draws = [_sized_draw(scene, stored_draw(scene, spec.model, spec.seed, r, spec.dt), combo) for r in range(n)]
    sim = scene.simulation
    chunk = chunk_dataset(level.simulate_draws(draws), draws, list(range(n)), spec.store, sim.settle_time,
                          sim.steady_after)
    ds = finish_ensemble([chunk], scene, model=spec.model, integrator=spec.integrator, dt=spec.dt,
                         elements=spec.elements, seed=spec.seed, store=spec.store, sampler=spec.sampler_attrs())
    ds.attrs["allocation"] = ("per-joint classes, each joint's size drawn in its class band on the seed's "
                              "uniforms (the [tolerance] bands in the scene attribute are the search's probe): "
                              + ", ".join(f"{j} {c.name}" for j, c in zip(joint_labels(), combo)))
    write_netcdf(ds, path)
    return tuple(judge_all(specs, ds, confidence))


def allocate_per_joint(spec: EnsembleSpec, specs: list[Spec], n: int, folder, confidence: float,
                       options: dict) -> Allocation:
    """The least-cost class per joint meeting every spec, verified by simulation (module doc)."""
    check_request(spec, specs, n, confidence)
    scene = spec.scene()
    res = joint_responses(spec, specs, n)
    found = joint_search(res, options, specs, scene, confidence)
    combo = found.combo
    uniform = cheapest_uniform(res.family(), options, specs, scene, confidence)
    predicted = {s.text: float(np.max(u)) for s, u in zip(specs, joint_uppers(res, combo, specs, scene, confidence))}
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{scene.name}_{spec.model}_allocated_per_joint.nc"
    verdicts = verify_per_joint(spec, specs, n, combo, path, confidence)
    return Allocation(combo, sum(c.cost for c in combo), uniform, None if uniform is None else cost_of(uniform),
                      found.judged, verdicts, predicted, path, None, method=found.method, joints=joint_labels())
