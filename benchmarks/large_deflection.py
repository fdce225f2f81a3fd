"""Issue 43's candidate 1, the large-deflection cantilever: how far the second-order form K + N K_G stays exact.

A uniform Euler-Bernoulli cantilever along x, clamped at x = 0, under (1) a transverse tip force P that keeps its
direction (the elastica; exact tip from the elliptic-integral closed form, Bisshopp & Drucker, Q. Appl. Math. 3
(1945) 272; tabulated by Mattiasson, Int. J. Numer. Meth. Eng. 17 (1981) 145-153, Table 1) and (2) a tip moment M
(a circular arc of curvature M / EI).  Solved with rss6's element (rss6core.beam) three ways:

  (a) linear:        K u = f;
  (b) second order:  (K + sum_e N_e K_G,e) u = f, rss6core.beam.geometric_stiffness, iterated to convergence on
                     N_e; with N_e = EA du / l from the axial DOFs (the rule of the acceleration harness's
                     `stiffening` switch, benchmarks/acceleration_candidates.py) a transverse load stretches
                     nothing, N = 0 and (b) is (a); so (b) takes N_e = P . t_e, the tip force along each
                     element's current chord (the deformed cantilever's axial force), the best N this form has;
  (c) co-rotational: rss6core.corotational, load increments and Newton iterations.

Relative errors against the exact tip: rotation theta, deflection v along the load, shortening u along the beam.
Prints the tables and the tip rotation at which (b) departs from the exact deflection by 1 % and 10 %, against
the robot's largest element chord rotation (2.4e-3 rad, docs/accelerations.md).  Nondimensional: E = I = L = 1,
EA = 1e8 EI / L^2 (inextensible to 1e-8, as the elastica), so P L^2 / EI = P and M L / EI = M.

    python benchmarks/large_deflection.py      (5-30 s on the shared 2-core machine)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from scipy.special import ellipe, ellipeinc, ellipk, ellipkinc

from rss6core.beam import geometric_stiffness, link_matrices
from rss6core.corotational import solve_static, straight_beam
from rss6core.sections import SectionProperties

ELEMENTS = 40
UNIT = SectionProperties(area=1e8, Iy=1.0, Iz=1.0, J=1.0)
ROBOT_CHORD_ROTATION = 2.4e-3        # rad, the rods' largest element chord rotation (docs/accelerations.md)
FORCES = (1e-3, 1e-2, 0.1, 0.3, 1.0, 2.0, 5.0, 10.0)                   # P L^2 / EI
MOMENTS = (1e-3, 1e-2, 0.1, 0.3, 1.0, np.pi / 2, np.pi)    # M L / EI (2 pi, the full circle: the test)
PLANE = (0, 1, 5)                    # u, v, r_z of a node in link_matrices' 6 DOFs per node
FIXED = (0, 1, 2)                    # the clamped node's (u, v, theta) in the planar DOFs


@dataclass(frozen=True)
class Tip:
    """A cantilever's tip: rotation (rad), deflection along the load / L, shortening along the beam / L."""
    rotation: float
    deflection: float
    shortening: float


def elastica_tip(load: float) -> Tip:
    """The inextensible elastica under a transverse dead tip load P L^2 / EI = ``load``: with s = sin theta_L,
    m = (1 + s) / 2 and phi_0 = atan(1 / sqrt(s)), sqrt(load) = K(m) - F(phi_0, m) fixes theta_L;
    v / L = 1 - 2 (E(m) - E(phi_0, m)) / sqrt(load), x_L / L = sqrt(2 s / load) (Bisshopp & Drucker 1945)."""
    def _excess(theta: float) -> float:
        s = np.sin(theta)
        m = (1.0 + s) / 2.0
        return ellipk(m) - ellipkinc(np.arctan2(1.0, np.sqrt(s)), m) - np.sqrt(load)

    theta = brentq(_excess, 1e-300, np.pi / 2, xtol=1e-300, rtol=4 * np.finfo(float).eps)
    s = np.sin(theta)
    m, phi0 = (1.0 + s) / 2.0, np.arctan2(1.0, np.sqrt(s))
    return Tip(rotation=theta, deflection=1.0 - 2.0 * (ellipe(m) - ellipeinc(phi0, m)) / np.sqrt(load),
               shortening=1.0 - np.sqrt(2.0 * s / load))


def arc_tip(moment: float) -> Tip:
    """The exact tip under an end moment M L / EI = ``moment``: a circular arc of radius EI / M,
    theta = M L / EI, v = (1 - cos theta) / theta, x = sin theta / theta (per L)."""
    return Tip(rotation=moment, deflection=(1.0 - np.cos(moment)) / moment, shortening=1.0 - np.sin(moment) / moment)


def plane_stiffness(elements: int = ELEMENTS) -> np.ndarray:
    """rss6's stiffness K of the cantilever's x-y plane (3 (n+1) DOFs u, v, theta per node)."""
    K, _ = link_matrices(UNIT, 1.0, 0.4, 1.0, 1.0, elements)
    keep = (6 * np.arange(elements + 1)[:, None] + np.array(PLANE)).ravel()
    return K[np.ix_(keep, keep)]


def plane_geometric(axial: np.ndarray) -> np.ndarray:
    """sum_e N_e K_G,e of rss6core.beam.geometric_stiffness, x-y plane, for element axial forces ``axial`` (N)."""
    n = len(axial)
    kg = geometric_stiffness(UNIT, 1.0 / n)[np.ix_([0, 1, 5, 6, 7, 11], [0, 1, 5, 6, 7, 11])]
    out = np.zeros((3 * n + 3, 3 * n + 3))
    for e, N in enumerate(axial):
        out[3 * e:3 * e + 6, 3 * e:3 * e + 6] += N * kg
    return out


def tip_load(kind: str, value: float, elements: int = ELEMENTS) -> np.ndarray:
    """The load vector: a transverse tip force (``kind`` 'force', N) or a tip moment ('moment', N m)."""
    f = np.zeros(3 * elements + 3)
    f[-2 if kind == "force" else -1] = value
    return f


def _tip(u: np.ndarray) -> Tip:
    return Tip(rotation=u[-1], deflection=u[-2], shortening=-u[-3])


def linear_tip(kind: str, value: float, elements: int = ELEMENTS) -> Tip:
    """(a) K u = f on the clamped cantilever."""
    f, K = tip_load(kind, value, elements), plane_stiffness(elements)
    u = np.zeros_like(f)
    u[3:] = np.linalg.solve(K[3:, 3:], f[3:])
    return _tip(u)


def chord_axial_forces(u: np.ndarray, f_tip: np.ndarray) -> np.ndarray:
    """N_e = f_tip . t_e (N): the tip force along each element's current chord t_e, from displacements u."""
    n = len(u) // 3 - 1
    x = np.linspace(0.0, 1.0, n + 1) + u[0::3]
    chords = np.column_stack([np.diff(x), np.diff(u[1::3])])
    return chords @ f_tip / np.linalg.norm(chords, axis=1)


def strain_axial_forces(u: np.ndarray) -> np.ndarray:
    """N_e = EA du / l (N): the acceleration harness's rule, from the axial DOFs."""
    n = len(u) // 3 - 1
    return UNIT.area * np.diff(u[0::3]) * n


def second_order_tip(kind: str, value: float, elements: int = ELEMENTS, rule: str = "chord") -> Tip:
    """(b) (K + sum N_e K_G,e) u = f with N_e from the solution itself (``rule`` 'chord': the tip force along each
    element's chord; 'strain': EA du / l), iterated until the tip moves by less than 1e-9 of itself (round-off
    1e-10)."""
    f, K = tip_load(kind, value, elements), plane_stiffness(elements)
    f_tip = f[-3:-1] if kind == "force" else np.zeros(2)
    u, previous = np.zeros_like(f), np.inf
    for _ in range(200):
        N = chord_axial_forces(u, f_tip) if rule == "chord" else strain_axial_forces(u)
        A = K + plane_geometric(N)
        u[3:] = np.linalg.solve(A[3:, 3:], f[3:])
        if abs(u[-2] - previous) <= 1e-9 * abs(u[-2]):
            return _tip(u)
        previous = u[-2]
    raise RuntimeError(f"the second-order iteration did not converge at {kind} {value}")


def corotational_tip(kind: str, value: float, elements: int = ELEMENTS) -> Tip:
    """(c) the co-rotational solve (rss6core.corotational), in increments of at most 1/8 rad of tip rotation."""
    increments = int(np.ceil(8 * (value if kind == "moment" else np.sqrt(value))))
    path = solve_static(straight_beam(UNIT, 1.0, 0.4, 1.0, elements), tip_load(kind, value, elements), FIXED,
                        increments=max(increments, 1))
    return _tip(path.displacements[-1])


FIELDS = ("rotation", "deflection", "position")


def relative_error(approx: Tip, exact: Tip, field: str) -> float:
    """|approx - exact| / |exact| of the tip's ``field``: rotation, deflection, or position (the tip's
    displacement vector (-shortening, deflection), which holds the shortening the linear forms lack)."""
    if field == "position":
        miss = np.hypot(approx.shortening - exact.shortening, approx.deflection - exact.deflection)
        return miss / np.hypot(exact.shortening, exact.deflection)
    return abs(getattr(approx, field) / getattr(exact, field) - 1.0)


def departure(kind: str, level: float, solver=second_order_tip, field: str = "deflection") -> float:
    """The exact tip rotation (rad) at which ``solver``'s ``field`` first departs from the exact one by ``level``
    (scanned on 8 loads per decade from 1e-3, then brentq); nan if it stays closer up to load 10."""
    exact = elastica_tip if kind == "force" else arc_tip

    def _excess(x: float) -> float:
        return relative_error(solver(kind, np.exp(x)), exact(np.exp(x)), field) - level

    grid = np.linspace(np.log(1e-3), np.log(10.0), 33)
    above = [x for x in grid if _excess(x) >= 0.0]
    if not above or above[0] == grid[0]:
        return float("nan")
    upper = above[0]
    value = brentq(_excess, grid[np.searchsorted(grid, upper) - 1], upper, xtol=1e-6)
    return exact(np.exp(value)).rotation


def _row(value: float, exact: Tip, tips: list[Tip]) -> str:
    errors = ["".join(f"{relative_error(t, exact, field):9.2e}" for field in FIELDS) for t in tips]
    return f"{value:9.4g} {exact.rotation:7.4f} {exact.deflection:8.5f} {exact.shortening:9.3e} " + " ".join(errors)


def table(kind: str, values) -> None:
    """One row per load: the exact tip and the relative errors of rotation, deflection and position of (a), (b),
    (c)."""
    exact = elastica_tip if kind == "force" else arc_tip
    name = "P L^2/EI" if kind == "force" else "M L/EI"
    heads = " ".join("".join(f"{m + ' ' + f:>9}" for f in ("theta", "v", "pos")) for m in ("(a)", "(b)", "(c)"))
    print(f"{name:>9} {'theta':>7} {'v/L':>8} {'u/L':>9} {heads}")
    for value in values:
        tips = [linear_tip(kind, value), second_order_tip(kind, value), corotational_tip(kind, value)]
        print(_row(value, exact(value), tips))


def _rotation_text(theta: float, kind: str) -> str:
    if np.isnan(theta):
        return f"not reached up to {'P L^2/EI = ' + f'{FORCES[-1]:g}' if kind == 'force' else 'M L/EI = pi'}"
    return f"{theta:6.3f} rad ({theta / ROBOT_CHORD_ROTATION:4.0f}x)"


def main() -> None:
    print(f"Cantilever, {ELEMENTS} Euler-Bernoulli elements, EI = L = 1, EA = {UNIT.area:.0e}; exact tip rotation, "
          "deflection v/L and shortening u/L; relative errors of (a) linear, (b) second order, (c) co-rotational "
          "in tip rotation, deflection and position (the displacement vector: (a) and (b) have no shortening)")
    print("\n1. Transverse tip force (elastica; Mattiasson 1981 Table 1)")
    table("force", FORCES)
    strain = second_order_tip("force", 10.0, rule="strain")
    print(f"(b) with N = EA du / l instead: tip deflection at P L^2/EI = 10 is {strain.deflection:.6f}, "
          f"(a)'s {linear_tip('force', 10.0).deflection:.6f}: N = 0, it is the linear solve")
    print("\n2. Tip moment (circular arc); N = 0, so (b) is (a)")
    table("moment", MOMENTS)
    print("\nTip rotation (rad) at which a field first departs from the exact one by 1 % and 10 % "
          f"(x: multiples of the robot's {ROBOT_CHORD_ROTATION} rad):")
    for kind, solver, label in (("force", second_order_tip, "(b) second order, tip force"),
                                ("force", linear_tip, "(a) linear, tip force"),
                                ("moment", linear_tip, "(a) = (b), tip moment")):
        for field in FIELDS:
            at = [_rotation_text(departure(kind, level, solver, field), kind) for level in (0.01, 0.10)]
            print(f"  {label:28s} {field:10s} 1 %: {at[0]}   10 %: {at[1]}")
    phi = ROBOT_CHORD_ROTATION
    print(f"At the robot's chord rotation {phi} rad the exact turned axial force N (cos phi, sin phi) differs from "
          f"K_G's chord load (0, N phi) by {np.hypot(np.cos(phi) - 1, np.sin(phi) - phi) / np.sin(phi):.1e} "
          "of N sin phi (its missing axial part, phi / 2).")


if __name__ == "__main__":
    main()
