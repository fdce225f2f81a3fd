"""Rigid inverse dynamics of the 6-RSS robot (Newton-Euler), vectorised over time.

Cranks turn about their fixed axes; rods are uniform tubes between two spherical
joints, so their spin about their own axis is neither driven nor loaded and is
taken as zero (for an axisymmetric rod it stays zero); the platform is rigid
with its centre of mass at o_p.  Each rod's transverse joint forces follow from
its own moment balance; the six axial rod forces from the platform's
Newton-Euler equations; the actuator torques from the cranks' moment balance
about their axes.  Gravity acts along -Z.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kinematics import RigidMotion, crank_axes
from .sections import crank_inertia, rod_inertia

__all__ = ["RigidLoads", "RodMotion", "inverse_dynamics", "rod_angular_motion", "mechanical_energy",
           "platform_inertia_world", "euler_moment"]


def _dot(x, y):
    return np.einsum("...i,...i->...", x, y)


@dataclass(frozen=True)
class RigidLoads:
    """Actuator torques and joint reactions along the trajectory (leading axis T), SI.

    Forces act on the distal body: A (base on crank), C (crank on rod), B (rod on platform).
    """
    torque: np.ndarray     # (T, 6) N m, generalised force conjugate to alpha_i
    force_A: np.ndarray    # (T, 6, 3) N
    moment_A: np.ndarray   # (T, 6, 3) N m, reaction moment of the revolute (normal to its axis)
    force_C: np.ndarray    # (T, 6, 3) N
    force_B: np.ndarray    # (T, 6, 3) N


@dataclass(frozen=True)
class RodMotion:
    """The rigid rods' rotation (T, 6, 3): unit vector u = (c - b)/L, angular velocity u x d'/L (rad/s)
    and angular acceleration u x d''/L (rad/s^2), without spin about u."""
    direction: np.ndarray
    omega: np.ndarray
    alpha: np.ndarray


def rod_angular_motion(m: RigidMotion) -> RodMotion:
    """The rods' :class:`RodMotion` along the rigid motion ``m``."""
    d = m.c - m.b
    L = np.linalg.norm(d, axis=-1, keepdims=True)
    u = d / L
    return RodMotion(u, np.cross(u, m.c_dot - m.b_dot) / L, np.cross(u, m.c_ddot - m.b_ddot) / L)


def platform_inertia_world(principal: np.ndarray, R: np.ndarray) -> np.ndarray:
    """R diag(I) R^T (T, 3, 3): the platform inertia about o_p in base axes, kg m^2."""
    return np.einsum("tij,j,tkj->tik", R, principal, R)


def euler_moment(I: np.ndarray, omega: np.ndarray, omega_dot: np.ndarray) -> np.ndarray:
    """I omega' + omega x I omega (T, 3): the rate of angular momentum of a rigid body, N m."""
    return (np.einsum("tij,tj->ti", I, omega_dot)
            + np.cross(omega, np.einsum("tij,tj->ti", I, omega)))


def inverse_dynamics(scene, m: RigidMotion) -> RigidLoads:
    """Actuator torques and joint reactions that drive the rigid robot along ``m`` (a realised
    robot's link lengths may differ per leg)."""
    g = scene.gravity_vector
    geo, pm = scene.geometry, m.platform
    crank, rod = crank_inertia(scene), rod_inertia(scene)
    L = _per_leg(geo.rod_length)
    rod_mass, crank_mass = _per_leg(rod.mass), _per_leg(crank.mass)
    rods = rod_angular_motion(m)
    u, wd_rod = rods.direction, rods.alpha
    a_rod = 0.5 * (m.c_ddot + m.b_ddot)
    # rod moment balance about C: (b - c) x F = I_t w' + (g - c) x m (a_g - g), F on rod at B
    m_req = _per_leg(rod.inertia[1]) * wd_rod + np.cross(-0.5 * L * u, rod_mass * (a_rod - g))
    f_perp = np.cross(u, m_req) / L
    # platform Newton-Euler fixes the axial part: F_i = f_i u_i + f_perp_i
    Ip = platform_inertia_world(scene.platform.inertia, pm.R)
    rhs = -np.concatenate([
        scene.platform.mass * (pm.a - g) + f_perp.sum(axis=1),
        euler_moment(Ip, pm.omega, pm.omega_dot) + np.cross(m.r, f_perp).sum(axis=1)], axis=-1)
    G = np.concatenate([u, np.cross(m.r, u)], axis=-1).transpose(0, 2, 1)  # columns per leg
    f_axial = np.linalg.solve(G, rhs[..., None])[..., 0]
    f_rod_B = f_axial[..., None] * u + f_perp
    f_rod_C = rod_mass * (a_rod - g) - f_rod_B
    # crank about its fixed axis e: I_A alpha'' = tau + e . [(c - a) x (-F_C) + (g_c - a) x m_c g]
    e = crank_axes(geo)[None]
    arm = m.c - geo.a[None]
    load = np.cross(arm, -f_rod_C) + np.cross(0.5 * arm, crank_mass * g)
    I_A = crank.inertia[1]
    torque = I_A * m.alpha_ddot - _dot(e, load)
    force_A = crank_mass * (0.5 * m.c_ddot - g) + f_rod_C
    moment_A = (I_A * m.alpha_ddot - torque)[..., None] * e - load
    return RigidLoads(torque, force_A, moment_A, f_rod_C, -f_rod_B)


def _per_leg(value) -> np.ndarray:
    """A link property, one value or one per leg (6,), shaped to multiply (..., 6, 3) vectors."""
    return np.asarray(value, float)[..., None]


def mechanical_energy(scene, m: RigidMotion) -> tuple[np.ndarray, np.ndarray]:
    """Kinetic and potential energy (T,) of cranks, rods and platform, J."""
    g = scene.gravity_vector
    crank, rod = crank_inertia(scene), rod_inertia(scene)
    pm = m.platform
    w_rod = rod_angular_motion(m).omega
    v_rod = 0.5 * (m.c_dot + m.b_dot)
    Ip = platform_inertia_world(scene.platform.inertia, pm.R)
    kinetic = (0.5 * crank.inertia[1] * np.sum(m.alpha_dot ** 2, axis=1)
               + 0.5 * rod.mass * np.sum(_dot(v_rod, v_rod), axis=1)
               + 0.5 * rod.inertia[1] * np.sum(_dot(w_rod, w_rod), axis=1)
               + 0.5 * scene.platform.mass * _dot(pm.v, pm.v)
               + 0.5 * _dot(pm.omega, np.einsum("tij,tj->ti", Ip, pm.omega)))
    a = scene.geometry.a[None]
    heights = (crank.mass * np.sum(0.5 * (a + m.c), axis=1) + rod.mass
               * np.sum(0.5 * (m.c + m.b), axis=1) + scene.platform.mass * pm.o)
    return kinetic, -heights @ g
