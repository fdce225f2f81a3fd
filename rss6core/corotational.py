"""Planar co-rotational form of rss6's beam element: large rotations, small strains, in one bending plane.

A verification of the geometric terms (issue 43, candidate 1), not a model level.  Element-independent
co-rotational formulation (Crisfield, Non-linear Finite Element Analysis of Solids and Structures, vol. 1
(1991), ch. 7; Battini & Pacoste, Comput. Methods Appl. Mech. Engrg. 191 (2002) 1755-1789;
equation numbers below are this module's): each element's rigid motion is removed with its chord, and
rss6's own element (:func:`rss6core.beam.element_matrices`, x-y plane, DOFs (u, v, r_z) = [0, 1, 5, 6, 7, 11])
acts on what is left, the axial stretch u_l and the end rotations theta_1l, theta_2l relative to the chord:

    u_l = (l^2 - l0^2) / (l + l0),   theta_il = theta_i + beta0 - beta,   f_l = K_l [u_l, theta_1l, theta_2l]   (C1)
    f = B^T f_l,   B = [r^T; e_3^T - z^T / l; e_6^T - z^T / l]                                                    (C2)
    K_t = B^T K_l B + N z z^T / l + (M_1 + M_2) (r z^T + z r^T) / l^2                                            (C3)

with c, s the cosine and sine of the chord's angle beta, r = [-c, -s, 0, c, s, 0], z = [s, -c, 0, -s, c, 0],
f_l = [N, M_1, M_2] (N, N m, N m), K_l the element's stiffness in the chord frame (one node held: N/m, N m/rad).
The second term of (C3) is the axial force turned with the chord: the chord part of
:func:`rss6core.beam.geometric_stiffness`, exactly; the consistent K_G's bending part is not in it (this
element's local strain is linear), which costs it only second-order convergence of buckling loads.
Global DOFs per node (x, y displacement in m, rotation in rad), node after node.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .beam import element_matrices
from .sections import SectionProperties

__all__ = ["PLANE_DOFS", "Chord", "ElementResponse", "MeshResponse", "PlanarBeam", "StaticPath", "chord_frame",
           "element_response", "mesh_response", "natural_stiffness", "solve_static", "straight_beam"]

PLANE_DOFS = (0, 1, 5, 6, 7, 11)     # u, v, r_z of both nodes in element_matrices' 12 DOFs


@dataclass(frozen=True)
class PlanarBeam:
    """A planar mesh of equal elements: initial node coordinates (n+1, 2) in m, node after node, and each
    element's stiffness in its chord frame (3 x 3 on u_l, theta_1l, theta_2l: N/m, N, N m/rad)."""
    nodes: np.ndarray
    local_stiffness: np.ndarray

    @property
    def dofs(self) -> int:
        return 3 * len(self.nodes)


@dataclass(frozen=True)
class ElementResponse:
    """One element at a state: global internal forces (6: N, N, N m), tangent (6 x 6), local deformations
    [u_l m, theta_1l rad, theta_2l rad] and local forces [N N, M_1 N m, M_2 N m] of (C1)."""
    force: np.ndarray
    tangent: np.ndarray
    deformation: np.ndarray
    local_force: np.ndarray


@dataclass(frozen=True)
class MeshResponse:
    """A mesh at a state: assembled internal forces (3 (n+1)) and tangent stiffness (3 (n+1) square)."""
    force: np.ndarray
    tangent: np.ndarray


@dataclass(frozen=True)
class StaticPath:
    """An equilibrium path: load factors (k+1,), nodal displacements (k+1, 3 (n+1)) at each, the Newton
    iterations each increment took (k,)."""
    load_factors: np.ndarray
    displacements: np.ndarray
    iterations: np.ndarray


def natural_stiffness(K: np.ndarray) -> np.ndarray:
    """The 3 x 3 stiffness on (u_l, theta_1l, theta_2l) of a 12 x 12 element stiffness (element_matrices):
    its x-y plane (PLANE_DOFS) with the first node's translations and the second's transverse one held."""
    pick = np.zeros((6, 3))
    pick[3, 0] = pick[2, 1] = pick[5, 2] = 1.0       # (u1, v1, r1, u2, v2, r2) of (u_l, theta_1l, theta_2l)
    plane = K[np.ix_(PLANE_DOFS, PLANE_DOFS)]
    return pick.T @ plane @ pick


def straight_beam(props: SectionProperties, E: float, G: float, length: float, elements: int,
                  shear_factor: float | None = None) -> PlanarBeam:
    """A straight beam of ``length`` (m) along x from the origin, ``elements`` equal elements of rss6's
    element (Euler-Bernoulli, or Timoshenko with ``shear_factor``), bending about z (I_z)."""
    if elements < 1:
        raise ValueError(f"elements must be at least 1, got {elements}")
    K, _ = element_matrices(props, E, G, 1.0, length / elements, shear_factor)
    nodes = np.column_stack([np.linspace(0.0, length, elements + 1), np.zeros(elements + 1)])
    return PlanarBeam(nodes=nodes, local_stiffness=natural_stiffness(K))


@dataclass(frozen=True)
class Chord:
    """The chord of an element: length (m), cosine and sine of its angle to x."""
    length: float
    cos: float
    sin: float


def chord_frame(x1: np.ndarray, x2: np.ndarray) -> Chord:
    """The chord from point x1 to point x2 (m)."""
    d = x2 - x1
    l = float(np.hypot(d[0], d[1]))
    return Chord(length=l, cos=d[0] / l, sin=d[1] / l)


def element_response(beam: PlanarBeam, e: int, d: np.ndarray) -> ElementResponse:
    """Element ``e`` of ``beam`` at global displacements ``d`` (3 (n+1)): eqs. (C1)-(C3)."""
    X1, X2 = beam.nodes[e], beam.nodes[e + 1]
    de = d[3 * e:3 * e + 6]
    start, now = chord_frame(X1, X2), chord_frame(X1 + de[0:2], X2 + de[3:5])
    l0, c0, s0, l, c, s = start.length, start.cos, start.sin, now.length, now.cos, now.sin
    # the chord's rotation since the start, wrapped: each local rotation is small, the chord's need not be
    turn = np.arctan2(c0 * s - s0 * c, c0 * c + s0 * s)
    local = np.array([(l * l - l0 * l0) / (l + l0),
                      np.angle(np.exp(1j * (de[2] - turn))), np.angle(np.exp(1j * (de[5] - turn)))])
    f_l = beam.local_stiffness @ local
    r = np.array([-c, -s, 0.0, c, s, 0.0])
    z = np.array([s, -c, 0.0, -s, c, 0.0])
    B = np.vstack([r, -z / l, -z / l])
    B[1, 2] += 1.0
    B[2, 5] += 1.0
    tangent = (B.T @ beam.local_stiffness @ B + f_l[0] * np.outer(z, z) / l
               + (f_l[1] + f_l[2]) * (np.outer(r, z) + np.outer(z, r)) / (l * l))
    return ElementResponse(force=B.T @ f_l, tangent=tangent, deformation=local, local_force=f_l)


def mesh_response(beam: PlanarBeam, d: np.ndarray) -> MeshResponse:
    """Assembled internal forces and tangent stiffness of ``beam`` at displacements ``d`` (3 (n+1))."""
    force, tangent = np.zeros(beam.dofs), np.zeros((beam.dofs, beam.dofs))
    for e in range(len(beam.nodes) - 1):
        part = element_response(beam, e, d)
        s = slice(3 * e, 3 * e + 6)
        force[s] += part.force
        tangent[s, s] += part.tangent
    return MeshResponse(force=force, tangent=tangent)


def solve_static(beam: PlanarBeam, load: np.ndarray, fixed: tuple[int, ...], increments: int = 20,
                 tolerance: float = 1e-10, max_iterations: int = 30) -> StaticPath:
    """Equilibrium f_int(d) = lambda ``load`` (dead loads, N and N m per DOF) for lambda = 1/k, ..., 1 with
    ``fixed`` DOFs held at zero: load increments, full Newton iterations on the tangent (C3) until the
    free residual is below ``tolerance`` times |load| (or 1 N) or the correction is at round-off (1e-13 of
    |d|), RuntimeError if one does not converge."""
    free = np.setdiff1d(np.arange(beam.dofs), fixed)
    scale = max(float(np.linalg.norm(load)), 1.0)
    d, factors = np.zeros(beam.dofs), np.linspace(0.0, 1.0, increments + 1)
    path, counts = [d.copy()], []
    for factor in factors[1:]:
        step = np.inf
        for iteration in range(max_iterations + 1):
            state = mesh_response(beam, d)
            residual = factor * load[free] - state.force[free]
            if np.linalg.norm(residual) <= tolerance * scale or step <= 1e-13 * np.linalg.norm(d):
                break
            if iteration == max_iterations:
                raise RuntimeError(f"no equilibrium at load factor {factor:.4g} after {max_iterations} "
                                   f"Newton iterations (residual {np.linalg.norm(residual):.3g} N)")
            correction = np.linalg.solve(state.tangent[np.ix_(free, free)], residual)
            d[free] += correction
            step = float(np.linalg.norm(correction))
        path.append(d.copy())
        counts.append(iteration)
    return StaticPath(load_factors=factors, displacements=np.array(path), iterations=np.array(counts))
