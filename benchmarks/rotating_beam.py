"""Issue 43's candidate 1 verified on the rotating cantilever (tests/test_rotating_beam.py holds the limits):
Southwell coefficients, frequencies at speed against an independent Rayleigh-Ritz solution, and the spin-up
manoeuvre, built from rss6's element matrices (rss6core.beam), the frame load (rss6core.assembly.frame_inertia_load)
and the harness's geometric load (benchmarks/acceleration_candidates.py: axial_forces, geometric_load).

A uniform Euler-Bernoulli cantilever clamped on the hub axis (hub radius 0) spins at Omega about an axis normal to
it (local z): flapwise (out of the rotation plane, w) omega^2 = omega_0^2 + K Omega^2, in-plane (chordwise, v)
omega^2 = omega_0^2 + (K - 1) Omega^2 (Southwell).  Coriolis coupling is left out of the frequencies, as in
Southwell's form.  Nondimensional: E = rho = A = I = L = 1, so Omega is lambda = Omega sqrt(rho A L^4 / E I).

    python benchmarks/rotating_beam.py      (about 1 minute)
"""
import importlib.util
import sys
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import eigh
from scipy.optimize import brentq

from rss6core.assembly import frame_inertia_load
from rss6core.beam import link_matrices
from rss6core.sections import SectionProperties


def _harness():
    """benchmarks/acceleration_candidates.py as a module (the benchmarks are scripts, not a package)."""
    spec = importlib.util.spec_from_file_location("acceleration_candidates",
                                                  Path(__file__).resolve().parent / "acceleration_candidates.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)
    spec.loader.exec_module(module)
    return module


HARNESS = _harness()
ELEMENTS = 40
UNIT = SectionProperties(area=1.0, Iy=1.0, Iz=1.0, J=1.0)
FLAP, IN_PLANE = (2, 4), (1, 5)      # (w, r_y) and (v, r_z) of each node
SOUTHWELL_K1 = 1.193                 # Wright, Smith, Thresher & Wang (1982); Hodges & Rutkowski (1981)


def _spin(omega):
    """Om = Omega~ (3, 3) of a spin Omega about local z."""
    return np.array([[0.0, -omega, 0.0], [omega, 0.0, 0.0], [0.0, 0.0, 0.0]])


def _as_matrix(load, size):
    """The matrix A with load(q) = -A q, of a linear load in row form."""
    return -np.stack([load(e) for e in np.eye(size)]).T


def spinning_frequencies(omega, plane, elements=ELEMENTS, stiffening=True, frame=True):
    """Squared frequencies (rad^2/s^2, ascending) of the spinning cantilever's ``plane`` DOFs."""
    K, M = link_matrices(UNIT, 1.0, 0.4, 1.0, 1.0, elements)
    size, length, Om = K.shape[0], 1.0 / elements, _spin(omega)
    free = np.arange(6, size)
    X = np.zeros(size)
    X[0::6] = np.linspace(0.0, 1.0, elements + 1)                 # the rigid positions: centrifugal load
    f = frame_inertia_load(M, X, np.zeros(size), Om, np.zeros((3, 3)))
    u = np.zeros(size)
    u[free] = np.linalg.solve(K[np.ix_(free, free)], f[free])
    N = HARNESS.axial_forces(u, 1.0, length)
    stiff = K.copy()
    if stiffening:
        stiff += _as_matrix(lambda q: HARNESS.geometric_load(q, N, length, UNIT), size)
    if frame:
        stiff += _as_matrix(lambda q: frame_inertia_load(M, q, np.zeros(size), Om, np.zeros((3, 3))), size)
    keep = free[np.isin(free % 6, plane)]
    return eigh(stiff[np.ix_(keep, keep)], M[np.ix_(keep, keep)], eigvals_only=True)


def cantilever_mode(k):
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
    shapes = [cantilever_mode(k) for k in range(1, modes + 1)]
    phi = np.stack([p(x) for _, p, _ in shapes])
    slope = np.stack([s(x) for _, _, s in shapes])
    M = (phi * w) @ phi.T
    K = np.diag([b ** 4 for b, _, _ in shapes]) @ M + omega ** 2 * (slope * w * (1 - x ** 2) / 2) @ slope.T
    return eigh(K, M, eigvals_only=True)


def spin_up(omega_s, stiffening, elements=8, end=20.0, period=15.0):
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
            f += HARNESS.geometric_load(q, HARNESS.axial_forces(q, E * props.area, length), length, props)
        return np.concatenate([y[m:], M_inv @ f[keep]])

    def runaway(t, y):
        return abs(y[m - 2]) - L
    runaway.terminal = True
    sol = solve_ivp(rhs, (0.0, end), np.zeros(2 * m), method="Radau", rtol=1e-6, atol=1e-9, events=runaway,
                    t_eval=np.linspace(0.0, end, 401))
    return sol.t, sol.y[m - 2]


def southwell(elements, plane, stiffening=True, modes=2):
    """(omega^2 - omega_0^2) / Omega^2 of the first ``modes`` modes of ``plane`` at Omega = 0.05 omega_1."""
    omega_0 = spinning_frequencies(0.0, FLAP, elements)
    omega = 0.05 * np.sqrt(omega_0[0])
    return (spinning_frequencies(omega, plane, elements, stiffening)[:modes] - omega_0[:modes]) / omega ** 2


def rayleigh_quotient(k):
    """The first-order Southwell coefficient of flapwise mode k: int (1 - x^2) / 2 phi'^2 / int phi^2 with the
    closed-form clamped-free mode (Gauss-Legendre, 200 points)."""
    x, w = np.polynomial.legendre.leggauss(200)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    _, phi, slope = cantilever_mode(k)
    return (w * (1 - x ** 2) / 2 * slope(x) ** 2).sum() / (w * phi(x) ** 2).sum()


def main():
    print(f"Southwell coefficients, published K1 = {SOUTHWELL_K1}; exact modes' Rayleigh quotients "
          f"{rayleigh_quotient(1):.4f}, {rayleigh_quotient(2):.4f}")
    for n in (10, 20, 40, 80):
        flap, in_plane = southwell(n, FLAP), southwell(n, IN_PLANE, modes=1)
        linear = southwell(n, FLAP, False, 1), southwell(n, IN_PLANE, False, 1)
        print(f"{n:3d} elements: flapwise K {flap[0]:.4f} {flap[1]:.4f}, in-plane K - 1 {in_plane[0]:.4f}; without "
              f"K_G flapwise {linear[0][0]:.4f} (0), in-plane {linear[1][0]:.4f} (-1)")
    omega_0 = np.sqrt(spinning_frequencies(0.0, FLAP)[0])
    for ratio in (1.0, 2.0):
        omega = ratio * omega_0
        ritz = ritz_frequencies(omega)[0]
        flap, in_plane = spinning_frequencies(omega, FLAP)[0], spinning_frequencies(omega, IN_PLANE)[0]
        print(f"Omega = {ratio:g} omega_0, {ELEMENTS} elements, against Rayleigh-Ritz: flapwise "
              f"{np.sqrt(flap / ritz) - 1:+.2%}, in-plane {np.sqrt(in_plane / (ritz - omega ** 2)) - 1:+.2%}; "
              f"against Southwell's form {np.sqrt(flap / (omega_0 ** 2 + SOUTHWELL_K1 * omega ** 2)) - 1:+.2%}, "
              f"{np.sqrt(in_plane / (omega_0 ** 2 + (SOUTHWELL_K1 - 1) * omega ** 2)) - 1:+.2%}")
    for omega_s in (4.0, 10.0):
        for stiffening in (True, False):
            t, tip = spin_up(omega_s, stiffening)
            print(f"spin-up to {omega_s:g} rad/s, {'with' if stiffening else 'without'} K_G: max |tip| "
                  f"{np.abs(tip).max():.3g} m, at {t[-1]:.1f} s {tip[-1]:.3g} m")


if __name__ == "__main__":
    main()
