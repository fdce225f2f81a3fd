"""3-D two-node beam finite elements (12 DOF, consistent or lumped mass): Euler-Bernoulli or Timoshenko.

Node DOFs in the element's local axes: [u_x, u_y, u_z, r_x, r_y, r_z]; x runs
along the beam.  Stiffness: axial EA, torsion GJ (Saint-Venant constant),
bending EI_z in the x-y plane and EI_y in the x-z plane.  Mass: consistent
translational mass plus torsional polar inertia rho (I_y + I_z).

Three options (:class:`BeamTheory`, scene table ``[beam]``):
- ``timoshenko``: shear deformation with shear area k A, k the section's shear
  correction factor (:func:`rss6core.sections.shear_correction_factor`); the
  element uses the interdependent (shear-locking-free) interpolation, exact in
  statics, with Phi = 12 E I / (k G A l^2) per bending plane;
- ``rotary_inertia``: the cross-section's rotary inertia rho I in bending, consistent
  with the same interpolation;
- ``mass = "lumped"``: a diagonal mass instead, half the element's at each node: rho A l / 2 on
  each translation, rho I l / 2 on each rotation (the section's rotary inertia, polar for torsion);
  it needs ``rotary_inertia`` (without it the bending rotations would carry no mass).
With none (the default) the element is the Hermite Euler-Bernoulli element with consistent mass.
Przemieniecki, Theory of Matrix Structural Analysis (1968), ch. 5 and 11 (eq. 11.41-11.42).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sections import SectionProperties

__all__ = ["BEAM_THEORIES", "MASS_MODELS", "BeamTheory", "element_matrices", "geometric_stiffness", "link_matrices"]

BEAM_THEORIES = ("euler-bernoulli", "timoshenko")
MASS_MODELS = ("consistent", "lumped")


@dataclass(frozen=True)
class BeamTheory:
    """Which beam theory the links use: ``theory`` (one of BEAM_THEORIES), bending rotary inertia,
    the mass model (one of MASS_MODELS), and ``link_modes``: 0 for the full mesh, m > 0 for each link
    reduced to m Craig-Bampton fixed-interface modes plus its joint nodes (rss6core/link_reduction.py)."""
    theory: str = "euler-bernoulli"
    rotary_inertia: bool = False
    mass: str = "consistent"
    link_modes: int = 0

    @property
    def label(self) -> str:
        name = {"euler-bernoulli": "Euler-Bernoulli", "timoshenko": "Timoshenko"}[self.theory]
        return (name + (" + rotary inertia" if self.rotary_inertia else "")
                + (", lumped mass" if self.mass == "lumped" else "")
                + (f", Craig-Bampton {self.link_modes} modes" if self.link_modes else ""))


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


def _sym(upper: list[list[float]]) -> np.ndarray:
    """4 x 4 symmetric matrix from its rows' upper-triangle entries."""
    a = np.zeros((4, 4))
    for i, row in enumerate(upper):
        a[i, i:] = row
    return a + np.triu(a, 1).T


def _timoshenko_bending(l: float, phi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stiffness (per EI), translational mass (per rho A) and rotary mass (per rho I) of the
    interdependent-interpolation Timoshenko element in the x-y plane; Phi = 12 EI / (k G A l^2).
    Phi = 0 gives the Hermite element and its Rayleigh rotary mass."""
    p, d = phi, 1.0 + phi
    k = _sym([[12, 6 * l, -12, 6 * l], [(4 + p) * l * l, -6 * l, (2 - p) * l * l],
              [12, -6 * l], [(4 + p) * l * l]]) / (d * l ** 3)
    a = 13 / 35 + 7 / 10 * p + p * p / 3
    b = (11 / 210 + 11 / 120 * p + p * p / 24) * l
    c = 9 / 70 + 3 / 10 * p + p * p / 6
    e = (13 / 420 + 3 / 40 * p + p * p / 24) * l
    f = (1 / 105 + p / 60 + p * p / 120) * l * l
    g = (1 / 140 + p / 60 + p * p / 120) * l * l
    m = _sym([[a, b, c, -e], [f, e, -g], [a, -b], [f]]) * l / d ** 2
    q = (1 / 10 - p / 2) * l
    r = (2 / 15 + p / 6 + p * p / 3) * l * l
    s = (-1 / 30 - p / 6 + p * p / 6) * l * l
    rot = _sym([[6 / 5, q, -6 / 5, q], [r, -q, s], [6 / 5, -q], [r]]) / (l * d ** 2)
    return k, m, rot


def _lumped_mass(props: SectionProperties, rho: float, l: float) -> np.ndarray:
    """Diagonal 12 x 12 mass: half the element at each node, rho A l / 2 per translation (kg),
    rho (I_y + I_z) l / 2, rho I_y l / 2, rho I_z l / 2 on r_x, r_y, r_z (kg m^2)."""
    node = np.array([props.area] * 3 + [props.Iy + props.Iz, props.Iy, props.Iz]) * rho * l / 2.0
    return np.diag(np.tile(node, 2))


def element_matrices(props: SectionProperties, E: float, G: float, rho: float, l: float,
                     shear_factor: float | None = None, rotary_inertia: bool = False,
                     mass: str = "consistent") -> tuple[np.ndarray, np.ndarray]:
    """Local stiffness K (N/m, N/rad, ...) and mass M (kg, kg m, kg m^2), 12 x 12.

    ``shear_factor``: the shear correction factor k of a Timoshenko element (None: Euler-Bernoulli,
    rigid in shear); ``rotary_inertia``: add the bending rotary inertia rho I; ``mass``:
    'consistent' or 'lumped' (:func:`_lumped_mass`, which needs ``rotary_inertia``).
    """
    if mass not in MASS_MODELS or (mass == "lumped" and not rotary_inertia):
        raise ValueError(f"mass must be one of {', '.join(MASS_MODELS)} (lumped with rotary inertia), "
                         f"got {mass!r} with rotary_inertia={rotary_inertia}")
    K, M = np.zeros((12, 12)), np.zeros((12, 12))
    bar = np.array([[1.0, -1.0], [-1.0, 1.0]])
    bar_mass = np.array([[2.0, 1.0], [1.0, 2.0]]) * l / 6.0
    for dofs, stiff, inertia in (([0, 6], E * props.area / l, rho * props.area),
                                 ([3, 9], G * props.J / l, rho * (props.Iy + props.Iz))):
        K[np.ix_(dofs, dofs)] += stiff * bar
        M[np.ix_(dofs, dofs)] += inertia * bar_mass
    # v, r_z bend about z (EI_z); w, r_y bend about y (EI_y) with the opposite rotation sign
    for dofs, I, sign in (([1, 5, 7, 11], props.Iz, 1.0), ([2, 4, 8, 10], props.Iy, -1.0)):
        if shear_factor is None and not rotary_inertia:
            k, m = _bending(l, sign)          # the default element, bit for bit as before
            K[np.ix_(dofs, dofs)] += E * I * k
            M[np.ix_(dofs, dofs)] += rho * props.area * m
            continue
        phi = 0.0 if shear_factor is None else 12.0 * E * I / (shear_factor * G * props.area * l * l)
        k, m, rot = _timoshenko_bending(l, phi)
        flip = np.diag([1.0, sign, 1.0, sign])
        K[np.ix_(dofs, dofs)] += E * I * flip @ k @ flip
        M[np.ix_(dofs, dofs)] += flip @ (rho * props.area * m + rotary_inertia * rho * I * rot) @ flip
    return K, (_lumped_mass(props, rho, l) if mass == "lumped" else M)


def geometric_stiffness(props: SectionProperties, l: float) -> np.ndarray:
    """Consistent geometric (initial-stress) stiffness K_G (12 x 12, local axes) of a 3-D Euler-Bernoulli
    element of length ``l`` (m) per unit axial force N (tension > 0): multiply by N (N) for N/m, N, N m.

    Bending, per plane, N / (30 l) [[36, 3l, -36, 3l], [3l, 4l^2, -3l, -l^2], [-36, -3l, 36, -3l],
    [3l, -l^2, -3l, 4l^2]] on (v1, r_z1, v2, r_z2), the x-z plane with the rotations' sign flipped as in
    :func:`element_matrices`; torsion N (I_y + I_z) / (A l) [[1, -1], [-1, 1]] (Wagner).  The same cubic
    interpolation as K: Przemieniecki, Theory of Matrix Structural Analysis (1968), ch. 15 (stability);
    McGuire, Gallagher & Ziemian, Matrix Structural Analysis, 2nd ed. (2000), ch. 9.  Axial DOFs carry none.
    """
    kg = np.array([[36, 3 * l, -36, 3 * l], [3 * l, 4 * l * l, -3 * l, -l * l],
                   [-36, -3 * l, 36, -3 * l], [3 * l, -l * l, -3 * l, 4 * l * l]]) / (30.0 * l)
    K = np.zeros((12, 12))
    for dofs, sign in (([1, 5, 7, 11], 1.0), ([2, 4, 8, 10], -1.0)):
        flip = np.diag([1.0, sign, 1.0, sign])
        K[np.ix_(dofs, dofs)] += flip @ kg @ flip
    K[np.ix_([3, 9], [3, 9])] += (props.Iy + props.Iz) / (props.area * l) * np.array([[1.0, -1.0], [-1.0, 1.0]])
    return K


def link_matrices(props: SectionProperties, E: float, G: float, rho: float, length: float,
                  elements: int, shear_factor: float | None = None, rotary_inertia: bool = False,
                  mass: str = "consistent") -> tuple[np.ndarray, np.ndarray]:
    """Stiffness and mass of a straight link of ``elements`` equal elements, 6 (n+1) square
    (``shear_factor``, ``rotary_inertia``, ``mass``: see :func:`element_matrices`)."""
    if elements < 1:
        raise ValueError(f"elements must be at least 1, got {elements}")
    k, m = element_matrices(props, E, G, rho, length / elements, shear_factor, rotary_inertia, mass)
    n = 6 * (elements + 1)
    K, M = np.zeros((n, n)), np.zeros((n, n))
    for e in range(elements):
        s = slice(6 * e, 6 * e + 12)
        K[s, s] += k
        M[s, s] += m
    return K, M
