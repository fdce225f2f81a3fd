"""The model ladder behind one entry point: ``simulate(scene, model=...)``.

Every level reports the same outputs: the platform pose error (actual minus
ideal rigid pose) as displacement, velocity and acceleration over time.
- rigid (L0): the reference itself, so its error is zero by definition;
- quasi-static (L1): rigid links, clearance eccentricities through the
  linearised leg closure (:mod:`.quasi_static`); needs a realisation;
- elastic (L2): kineto-elastodynamics with ideal joints (:mod:`.elastic`).
"""
from __future__ import annotations

import numpy as np
import scipy.linalg

from .assembly import build_elastic_model, dense_matrices, end_maps
from .clearance import draw_clearances
from .elastic import SimulationResult, simulate_elastic, time_grid
from .integrators import make_integrator
from .kinematics import rigid_motion
from .quasi_static import quasi_static_error
from .scene import MODELS

__all__ = ["simulate", "natural_frequencies", "MODELS"]


def simulate(scene, model: str | None = None, integrator: str | None = None,
             dt: float | None = None, elements: int | None = None, seed: int = 0,
             realization: int = 0) -> SimulationResult:
    """One run of ``model`` (default: the scene's) along the scene's trajectory.

    Clearance levels use realisation ``realization`` of the run seeded ``seed``;
    the same pair always gives the same result.
    """
    sim = scene.simulation
    model = model or sim.model
    if model not in MODELS:
        raise ValueError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
    dt = sim.time_step if dt is None else dt
    if model == "rigid":
        t = time_grid(scene.trajectory.duration, dt)
        zero = np.zeros((len(t), 6))
        return SimulationResult(t, zero, zero, zero, "finished", "", len(t) - 1)
    if model == "quasi-static":
        t = time_grid(scene.trajectory.duration, dt)
        d, v, a = quasi_static_error(scene, rigid_motion(scene, t),
                                     draw_clearances(scene, seed, realization),
                                     sim.quasi_static_eccentricity)
        return SimulationResult(t, d, v, a, "finished", "", len(t) - 1)
    method = make_integrator(integrator or sim.integrator, sim.newmark_beta, sim.newmark_gamma,
                             sim.hht_alpha, sim.spectral_radius)
    return simulate_elastic(scene, elements or sim.elements_per_link, method, dt)


def natural_frequencies(scene, elements: int | None = None, t: float = 0.0) -> np.ndarray:
    """Undamped natural angular frequencies (rad/s, ascending) of the whole robot at time t."""
    model = build_elastic_model(scene, elements or scene.simulation.elements_per_link)
    maps = end_maps(model, rigid_motion(scene, np.array([t])), scene.geometry)
    M, K = dense_matrices(model, maps[0])
    return np.sqrt(np.abs(scipy.linalg.eigh(K, M, eigvals_only=True)))
