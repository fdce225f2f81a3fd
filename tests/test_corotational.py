"""The planar co-rotational form of rss6's element (rss6core.corotational, issue 43's candidate 1) on large-deflection
cantilevers, against closed forms and a published table, and its small-rotation limits against rss6's own K and K_G.

Nondimensional unless said: E = I = L = 1, EA = 1e8 (inextensible to 1e-8, as the elastica), so P L^2 / EI = P
and M L / EI = M.  benchmarks/large_deflection.py prints the errors these tests bound.
"""
import numpy as np
import pytest
from scipy.integrate import solve_bvp
from scipy.optimize import brentq

from rss6core.beam import element_matrices, geometric_stiffness, link_matrices
from rss6core.corotational import PLANE_DOFS, element_response, mesh_response, solve_static, straight_beam
from rss6core.sections import SectionProperties

from .conftest import load_benchmark

UNIT = SectionProperties(area=1e8, Iy=1.0, Iz=1.0, J=1.0)
CLAMPED = (0, 1, 2)
# Mattiasson, Int. J. Numer. Meth. Eng. 17 (1981) 145-153, Table 1: P L^2 / EI -> (tip deflection / L along the
# load, tip shortening / L), five digits
MATTIASSON = {1.0: (0.30172, 0.05643), 2.0: (0.49346, 0.16064), 5.0: (0.71379, 0.38763), 10.0: (0.81061, 0.55500)}


@pytest.fixture(scope="module")
def bench():
    return load_benchmark("large_deflection")


def _cantilever(elements, kind, value, increments):
    """Tip (x, y) in m and rotation in rad of the co-rotational cantilever under a tip force or moment."""
    beam = straight_beam(UNIT, 1.0, 0.4, 1.0, elements)
    load = np.zeros(beam.dofs)
    load[-2 if kind == "force" else -1] = value
    d = solve_static(beam, load, CLAMPED, increments=increments).displacements[-1]
    return beam.nodes[-1] + d[-3:-1], d[-1]


def test_the_tangent_is_the_derivative_of_the_internal_forces():
    """(C3) against central differences of (C1)-(C2) at a state with large rotations, stretch and bending (3
    elements, chords turned by up to 2 rad, a Timoshenko element): within 1e-6 of the tangent's largest entry."""
    props = SectionProperties(area=3.0, Iy=0.5, Iz=0.7, J=1.0)
    beam = straight_beam(props, 10.0, 4.0, 2.0, 3, shear_factor=0.85)
    d = np.random.default_rng(3).normal(scale=0.4, size=beam.dofs)
    d[-1] += 2.0
    tangent, h = mesh_response(beam, d).tangent, 1e-6
    numeric = np.column_stack([(mesh_response(beam, d + h * e).force - mesh_response(beam, d - h * e).force) / (2 * h)
                               for e in np.eye(beam.dofs)])
    np.testing.assert_allclose(tangent, numeric, atol=1e-6 * np.abs(tangent).max())


@pytest.mark.parametrize("theta", [np.pi / 2, np.pi, 2 * np.pi])
def test_a_tip_moment_bends_the_cantilever_into_the_closed_form_arc(theta):
    """Tip moment M = theta EI / L: the exact tip is the arc's, rotation theta, (x, y) = (EI / M)(sin theta,
    1 - cos theta).  On 20 elements the rotation is exact (1e-9) and the tip within 7e-4 L of the arc (measured
    2.3e-4 at pi/2, 6.5e-4 at pi, 4e-12 at 2 pi, where the polygon closes): each chord element carries the moment
    as end rotations +-phi, phi = theta / 2n, so its nodes lie on a circle of radius (EI / M) phi / sin phi, which
    the tip matches to 1e-9 L; that is the mesh error, second order, 4x smaller on 40 elements."""
    errors = []
    for elements in (20, 40):
        tip, rotation = _cantilever(elements, "moment", theta, increments=int(np.ceil(8 * theta)))
        arc = np.array([np.sin(theta), 1.0 - np.cos(theta)]) / theta
        phi = theta / (2 * elements)
        assert rotation == pytest.approx(theta, rel=1e-9)
        np.testing.assert_allclose(tip, arc * phi / np.sin(phi), atol=1e-9)
        errors.append(np.linalg.norm(tip - arc))
    assert errors[0] < 7e-4
    if theta < 2 * np.pi:
        assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.01)


def _elastica_bvp(load):
    """Tip (deflection / L, shortening / L, rotation) of EI theta'' = -P cos theta, theta(0) = 0, theta'(L) = 0,
    x' = cos theta, y' = sin theta from the clamp, by scipy.integrate.solve_bvp (E = I = L = 1)."""
    def rhs(s, y):
        return np.vstack([np.cos(y[2]), np.sin(y[2]), y[3], -load * np.cos(y[2])])

    def ends(a, b):
        return np.array([a[0], a[1], a[2], b[3]])

    s = np.linspace(0.0, 1.0, 201)
    guess = np.vstack([s, load * (s ** 2 / 2 - s ** 3 / 6), load * (s - s ** 2 / 2), load * (1 - s)])
    solution = solve_bvp(rhs, ends, s, guess, tol=1e-10, max_nodes=100000)
    assert solution.success
    tip = solution.sol(1.0)
    return tip[1], 1.0 - tip[0], tip[2]


@pytest.mark.parametrize("load", sorted(MATTIASSON))
def test_the_elastica_reference_agrees_with_mattiasson_and_with_a_boundary_value_solve(bench, load):
    """The benchmark's elliptic-integral elastica (Bisshopp & Drucker 1945) against an independent solve_bvp of the
    elastica ODE (1e-7) and against Mattiasson's Table 1 to its five digits (half a unit of the last: 5e-6)."""
    exact = bench.elastica_tip(load)
    deflection, shortening, rotation = _elastica_bvp(load)
    assert [exact.deflection, exact.shortening, exact.rotation] == pytest.approx(
        [deflection, shortening, rotation], abs=1e-7)
    assert [exact.deflection, exact.shortening] == pytest.approx(MATTIASSON[load], abs=5e-6)


@pytest.mark.parametrize("load", sorted(MATTIASSON))
def test_a_tip_force_gives_the_elastica(bench, load):
    """Transverse dead tip force, P L^2 / EI = 1, 2, 5, 10: tip deflection, shortening and rotation on 20 elements
    within 5e-4 of the exact elastica, relative (measured at most 4.2e-4, the shortening at 1), and the largest error
    3.8-4.2x smaller on 40 (measured 4.00-4.02: second order in the element length, as the chords' polygon)."""
    exact = bench.elastica_tip(load)
    errors = []
    for elements in (20, 40):
        tip, rotation = _cantilever(elements, "force", load, increments=int(np.ceil(8 * np.sqrt(load))))
        got = np.array([tip[1], 1.0 - tip[0], rotation])
        errors.append(np.abs(got / [exact.deflection, exact.shortening, exact.rotation] - 1.0))
    assert errors[0].max() < 5e-4
    assert 3.8 < errors[0].max() / errors[1].max() < 4.2


@pytest.mark.parametrize("shear_factor", [None, 0.85])
@pytest.mark.parametrize("kind", ["force", "moment"])
def test_at_a_tiny_load_the_corotational_tip_is_the_linear_solve(kind, shear_factor):
    """P L^2 / EI or M L / EI = 1e-6 on 8 elements of rss6's Euler-Bernoulli or Timoshenko element (EA = 1e4 EI /
    L^2, k = 0.85, kGA = 3.4e3 EI / L^2): tip deflection and rotation equal K u = f's (rss6's link_matrices, x-y
    plane) to 1e-6 relative (the nonlinearity there is of order theta^2 = 1e-12)."""
    props, elements = SectionProperties(area=1e4, Iy=1.0, Iz=1.0, J=1.0), 8
    beam = straight_beam(props, 1.0, 0.4, 1.0, elements, shear_factor=shear_factor)
    load = np.zeros(beam.dofs)
    load[-2 if kind == "force" else -1] = 1e-6
    d = solve_static(beam, load, CLAMPED, increments=1).displacements[-1]
    K, _ = link_matrices(props, 1.0, 0.4, 1.0, 1.0, elements, shear_factor=shear_factor)
    keep = (6 * np.arange(elements + 1)[:, None] + np.array([0, 1, 5])).ravel()
    linear = np.linalg.solve(K[np.ix_(keep, keep)][3:, 3:], load[3:])
    assert d[-2:] == pytest.approx(linear[-2:], rel=1e-6)


# a slender aluminium element (radius of gyration 0.32 mm, l = 0.1 m) stretched by 1e-6: N = 7 N
E_AL, G_AL, SLENDER, L0, STRETCH = 70e9, 26e9, SectionProperties(area=1e-4, Iy=1e-11, Iz=1e-11, J=2e-11), 0.1, 1e-6


def _plane(matrix):
    return matrix[np.ix_(PLANE_DOFS, PLANE_DOFS)]


def test_at_pure_stretch_the_corotational_geometric_term_is_the_chord_part_of_k_g():
    """One element under pure axial stretch (N = EA * 1e-6, no bending): its tangent less rss6's K (x-y plane) is
    N times the chord part of K_G, the acceleration harness's chord_load (+-N phi on the end nodes, docs/
    accelerations.md "chord part") as a matrix, within 1e-3 (measured 2.4e-4: K's bending rows taken at the
    stretched length); it is NOT N times the consistent K_G (17 % of K_G's largest entry apart): K_G less its chord
    part is the bending part, which vanishes on a rigid rotation (1e-12), the rigid rotation being all the chord part
    carries."""
    harness = load_benchmark("acceleration_candidates")
    beam = straight_beam(SLENDER, E_AL, G_AL, L0, 1)
    N = E_AL * SLENDER.area * STRETCH
    tangent = element_response(beam, 0, np.array([0.0, 0.0, 0.0, STRETCH * L0, 0.0, 0.0])).tangent
    K = _plane(element_matrices(SLENDER, E_AL, G_AL, 2700.0, L0)[0])
    KG = _plane(geometric_stiffness(SLENDER, L0))
    chord = _plane(-np.column_stack([harness.chord_load(e, np.array([1.0]), L0) for e in np.eye(12)]))
    per_N = (tangent - K) / N
    assert np.abs(per_N - chord).max() < 1e-3 * np.abs(chord).max()
    assert np.abs(per_N - KG).max() > 0.1 * np.abs(KG).max()
    rigid = np.array([0.0, 0.0, 1.0, 0.0, L0, 1.0])          # a rigid rotation by 1 rad, to first order
    np.testing.assert_allclose((KG - chord) @ rigid, 0.0, atol=1e-12 * np.abs(KG @ rigid).max())


@pytest.mark.parametrize("phi", [1e-4, 0.3, 1.0, 2.5])
def test_a_rigidly_turned_stretched_element_carries_its_axial_force_turned_exactly(phi):
    """The stretched element turned rigidly by phi: its end forces are N (cos phi, sin phi) and minus that, no
    moments, for any phi (1e-12 relative): the exact form of "the axial force turned with the chord".  To first
    order (phi = 1e-4) rss6's linear K q + N K_G q of the linearised rotation gives the same forces within N phi^2."""
    beam = straight_beam(SLENDER, E_AL, G_AL, L0, 1)
    N = E_AL * SLENDER.area * STRETCH
    l = L0 * (1 + STRETCH)
    d = np.array([0.0, 0.0, phi, l * np.cos(phi) - L0, l * np.sin(phi), phi])
    force = element_response(beam, 0, d).force
    turned = N * np.array([np.cos(phi), np.sin(phi)])
    expected = np.concatenate([-turned, [0.0], turned, [0.0]])
    np.testing.assert_allclose(force, expected, atol=1e-12 * N)
    if phi < 1e-3:
        q = np.array([0.0, 0.0, phi, STRETCH * L0, L0 * phi, phi])
        K = _plane(element_matrices(SLENDER, E_AL, G_AL, 2700.0, L0)[0])
        linear = K @ q + N * _plane(geometric_stiffness(SLENDER, L0)) @ q
        np.testing.assert_allclose(linear, force, atol=N * phi ** 2)


def _corotational_euler_load(elements):
    """The compressive tip load (P L^2 / EI) at which the co-rotational tangent of a pinned column, straight and
    uniformly compressed, turns singular (its smallest eigenvalue crosses zero; brentq)."""
    beam = straight_beam(UNIT, 1.0, 0.4, 1.0, elements)
    free = np.setdiff1d(np.arange(beam.dofs), [0, 1, 3 * elements + 1])

    def smallest(P):
        d = np.zeros(beam.dofs)
        d[0::3] = -P * beam.nodes[:, 0] / UNIT.area
        return np.linalg.eigvalsh(mesh_response(beam, d).tangent[np.ix_(free, free)])[0]

    return brentq(smallest, 0.5 * np.pi ** 2, 1.5 * np.pi ** 2, xtol=1e-13)


def _consistent_euler_load(elements):
    """The smallest P of K x = P K_G x on the pinned column's x-y plane (rss6's K and K_G, E = I = L = 1)."""
    from .test_rotating_beam import pinned_column_loads
    return pinned_column_loads(elements, "in-plane")[0]


def test_both_geometric_terms_give_the_euler_load_as_the_mesh_refines():
    """A pinned column's buckling load pi^2 EI / L^2 from the co-rotational tangent (chord part only) and from
    rss6's K + P K_G (consistent): both converge from above, the co-rotational one at second order (errors 5.2, 1.3,
    0.32 % on 4, 8, 16 elements: ratio 4 within 5 %), the consistent one at fourth (0.051, 0.0033, 0.0002 %: ratio
    16 within 10 %).  The bending part of K_G only speeds the convergence; the limit is the same."""
    corotational = np.array([_corotational_euler_load(n) for n in (4, 8, 16)]) / np.pi ** 2 - 1.0
    consistent = np.array([_consistent_euler_load(n) for n in (4, 8, 16)]) / np.pi ** 2 - 1.0
    assert np.all(corotational > 0) and np.all(consistent > 0)
    assert corotational[-1] < 4e-3 and consistent[-1] < 3e-6
    assert corotational[:-1] / corotational[1:] == pytest.approx([4.0, 4.0], rel=0.05)
    assert consistent[:-1] / consistent[1:] == pytest.approx([16.0, 16.0], rel=0.1)
