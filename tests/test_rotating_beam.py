"""The geometrically nonlinear terms of issue 43's candidate 1 (rss6core.beam.geometric_stiffness, the harness's
geometric_load and axial_forces, rss6core.assembly.frame_inertia_load) on the rotating cantilever, where a linear
formulation is known to fail.

A uniform Euler-Bernoulli cantilever clamped on the hub axis (hub radius 0) spins at Omega about an axis normal to
it (local z): flapwise (out of the rotation plane, w) omega^2 = omega_0^2 + K Omega^2, in-plane (chordwise, v)
omega^2 = omega_0^2 + (K - 1) Omega^2 (Southwell).  Published first-mode coefficient K1 = 1.193 (Wright, Smith,
Thresher & Wang, J. Appl. Mech. 49 (1982) 197-202; Hodges & Rutkowski, AIAA J. 19 (1981) 1459-1466).  The
spinning beam's stiffness is rss6's element K + K_G(N), N the element forces EA du/l of the static stretch under
the centrifugal load, minus the frame term's Omega^2 M; Coriolis coupling is left out, as in Southwell's form.
Nondimensional: E = rho = A = I = L = 1, so Omega is lambda = Omega sqrt(rho A L^4 / E I).
"""
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import eigh
from scipy.optimize import brentq

from rss6core.assembly import frame_inertia_load
from rss6core.beam import link_matrices
from rss6core.sections import SectionProperties

BENCHMARK = Path(__file__).resolve().parents[1] / "benchmarks" / "acceleration_candidates.py"
ELEMENTS = 40
UNIT = SectionProperties(area=1.0, Iy=1.0, Iz=1.0, J=1.0)
FLAP, IN_PLANE = (2, 4), (1, 5)      # (w, r_y) and (v, r_z) of each node


@pytest.fixture(scope="module")
def harness():
    spec = importlib.util.spec_from_file_location("acceleration_candidates", BENCHMARK)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def _spin(omega):
    """Om = Omega~ (3, 3) of a spin Omega about local z."""
    return np.array([[0.0, -omega, 0.0], [omega, 0.0, 0.0], [0.0, 0.0, 0.0]])


def _as_matrix(load, size):
    """The matrix A with load(q) = -A q, of a linear load in row form."""
    return -np.stack([load(e) for e in np.eye(size)]).T


def spinning_frequencies(harness, omega, plane, elements=ELEMENTS, stiffening=True, frame=True):
    """Squared frequencies (rad^2/s^2, ascending) of the spinning cantilever's ``plane`` DOFs."""
    K, M = link_matrices(UNIT, 1.0, 0.4, 1.0, 1.0, elements)
    size, length, Om = K.shape[0], 1.0 / elements, _spin(omega)
    free = np.arange(6, size)
    X = np.zeros(size)
    X[0::6] = np.linspace(0.0, 1.0, elements + 1)                 # the rigid positions: centrifugal load
    f = frame_inertia_load(M, X, np.zeros(size), Om, np.zeros((3, 3)))
    u = np.zeros(size)
    u[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
    N = harness.axial_forces(u, 1.0, length)
    stiff = K.copy()
    if stiffening:
        stiff += _as_matrix(lambda q: harness.geometric_load(q, N, length, UNIT), size)
    if frame:
        stiff += _as_matrix(lambda q: frame_inertia_load(M, q, np.zeros(size), Om, np.zeros((3, 3))), size)
    keep = free[np.isin(free % 6, plane)]
    return eigh(stiff[np.ix_(keep, keep)], M[np.ix_(keep, keep)], eigvals_only=True)


def _cantilever_mode(k):
    """beta_k L and the clamped-free mode phi_k, phi_k' on [0, 1] (closed form)."""
    beta = brentq(lambda b: np.cos(b) * np.cosh(b) + 1.0, (k - 0.5) * np.pi - 0.6, (k - 0.5) * np.pi + 0.6)
    s = (np.cosh(beta) + np.cos(beta)) / (np.sinh(beta) + np.sin(beta))

    def phi(x):
        return np.cosh(beta * x) - np.cos(beta * x) - s * (np.sinh(beta * x) - np.sin(beta * x))

    def slope(x):
        return beta * (np.sinh(beta * x) + np.sin(beta * x) - s * (np.cosh(beta * x) - np.cos(beta * x)))
    return beta, phi, slope


def ritz_frequencies(omega, modes=8):
    """Independent flapwise omega^2 of the spinning cantilever: Rayleigh-Ritz on the first ``modes`` closed-form
    cantilever modes, K_ij = beta_i^4 delta_ij + Omega^2 int (1 - x^2) / 2 phi_i' phi_j' dx, M_ij = int phi_i phi_j
    (Gauss-Legendre, 200 points)."""
    x, w = np.polynomial.legendre.leggauss(200)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    shapes = [_cantilever_mode(k) for k in range(1, modes + 1)]
    phi = np.stack([p(x) for _, p, _ in shapes])
    slope = np.stack([s(x) for _, _, s in shapes])
    M = (phi * w) @ phi.T
    K = np.diag([b ** 4 for b, _, _ in shapes]) @ M + omega ** 2 * (slope * w * (1 - x ** 2) / 2) @ slope.T
    return eigh(K, M, eigvals_only=True)


def test_southwell_coefficients_of_the_first_two_flapwise_modes(harness):
    """At Omega = 0.05 omega_1 (the coefficients' small-speed limit), (omega^2 - omega_0^2) / Omega^2 on 40 elements:
    mode 1 within 1 % of the published K1 = 1.193 and of the first-order Rayleigh quotient with the exact mode
    int (1 - x^2) / 2 phi'^2 / int phi^2 (1.1933); mode 2 within 1 % of that quotient (6.478).  The task brief
    quoted 6.38 for mode 2; the closed-form quotient gives 6.478, which is what this tests."""
    omega_0 = spinning_frequencies(harness, 0.0, FLAP)
    omega = 0.05 * np.sqrt(omega_0[0])
    K = (spinning_frequencies(harness, omega, FLAP)[:2] - omega_0[:2]) / omega ** 2
    x, w = np.polynomial.legendre.leggauss(200)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    quotient = []
    for k in (1, 2):
        _, phi, slope = _cantilever_mode(k)
        quotient.append((w * (1 - x ** 2) / 2 * slope(x) ** 2).sum() / (w * phi(x) ** 2).sum())
    assert quotient[0] == pytest.approx(1.193, rel=1e-3)
    assert K[0] == pytest.approx(1.193, rel=0.01)
    assert K == pytest.approx(quotient, rel=0.01)


@pytest.mark.parametrize("ratio", [1.0, 2.0])
def test_flapwise_and_in_plane_frequencies_at_one_and_two_omega_0(harness, ratio):
    """The first flapwise and in-plane frequencies at Omega = omega_0 and 2 omega_0 on 40 elements, within 1 % of
    an independent Rayleigh-Ritz solution (8 closed-form cantilever modes; in-plane omega^2 = flapwise - Omega^2
    for a uniform beam without Coriolis).  At omega_0 also within 1 % of Southwell's form with K1 = 1.193; at
    2 omega_0 that linear form is no longer exact (the coefficient falls with the speed: in-plane it is 4 % high)."""
    omega_0 = np.sqrt(spinning_frequencies(harness, 0.0, FLAP)[0])
    omega = ratio * omega_0
    ritz = ritz_frequencies(omega)[0]
    flap, in_plane = spinning_frequencies(harness, omega, FLAP)[0], spinning_frequencies(harness, omega, IN_PLANE)[0]
    assert np.sqrt(flap) == pytest.approx(np.sqrt(ritz), rel=0.01)
    assert np.sqrt(in_plane) == pytest.approx(np.sqrt(ritz - omega ** 2), rel=0.01)
    if ratio == 1.0:
        assert np.sqrt(flap) == pytest.approx(np.sqrt(omega_0 ** 2 + 1.193 * omega ** 2), rel=0.01)
        assert np.sqrt(in_plane) == pytest.approx(np.sqrt(omega_0 ** 2 + 0.193 * omega ** 2), rel=0.01)


def test_without_geometric_stiffness_the_in_plane_beam_softens_and_buckles_at_omega_0(harness):
    """The linear formulation's known failure: without K_G the in-plane omega^2 = omega_0^2 - Omega^2 (1 % at
    Omega = 0.5 omega_0), down to zero at Omega = omega_0 (|omega^2| < 1 % of omega_0^2), negative beyond; with
    K_G it stays above omega_0^2."""
    omega_0 = np.sqrt(spinning_frequencies(harness, 0.0, IN_PLANE)[0])
    half = spinning_frequencies(harness, 0.5 * omega_0, IN_PLANE, stiffening=False)[0]
    assert half == pytest.approx(0.75 * omega_0 ** 2, rel=0.01)
    assert abs(spinning_frequencies(harness, omega_0, IN_PLANE, stiffening=False)[0]) < 0.01 * omega_0 ** 2
    assert spinning_frequencies(harness, 1.2 * omega_0, IN_PLANE, stiffening=False)[0] < 0.0
    assert spinning_frequencies(harness, 1.2 * omega_0, IN_PLANE)[0] > omega_0 ** 2


def test_the_frame_load_of_point_masses_is_the_rotating_frame_inertia():
    """frame_inertia_load with a lumped mass m on each translation and J on each rotation: each node's load is
    -m (2 w x q' + w' x q + w x (w x q)) on its translation (Coriolis, Euler, centrifugal), and the same with J
    on its rotation triple, for random w, w', q, q' (closed form)."""
    rng = np.random.default_rng(7)
    m, J, nodes = 2.5, 0.3, 3
    M = np.diag(np.tile([m] * 3 + [J] * 3, nodes))
    w, w_dot = rng.normal(size=3), rng.normal(size=3)
    q, q_dot = rng.normal(size=(4, 6 * nodes)), rng.normal(size=(4, 6 * nodes))
    load = frame_inertia_load(M, q, q_dot, _skew(w), _skew(w_dot))
    q3, v3 = q.reshape(4, -1, 3), q_dot.reshape(4, -1, 3)
    acc = 2 * np.cross(w, v3) + np.cross(w_dot, q3) + np.cross(w, np.cross(w, q3))
    expected = -acc * np.tile([m, J], nodes)[:, None]
    np.testing.assert_allclose(load, expected.reshape(4, -1), rtol=1e-12, atol=1e-12)


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@pytest.mark.parametrize("plane", [IN_PLANE, FLAP])
def test_the_geometric_stiffness_buckles_a_pinned_column_at_the_euler_load(plane):
    """K + P K_G of a pinned-pinned column (both ends' translations held) singular at the Euler load
    P = -pi^2 E I / L^2 in either bending plane: the smallest eigenvalue mu = -P of K x = mu K_G x on 8 elements
    within 0.1 % of pi^2 (E = I = L = 1; the cubic element converges from above at fourth order)."""
    from rss6core.beam import geometric_stiffness

    n = 8
    K, _ = link_matrices(UNIT, 1.0, 0.4, 1.0, 1.0, n)
    KG = np.zeros_like(K)
    for e in range(n):
        KG[6 * e:6 * e + 12, 6 * e:6 * e + 12] += geometric_stiffness(UNIT, 1.0 / n)
    dofs = np.arange(K.shape[0])
    keep = dofs[np.isin(dofs % 6, plane) & ~np.isin(dofs, [plane[0], 6 * n + plane[0]])]
    P = eigh(K[np.ix_(keep, keep)], KG[np.ix_(keep, keep)], eigvals_only=True)
    assert P[0] == pytest.approx(np.pi ** 2, rel=1e-3)


def test_the_chord_part_of_the_geometric_load_is_the_axial_force_turned_with_the_chord(harness):
    """-K_G(N) q of an element turned rigidly by phi in either bending plane is +N phi, -N phi on its end nodes'
    transverse translations (the axial force turned with the chord) and nothing on the rotations: the harness's
    chord_load gives exactly that, and geometric_load - chord_load (the bending stiffening) vanishes on it."""
    n, phi, N = 4, 1e-3, np.array([3.0, -2.0, 5.0, 7.0])
    x = np.linspace(0.0, 1.0, n + 1)
    for transverse, rotation, sign in ((1, 5, 1.0), (2, 4, -1.0)):
        q = np.zeros(6 * n + 6)
        q[transverse::6], q[rotation::6] = phi * x, sign * phi
        full = harness.geometric_load(q, N, 1.0 / n, UNIT)
        expected = np.zeros(6 * n + 6)
        expected[transverse:-6:6] += N * phi
        expected[6 + transverse::6] -= N * phi
        np.testing.assert_allclose(full, expected, atol=1e-15)
        np.testing.assert_allclose(harness.chord_load(q, N, 1.0 / n), expected, atol=1e-15)


def _spin_up(harness, omega_s, stiffening, elements=8, end=20.0, period=15.0):
    """The spin-up manoeuvre of Kane, Ryan & Banerjee (1987) and Simo & Vu-Quoc (1986), in the hub frame: a beam
    L = 10 m, E = 7e10 Pa, rho = 3000 kg/m^3, A = 4e-4 m^2, I = 2e-7 m^4 (EA 2.8e7 N, EI 1.4e4 N m^2, rho A
    1.2 kg/m) clamped on the hub axis, turned in its plane by theta'(t) = omega_s / T (t - T / 2 pi sin(2 pi t / T))
    up to T = 15 s, then at omega_s.  In-plane and axial DOFs, rss6's element matrices, the frame load of the
    displacements and of the rigid positions (centrifugal and tangential), and with ``stiffening`` the harness's
    -K_G(N) q; Radau (scipy), stopped once the tip's transverse displacement exceeds the beam's length.
    Returns the times (s) and the tip's transverse displacement (m) in the hub frame."""
    L, E, rho = 10.0, 7e10, 3000.0
    props = SectionProperties(area=4e-4, Iy=2e-7, Iz=2e-7, J=4e-7)
    K, M = link_matrices(props, E, 2.7e10, rho, L, elements)
    size, length = K.shape[0], L / elements
    keep = np.array([6 * k + d for k in range(1, elements + 1) for d in (0, 1, 5)])
    X = np.zeros(size)
    X[0::6] = np.linspace(0.0, L, elements + 1)
    M_inv, m = np.linalg.inv(M[np.ix_(keep, keep)]), len(keep)

    def rates(t):
        if t >= period:
            return omega_s, 0.0
        phase = 2 * np.pi * t / period
        return omega_s / period * (t - period / (2 * np.pi) * np.sin(phase)), omega_s / period * (1 - np.cos(phase))

    def rhs(t, y):
        q, v = np.zeros(size), np.zeros(size)
        q[keep], v[keep] = y[:m], y[m:]
        omega, omega_dot = rates(t)
        Om, Om_dot = _spin(omega), _spin(omega_dot)
        f = -K @ q + frame_inertia_load(M, q, v, Om, Om_dot) + frame_inertia_load(M, X, np.zeros(size), Om, Om_dot)
        if stiffening:
            f += harness.geometric_load(q, harness.axial_forces(q, E * props.area, length), length, props)
        return np.concatenate([y[m:], M_inv @ f[keep]])

    def runaway(t, y):
        return abs(y[m - 2]) - L
    runaway.terminal = True
    sol = solve_ivp(rhs, (0.0, end), np.zeros(2 * m), method="Radau", rtol=1e-6, atol=1e-9, events=runaway,
                    t_eval=np.linspace(0.0, end, 401))
    return sol.t, sol.y[m - 2]


def test_the_spin_up_stays_bounded_with_the_geometric_stiffness_and_diverges_without(harness):
    """The spin-up at omega_s = 10 rad/s, well above the beam's first bending frequency (3.8 rad/s): with K_G the
    tip's transverse displacement stays below 1 m (0.87 m measured) over 20 s and is back under 0.1 m at 20 s;
    without it, the linear formulation's in-plane stiffness K - Omega^2 M turns negative and the tip runs away
    past the beam's 10 m length before 20 s.  No published tip deflection is compared (none found as a number)."""
    t, tip = _spin_up(harness, 10.0, stiffening=True)
    assert t[-1] == pytest.approx(20.0)
    assert np.abs(tip).max() < 1.0 and abs(tip[-1]) < 0.1
    t, tip = _spin_up(harness, 10.0, stiffening=False)
    assert t[-1] < 20.0 and np.abs(tip).max() > 5.0
