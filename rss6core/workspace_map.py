"""The workspace error map of the quasi-static level (docs/model.md section 3, "Workspace error map").

At a static platform pose the quasi-static error is linear in the eccentricities:
G d = [n_i . (e_A,i + e_C,i - e_B,i)]_i, so d_k = sum_i g_ki n_i . (e_A,i + e_C,i - e_B,i) with
g = G^-1.  Each eccentricity ranges over its joint's clearance set, independently of the others, and
every set is symmetric about its centre, so the largest |d_k| any clearance state can cause is
    max |d_k| = sum_i |g_ki| (h_A,i(n_i) + h_C,i(n_i) + h_B,i(n_i))                       (M1)
with h the support function h(n) = max_{e in set} n . e of the joint's set (M2, M3).  The revolute
A_i's set is what rss6core/clearance.py draws e_A from: a radial part of length at most delta_r in
the plane normal to w_i plus an axial part of at most delta_a along w_i (a solid cylinder), so
    h_A(n) = delta_r |n - (n . w) w| + delta_a |n . w|                                     (M2)
and a spherical joint's set is a ball of radius delta_s, h(n) = delta_s |n|                 (M3).
The sizes are the nominal [clearance] sizes, or the upper end of the family's size band where the
scene draws sizes from one ([tolerance.<family>] high_m, or RELATIVE_BAND_REACH x nominal under
[sampling] size_tolerance).  A pose the robot cannot reach (no inverse kinematics, a leg at its
crank-rod singularity, an ill-conditioned G by check_workspace's thresholds) gives NaN.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .clearance import FAMILIES, draw_clearances, size_band
from .kinematics import (MAX_CONDITION, MIN_TRANSMISSION, crank_points, inverse_kinematics,
                         platform_joints)
from .quasi_static import closure_rows
from .trajectory import rotation

__all__ = ["WorstCaseSizes", "worst_case_sizes", "revolute_support", "ball_support", "StaticClosure",
           "static_closure", "worst_case_error", "DrawnEccentricities", "drawn_eccentricities",
           "sampled_errors"]


@dataclass(frozen=True)
class WorstCaseSizes:
    """The clearance sizes (m) the worst case (M1) takes, and whether each is a band's upper end."""
    revolute_radial: float
    revolute_axial: float
    spherical_C: float
    spherical_B: float
    from_band: tuple   # the FAMILIES whose size is the upper end of a size band (else nominal)


def worst_case_sizes(scene) -> WorstCaseSizes:
    """Per joint family the largest size the scene can draw (m): nominal, or its size band's upper end."""
    sizes, banded = {}, []
    for family in FAMILIES:
        band = size_band(scene, family)
        sizes[family] = float(band.high) if band is not None else float(getattr(scene.clearance, family))
        if band is not None:
            banded.append(family)
    return WorstCaseSizes(**sizes, from_band=tuple(banded))


def revolute_support(n: np.ndarray, w: np.ndarray, radial: float, axial: float) -> np.ndarray:
    """Support function (M2) of a revolute joint's clearance set (m): radial <= ``radial`` normal to
    the unit axis w, axial <= ``axial`` along it, for directions n (..., 3) and axes w (..., 3)."""
    along = np.sum(n * w, axis=-1)
    return radial * np.linalg.norm(n - along[..., None] * w, axis=-1) + axial * np.abs(along)


def ball_support(n: np.ndarray, size: float) -> np.ndarray:
    """Support function (M3) of a spherical joint's clearance ball of radius ``size`` (m)."""
    return size * np.linalg.norm(n, axis=-1)


@dataclass(frozen=True)
class StaticClosure:
    """The linearised leg closure at static poses (leading axis P); NaN where a pose is unreachable."""
    pose: np.ndarray          # (P, 6) x, y, z [m], n1, n2, n3 [rad]
    reachable: np.ndarray     # (P,) bool: inverse kinematics exists and G is well conditioned
    n: np.ndarray             # (P, 6, 3) unit rod vectors n_i
    inverse: np.ndarray       # (P, 6, 6) g = G^-1: platform error (m, rad) per unit of n_i . e (m)
    transmission: np.ndarray  # (P,) smallest |n_i . dc_i/dalpha_i| / (L_ac L_cb) over the legs
    condition: np.ndarray     # (P,) condition number of G

    def poses(self, part: slice) -> StaticClosure:
        """The closure at the poses ``part`` of these (a block of a large grid)."""
        return StaticClosure(*(getattr(self, f.name)[part] for f in fields(self)))


def static_closure(geometry, pose) -> StaticClosure:
    """G (docs/model.md section 3) and its inverse at poses (P, 6), reachability by check_workspace's
    thresholds (MIN_TRANSMISSION, MAX_CONDITION); an unreachable pose is NaN, never an exception."""
    pose = np.atleast_2d(np.asarray(pose, dtype=float))
    b, r = platform_joints(geometry, pose[:, :3], rotation(pose[:, 3:]))
    alpha = inverse_kinematics(geometry, b)
    solved = np.all(np.isfinite(alpha), axis=-1)
    c, dc, _ = crank_points(geometry, np.where(solved[:, None], alpha, 0.0))
    G, n = closure_rows(c, b, r)
    transmission = np.min(np.abs(np.sum((c - b) * dc, axis=-1)), axis=-1) / (
        geometry.crank_length * geometry.rod_length)
    G = np.where(solved[:, None, None], G, np.eye(6))
    condition = np.linalg.cond(G)
    reachable = solved & (transmission >= MIN_TRANSMISSION) & (condition < MAX_CONDITION)
    inverse = np.linalg.inv(np.where(reachable[:, None, None], G, np.eye(6)))
    nan = ~reachable
    inverse[nan], n = np.nan, np.where(nan[:, None, None], np.nan, n)
    transmission, condition = np.where(solved, transmission, np.nan), np.where(solved, condition, np.nan)
    return StaticClosure(pose, reachable, n, inverse, transmission, condition)


def worst_case_error(closure: StaticClosure, w: np.ndarray, sizes: WorstCaseSizes) -> np.ndarray:
    """(P, 6) the largest |d_k| (m for x, y, z; rad for rx, ry, rz) over every clearance state (M1)."""
    h = (revolute_support(closure.n, w, sizes.revolute_radial, sizes.revolute_axial)
         + ball_support(closure.n, sizes.spherical_C) + ball_support(closure.n, sizes.spherical_B))
    return np.einsum("pkl,pl->pk", np.abs(closure.inverse), h)


@dataclass(frozen=True)
class DrawnEccentricities:
    """N realisations' e_A + e_C - e_B (N, 6, 3), m: all the quasi-static level takes of a draw."""
    seed: int
    combined: np.ndarray


def drawn_eccentricities(scene, draws: int, seed: int) -> DrawnEccentricities:
    """Realisations 0 .. draws-1 of the run seeded ``seed`` (the same draws as ``rss6 run``'s)."""
    out = np.empty((draws, 6, 3))
    for k in range(draws):
        d = draw_clearances(scene, seed, k)
        out[k] = d.e_A + d.e_C - d.e_B
    return DrawnEccentricities(seed, out)


def sampled_errors(closure: StaticClosure, drawn: DrawnEccentricities) -> np.ndarray:
    """|d| (P, N, 6) of every drawn realisation at every pose (m, rad), by G d = n_i . e; NaN where
    the pose is unreachable."""
    rhs = np.einsum("pli,nli->pnl", closure.n, drawn.combined)
    return np.abs(np.einsum("pkl,pnl->pnk", closure.inverse, rhs))
