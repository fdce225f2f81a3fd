"""Quasi-static clearance level (L1): rigid links, platform error from the linearised leg closure.

For each leg, with n_i the unit rod vector (c_i - b_i)/|c_i - b_i| and r_i = b_i - o_p,
    n_i . (dp + dtheta x r_i) = n_i . (e_A,i + e_C,i - e_B,i)      (docs/model.md section 3)
is six linear equations in the platform error (dp, dtheta).  The eccentricities
are the realisation's draw, or sit at the clearance boundary along the rigid
joint reaction force (a loaded joint pushed to its wall).  Velocity and
acceleration errors are the time derivatives of the quasi-static error
(second-order central differences on the time grid).
"""
from __future__ import annotations

import numpy as np

from .clearance import ClearanceDraw
from .dynamics import inverse_dynamics
from .kinematics import RigidMotion
from .results import SimulationResult
from .status import check_history

__all__ = ["closure_matrix", "reaction_eccentricities", "quasi_static_error", "quasi_static_result",
           "time_derivatives"]


def closure_matrix(motion: RigidMotion) -> tuple[np.ndarray, np.ndarray]:
    """Rows [n_i, r_i x n_i] (T, 6, 6) of the linearised closure, and the unit rod vectors n_i."""
    n = motion.c - motion.b
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    return np.concatenate([n, np.cross(motion.r, n)], -1), n


def _unit(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    fb = fallback / np.maximum(np.linalg.norm(fallback, axis=-1, keepdims=True), 1e-300)
    return np.where(norm > 1e-12, v / np.maximum(norm, 1e-300), fb)


def reaction_eccentricities(scene, motion: RigidMotion, draw: ClearanceDraw):
    """e_A, e_C, e_B (T, 6, 3) at the clearance boundary, opposite the force on the ball side.

    The ball (journal) is pressed against the wall it is pushed towards, so e =
    -delta F_ball/|F_ball|.  The ball side is the distal body at A (crank) and C
    (rod) but the proximal one at B (the rod's ball in the platform's socket):
    there F_ball = -force_B.  Where a joint force vanishes the drawn direction is kept.
    """
    loads = inverse_dynamics(scene, motion)
    w = scene.geometry.w[None]
    fa = loads.force_A
    fa_axial = np.einsum("tli,tli->tl", fa, np.broadcast_to(w, fa.shape))
    fa_radial = fa - fa_axial[..., None] * w
    drawn_radial = draw.e_A - np.einsum("li,li->l", draw.e_A, w[0])[:, None] * w[0]
    e_A = (-draw.radial_size[:, None] * _unit(fa_radial, -drawn_radial[None])
           - (draw.axial_size * np.sign(fa_axial))[..., None] * w)
    e_C = -draw.size_C[:, None] * _unit(loads.force_C, -draw.e_C[None])
    e_B = draw.size_B[:, None] * _unit(loads.force_B, draw.e_B[None])
    return e_A, e_C, e_B


def quasi_static_error(scene, motion: RigidMotion, draw: ClearanceDraw, mode: str = "drawn"):
    """Platform error (T, 6) as displacement, velocity, acceleration (m, rad and rates)."""
    G, n = closure_matrix(motion)
    if mode == "reaction":
        e_A, e_C, e_B = reaction_eccentricities(scene, motion, draw)
    elif mode == "drawn":
        e_A, e_C, e_B = draw.e_A[None], draw.e_C[None], draw.e_B[None]
    else:
        raise ValueError(f"quasi-static eccentricity must be 'drawn' or 'reaction', got {mode!r}")
    rhs = np.einsum("tli,tli->tl", n, np.broadcast_to(e_A + e_C - e_B, n.shape))
    return time_derivatives(np.linalg.solve(G, rhs[..., None])[..., 0], motion.t)


def quasi_static_result(scene, motion: RigidMotion, draw: ClearanceDraw, mode: str = "drawn"):
    """One realisation's result; failed where the error is not finite or beyond the divergence
    limit (a near-singular closure, or clearances no linearisation can carry)."""
    d, v, a = quasi_static_error(scene, motion, draw, mode)
    status, message, steps = check_history(d, motion.t, "quasi-static displacement error")
    return SimulationResult(motion.t, d, v, a, status, message, steps, draw=draw)


def time_derivatives(d: np.ndarray, t: np.ndarray):
    """d (T, ...) with its first and second time derivatives, second-order central differences."""
    v = np.gradient(d, t, axis=0, edge_order=2)
    return d, v, np.gradient(v, t, axis=0, edge_order=2)
