"""Ideal kinematics of the 6-RSS robot (eq. 1-4), vectorised over time.

Leg i: revolute A_i at a_i drives the crank to c_i = a_i + k_i L_ac [cos alpha_i, 0,
sin alpha_i] (eq. 2); the rod joins c_i to the platform joint b_i = R p_i + o_p
(eq. 3) with |c_i - b_i| = L_cb (eq. 4).  alpha_i is a right-handed rotation about
the crank axis e_i = -w_i.  Twists are [v, omega] in the base frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .trajectory import PlatformMotion, euler_rate_matrix, platform_motion, rotation

__all__ = [
    "inverse_kinematics", "crank_points", "crank_axes", "platform_joints", "leg_jacobian",
    "RigidMotion", "rigid_motion", "forward_kinematics", "check_workspace", "WorkspaceError",
    "MIN_TRANSMISSION", "MAX_CONDITION", "WorkspaceQuality", "workspace_quality",
]

MIN_TRANSMISSION = 1e-3   # |n . dc| / (L_ac L_cb) below this: a leg at its crank-rod singularity
MAX_CONDITION = 1e8       # condition number of the rows [n_i, r_i x n_i] / L_cb above this: singular


class WorkspaceError(ValueError):
    """A trajectory that leaves the robot's workspace; the message names the leg and the time."""


def platform_joints(geometry, o: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """b_i = R p_i + o_p (eq. 3) and r_i = R p_i, both (T, 6, 3), m."""
    r = np.einsum("tij,lj->tli", R, geometry.p)
    return r + o[:, None, :], r


def _reach(geometry, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Leg-plane coordinates: phi = atan2(d_z, d_x), rho = hypot(d_x, d_z), K/rho."""
    d = np.einsum("lji,tlj->tli", geometry.k, b - geometry.a)  # k_i^T (b_i - a_i)
    lac, lcb = geometry.crank_length, geometry.rod_length
    K = (lac ** 2 + np.einsum("tli,tli->tl", d, d) - lcb ** 2) / (2.0 * lac)
    rho = np.hypot(d[..., 0], d[..., 2])
    return np.arctan2(d[..., 2], d[..., 0]), rho, K / rho


def inverse_kinematics(geometry, b: np.ndarray) -> np.ndarray:
    """Crank angles alpha_i = atan2(d_z, d_x) + acos(K / hypot(d_x, d_z)) (T, 6), rad.

    The closed form of eq. 4 on the branch of docs/model.md section 2; NaN where the
    joint b_i is out of reach (use :func:`check_workspace` for a clear error).
    """
    phi, _, ratio = _reach(geometry, b)
    with np.errstate(invalid="ignore"):
        return phi + np.arccos(ratio)


def crank_points(geometry, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """c_i (eq. 2) and its first two derivatives in alpha_i, each (T, 6, 3), m."""
    ca, sa, z = np.cos(alpha), np.sin(alpha), np.zeros_like(alpha)
    L = np.asarray(geometry.crank_length, float)[..., None]   # scalar or per leg (6, 1)
    m = L * np.stack([ca, z, sa], -1)
    dm = L * np.stack([-sa, z, ca], -1)
    c = np.einsum("lij,tlj->tli", geometry.k, m)
    dc = np.einsum("lij,tlj->tli", geometry.k, dm)
    return c + geometry.a, dc, -c


def crank_axes(geometry) -> np.ndarray:
    """Unit axes e_i with c_i' = alpha_i' e_i x (c_i - a_i); e_i = -w_i (6, 3)."""
    return -geometry.w


def leg_jacobian(geometry, b: np.ndarray, r: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """J (T, 6, 6) with alpha' = J [v, omega]: rows [n_i, r_i x n_i] / (n_i . dc_i/dalpha_i)."""
    c, dc, _ = crank_points(geometry, alpha)
    n = c - b
    rows = np.concatenate([n, np.cross(r, n)], axis=-1)
    return rows / np.einsum("tli,tli->tl", n, dc)[..., None]


@dataclass(frozen=True)
class RigidMotion:
    """Ideal rigid motion of platform and legs along a trajectory (leading axis T), SI."""
    platform: PlatformMotion
    alpha: np.ndarray        # (T, 6) rad
    alpha_dot: np.ndarray    # (T, 6) rad/s
    alpha_ddot: np.ndarray   # (T, 6) rad/s^2
    c: np.ndarray            # (T, 6, 3) crank tips C_i
    c_dot: np.ndarray
    c_ddot: np.ndarray
    b: np.ndarray            # (T, 6, 3) platform joints B_i
    b_dot: np.ndarray
    b_ddot: np.ndarray
    r: np.ndarray            # (T, 6, 3) b_i - o_p
    jacobian: np.ndarray     # (T, 6, 6) alpha' = J [v, omega]

    @property
    def t(self) -> np.ndarray:
        return self.platform.t


def rigid_motion(scene, t: np.ndarray | None = None) -> RigidMotion:
    """Exact ideal motion at times t (default: the scene's time grid)."""
    geo = scene.geometry
    pm = platform_motion(scene.trajectory, scene.times if t is None else t)
    b, r = platform_joints(geo, pm.o, pm.R)
    w, wd = pm.omega[:, None, :], pm.omega_dot[:, None, :]
    b_dot = pm.v[:, None, :] + np.cross(w, r)
    b_ddot = pm.a[:, None, :] + np.cross(wd, r) + np.cross(w, np.cross(w, r))
    alpha = inverse_kinematics(geo, b)
    c, dc, d2c = crank_points(geo, alpha)
    J = leg_jacobian(geo, b, r, alpha)
    alpha_dot = np.einsum("tlk,tk->tl", J, np.concatenate([pm.v, pm.omega], axis=-1))
    n = c - b
    c_dot = dc * alpha_dot[..., None]
    n_dot = c_dot - b_dot
    dot = lambda x, y: np.einsum("tli,tli->tl", x, y)  # noqa: E731
    # second derivative of |n|^2 = L_cb^2: n . n'' + |n'|^2 = 0, solved for alpha''
    alpha_ddot = (dot(n, b_ddot) - dot(n, d2c) * alpha_dot ** 2 - dot(n_dot, n_dot)) / dot(n, dc)
    c_ddot = dc * alpha_ddot[..., None] + d2c * (alpha_dot ** 2)[..., None]
    return RigidMotion(pm, alpha, alpha_dot, alpha_ddot, c, c_dot, c_ddot, b, b_dot, b_ddot, r, J)


def forward_kinematics(geometry, alpha: np.ndarray, pose0: np.ndarray, tol: float = 1e-13,
                       max_iter: int = 50) -> tuple[np.ndarray, int]:
    """Platform pose (T, 6) from crank angles (T, 6) by Newton's method on eq. 4.

    Starts from ``pose0`` (T, 6); returns the pose and the iterations taken.
    Raises ArithmeticError if the largest step is still above ``tol`` after ``max_iter``.
    """
    alpha = np.atleast_2d(alpha)
    pose = np.array(np.broadcast_to(pose0, alpha.shape), dtype=float)
    c, _, _ = crank_points(geometry, alpha)
    for it in range(1, max_iter + 1):
        b, r = platform_joints(geometry, pose[:, :3], rotation(pose[:, 3:]))
        n = c - b
        g = np.einsum("tli,tli->tl", n, n) - geometry.rod_length ** 2
        # d g_i = -2 [n_i, (r_i x n_i)^T E] d pose
        dg = -2.0 * np.concatenate(
            [n, np.einsum("tli,tij->tlj", np.cross(r, n), euler_rate_matrix(pose[:, 3:]))], -1)
        step = np.linalg.solve(dg, -g[..., None])[..., 0]
        pose += step
        if np.max(np.abs(step)) < tol:
            return pose, it
    raise ArithmeticError(f"forward kinematics did not converge in {max_iter} iterations "
                          f"(last step {np.max(np.abs(step)):.3e})")


@dataclass(frozen=True)
class WorkspaceQuality:
    """How well the robot reaches and drives each pose of a trajectory (leading axis T)."""
    t: np.ndarray             # (T,) s
    reach: np.ndarray         # (T, 6) |K/rho| of each leg: its joint b_i is reachable when <= 1
    transmission: np.ndarray  # (T, 6) |n_i . dc_i/dalpha_i| / (L_ac L_cb): 0 at the crank-rod singularity
    condition: np.ndarray     # (T,) condition number of the platform Jacobian rows [n_i, r_i x n_i] / L_cb
    alpha: np.ndarray         # (T, 6) crank angles, rad


_WHERE = "; check [trajectory] against [geometry]"


def workspace_quality(scene, t: np.ndarray | None = None) -> WorkspaceQuality:
    """Reach, transmission and conditioning at times t (s; default the scene's grid); WorkspaceError
    naming the leg and the first time where a platform joint is out of reach."""
    geo = scene.geometry
    t = scene.times if t is None else np.atleast_1d(np.asarray(t, dtype=float))
    pm = platform_motion(scene.trajectory, t)
    b, r = platform_joints(geo, pm.o, pm.R)
    _, _, ratio = _reach(geo, b)
    bad = np.argwhere(~(np.abs(ratio) <= 1.0))
    if bad.size:
        k, leg = bad[0]
        raise WorkspaceError(f"trajectory leaves the workspace: leg {leg + 1} cannot reach its "
                             f"platform joint at t = {t[k]:.4f} s (|K/rho| = {abs(ratio[k, leg]):.7g} "
                             f"> 1){_WHERE}")
    alpha = inverse_kinematics(geo, b)
    c, dc, _ = crank_points(geo, alpha)
    n = c - b
    trans = np.abs(np.einsum("tli,tli->tl", n, dc)) / (geo.crank_length * geo.rod_length)
    rows = np.concatenate([n, np.cross(r, n)], axis=-1) / np.asarray(geo.rod_length, float)[..., None]
    return WorkspaceQuality(t, np.abs(ratio), trans, np.linalg.cond(rows), alpha)


def check_workspace(scene, min_transmission: float = MIN_TRANSMISSION, max_condition: float = MAX_CONDITION) -> None:
    """Raise WorkspaceError naming the leg and time where the trajectory leaves the workspace.

    Checks on the scene's time grid that every b_i is reachable (|K/rho| <= 1),
    that no leg is near its crank-rod singularity (|n . dc| / (L_ac L_cb) >=
    ``min_transmission``) and that the platform Jacobian is well conditioned.
    """
    q = workspace_quality(scene)
    t = q.t
    bad = np.argwhere(q.transmission < min_transmission)
    if bad.size:
        k, leg = bad[0]
        raise WorkspaceError(f"trajectory leaves the workspace: leg {leg + 1} is at its crank-rod "
                             f"singularity at t = {t[k]:.4f} s{_WHERE}")
    cond = q.condition
    if np.any(~(cond < max_condition)):
        k = int(np.argmax(~(cond < max_condition)))
        raise WorkspaceError(f"trajectory leaves the workspace: the platform is singular "
                             f"(condition number {cond[k]:.3g}) at t = {t[k]:.4f} s{_WHERE}")
