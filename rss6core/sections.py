"""Cross-section properties of the links and the rigid-link masses and inertias they imply.

Table 1 of the paper lists link inertias that disagree with its stated geometry,
so rss6 derives them from density, section and length (docs/model.md section 2).
Local beam axes: x along the link; for the crank y is the revolute axis w_i
(the ``axial_width`` side) and z lies in the crank's plane of motion.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RectangleSection", "TubeSection", "SectionProperties", "section_properties", "rectangle_torsion_constant",
           "shear_correction_factor", "LinkInertia", "crank_inertia", "crank_on_motor_frequency",
           "rod_inertia"]


@dataclass(frozen=True)
class RectangleSection:
    """Solid rectangle: ``axial_width`` along the revolute axis, ``height`` in the plane of motion, m."""
    axial_width: float
    height: float


@dataclass(frozen=True)
class TubeSection:
    """Circular tube, outer and inner diameters, m."""
    outer_diameter: float
    inner_diameter: float


@dataclass(frozen=True)
class SectionProperties:
    area: float   # A, m^2
    Iy: float     # second moment about local y, m^4
    Iz: float     # second moment about local z, m^4
    J: float      # Saint-Venant torsion constant, m^4


def rectangle_torsion_constant(a: float, b: float, terms: int = 50) -> float:
    """Saint-Venant torsion constant of a solid a x b rectangle, m^4 (series, exact to round-off).

    J = a b^3 / 3 [1 - 192 b / (pi^5 a) sum_{n odd} tanh(n pi a / 2b) / n^5], a >= b.
    Not the polar moment, which overestimates it (by 2.7x for a 2:1 rectangle).
    """
    a, b = max(a, b), min(a, b)
    n = np.arange(1, 2 * terms, 2, dtype=float)
    series = np.sum(np.tanh(n * np.pi * a / (2.0 * b)) / n ** 5)
    return a * b ** 3 / 3.0 * (1.0 - 192.0 * b / (np.pi ** 5 * a) * series)


def section_properties(section) -> SectionProperties:
    """A, Iy, Iz, J of a rectangle (y along ``axial_width``) or a tube."""
    if isinstance(section, RectangleSection):
        by, hz = section.axial_width, section.height
        return SectionProperties(by * hz, by * hz ** 3 / 12.0, hz * by ** 3 / 12.0,
                                 rectangle_torsion_constant(by, hz))
    if isinstance(section, TubeSection):
        ro, ri = section.outer_diameter / 2.0, section.inner_diameter / 2.0
        I = np.pi * (ro ** 4 - ri ** 4) / 4.0
        return SectionProperties(np.pi * (ro ** 2 - ri ** 2), I, I, 2.0 * I)
    raise TypeError(f"unknown section type {type(section).__name__}")


def shear_correction_factor(section, poisson: float) -> float:
    """Timoshenko shear correction factor k (shear area k A) of a section, Cowper (1966), Table 1.

    Solid rectangle: k = 10 (1 + nu) / (12 + 11 nu) (0.850 at nu = 0.3, either bending plane);
    circular tube, m = d_i / d_o: k = 6 (1 + nu) (1 + m^2)^2 / ((7 + 6 nu) (1 + m^2)^2
    + (20 + 12 nu) m^2) (solid circle 0.886, thin tube 0.531 at nu = 0.3).
    """
    nu = poisson
    if isinstance(section, RectangleSection):
        return 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu)
    if isinstance(section, TubeSection):
        m2 = (section.inner_diameter / section.outer_diameter) ** 2
        return 6.0 * (1.0 + nu) * (1.0 + m2) ** 2 / ((7.0 + 6.0 * nu) * (1.0 + m2) ** 2
                                                    + (20.0 + 12.0 * nu) * m2)
    raise TypeError(f"unknown section type {type(section).__name__}")


@dataclass(frozen=True)
class LinkInertia:
    """Rigid link: mass and principal moments in local (x along link, y, z) axes."""
    mass: float               # kg
    inertia: np.ndarray       # (3,) kg m^2, about ``reference``
    reference: str            # 'joint A' (crank) or 'centroid' (rod)


def crank_inertia(scene) -> LinkInertia:
    """Uniform crank A_iC_i; principal moments about A_i in (crank, w, in-plane normal) axes."""
    s, L, rho = scene.crank_section, scene.geometry.crank_length, scene.material.density
    m = rho * s.axial_width * s.height * L
    by, hz = s.axial_width, s.height
    return LinkInertia(m, np.array([m * (by ** 2 + hz ** 2) / 12.0,
                                    m * (L ** 2 / 3.0 + hz ** 2 / 12.0),
                                    m * (L ** 2 / 3.0 + by ** 2 / 12.0)]), "joint A")


def crank_on_motor_frequency(scene, motor_stiffness: float) -> float:
    """Hz: the rigid crank, J_A about the motor axis at A (:func:`crank_inertia`), on a torsional spring of
    ``motor_stiffness`` k_m (N m/rad), sqrt(k_m / J_A) / 2 pi (a servo-driven crank, [actuator])."""
    return float(np.sqrt(motor_stiffness / crank_inertia(scene).inertia[1]) / (2 * np.pi))


def rod_inertia(scene) -> LinkInertia:
    """Uniform tube C_iB_i; principal moments about its centroid (axial, transverse, transverse)."""
    s, L, rho = scene.rod_section, scene.geometry.rod_length, scene.material.density
    ro, ri = s.outer_diameter / 2.0, s.inner_diameter / 2.0
    m = rho * np.pi * (ro ** 2 - ri ** 2) * L
    axial = m * (ro ** 2 + ri ** 2) / 2.0
    transverse = m * (3.0 * (ro ** 2 + ri ** 2) + L ** 2) / 12.0
    return LinkInertia(m, np.array([axial, transverse, transverse]), "centroid")
