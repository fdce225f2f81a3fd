"""Contact laws (eq. 17-18), the paper level (L3) and the contact level (L4): laws, limits, repeatability."""
import dataclasses

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from rss6core.clearance import draw_clearances
from rss6core.contact_dynamics import CompiledStepper, _ball, simulate_contact
from rss6core.contact_kernel import balance_next, coarsest_next
from rss6core.contact_numpy import NumpyStepper
from rss6core.integrators import Integrator, correct, predict
from rss6core.contact_laws import coulomb_friction, friction_factor, hertz_stiffness, lankarani_nikravesh, poisson_ratio
from rss6core.kinematics import rigid_motion
from rss6core.models import simulate, simulate_batch
from rss6core.paper_method import PaperClosure, paper_contact_forces, paper_draw
from rss6core.quasi_static import CENTRAL_PAD, quasi_static_error


def _with(scene, **tables):
    """A copy of ``scene`` with fields of its sub-tables replaced: _with(s, trajectory={'duration': 1})."""
    return dataclasses.replace(scene, **{name: dataclasses.replace(getattr(scene, name), **fields)
                                         for name, fields in tables.items()})


def _clearance(scene, size):
    return _with(scene, clearance=dict(revolute_radial=size, revolute_axial=size,
                                       spherical_C=size, spherical_B=size))


# --- laws ------------------------------------------------------------------

def test_hertz_stiffness_matches_the_papers_form_for_two_materials():
    # eq. 17 as printed: 4 Ei Eo / (3 [Ei + Eo - (Eo nu_i^2 + Ei nu_o^2)]) sqrt(Ri Ro / (Ro - Ri))
    Ei, nui, Eo, nuo, Ri, Ro = 210e9, 0.29, 70e9, 0.32, 0.010, 0.01025
    paper = 4 * Ei * Eo / (3 * (Ei + Eo - (Eo * nui ** 2 + Ei * nuo ** 2))) * np.sqrt(Ri * Ro / (Ro - Ri))
    assert hertz_stiffness(Ri, Ro, Ei, nui, Eo, nuo) == pytest.approx(paper, rel=1e-12)
    # the paper scene's aluminium pair: nu from E and G, K of order 1e10 N/m^1.5
    nu = poisson_ratio(70e9, 26.5e9)
    assert nu == pytest.approx(70 / 53 - 1)
    assert 1e10 < hertz_stiffness(0.010, 0.01025, 70e9, nu, 70e9, nu) < 1e11
    with pytest.raises(ValueError, match="outer"):
        hertz_stiffness(0.011, 0.010, 70e9, nu, 70e9, nu)


def _restitution(K, m, v, xi=0.9, n=1.5):
    """Rebound over impact speed of a mass m hitting a rigid wall at v under eq. 17."""
    def rhs(t, y):
        return [y[1], -lankarani_nikravesh(y[0], y[1], v, K, n, xi)[0] / m]

    def leaves(t, y):
        return y[0]
    leaves.terminal, leaves.direction = True, -1
    span = 50 * (m / (K * np.sqrt(v))) ** 0.4   # many contact durations
    sol = solve_ivp(rhs, [0, span], [1e-18, v], method="DOP853", rtol=1e-10, atol=1e-18,
                    events=leaves)
    return -sol.y_events[0][0][1] / v


def test_lankarani_nikravesh_restitution_is_xi_for_any_stiffness_mass_and_speed():
    values = np.array([_restitution(K, m, v) for K in (1e9, 3e10, 1e12) for m in (0.1, 1.0, 10.0)
                       for v in (1e-3, 0.1, 1.0)])
    assert np.all(np.abs(values / 0.9 - 1) < 0.03)      # LN's hysteresis gives 0.913 for xi = 0.9
    assert values.max() - values.min() < 1e-5           # the model's scale invariance


def test_lankarani_nikravesh_is_zero_apart_and_never_pulls():
    F, dF, dFr = lankarani_nikravesh(np.array([-1e-6, 0.0, 1e-6, 1e-6]),
                                     np.array([0.0, 0.0, 0.0, -10.0]), 0.1, 1e10, 1.5, 0.9)
    assert F[0] == F[1] == 0 and F[3] == 0 and dF[3] == 0
    assert F[2] == pytest.approx(1e10 * 1e-9)


def test_friction_vanishes_below_v0_and_is_full_above_v1():
    v0, v1, mu, FN = 1e-4, 1e-2, 0.1, 50.0
    cd, _ = friction_factor(np.array([0.0, 0.5e-4, v0, 0.5 * (v0 + v1), v1, 1.0]), v0, v1)
    np.testing.assert_allclose(cd, [0, 0, 0, 0.5, 1, 1], atol=1e-15)
    d = np.array([0.6, -0.8, 0.0])
    for speed, scale in ((0.9 * v0, 0.0), (2 * v1, 1.0), (0.5 * (v0 + v1), 0.5)):
        Ft, _, _ = coulomb_friction(FN, speed * d, mu, v0, v1)
        np.testing.assert_allclose(Ft, -scale * mu * FN * d, atol=1e-12)


def test_contact_jacobians_match_finite_differences():
    law = dataclasses.replace(_law(), impact_speed_floor=1e-3)
    rng = np.random.default_rng(4)
    e = rng.normal(size=3)
    e *= 2.5003e-4 / np.linalg.norm(e)                   # 0.3 um into a 0.25 mm clearance
    de = 0.02 * rng.normal(size=3)
    omega = rng.normal(size=3)
    args = (2.5e-4, 3e10, 0.05, law, omega, 0.01)
    f, De, Dv, *_ = _ball(e, de, *args)
    h = 1e-12
    num_e = np.stack([(_ball(e + h * u, de, *args)[0] - _ball(e - h * u, de, *args)[0]) / (2 * h)
                      for u in np.eye(3)], -1)
    num_v = np.stack([(_ball(e, de + 1e-8 * u, *args)[0] - _ball(e, de - 1e-8 * u, *args)[0]) / 2e-8
                      for u in np.eye(3)], -1)
    np.testing.assert_allclose(Dv, num_v, rtol=1e-5, atol=1e-6 * np.abs(num_v).max())
    # d/de leaves out friction's and the rate's turn with the normal (a modified Newton)
    normal = np.outer(e, e) / (e @ e)
    np.testing.assert_allclose(normal @ De @ normal, normal @ num_e @ normal, rtol=1e-4)


def _frozen_normal_force(e, de, n0, size, stiffness, impact, law, omega, radius):
    """The ball's force with its penetration rate and slip taken along the fixed normal n0: the
    function the contact Newton differentiates in e (the normal's turn in them is left out)."""
    rho = np.linalg.norm(e)
    F = lankarani_nikravesh(rho - size, n0 @ de, impact, stiffness, law.exponent, law.restitution)[0]
    v = de + radius * np.cross(omega, n0)
    ft = coulomb_friction(F, v - (n0 @ v) * n0, law.friction_coefficient, law.stick_velocity,
                          law.slip_velocity)[0]
    return -F * e / rho + ft


def _central_jacobian(f, x, h):
    return np.stack([(f(x + h * u) - f(x - h * u)) / (2 * h) for u in np.eye(len(x))], -1)


def test_modified_newton_jacobian_is_exact_for_the_frozen_normal():
    """d force/d e, all nine entries (normal and tangential, spring, damping and friction), is
    exactly the derivative of the force with the rate and slip along a frozen normal."""
    law = dataclasses.replace(_law(), impact_speed_floor=1e-3)
    rng = np.random.default_rng(5)
    e = rng.normal(size=3)
    e *= 2.5003e-4 / np.linalg.norm(e)                   # 0.3 um into a 0.25 mm clearance
    de, omega = 0.02 * rng.normal(size=3), rng.normal(size=3)
    args = (2.5e-4, 3e10, 0.05, law, omega, 0.01)
    f, De, *_ = _ball(e, de, *args)
    n0 = e / np.linalg.norm(e)
    assert np.abs(_frozen_normal_force(e, de, n0, *args)).max() == pytest.approx(np.abs(f).max())
    num = _central_jacobian(lambda x: _frozen_normal_force(x, de, n0, *args), e, 1e-12)
    tangential = num - np.outer(n0, n0) @ num @ np.outer(n0, n0)
    assert np.abs(tangential).max() > 1e-3 * np.abs(num).max()   # more than the normal-normal part
    np.testing.assert_allclose(De, num, rtol=1e-5, atol=1e-5 * np.abs(num).max())


def test_full_jacobian_of_the_normal_force_is_the_modified_one_plus_the_rate_turn():
    """Without friction the full finite-difference d force/d e is De plus the one term the
    modified Newton leaves out, -dF/d(rate) n [(I - n n) de / rho]^T (the rate's turn)."""
    law = _law()
    rng = np.random.default_rng(6)
    e = rng.normal(size=3)
    e *= 2.5003e-4 / np.linalg.norm(e)
    rho = np.linalg.norm(e)
    n = e / rho
    slide = np.cross(n, rng.normal(size=3))
    de = slide / np.linalg.norm(slide) + 1e-3 * n        # sliding at 1 m/s, closing at 1 mm/s
    args = (2.5e-4, 3e10, 1e-3, law, rng.normal(size=3), 0.01)
    _, De, *_ = _ball(e, de, *args, friction=False)
    dF_rate = lankarani_nikravesh(rho - 2.5e-4, n @ de, 1e-3, 3e10, law.exponent, law.restitution)[2]
    turn = -dF_rate * np.outer(n, (de - (n @ de) * n) / rho)
    num = _central_jacobian(lambda x: _ball(x, de, *args, friction=False)[0], e, 1e-12)
    assert np.abs(turn).max() > 1e-2 * np.abs(num).max()      # the term is not negligible here
    np.testing.assert_allclose(De + turn, num, rtol=1e-5, atol=1e-5 * np.abs(num).max())


def test_joint_jacobians_of_all_legs_match_finite_differences(smoke):
    """Every joint of every leg in contact, frictionless and at rest (where the modified Newton
    is exact): d force/d e of the revolute (radial in the plane normal to w_i, axial along w_i)
    and of both spheres, all 27 entries per leg, against central differences."""
    from rss6core.contact_dynamics import _contacts, _joints
    joints = _joints(smoke, [draw_clearances(smoke, 0, 0)])
    law = dataclasses.replace(smoke.contact, friction_coefficient=0.0)
    w = smoke.geometry.w
    rng = np.random.default_rng(7)
    e = np.empty((1, 6, 3, 3))
    radial = np.cross(w, rng.normal(size=(6, 3)))
    e[0, :, 0] = (radial / np.linalg.norm(radial, axis=-1, keepdims=True)
                  * (joints.radial[0, :, None] + 2e-7)
                  + w * (joints.axial[0, :, None] + 1e-7) * rng.choice([-1, 1], size=(6, 1)))
    for j, size in ((1, joints.size_C), (2, joints.size_B)):
        u = rng.normal(size=(6, 3))
        e[0, :, j] = u / np.linalg.norm(u, axis=-1, keepdims=True) * (size[0, :, None] + 3e-7)
    de, impact = np.zeros_like(e), np.full((1, 6, 4), 0.05)
    omega, radius = np.zeros((6, 3, 3)), np.array([[0.01], [0.01], [0.01]])

    def force(x):
        return _contacts(x.reshape(e.shape), de, w, joints, impact, law, omega, radius)[0].ravel()
    f, De, _, delta, _ = _contacts(e, de, w, joints, impact, law, omega, radius)
    assert np.all(delta > 0)                                   # all four contacts of every leg
    num = _central_jacobian(force, e.ravel(), 1e-13).reshape(6, 3, 3, 6, 3, 3)
    for leg in range(6):
        for j in range(3):
            block = num[leg, j, :, leg, j, :]
            np.testing.assert_allclose(De[0, leg, j], block, rtol=1e-5, atol=1e-6 * np.abs(block).max())


def _law(exponent=1.5):
    from rss6core.scene import ContactLaw
    return ContactLaw(0.01, 0.01, 0.9, exponent, 0.1, 1e-4, 1e-2)


def test_newton_predictor_extrapolates_polynomials_exactly_in_both_engines():
    """The first Newton iterate of a step is the polynomial through the last accepted accelerations,
    at uneven steps: exact for a quadratic history (degree 2 once two steps are known), a line after
    one step, the last value before any; the compiled twin gives the same at the joint nodes."""
    from rss6core.contact_numpy import _extrapolated
    from rss6core.contact_kernel import _predict
    rng = np.random.default_rng(7)
    N, nc = 6 * 52 + 6, 27
    cb = np.r_[0:3, 21:24].astype(np.int64)       # the crank's joint nodes, 4 elements
    c0, c1, c2 = rng.normal(size=(3, N))
    poly = lambda t, degree: c0 + (degree > 0) * c1 * t + (degree > 1) * c2 * t * t  # noqa: E731
    h, h1, h2 = 1.25e-5, 5e-5, 2e-4      # the next step, the last two accepted ones (s)
    for degree, h_past in ((2, [h1, h2]), (1, [h1, 0.0]), (0, [0.0, 0.0])):
        a = poly(0.0, degree)[None]
        past = np.stack([poly(-h1, degree), poly(-h1 - h2, degree)])[None] if degree else rng.normal(size=(1, 2, N))
        want = poly(h, degree)
        tol = 1e-12 * np.abs(want).max()
        got = _extrapolated(h, a, past, np.array([h_past]))[0]
        np.testing.assert_allclose(got, want, rtol=0, atol=tol)
        ab, ap = np.empty((6, 12)), np.empty(6)
        _predict(0, h, a, past, np.array([h_past]), cb, nc, ab, ap)
        legs = want[:-6].reshape(6, 52)
        np.testing.assert_allclose(ab, np.concatenate([legs[:, cb], legs[:, -6:]], -1), rtol=0, atol=tol)
        np.testing.assert_allclose(ap, want[-6:], rtol=0, atol=tol)


@pytest.mark.parametrize("depth, spin, exponent", [(-1e-6, 1.0, 1.5), (3e-7, 0.0, 1.5), (3e-7, 1e-3, 1.5),
                                                   (3e-7, 0.5, 1.5), (3e-7, 50.0, 1.5), (3e-7, 0.5, 1.3)])
def test_compiled_contact_pair_matches_the_vectorised_one(depth, spin, exponent):
    """Apart; in contact sticking (no spin, tiny slip), in the friction ramp, and sliding; with
    Hertz's 3/2 (computed as delta sqrt(delta)) and another exponent (pow)."""
    from rss6core.contact_kernel import Law, ball
    law = _law(exponent)
    law_v = Law(exponent=float(law.exponent), v0=float(law.stick_velocity), v1=float(law.slip_velocity))
    rng = np.random.default_rng(9)
    e = rng.normal(size=3)
    e *= (2.5e-4 + depth) / np.linalg.norm(e)
    de = 1e-5 * rng.normal(size=3)
    omega = spin * rng.normal(size=3)
    f, De, Dv, delta, rate, _ = _ball(e, de, 2.5e-4, 3e10, 0.05, law, omega, 0.01)
    fc, Dec, Dvc = np.empty(3), np.empty((3, 3)), np.empty((3, 3))
    dc, rc = ball(e, de, 2.5e-4, 3e10, 0.05, law_v, float(law.friction_coefficient), float(law.restitution), omega,
                  0.01, fc, Dec, Dvc)
    assert (dc, rc) == pytest.approx((delta, rate), rel=1e-12, abs=1e-22)
    for mine, ref in ((fc, f), (Dec, De), (Dvc, Dv)):
        np.testing.assert_allclose(mine, ref, rtol=1e-10, atol=1e-12 * max(np.abs(ref).max(), 1.0))
    assert (np.abs(f).max() > 0) == (depth > 0)


@pytest.mark.parametrize("shape", [(6, 54, 27), (6, 25, 31), (1, 3, 2)])
def test_kernel_blas_product_equals_numpy_bit_for_bit(shape):
    """The steps' dgemm called by symbol (contact_kernel._product: column-major, so out^T = A^T X^T)
    gives numpy's X @ A exactly, for the link products' shapes and a tiny one."""
    from numba import njit

    from rss6core.contact_kernel import _product, make_work
    m, k, n = shape
    rng = np.random.default_rng(4)
    X, A = rng.normal(size=(m, k)), rng.normal(size=(k, n))
    out = np.full((m, n), np.nan)

    @njit(_nrt=False)
    def product(X, A, out, work):
        _product(X, A, out, work)
    product(X, A, out, make_work(18, 1, 1, 1, 1))
    assert np.array_equal(out, X @ A)


def test_compiled_joint_maps_from_link_frames_equal_the_chunks_G(paper):
    """The kernel reads the joint maps' blocks from the link frames Rc, Rr (contact_kernel._gmap:
    Rc, -Rc, Rr, Rr) instead of the chunk's G (9x12 per leg, the numpy engine's): relative
    displacements and generalised forces agree with the products with G to round-off."""
    from numba import njit

    from rss6core.contact_dynamics import _Chunk, _generalized, _relative, build_joint_model
    from rss6core.contact_kernel import _generalized as generalized_c
    from rss6core.contact_kernel import relative

    @njit(_nrt=False)
    def both(Rc, Rr, J, xb, xp, f, e, gl, gp):
        relative(Rc, Rr, J, xb, xp, e)
        generalized_c(Rc, Rr, J, f, gl, gp)
    ch = _Chunk(paper, build_joint_model(paper, 4), np.linspace(0.1, 0.3, 3))
    rng = np.random.default_rng(11)
    xb, xp, f = rng.normal(size=(6, 12)), rng.normal(size=6), rng.normal(size=(6, 3, 3))
    e, gl, gp = np.empty((6, 3, 3)), np.empty((6, 12)), np.empty(6)
    for k in range(3):
        both(ch.Rc[k], ch.Rr[k], ch.J[k], xb, xp, f, e, gl, gp)
        want_gl, want_gp = _generalized(ch, k, f)
        for got, want in ((e, _relative(ch, k, xb, xp)), (gl, want_gl), (gp, want_gp)):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-14 * np.abs(want).max())


def test_compiled_recovery_equals_the_condensed_links_recover(paper):
    """The kernel's recovery of the link interiors, x_i = y - x_b P^T from P alone (contact_kernel
    _recover), gives what _Condensed.recover (the numpy engine's) gives, and the corrector on it."""
    from numba import njit

    from rss6core.assembly import join
    from rss6core.contact_dynamics import _Condensed, build_joint_model
    from rss6core.contact_kernel import Layout, Levels, _recover, make_work

    @njit(_nrt=False)
    def recover(lv, layout, work):
        _recover(0, lv, layout, work)
    jm = build_joint_model(paper, 4)
    cond = _Condensed(jm, 2.0e6, 3.0)
    (Tc, Pc), (Tr, Pr) = cond.maps()
    one, nc, nr = np.ones(1), jm.crank_dofs, jm.rod_dofs
    lv = Levels(span=np.ones(1, np.int64), h=one, coef_p=one, d_pred=one, v_pred=one, d_corr=0.25 * one,
                v_corr=0.5 * one, error=one, legs=cond.legs[None], crank_T=Tc[None], crank_P=Pc[None],
                rod_T=Tr[None], rod_P=Pr[None])
    layout = Layout(crank_dofs=nc, crank_MK=np.zeros((2 * nc, nc)), rod_MK=np.zeros((2 * nr, nr)),
                    crank_M=jm.crank_M, rod_M=jm.rod_M, crank_boundary=jm.crank_boundary.astype(np.int64),
                    crank_interior=cond.crank[0].astype(np.int64))
    N = 6 * (nc + nr) + 6
    work = make_work(N, nc, nr, Tc.shape[1] - 6, Tr.shape[1] - 6)
    rng = np.random.default_rng(12)
    _, keep = cond.condense(rng.normal(size=(6, nc)), rng.normal(size=(6, nr)))
    work.Yc[:, :-6], work.Yr[:, :-6] = keep
    work.ab[:], work.ap[:], work.dp[:], work.vp[:] = (rng.normal(size=x.shape) for x in (work.ab, work.ap,
                                                                                       work.dp, work.vp))
    recover(lv, layout, work)
    want = join(*cond.recover(work.ab, keep, (6, nc), (6, nr)), work.ap)
    np.testing.assert_allclose(work.a_new, want, rtol=0, atol=1e-13 * np.abs(want).max())
    np.testing.assert_allclose(work.d_new, work.dp + 0.25 * work.a_new, rtol=1e-15, atol=0)
    np.testing.assert_allclose(work.v_new, work.vp + 0.5 * work.a_new, rtol=1e-15, atol=0)


def _rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def test_compiled_newton_update_solves_the_assembled_block_arrow_system():
    """The kernel's Newton update (contact_kernel._newton_update: each leg's chain eliminated block by
    block, the platform's Schur complement) solves the whole system assembled densely,
    blockdiag(Sl, .., Sl, Sp) - sum over legs of G^T diag(D_A, D_C, D_B) G with G's blocks Rc, -Rc, Rr,
    Rr and -J on the platform, as np.linalg.solve does; non-symmetric contact Jacobians, two of them
    zero (joints apart)."""
    from numba import njit

    from rss6core.contact_kernel import Frame, _newton_update, make_scratch

    @njit(_nrt=False)
    def update(fr, Sl, Sp, s):
        _newton_update(fr, Sl, Sp, s)
    rng = np.random.default_rng(13)
    Rc, Rr = np.array([_rotation(rng) for _ in range(6)]), np.array([_rotation(rng) for _ in range(6)])
    J = rng.normal(size=(6, 3, 6))
    spd = [(lambda a: 10 * (a @ a.T + 6 * np.eye(6)))(rng.normal(size=(6, 6))) for _ in range(3)]
    Sl, Sp = np.zeros((12, 12)), spd[2]
    Sl[:6, :6], Sl[6:, 6:] = spd[0], spd[1]
    D = rng.normal(size=(6, 3, 3, 3))
    D[2, 1] = D[4, 2] = 0.0
    s = make_scratch()
    s.D[:], s.res_l[:], s.res_p[:] = D, rng.normal(size=(6, 12)), rng.normal(size=6)
    update(Frame(Rc=Rc, J=J, Rr=Rr, omega=np.zeros((6, 3, 3))), Sl, Sp, s)
    K = np.zeros((78, 78))
    K[72:, 72:] = Sp
    for leg in range(6):
        c = 12 * leg
        K[c:c + 12, c:c + 12] = Sl
        G = np.zeros((9, 78))
        G[0:3, c:c + 3], G[3:6, c + 3:c + 6], G[3:6, c + 6:c + 9] = Rc[leg], -Rc[leg], Rr[leg]
        G[6:9, c + 9:c + 12], G[6:9, 72:] = Rr[leg], -J[leg]
        Dl = np.zeros((9, 9))
        for j in range(3):
            Dl[3 * j:3 * j + 3, 3 * j:3 * j + 3] = D[leg, j]
        K -= G.T @ Dl @ G
    want = np.linalg.solve(K, np.concatenate([s.res_l.ravel(), s.res_p]))
    np.testing.assert_allclose(np.concatenate([s.dl.ravel(), s.dp]), want, rtol=0,
                               atol=1e-13 * np.abs(want).max())


def test_compiled_steps_run_without_reference_counting():
    """The entry points that run the steps allocate nothing and skip numba's atomic reference counts
    (a fifth of the steps' time, docs/performance.md section 15); an allocation there fails to compile."""
    from rss6core.contact_kernel import advance_chunk, newton_step
    assert advance_chunk.targetoptions.get("_nrt") is False
    assert newton_step.targetoptions.get("_nrt") is False


# --- paper level (L3) -------------------------------------------------------

def test_paper_level_keeps_every_leg_closed_with_its_virtual_lengths(paper):
    t = paper.times[:50]
    motion = rigid_motion(paper, t)
    draw = paper_draw(paper, 3, 1, len(t))
    d, _, _ = PaperClosure(paper, t).error(draw)
    # independent check with positions: crank tip moved along the crank by the virtual
    # length, platform joint moved by the error, leg length L_cb + dl_cb (exact geometry)
    geo = paper.geometry
    x_c = (motion.c - geo.a) / geo.crank_length
    x_r = (motion.b - motion.c) / geo.rod_length
    out = slice(CENTRAL_PAD, -CENTRAL_PAD)   # the output steps of the draw
    dl_ac = np.einsum("tli,tli->tl", x_c, draw.e_A[out])
    dl_cb = np.einsum("tli,tli->tl", x_r, draw.e_C[out] - draw.e_B[out])
    c = motion.c + dl_ac[..., None] * x_c
    b = motion.b + d[:, None, :3] + np.cross(d[:, None, 3:], motion.r)
    gap = np.linalg.norm(b - c, axis=-1) - (geo.rod_length + dl_cb)
    unclosed = np.linalg.norm(motion.b - c, axis=-1) - (geo.rod_length + dl_cb)
    assert np.abs(unclosed).max() > 1e-4                 # the virtual lengths do open the legs
    assert np.abs(gap).max() < 2e-6                      # closed to second order, (0.5 mm)^2 / L


def test_paper_level_contact_forces_are_hertz_beyond_the_clearance_and_zero_inside(paper):
    """The paper's draws stay inside their clearances (|e| <= size at every step, the reason its
    eq. 17 forces vanish), and there the forces are zero; a spherical joint held 1 um beyond its
    clearance at a constant depth (zero penetration rate: eq. 17's damping term vanishes) carries
    Hertz's K delta^n, K written out here for a ball in a socket of the same material, in its own
    column (joints A, C, B by leg) and nowhere else."""
    steps, leg, depth = 200, 2, 1e-6
    draw = paper_draw(paper, 0, 0, steps)
    w = paper.geometry.w
    radial = draw.e_A - np.einsum("tli,li->tl", draw.e_A, w)[..., None] * w
    for e, size in ((radial, draw.radial_size), (draw.e_C, draw.size_C), (draw.e_B, draw.size_B)):
        assert np.all(np.linalg.norm(e, axis=-1) <= size)
    assert np.array_equal(paper_contact_forces(paper, draw, paper.time_step), np.zeros((steps, 18)))
    e_C = draw.e_C.copy()
    e_C[:, leg] *= ((draw.size_C[leg] + depth) / np.linalg.norm(e_C[:, leg], axis=-1))[:, None]
    forces = paper_contact_forces(paper, dataclasses.replace(draw, e_C=e_C), paper.time_step)
    ct, mat = paper.contact, paper.material
    sigma = 2 * (1 - (mat.youngs_modulus / (2 * mat.shear_modulus) - 1) ** 2) / mat.youngs_modulus
    R_ball, R_socket = ct.sphere_radius, ct.sphere_radius + draw.size_C[leg]
    K = 4 / (3 * sigma) * np.sqrt(R_ball * R_socket / (R_socket - R_ball))
    column = 6 + leg
    np.testing.assert_allclose(forces[:, column], K * depth ** ct.exponent, rtol=1e-8)
    assert not np.any(np.delete(forces, column, axis=1))


def test_paper_level_velocity_error_grows_like_one_over_the_time_step(smoke):
    mean_v = [np.abs(simulate(smoke, "paper", dt=dt).velocity[:, :3]).mean() for dt in (2e-3, 1e-3, 5e-4)]
    ratios = np.array(mean_v[1:]) / np.array(mean_v[:-1])
    np.testing.assert_allclose(ratios, 2.0, rtol=0.15)


# --- contact level (L4) -----------------------------------------------------

def test_contact_tends_to_elastic_as_the_clearance_vanishes(smoke):
    scene = _with(smoke, trajectory=dict(duration=0.1))
    elastic = simulate(scene, "elastic", dt=1e-4)
    diffs = []
    for size in (1e-4, 1e-5, 1e-6):
        s = _clearance(scene, size)
        run = simulate_contact(s, [draw_clearances(s, 0, 0)], dt=1e-4, output_step=1e-4)
        assert run.status == ["finished"], run.message
        diffs.append(np.abs(run.displacement[0, :, :3] - elastic.displacement[:, :3]).max())
    diffs = np.array(diffs)
    # the gap to the ideal-joint solution shrinks with the clearance, about in proportion
    assert np.all(diffs[1:] < diffs[:-1] / 5)
    assert np.all(diffs < 8 * np.array([1e-4, 1e-5, 1e-6]))


def test_contact_on_a_slow_trajectory_agrees_with_quasi_static(paper):
    """Paper trajectory slowed tenfold: after the joints settle (0.1 s) the contact level is the
    quasi-static level (joints at their walls along the rigid reactions) plus the elastic
    deflection, to 3 % of the largest quasi-static error; without the elastic part, to 5 %."""
    scene = _with(paper, trajectory=dict(frequency=0.1, duration=0.5))
    draw = draw_clearances(scene, 0, 0)
    run = simulate_contact(scene, [draw], dt=1e-4)
    assert run.status == ["finished"], run.message
    qs = quasi_static_error(scene, rigid_motion(scene, run.t), draw, "reaction")[0]
    elastic = simulate(scene, "elastic", dt=scene.time_step).displacement
    late = run.t >= 0.1
    scale = np.abs(qs[:, :3]).max()
    assert scale > 0.5e-3                                      # the sag is of the clearance's order
    assert np.abs(run.displacement[0] - qs - elastic)[late, :3].max() < 0.03 * scale
    assert np.abs(run.displacement[0] - qs)[late, :3].max() < 0.05 * scale


@pytest.mark.parametrize("tolerance, refinements", [(0.0, 0), (1e-8, 3)])
def test_contact_batch_equals_one_at_a_time_bit_for_bit(smoke, tolerance, refinements):
    """Also with the adaptive step, where every realisation refines where it needs to."""
    scene = _with(smoke, trajectory=dict(duration=0.03))
    draws = [draw_clearances(scene, 5, r) for r in range(3)]
    batch = simulate_contact(scene, draws, tolerance=tolerance, refinements=refinements)
    assert (batch.refined > 0).all() == (refinements > 0)
    for k, draw in enumerate(draws):
        one = simulate_contact(scene, [draw], tolerance=tolerance, refinements=refinements)
        assert np.array_equal(one.displacement[0], batch.displacement[k])
        assert np.array_equal(one.acceleration[0], batch.acceleration[k])
        assert np.array_equal(one.contact_peak[0], batch.contact_peak[k])
        assert one.steps[0] == batch.steps[k]


def test_chunks_filled_on_demand_give_the_bits_of_chunks_filled_up_front(smoke, monkeypatch):
    """A chunk computes its base steps' interior instants only where a refined step needs them
    (_Chunk.fill, the kernel pausing): the run equals one whose chunks were filled up front, bit for
    bit, with base steps left unfilled, and the same iteration and refinement counts."""
    from rss6core import contact_dynamics
    scene = _with(smoke, trajectory=dict(duration=0.05))
    draws = [draw_clearances(scene, 5, r) for r in range(2)]
    filled = []
    original = contact_dynamics._Chunk.__init__

    def watched(self, *args, **kw):
        original(self, *args, **kw)
        filled.append(self.filled)

    monkeypatch.setattr(contact_dynamics._Chunk, "__init__", watched)
    lazy = simulate_contact(scene, draws, tolerance=1e-8, refinements=3)
    share = np.concatenate(filled).mean()
    assert (lazy.refined > 0).all() and 0 < share < 0.9, share   # the start-up refines most steps

    def eager(self, *args, **kw):
        original(self, *args, **kw)
        self.fill_all()

    monkeypatch.setattr(contact_dynamics._Chunk, "__init__", eager)
    full = simulate_contact(scene, draws, tolerance=1e-8, refinements=3)
    for q in ("displacement", "velocity", "acceleration", "peak", "contact_peak", "steps", "iterations", "refined"):
        assert np.array_equal(getattr(lazy, q), getattr(full, q)), q


def test_adaptive_step_limits_are_the_fixed_steps(smoke):
    """A vanishing tolerance refines every step: the fixed run at the finest step, bit for bit,
    with each coarser level refused once, in the first base step (the step-size memory then keeps
    the finest); a huge one refines none: the fixed run at the base step."""
    scene = _with(smoke, trajectory=dict(duration=0.02))
    draws = [draw_clearances(scene, 1, r) for r in range(2)]
    for adaptive, fixed, substeps in (
            (dict(dt=2e-4, tolerance=1e-30, refinements=2), dict(dt=5e-5, refinements=0), 4),
            (dict(dt=2e-4, tolerance=1.0, refinements=3), dict(dt=2e-4, refinements=0), 1)):
        a, b = simulate_contact(scene, draws, **adaptive), simulate_contact(scene, draws, **fixed)
        for q in ("displacement", "velocity", "acceleration", "peak", "contact_peak"):
            assert np.array_equal(getattr(a, q), getattr(b, q)), q
        assert np.array_equal(a.steps, b.steps)
        assert np.array_equal(a.refined, np.full(2, adaptive["refinements"] if substeps > 1 else 0))


@pytest.mark.parametrize("first, count", [(0, 201), (200, 201), (7, 1), (399, 2)])
def test_an_instants_chunk_data_do_not_depend_on_the_chunk(smoke, first, count):
    """Loads, frames and maps at an instant are the same bits whether computed in a chunk of 1, 2,
    201 or 801 instants, at any place in it: a refined run's chunks hold 2^refinements times more
    instants than the fixed run's at its finest step (BLAS's edge kernels sum a row of one long
    product differently with its place and the rows' number; more so under OPENBLAS_CORETYPE=Haswell)."""
    from rss6core.contact_dynamics import _Chunk, build_joint_model
    jm, h = build_joint_model(smoke, 4), 5e-5
    whole = _Chunk(smoke, jm, np.arange(801) * h)
    part = _Chunk(smoke, jm, (first + np.arange(count)) * h)
    for name in ("F", "Mp", "Rc", "J", "Rr", "omega", "t"):
        assert np.array_equal(getattr(whole, name)[first:first + count], getattr(part, name)), name


@pytest.mark.parametrize("level, estimate, expected", [
    (3, 1e-8 / 64, 1), (3, 1e-8 / 63, 2), (3, 1e-8 / 8, 2), (3, 1e-8 / 7.9, 3), (3, 0.0, 0),
    (0, 0.0, 0), (2, 2e-8, 2), (4, 1e-8 / 8 ** 4, 0), (4, np.nan, 4), (2, np.inf, 2)])
def test_step_size_memory_takes_the_coarsest_level_its_h3_prediction_allows(level, estimate, expected):
    """After an accepted step of ``level`` with local error estimate e, a step 2^j times longer is
    predicted at e 8^j (the estimate grows as h^3 where the acceleration is smooth); the next
    step may take the coarsest level whose prediction stays within the tolerance (1e-8 m)."""
    assert coarsest_next(level, estimate, 1e-8) == expected


def test_adaptive_step_converges_where_the_fixed_base_step_does_not(smoke):
    """Start-up impacts (all of a 0.03 s run): error peaks against a fixed 6.25 us run.  The base
    0.2 ms step misses the acceleration peaks by tens of percent; the adaptive step at 1e-8 m
    (down to 12.5 us) is within 2 %, and a tenfold tighter tolerance (down to 6.25 us) shrinks
    that error at least fivefold."""
    scene = _with(smoke, trajectory=dict(duration=0.03))
    draws = [draw_clearances(scene, 1, r) for r in range(2)]
    ref = simulate_contact(scene, draws, dt=6.25e-6, refinements=0)

    def error(**kw):
        run = simulate_contact(scene, draws, **kw)
        assert run.status == ["finished"] * 2
        whole, whole_ref = run.peak.max(1), ref.peak.max(1)        # over both windows
        return (np.abs(whole - whole_ref).max((0, 2)) / np.abs(whole_ref).max((0, 2)))[2], run

    base, _ = error(dt=2e-4, refinements=0)
    loose, run = error(dt=2e-4, tolerance=1e-8, refinements=4)
    tight, _ = error(dt=2e-4, tolerance=1e-9, refinements=5)
    assert base > 0.2
    assert loose < 0.02
    assert tight < loose / 5
    assert np.all(run.steps < 0.5 * 0.03 / 12.5e-6)   # it refined only where it had to


@pytest.mark.parametrize("stepper", [CompiledStepper, NumpyStepper], ids=["compiled", "numpy"])
def test_refinement_rescues_a_step_where_newton_fails(smoke, stepper):
    """1 ms is beyond Newton's reach at the smoke scene's start-up; with refinements allowed the
    failing steps are retried as halves, and the run, mostly at 1 ms, is no further from a fine
    fixed-step run than the fixed 0.5 ms run (twice the steps) is.  Newton's extrapolated first
    iterate, retried from the last accelerations where it fails, must not cost steps here: without
    that retry the rescue took 34 steps and the fixed 0.5 ms run failed."""
    scene = _with(smoke, trajectory=dict(duration=0.02))
    draws = [draw_clearances(scene, 1, r) for r in range(2)]
    fixed = simulate_contact(scene, draws, dt=1e-3, refinements=0, stepper=stepper)
    assert fixed.status == ["failed"] * 2 and "Newton" in fixed.message[0]
    rescued = simulate_contact(scene, draws, dt=1e-3, tolerance=0.0, refinements=3, stepper=stepper)
    assert rescued.status == ["finished"] * 2 and np.all(rescued.refined > 0)
    assert np.all(rescued.steps < 1.5 * 0.02 / 1e-3)
    fine = simulate_contact(scene, draws, dt=1.25e-4, refinements=0, stepper=stepper)
    half = simulate_contact(scene, draws, dt=5e-4, refinements=0, stepper=stepper)
    assert half.status == ["finished"] * 2
    assert (np.abs(rescued.displacement - fine.displacement)[..., :3].max()
            < np.abs(half.displacement - fine.displacement)[..., :3].max())


@pytest.mark.parametrize("integrator, adaptive", [("generalized-alpha", {}),
                                                   ("newmark", dict(tolerance=1e-8, refinements=3))])
def test_compiled_and_numpy_contact_engines_agree(smoke, integrator, adaptive):
    """The compiled steps (contact_stepper, contact_kernel: BLAS products, a block-tridiagonal
    elimination per leg) against the numpy ones (vectorised over the batch, dense solves): the
    same arithmetic in another order, so equal to round-off (1e-9 of each history's largest value)
    with Newton iteration counts within 0.5 % and the same adaptive steps, on a run whose joints are
    in contact and sliding; with the alpha-weighted integrator at a fixed step and with Newmark
    (no weighted terms) refining its step."""
    from rss6core.integrators import make_integrator
    scene = _with(smoke, trajectory=dict(duration=0.02))
    draws = [draw_clearances(scene, 2, r) for r in range(2)]
    method = make_integrator(integrator)
    compiled = simulate_contact(scene, draws, integrator=method, **adaptive)
    reference = simulate_contact(scene, draws, integrator=method, stepper=NumpyStepper, **adaptive)
    assert compiled.status == reference.status == ["finished"] * 2
    # Newton's first iterate is extrapolated from three accelerations, which the compiled code
    # (fused multiply-adds) and numpy round differently; where the stopping test is that close, one
    # engine takes one more update: counts agree to 0.5 %, steps exactly
    np.testing.assert_allclose(compiled.iterations, reference.iterations, rtol=5e-3)
    assert np.array_equal(compiled.steps, reference.steps)
    assert np.array_equal(compiled.refined, reference.refined)
    assert np.all(compiled.refined > 0) == bool(adaptive)
    assert np.all(reference.contact_peak > 0)
    for q in ("displacement", "velocity", "acceleration", "peak", "contact_peak"):
        a, b = getattr(compiled, q), getattr(reference, q)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * np.abs(b).max())
    with pytest.raises(ValueError, match="contact stepper must be a ContactStepper class"):
        simulate_contact(scene, draws, stepper="fortran")


@pytest.mark.parametrize("stepper", [CompiledStepper, NumpyStepper], ids=["compiled", "numpy"])
def test_a_diverging_realisation_is_stopped_and_reported(smoke, stepper):
    """A displacement beyond the divergence limit ends the realisation at that step, with a message
    naming the time, the size and the limit; its history stops there, and nothing is kept after."""
    scene = _with(smoke, trajectory=dict(duration=0.01))
    draws = [draw_clearances(scene, 0, r) for r in range(2)]
    run = simulate_contact(scene, draws, divergence_limit=1e-9, stepper=stepper)
    assert run.status == ["failed"] * 2
    assert all(m.startswith("displacement ") and "exceeds the 1e-09 m divergence limit" in m
               and m.endswith("at t = 0.0001 s, step 1, with a 0.0001 s step") for m in run.message)
    assert np.all(run.steps == 0)
    assert np.all(np.isfinite(run.displacement[:, 0])) and np.all(np.isnan(run.displacement[:, 1:]))


@pytest.mark.parametrize("model", ["paper", "contact", "quasi-static"])
def test_results_carry_the_draw_an_ensemble_file_records(smoke, model):
    """The clearance levels hand back each realisation's draw (the paper level: its sizes and
    first-step eccentricities), so that an ensemble chunk need not redraw it: the same as drawing
    it again, per realisation."""
    from rss6core.levels import default_time_step
    from rss6core.models import stored_draw
    scene = _with(smoke, trajectory=dict(duration=0.05))
    results = simulate_batch(scene, model, seed=5, realizations=[2, 7])
    for r, result in zip((2, 7), results):
        again = stored_draw(scene, model, 5, r, default_time_step(scene, model))
        for field in dataclasses.fields(again):
            assert np.array_equal(getattr(result.draw, field.name), getattr(again, field.name))
        # own copies: a view of the first step would keep every step's draw alive with the result
        assert all(getattr(result.draw, e).base is None for e in ("e_A", "e_C", "e_B"))
    assert not np.array_equal(results[0].draw.e_C, results[1].draw.e_C)


@pytest.mark.parametrize("model", ["paper", "contact", "quasi-static"])
def test_same_seed_and_realization_give_identical_output(smoke, model):
    scene = _with(smoke, trajectory=dict(duration=0.05))
    a, b = (simulate_batch(scene, model, seed=11, realizations=[2])[0] for _ in range(2))
    for q in ("displacement", "velocity", "acceleration"):
        assert np.array_equal(getattr(a, q), getattr(b, q))
    other = simulate_batch(scene, model, seed=11, realizations=[3])[0]
    assert not np.array_equal(a.displacement, other.displacement)


def test_contact_level_refuses_zero_clearance(smoke):
    s = _with(smoke, clearance=dict(spherical_B=0.0))
    with pytest.raises(ValueError, match="spherical_B_m"):
        simulate(s, "contact")


def test_a_newton_failure_is_reported_and_the_batch_returns(smoke, monkeypatch):
    import rss6core.contact_dynamics as cd
    scene = _with(smoke, trajectory=dict(duration=0.05))
    monkeypatch.setattr(cd, "MAX_ITERATIONS", 0)       # no Newton update: no step converges
    run = simulate_contact(scene, [draw_clearances(scene, 0, r) for r in range(2)])
    assert run.status == ["failed", "failed"]
    assert all("Newton" in m and "t = 0.0001 s, step 1, with a 0.0001 s step" in m for m in run.message)
    assert np.all(np.isnan(run.displacement[:, 1:]))


def test_force_balance_carried_by_the_step_equation_equals_the_forces_recomputed():
    """Generalized-alpha on a damped oscillator m a + c v + k d = F(t) (three uncoupled DOFs, a
    load that changes each step): the balance F + g - (c v + k d) that the contact steps carry from
    one step to the next (:func:`balance_next`, from M a alone) equals the one recomputed from the
    state, to round-off, over 200 steps of mixed size."""
    method = Integrator.generalized_alpha(0.8)
    am, af = method.alpha_m, method.alpha_f
    m, c, k = np.array([1.0, 2.0, 0.5]), np.array([0.3, 0.0, 1.5]), np.array([40.0, 900.0, 5.0])
    load = lambda t: np.array([np.sin(3 * t), 1.0 + t, np.cos(17 * t)])   # noqa: E731
    t, d, v = 0.0, np.array([0.01, -0.02, 0.0]), np.array([0.0, 0.1, -0.3])
    a = (load(t) - c * v - k * d) / m
    balance = load(t) - c * v - k * d
    rng = np.random.default_rng(3)
    for _ in range(200):
        w = method.weights(float(rng.choice([1e-3, 5e-4, 2.5e-4])))
        dp, vp = predict(d, v, a, w.h, w.d_pred, w.v_pred)
        rhs = (1 - af) * (load(t + w.h) - c * vp - k * dp) + af * balance - am * m * a
        a_new = rhs / ((1 - am) * m + (1 - af) * (c * w.v_corr + k * w.d_corr))
        d, v = correct(dp, vp, a_new, w.d_corr, w.v_corr)
        balance = balance_next(m * a_new, m * a, balance, am, af)
        a, t = a_new, t + w.h
        direct = load(t) - c * v - k * d
        assert np.allclose(balance, direct, rtol=1e-9, atol=1e-12 * np.abs(load(t)).max())
