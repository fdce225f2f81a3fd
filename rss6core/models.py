"""The model ladder behind one entry point: ``simulate(scene, model=...)``.

Every level reports the same outputs: the platform pose error (actual minus
ideal rigid pose) as displacement, velocity and acceleration over time.
- rigid (L0): the reference itself, so its error is zero by definition;
- quasi-static (L1): rigid links, clearance eccentricities through the
  linearised leg closure (:mod:`.quasi_static`); needs a realisation;
- elastic (L2): kineto-elastodynamics with ideal joints (:mod:`.elastic`);
- paper (L3): the seed's method, clearances redrawn every step on top of L2
  (:mod:`.paper_method`); needs a realisation;
- contact (L4): clearance joints as contact pairs on top of L2
  (:mod:`.contact_dynamics`); the realisation's draw is the initial eccentricity.
:func:`simulate_batch` runs many realisations of one scene and shares what they
share: L2 is computed once for all realisations of L2 and L3, and L4 integrates
the batch as one array.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import scipy.linalg

from .assembly import build_elastic_model, dense_matrices, end_maps
from .clearance import draw_clearances
from .contact_dynamics import simulate_contact
from .elastic import simulate_elastic
from .results import SimulationResult, time_grid
from .integrators import make_integrator
from .kinematics import rigid_motion
from .paper_method import PaperClosure, paper_contact_forces, paper_draw, paper_result
from .quasi_static import quasi_static_result
from .scene import MODELS
from .status import FINISHED

__all__ = ["simulate", "simulate_batch", "default_time_step", "default_integrator", "stored_draw",
           "natural_frequencies", "MODELS"]


def stored_draw(scene, model: str, seed: int, realization: int, dt: float):
    """The draw an ensemble file records for a realisation: the paper level's first step, else the draw."""
    if model == "paper":
        steps = len(time_grid(scene.trajectory.duration, dt))
        return _first_step(paper_draw(scene, seed, realization, steps))
    return draw_clearances(scene, seed, realization)


def _first_step(draw):
    """A per-step draw's sizes with its first step's eccentricities, copied: a view would keep
    every step's draw (0.9 MB per realisation at 2001 steps) alive with the result."""
    return type(draw)(draw.radial_size, draw.axial_size, draw.size_C, draw.size_B,
                      draw.e_A[0].copy(), draw.e_C[0].copy(), draw.e_B[0].copy())


def default_time_step(scene, model: str) -> float:
    """The scene's time step for ``model``: the contact level has its own, finer one."""
    sim = scene.simulation
    return sim.contact_time_step if model == "contact" else sim.time_step


def default_integrator(scene, model: str) -> str:
    """The scene's integrator for ``model``: the contact level has its own (README, contact level)."""
    sim = scene.simulation
    return sim.contact_integrator if model == "contact" else sim.integrator


def simulate(scene, model: str | None = None, integrator: str | None = None,
             dt: float | None = None, elements: int | None = None, seed: int = 0,
             realization: int = 0) -> SimulationResult:
    """One run of ``model`` (default: the scene's) along the scene's trajectory.

    Clearance levels use realisation ``realization`` of the run seeded ``seed``;
    the same pair always gives the same result.
    """
    return simulate_batch(scene, model, integrator, dt, elements, seed, [realization])[0]


def simulate_batch(scene, model: str | None = None, integrator: str | None = None,
                   dt: float | None = None, elements: int | None = None, seed: int = 0,
                   realizations=(0,), tolerance: float | None = None,
                   refinements: int | None = None) -> list[SimulationResult]:
    """Realisations ``realizations`` of the run seeded ``seed``, one result each, in order.

    ``tolerance`` (m) and ``refinements`` set the contact level's adaptive step
    (default: the scene's; see :func:`.contact_dynamics.simulate_contact`).
    """
    sim = scene.simulation
    model = model or sim.model
    if model not in MODELS:
        raise ValueError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
    dt = default_time_step(scene, model) if dt is None else dt
    elements = elements or sim.elements_per_link
    realizations = list(realizations)
    if model in ("rigid", "quasi-static"):
        t = time_grid(scene.trajectory.duration, dt)
        if model == "rigid":
            zero = np.zeros((len(t), 6))
            return [SimulationResult(t, zero, zero, zero, FINISHED, "", len(t) - 1)] * len(realizations)
        motion = rigid_motion(scene, t)
        return [quasi_static_result(scene, motion, draw_clearances(scene, seed, r),
                                    sim.quasi_static_eccentricity) for r in realizations]
    method = make_integrator(integrator or default_integrator(scene, model), sim.newmark_beta,
                             sim.newmark_gamma, sim.hht_alpha, sim.spectral_radius)
    if model == "contact":
        draws = [draw_clearances(scene, seed, r) for r in realizations]
        batch = simulate_contact(scene, draws, elements, method, dt, tolerance=tolerance,
                                 refinements=refinements)
        return [dataclasses.replace(batch.result(k), draw=draw) for k, draw in enumerate(draws)]
    elastic = simulate_elastic(scene, elements, method, dt)
    if model == "elastic":
        return [elastic] * len(realizations)
    closure = PaperClosure(scene, rigid_motion(scene, elastic.t))
    out = []
    for r in realizations:
        draw = paper_draw(scene, seed, r, len(elastic.t))
        out.append(paper_result(elastic, closure, draw, paper_contact_forces(scene, draw, dt),
                                _first_step(draw)))
    return out


def natural_frequencies(scene, elements: int | None = None, t: float = 0.0) -> np.ndarray:
    """Undamped natural angular frequencies (rad/s, ascending) of the whole robot at time t."""
    model = build_elastic_model(scene, elements or scene.simulation.elements_per_link)
    maps = end_maps(model, rigid_motion(scene, np.array([t])), scene.geometry)
    M, K = dense_matrices(model, maps[0])
    return np.sqrt(np.abs(scipy.linalg.eigh(K, M, eigvals_only=True)))
