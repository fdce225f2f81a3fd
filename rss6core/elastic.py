"""Time integration of the KED equations (eq. 32) along the scene's trajectory.

Per chunk of steps the condensed step matrices are factorised for all steps at
once (numpy over time); the step loop then only does small matrix-vector
products with constant link matrices and the time-varying end maps.  A run
that blows up (non-finite state or an elastic displacement above
``divergence_limit``) stops with status :data:`.status.FAILED` and a message; it does not raise.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .assembly import (ElasticModel, StepSolver, apply, build_elastic_model, internal_force,
                       system_at)
from .integrators import Integrator, correct, predict
from .kinematics import rigid_motion
from .results import SimulationResult, time_grid
from .status import DIVERGENCE_LIMIT, FAILED, FINISHED, diverged, failure_message

__all__ = ["simulate_elastic", "quasi_static_state", "elastic_energy"]


def _system(scene, model: ElasticModel, t: np.ndarray, motion=None):
    return system_at(model, rigid_motion(scene, t) if motion is None else motion(t), scene)


def quasi_static_state(scene, model: ElasticModel, t0: float = 0.0, h: float = 1e-4, motion=None):
    """Initial state on the quasi-static path d_qs(t) = K(t)^-1 F(t), consistent with eq. 32.

    v and a are second-order differences of d_qs (step h, s): central about t0 where the
    trajectory continued to t0 - h stays in the workspace, else one-sided over t0..t0 + 3h (a start
    on the workspace's border); d = K^-1 (F - C v - M a) then satisfies eq. 32 exactly at t0, so
    the run starts without the stiff-mode transient that d = K^-1 F, v = a = 0 would ring.
    ``motion``: as in :func:`simulate_elastic`.
    """
    path = _quasi_static_path(scene, model, t0 + h * np.array([-1.0, 0.0, 1.0]), motion)
    if np.all(np.isfinite(path.d)):
        v = (path.d[2] - path.d[0]) / (2.0 * h)
        a = (path.d[2] - 2.0 * path.d[1] + path.d[0]) / (h * h)
        at = 1
    else:
        path = _quasi_static_path(scene, model, t0 + h * np.arange(4.0), motion)
        d0, d1, d2, d3 = path.d
        v = (-3.0 * d0 + 4.0 * d1 - d2) / (2.0 * h)
        a = (2.0 * d0 - 5.0 * d1 + 4.0 * d2 - d3) / (h * h)
        at = 0
    maps, F = path.maps, path.F
    rhs = F[at] - internal_force(model, maps[at], np.zeros_like(v), v) - apply(model, maps[at], a, 1.0, 0.0)
    return path.stiff.solve(at, rhs), v, a


@dataclass(frozen=True)
class _QuasiStaticPath:
    """d_qs(t) = K(t)^-1 F(t) at a few instants, with the end maps, loads and stiffness solver there."""

    maps: object
    F: np.ndarray
    stiff: StepSolver
    d: np.ndarray


def _quasi_static_path(scene, model: ElasticModel, t: np.ndarray, motion) -> _QuasiStaticPath:
    maps, F = _system(scene, model, t, motion)
    stiff = StepSolver(model, maps, 0.0, 1.0)
    return _QuasiStaticPath(maps, F, stiff, np.stack([stiff.solve(k, F[k]) for k in range(len(t))]))


def simulate_elastic(scene, elements: int = 4, integrator: Integrator | None = None,
                     dt: float | None = None, model: ElasticModel | None = None,
                     initial=None, chunk: int = 200, keep_states: bool = False,
                     divergence_limit: float = DIVERGENCE_LIMIT, motion=None) -> SimulationResult:
    """Integrate eq. 32 along the scene's trajectory; the platform error is its elastic motion.

    ``initial`` is (d, v, a) or None for the quasi-static state at t = 0;
    ``divergence_limit`` (m or rad) marks a run as failed; ``motion(t)`` gives the rigid motion
    (:class:`.kinematics.RigidMotion`) the elastic motion is superposed on at times t (default the
    scene's inverse kinematics; a realised robot's under the nominal commands, rss6core/realised.py).
    """
    integrator = integrator or Integrator.newmark()
    model = model or build_elastic_model(scene, elements)
    h = scene.time_step if dt is None else dt
    t = time_grid(scene.trajectory.duration, h)
    d, v, a = quasi_static_state(scene, model, motion=motion) if initial is None else map(np.asarray, initial)
    cM, cC, cK = integrator.step_coefficients(h)
    lam1, lam2 = model.mass_damping, model.stiffness_damping
    am, af, w = integrator.alpha_m, integrator.alpha_f, integrator.weights(h)
    weighted = am != 0.0 or af != 0.0
    keep = slice(None) if keep_states else slice(-6, None)  # full states or the platform's
    hist = np.full((3, len(t), d[..., keep].shape[-1]), np.nan)
    hist[:, 0] = d[keep], v[keep], a[keep]
    status, message, steps = FINISHED, "", 0
    maps, F = _system(scene, model, t[:1], motion)
    Ma, rest = apply(model, maps[0], a, 1.0, 0.0), internal_force(model, maps[0], d, v)
    Fn = F[0]
    for start in range(1, len(t), chunk):
        stop = min(start + chunk, len(t))
        maps, F = _system(scene, model, t[start:stop], motion)
        solver = StepSolver(model, maps, cM + cC * lam1, cC * lam2 + cK)
        for j in range(stop - start):
            dp, vp = predict(d, v, a, h, w.d_pred, w.v_pred)
            r = (1.0 - af) * (F[j] - internal_force(model, maps[j], dp, vp))
            if weighted:
                r += af * (Fn - rest) - am * Ma
            a = solver.solve(j, r)
            d, v = correct(dp, vp, a, w.d_corr, w.v_corr)
            if weighted:
                Ma = apply(model, maps[j], a, 1.0, 0.0)
                rest = internal_force(model, maps[j], d, v)
                Fn = F[j]
            k = start + j
            if not (np.all(np.isfinite(d)) and np.abs(d).max() < divergence_limit):
                status = FAILED
                message = failure_message(diverged("elastic displacement", np.abs(d).max(),
                                                   divergence_limit), t[k], k, h)
                break
            hist[:, k] = d[keep], v[keep], a[keep]
            steps = k
        if status == FAILED:
            break
    p = hist[..., -6:]
    return SimulationResult(t, p[0], p[1], p[2], status, message, steps,
                            tuple(hist) if keep_states else None)


def elastic_energy(scene, model: ElasticModel, t: np.ndarray, d: np.ndarray, v: np.ndarray):
    """Kinetic 1/2 v'Mv and strain 1/2 d'Kd energy of the elastic motion (T,), J."""
    maps, _ = _system(scene, model, t)
    kin = np.array([0.5 * v[k] @ apply(model, maps[k], v[k], 1.0, 0.0) for k in range(len(t))])
    pot = np.array([0.5 * d[k] @ apply(model, maps[k], d[k], 0.0, 1.0) for k in range(len(t))])
    return kin, pot
