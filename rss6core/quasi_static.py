"""Quasi-static clearance level (L1): rigid links, platform error from the linearised leg closure.

For each leg, with n_i the unit rod vector (c_i - b_i)/|c_i - b_i| and r_i = b_i - o_p,
    n_i . (dp + dtheta x r_i) = n_i . (e_A,i + e_C,i - e_B,i)      (docs/model.md section 3)
is six linear equations in the platform error (dp, dtheta).  The eccentricities
are the realisation's draw, or sit at the clearance boundary along the rigid
joint reaction force (a loaded joint pushed to its wall).  Velocity and
acceleration errors are the time derivatives of the quasi-static error
(second-order central differences on the time grid; one-sided, of the same
order, at its two ends, where this smooth signal needs nothing beyond the grid).
"""
from __future__ import annotations

import numpy as np

from .clearance import ClearanceDraw
from .dynamics import inverse_dynamics
from .kinematics import RigidMotion
from .results import SimulationResult
from .status import check_history

__all__ = ["closure_matrix", "closure_rows", "reaction_eccentricities", "quasi_static_error", "quasi_static_result",
           "time_derivatives", "uniform_step", "padded_grid", "CENTRAL_PAD"]

CENTRAL_PAD = 2   # samples beyond each end that give every sample time_derivatives' central differences


def closure_matrix(motion: RigidMotion) -> tuple[np.ndarray, np.ndarray]:
    """Rows [n_i, r_i x n_i] (T, 6, 6) of the linearised closure, and the unit rod vectors n_i."""
    return closure_rows(motion.c, motion.b, motion.r)


def closure_rows(c: np.ndarray, b: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`closure_matrix` from crank tips c_i, platform joints b_i and r_i = b_i - o_p (..., 6, 3), m."""
    n = c - b
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    return np.concatenate([n, np.cross(r, n)], -1), n


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
    outcome = check_history(d, motion.t, "quasi-static displacement error")
    return SimulationResult(motion.t, d, v, a, outcome.status, outcome.message, outcome.steps, draw=draw)


def uniform_step(t: np.ndarray) -> float | None:
    """The step (s) of a uniform time grid t, (t_end - t_0) / (T - 1), where every step equals it to
    1e-9 of itself (their rounding); None for a grid of unequal steps or fewer than two times."""
    if len(t) < 2:
        return None
    h = (t[-1] - t[0]) / (len(t) - 1)
    return float(h) if np.all(np.abs(np.diff(t) - h) <= 1e-9 * abs(h)) and h != 0 else None


def padded_grid(t: np.ndarray, pad: int) -> np.ndarray:
    """The uniform time grid t (s) extended by ``pad`` steps before its start and after its end."""
    steps = np.arange(1, pad + 1) * (t[1] - t[0])
    return np.concatenate([t[0] - steps[::-1], t, t[-1] + steps])


def time_derivatives(d: np.ndarray, t: np.ndarray, pad: int = 0):
    """d (T, ...) on times t (s) with its first and second time derivatives: the central difference
    f'_k = (f_k+1 - f_k-1) / 2h applied twice, so a_k spans the samples k-2 .. k+2.

    With ``pad`` = 0 the first and last samples take second-order one-sided differences: as exact as
    the central ones for a smooth signal (error h^2 f^(3) / 3 against h^2 f^(3) / 6), but for a signal
    redrawn every step they weigh its noise more and put most maxima at the ends.  With ``pad`` =
    :data:`CENTRAL_PAD` d and t also hold that many samples beyond each end: every other sample
    gets the same central differences, and the pads are cut off the result.
    """
    h = uniform_step(t)
    spacing = t if h is None else h   # numpy's scalar-step differences: cheaper than from t
    v = np.gradient(d, spacing, axis=0, edge_order=2)
    a = np.gradient(v, spacing, axis=0, edge_order=2)
    if pad:
        d, v, a = d[pad:-pad], v[pad:-pad], a[pad:-pad]
    return d, v, a
