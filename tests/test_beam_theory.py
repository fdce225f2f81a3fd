"""Timoshenko and rotary-inertia beam elements against closed forms: the exact cantilever frequencies
of the Timoshenko and Rayleigh beam equations (frequency determinant solved with brentq), the
Euler-Bernoulli limit of a slender beam, the static tip deflection with shear, mesh convergence."""
import numpy as np
import pytest
import scipy.linalg
from scipy.optimize import brentq

from rss6core import SceneError, parse_scene
from rss6core.beam import BeamTheory, element_matrices, link_matrices
from rss6core.sections import RectangleSection, TubeSection, section_properties, shear_correction_factor

E, G, RHO = 70e9, 26.5e9, 2700.0
NU = E / (2 * G) - 1
THICK = RectangleSection(0.040, 0.020)   # the paper's crank section
BETA_L = np.array([1.8751040687, 4.6940911330, 7.8547574382])  # Euler-Bernoulli cantilever roots


def _exact_determinant(omega, L, EI, rhoA, rhoI, shear_compliance):
    """Cantilever frequency determinant of the Timoshenko beam (shear_compliance = 1 / kGA; 0 with
    rhoI > 0: Rayleigh beam; both 0: Euler-Bernoulli), from w = sum C_j f_j(x) on the basis
    cosh, sinh (lambda^2 = a^2), cos, sin (lambda^2 = -b^2) of the characteristic equation
    EI lam^4 + w^2 (EI rhoA s + rhoI) lam^2 + rhoA w^2 (rhoI w^2 s - 1) = 0.
    Rows: w(0) = 0, psi(0) = 0, psi'(L) = 0, EI psi''(L) + rhoI w^2 psi(L) = 0 (zero shear)."""
    s, w2 = shear_compliance, omega ** 2
    p, q = w2 * (EI * rhoA * s + rhoI) / EI, rhoA * w2 * (rhoI * w2 * s - 1) / EI
    root = np.sqrt(p * p / 4 - q)
    a, b = np.sqrt(-p / 2 + root), np.sqrt(p / 2 + root)   # real and imaginary wavenumbers, 1/m
    ca, d = a + rhoA * w2 * s / a, rhoA * w2 * s / b - b    # psi per w of each basis pair
    ch, sh, co, si = np.cosh(a * L), np.sinh(a * L), np.cos(b * L), np.sin(b * L)
    rows = np.array([
        [1.0, 0.0, 1.0, 0.0],
        [0.0, ca, 0.0, -d],
        [ca * a * ch, ca * a * sh, d * b * co, d * b * si],
        [ca * (EI * a * a + rhoI * w2) * sh, ca * (EI * a * a + rhoI * w2) * ch,
         d * (rhoI * w2 - EI * b * b) * si, -d * (rhoI * w2 - EI * b * b) * co]])
    rows[2:] /= np.abs(rows[2:]).max(axis=1, keepdims=True)   # positive scaling keeps the sign
    return np.linalg.det(rows)


def exact_frequencies(L, EI, rhoA, rhoI, shear_compliance, count, top):
    """The lowest ``count`` roots (rad/s) of the determinant below ``top``: scan, then brentq."""
    grid = np.linspace(1.0, top, 20000)
    f = np.array([_exact_determinant(w, L, EI, rhoA, rhoI, shear_compliance) for w in grid])
    roots = [brentq(_exact_determinant, grid[i], grid[i + 1], args=(L, EI, rhoA, rhoI, shear_compliance),
                    xtol=1e-10) for i in np.flatnonzero(np.sign(f[:-1]) != np.sign(f[1:]))]
    assert len(roots) >= count, f"found {len(roots)} roots below {top} rad/s"
    return np.array(roots[:count])


def fe_frequencies(section, L, elements, shear, rotary, count, mass="consistent"):
    """Lowest ``count`` frequencies (rad/s) of the x-y plane bending (v, r_z; EI_z) of a cantilever."""
    props = section_properties(section)
    k = shear_correction_factor(section, NU) if shear else None
    K, M = link_matrices(props, E, G, RHO, L, elements, k, rotary, mass)
    plane = np.sort(np.r_[np.arange(7, K.shape[0], 6), np.arange(11, K.shape[0], 6)])  # nodes 1..n
    K, M = K[np.ix_(plane, plane)], M[np.ix_(plane, plane)]
    return np.sqrt(scipy.linalg.eigh(K, M, eigvals_only=True)[:count])


def closed_form(section, L, shear, rotary, count=3):
    props = section_properties(section)
    EI, rhoA, rhoI = E * props.Iz, RHO * props.area, RHO * props.Iz * rotary
    s = 1.0 / (shear_correction_factor(section, NU) * G * props.area) if shear else 0.0
    top = 1.2 * (BETA_L[count - 1] / L) ** 2 * np.sqrt(EI / rhoA)   # above the EB frequency
    if s * rhoI > 0:   # the basis holds below the second-spectrum cut-off sqrt(kGA / rho I)
        top = min(top, (1 - 1e-9) / np.sqrt(s * rhoI))
    return exact_frequencies(L, EI, rhoA, rhoI, s, count, top)


# x-y plane of the thick crank section: bending about z, depth 40 mm; L/h = 2.5
SHORT = 0.1


def test_timoshenko_short_thick_cantilever_frequencies():
    exact = closed_form(THICK, SHORT, shear=True, rotary=True)
    computed = fe_frequencies(THICK, SHORT, 64, True, True, 3)   # errors 4e-6, 7e-5, 3e-4
    # below the second-spectrum cut-off sqrt(kGA / rho I), where the basis used holds
    props = section_properties(THICK)
    assert exact.max() < np.sqrt(shear_correction_factor(THICK, NU) * G * props.area / (RHO * props.Iz))
    assert np.abs(computed / exact - 1).max() < 5e-4
    # and the beam is thick enough for the test to tell: Euler-Bernoulli is 12-117 % high
    eb = (BETA_L / SHORT) ** 2 * np.sqrt(E * props.Iz / (RHO * props.area))
    assert (eb / exact - 1).min() > 0.1


def test_rayleigh_beam_frequencies():
    exact = closed_form(THICK, SHORT, shear=False, rotary=True)
    computed = fe_frequencies(THICK, SHORT, 32, False, True, 3)   # errors 7e-9, 2e-7, 2e-6
    assert np.abs(computed / exact - 1).max() < 1e-5
    eb = closed_form(THICK, SHORT, shear=False, rotary=False)
    assert np.abs(eb / ((BETA_L / SHORT) ** 2 * np.sqrt(E * section_properties(THICK).Iz
                                                       / (RHO * section_properties(THICK).area))) - 1).max() < 1e-6
    assert (eb / exact - 1).min() > 0.01     # rotary inertia alone moves them by more than 1 %


@pytest.mark.parametrize("shear, rotary", [(True, True), (True, False), (False, True)])
def test_slender_beam_reaches_the_euler_bernoulli_limit(shear, rotary):
    L = 4.0   # L/h = 100
    props = section_properties(THICK)
    eb = (BETA_L / L) ** 2 * np.sqrt(E * props.Iz / (RHO * props.area))
    computed = fe_frequencies(THICK, L, 16, shear, rotary, 3)
    assert np.abs(computed / eb - 1).max() < 2e-3
    assert np.abs(closed_form(THICK, L, shear, rotary) / eb - 1).max() < 2e-3


@pytest.mark.parametrize("section", [THICK, TubeSection(0.025, 0.010)])
@pytest.mark.parametrize("elements", [1, 4])
def test_static_tip_deflection_with_shear(section, elements):
    props = section_properties(section)
    k = shear_correction_factor(section, NU)
    K, _ = link_matrices(props, E, G, RHO, SHORT, elements, k, True)
    K = K[6:, 6:]
    for dof, I in ((1, props.Iz), (2, props.Iy)):
        load = np.zeros(len(K))
        load[-6 + dof] = 1.0
        tip = np.linalg.solve(K, load)[-6 + dof]
        assert tip == pytest.approx(SHORT ** 3 / (3 * E * I) + SHORT / (k * G * props.area), rel=1e-10)


@pytest.mark.parametrize("shear, order", [(True, 2), (False, 4)])
def test_frequencies_converge_with_elements(shear, order):
    """Measured: second order with shear (the shear-deformable element's rotation is quadratic),
    fourth order for the Rayleigh beam (Hermite cubics), on the first three modes."""
    exact = closed_form(THICK, SHORT, shear=shear, rotary=True)
    err = [np.abs(fe_frequencies(THICK, SHORT, n, shear, True, 3) / exact - 1) for n in (4, 8, 16, 32)]
    assert err[0].max() < 0.1
    for coarse, fine in zip(err[:-1], err[1:]):
        assert (coarse / fine).min() > 0.75 * 2 ** order   # 3 (12) per halving, mode 3 pre-asymptotic


def test_matrices_are_the_integrals_of_the_interdependent_shape_functions():
    """Gauss quadrature of Friedman & Kosmatka's (1993) exact static shape functions (w cubic,
    rotation quadratic): K = int EI N_t'^2 + kGA (N_w' - N_t)^2, M = int rho A N_w^2 + rho I N_t^2."""
    props, l, k = section_properties(THICK), 0.013, shear_correction_factor(THICK, NU)
    EI, kGA, rhoA, rhoI = E * props.Iz, k * G * props.area, RHO * props.area, RHO * props.Iz
    P = 12 * EI / (kGA * l * l)
    x, wq = np.polynomial.legendre.leggauss(6)
    xi, wq, d = (x + 1) / 2, wq * l / 2, 1 + P
    Nw = np.array([2 * xi ** 3 - 3 * xi ** 2 - P * xi + d, l * (xi ** 3 - (2 + P / 2) * xi ** 2 + (1 + P / 2) * xi),
                   -(2 * xi ** 3 - 3 * xi ** 2 - P * xi), l * (xi ** 3 - (1 - P / 2) * xi ** 2 - P / 2 * xi)]) / d
    Nt = np.array([6 * (xi ** 2 - xi) / l, 3 * xi ** 2 - (4 + P) * xi + d, -6 * (xi ** 2 - xi) / l,
                   3 * xi ** 2 - (2 - P) * xi]) / d
    dNw = np.array([6 * xi ** 2 - 6 * xi - P, l * (3 * xi ** 2 - (4 + P) * xi + 1 + P / 2),
                    -(6 * xi ** 2 - 6 * xi - P), l * (3 * xi ** 2 - (2 - P) * xi - P / 2)]) / (d * l)
    dNt = np.array([6 * (2 * xi - 1) / l, 6 * xi - 4 - P, -6 * (2 * xi - 1) / l, 6 * xi - 2 + P]) / (d * l)
    K_ref = EI * (dNt * wq) @ dNt.T + kGA * ((dNw - Nt) * wq) @ (dNw - Nt).T
    M_ref = rhoA * (Nw * wq) @ Nw.T + rhoI * (Nt * wq) @ Nt.T
    K, M = element_matrices(props, E, G, RHO, l, k, True)
    plane = [1, 5, 7, 11]
    assert np.allclose(K[np.ix_(plane, plane)], K_ref, rtol=1e-12, atol=1e-12 * np.abs(K_ref).max())
    assert np.allclose(M[np.ix_(plane, plane)], M_ref, rtol=1e-12, atol=1e-12 * np.abs(M_ref).max())


def test_rigid_rotation_carries_the_rotary_inertia():
    """q^T M q of a rigid rotation theta about z (v = x theta, r_z = theta) on x in [0, l]:
    rho A l^3 / 3 + rho I_z l with rotary inertia, rho A l^3 / 3 without; shear-free, so both theories."""
    props, l = section_properties(THICK), 0.07
    q = np.zeros(12)
    q[[5, 7, 11]] = [1.0, l, 1.0]
    for k in (None, shear_correction_factor(THICK, NU)):
        for rotary in (False, True):
            K, M = element_matrices(props, E, G, RHO, l, k, rotary)
            assert q @ M @ q == pytest.approx(RHO * props.area * l ** 3 / 3 + rotary * RHO * props.Iz * l,
                                              rel=1e-12)
            assert np.abs(K @ q).max() < 1e-6 * np.abs(K).max()


def test_default_element_is_the_shear_rigid_limit_of_the_timoshenko_element():
    props = section_properties(TubeSection(0.025, 0.010))
    K0, M0 = element_matrices(props, E, G, RHO, 0.1)
    K1, M1 = element_matrices(props, E, G, RHO, 0.1, 1e9, False)
    assert np.allclose(K1, K0, rtol=1e-6, atol=1e-9 * np.abs(K0).max())
    assert np.allclose(M1, M0, rtol=1e-6, atol=1e-12)


def test_cowper_shear_factors():
    assert shear_correction_factor(RectangleSection(0.04, 0.02), 0.3) == pytest.approx(13 / 15.3)
    assert shear_correction_factor(TubeSection(0.02, 0.0), 0.3) == pytest.approx(7.8 / 8.8)
    assert shear_correction_factor(TubeSection(0.02, 0.02 * (1 - 1e-9)), 0.3) == pytest.approx(2.6 / 4.9)


def test_scene_beam_table(paper_text):
    scene = parse_scene(paper_text + '\n[beam]\ntheory = "timoshenko"\nrotary_inertia = true\n')
    assert scene.beam == BeamTheory("timoshenko", True)
    assert parse_scene(paper_text).beam == BeamTheory("euler-bernoulli", False)
    for bad, key in (('theory = "timoshinko"', "[beam] theory"), ("rotary_inertia = 1", "[beam] rotary_inertia"),
                     ("shear = true", "[beam] shear"), ('mass = "lumped"', "[beam] mass"),
                     ('mass = "diagonal"\nrotary_inertia = true', "[beam] mass")):
        with pytest.raises(SceneError, match=key.replace("[", r"\[").replace("]", r"\]")) as info:
            parse_scene(paper_text + f"\n[beam]\n{bad}\n")
        assert "\n" not in str(info.value)


@pytest.mark.parametrize("shear", [True, False])
def test_lumped_mass_converges_from_below_at_second_order(shear):
    """Measured: first mode 8.7-9.8 % low on 2 elements, 0.04 % on 32; ratio 4 per halving."""
    exact = closed_form(THICK, SHORT, shear=shear, rotary=True)
    err = [fe_frequencies(THICK, SHORT, n, shear, True, 3, "lumped") / exact - 1 for n in (8, 16, 32, 64)]
    assert all((e < 0).all() for e in err)
    assert np.abs(err[-1]).max() < 6e-4
    for coarse, fine in zip(err[:-1], err[1:]):
        assert (coarse / fine).min() > 3.5


def test_lumped_mass_is_half_the_element_at_each_node():
    props, l = section_properties(THICK), 0.07
    _, M = element_matrices(props, E, G, RHO, l, None, True, "lumped")
    assert np.count_nonzero(M - np.diag(np.diag(M))) == 0
    assert np.diag(M)[[0, 1, 2, 6, 7, 8]] == pytest.approx([RHO * props.area * l / 2] * 6)
    assert np.diag(M)[[3, 4, 5]] == pytest.approx(RHO * l / 2 * np.array([props.Iy + props.Iz, props.Iy,
                                                                          props.Iz]))
    with pytest.raises(ValueError, match="rotary"):
        element_matrices(props, E, G, RHO, l, None, False, "lumped")
