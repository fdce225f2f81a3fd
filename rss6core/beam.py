"""3-D two-node Euler-Bernoulli beam finite elements (12 DOF, consistent mass).

Node DOFs in the element's local axes: [u_x, u_y, u_z, r_x, r_y, r_z]; x runs
along the beam.  Stiffness: axial EA, torsion GJ (Saint-Venant constant),
bending EI_z in the x-y plane and EI_y in the x-z plane.  Mass: consistent
translational mass (cubic Hermite) plus torsional polar inertia rho (I_y + I_z);
rotary inertia of bending is neglected, as Euler-Bernoulli theory does (links
here are slender: L/h >= 10).  Przemieniecki, Theory of Matrix Structural
Analysis (1968), ch. 5 and 11.
"""
from __future__ import annotations

import numpy as np

from .sections import SectionProperties

__all__ = ["element_matrices", "link_matrices"]


def _bending(l: float, sign: float) -> tuple[np.ndarray, np.ndarray]:
    """Hermite stiffness (per EI) and mass (per rho A) for (v1, theta1, v2, theta2); sign -1 for x-z."""
    s = sign
    k = np.array([[12, 6 * l * s, -12, 6 * l * s],
                  [6 * l * s, 4 * l * l, -6 * l * s, 2 * l * l],
                  [-12, -6 * l * s, 12, -6 * l * s],
                  [6 * l * s, 2 * l * l, -6 * l * s, 4 * l * l]]) / l ** 3
    m = np.array([[156, 22 * l * s, 54, -13 * l * s],
                  [22 * l * s, 4 * l * l, 13 * l * s, -3 * l * l],
                  [54, 13 * l * s, 156, -22 * l * s],
                  [-13 * l * s, -3 * l * l, -22 * l * s, 4 * l * l]]) * l / 420.0
    return k, m


def element_matrices(props: SectionProperties, E: float, G: float, rho: float,
                     l: float) -> tuple[np.ndarray, np.ndarray]:
    """Local stiffness K (N/m, N/rad, ...) and consistent mass M (kg, kg m, kg m^2), 12 x 12."""
    K, M = np.zeros((12, 12)), np.zeros((12, 12))
    bar = np.array([[1.0, -1.0], [-1.0, 1.0]])
    bar_mass = np.array([[2.0, 1.0], [1.0, 2.0]]) * l / 6.0
    for dofs, stiff, inertia in (([0, 6], E * props.area / l, rho * props.area),
                                 ([3, 9], G * props.J / l, rho * (props.Iy + props.Iz))):
        K[np.ix_(dofs, dofs)] += stiff * bar
        M[np.ix_(dofs, dofs)] += inertia * bar_mass
    # v, r_z bend about z (EI_z); w, r_y bend about y (EI_y) with the opposite rotation sign
    for dofs, EI, sign in (([1, 5, 7, 11], E * props.Iz, 1.0), ([2, 4, 8, 10], E * props.Iy, -1.0)):
        k, m = _bending(l, sign)
        K[np.ix_(dofs, dofs)] += EI * k
        M[np.ix_(dofs, dofs)] += rho * props.area * m
    return K, M


def link_matrices(props: SectionProperties, E: float, G: float, rho: float, length: float,
                  elements: int) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness and mass of a straight link of ``elements`` equal elements, 6 (n+1) square."""
    if elements < 1:
        raise ValueError(f"elements must be at least 1, got {elements}")
    k, m = element_matrices(props, E, G, rho, length / elements)
    n = 6 * (elements + 1)
    K, M = np.zeros((n, n)), np.zeros((n, n))
    for e in range(elements):
        s = slice(6 * e, 6 * e + 12)
        K[s, s] += k
        M[s, s] += m
    return K, M
