"""Platform motion along a scene's trajectory (any kind of :mod:`.trajectory_kinds`, eq. 35 by
default) with exact velocity and acceleration, and Euler-angle maps.

Orientation is R = Rz(n3) Ry(n2) Rx(n1) (eq. 1, with the paper's typo in the
(1,2) entry corrected).  Angular velocity and acceleration are in the base
frame: omega = E(n) n', omega' = E(n) n'' + E'(n, n') n'.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["rotation", "euler_rate_matrix", "euler_rate_matrix_dot", "PlatformMotion", "platform_motion"]


def rotation(n: np.ndarray) -> np.ndarray:
    """R = Rz(n3) Ry(n2) Rx(n1) for angles n (..., 3), rad (eq. 1)."""
    ca, cb, cg = np.cos(n[..., 0]), np.cos(n[..., 1]), np.cos(n[..., 2])
    sa, sb, sg = np.sin(n[..., 0]), np.sin(n[..., 1]), np.sin(n[..., 2])
    return np.stack([
        np.stack([cb * cg, -ca * sg + sa * sb * cg, sa * sg + ca * sb * cg], -1),
        np.stack([cb * sg, ca * cg + sa * sb * sg, -sa * cg + ca * sb * sg], -1),
        np.stack([-sb, sa * cb, ca * cb], -1)], -2)


def euler_rate_matrix(n: np.ndarray) -> np.ndarray:
    """E(n) with omega = E n' for R = Rz(n3) Ry(n2) Rx(n1); columns Rz Ry e_x, Rz e_y, e_z."""
    cb, cg = np.cos(n[..., 1]), np.cos(n[..., 2])
    sb, sg = np.sin(n[..., 1]), np.sin(n[..., 2])
    z, o = np.zeros_like(cb), np.ones_like(cb)
    return np.stack([np.stack([cb * cg, -sg, z], -1),
                     np.stack([cb * sg, cg, z], -1),
                     np.stack([-sb, z, o], -1)], -2)


def euler_rate_matrix_dot(n: np.ndarray, nd: np.ndarray) -> np.ndarray:
    """Time derivative of E(n) along n' (exact)."""
    cb, cg = np.cos(n[..., 1]), np.cos(n[..., 2])
    sb, sg = np.sin(n[..., 1]), np.sin(n[..., 2])
    bd, gd = nd[..., 1], nd[..., 2]
    z = np.zeros_like(cb)
    return np.stack([np.stack([-sb * cg * bd - cb * sg * gd, -cg * gd, z], -1),
                     np.stack([-sb * sg * bd + cb * cg * gd, -sg * gd, z], -1),
                     np.stack([-cb * bd, z, z], -1)], -2)


@dataclass(frozen=True)
class PlatformMotion:
    """Platform pose, twist and its rate at times t (leading axis T); base frame, SI."""
    t: np.ndarray          # (T,) s
    pose: np.ndarray       # (T, 6) x, y, z [m], n1, n2, n3 [rad]
    pose_rate: np.ndarray  # (T, 6) d pose/dt
    pose_acc: np.ndarray   # (T, 6) d2 pose/dt2
    R: np.ndarray          # (T, 3, 3)
    omega: np.ndarray      # (T, 3) rad/s
    omega_dot: np.ndarray  # (T, 3) rad/s^2

    @property
    def o(self) -> np.ndarray:
        return self.pose[:, :3]

    @property
    def v(self) -> np.ndarray:
        return self.pose_rate[:, :3]

    @property
    def a(self) -> np.ndarray:
        return self.pose_acc[:, :3]


def platform_motion(trajectory, t: np.ndarray) -> PlatformMotion:
    """The platform motion at times t (s) along ``trajectory`` (a kind of :mod:`.trajectory_kinds`: its
    own exact pose, pose rate and pose acceleration), with the twist that follows from them."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    pose, rate, acc = trajectory.derivatives(t)
    n, nd, ndd = pose[:, 3:], rate[:, 3:], acc[:, 3:]
    E = euler_rate_matrix(n)
    omega = np.einsum("tij,tj->ti", E, nd)
    omega_dot = np.einsum("tij,tj->ti", E, ndd) + np.einsum("tij,tj->ti",
                                                            euler_rate_matrix_dot(n, nd), nd)
    return PlatformMotion(t, pose, rate, acc, rotation(n), omega, omega_dot)
