"""The contact level's crank driven through a compliant motor (build_joint_model's motor_stiffness, issue 43
candidate 3): the option off changes nothing; on, the crank's root spring against the Euler-Bernoulli closed
form, its stiff limit against the clamped crank, and the feed-forward torque against the rigid robot's."""
import dataclasses
import re

import numpy as np
import pytest
from scipy.linalg import eigh
from scipy.optimize import brentq

from rss6core.assembly import scene_link_matrices, split
from rss6core.contact_dynamics import _Chunk, _crank_keep, build_joint_model
from rss6core.dynamics import inverse_dynamics
from rss6core.kinematics import crank_axes, rigid_motion
from rss6core.sections import crank_inertia, section_properties


def spring_root_lambda(kappa: float) -> float:
    """The lowest beta L of a uniform Euler-Bernoulli cantilever whose root rotation is held by a
    torsional spring, kappa = k_m L / (E I), tip free: the lowest positive root of
    kappa (1 + cos l cosh l) = l (sin l cosh l - cos l sinh l)
    (w = c1 cos + c2 sin + c3 cosh + c4 sinh of beta x; w(0) = 0, E I w''(0) = k_m w'(0),
    w''(L) = w'''(L) = 0; the 3x3 determinant in c2, c4, c3 gives the equation).  It lies in
    (0, 1.8751): l^4 -> 3 kappa as kappa -> 0 (the rigid crank on the spring), the clamped root as
    kappa -> inf."""
    def f(lam):   # the equation over kappa: decreasing on (0, 1.88), +2 at 0, negative at 1.88
        return 1 + np.cos(lam) * np.cosh(lam) - lam / kappa * (np.sin(lam) * np.cosh(lam) - np.cos(lam) * np.sinh(lam))
    return brentq(f, 1e-8, 1.88, xtol=1e-15)


def _crank_frequencies(jm) -> np.ndarray:
    """The crank alone, node 0's translations clamped (the journal held in its bearing): its natural
    angular frequencies (rad/s), lowest first."""
    free = np.arange(3, jm.crank_dofs)
    return np.sqrt(eigh(jm.crank_K[np.ix_(free, free)], jm.crank_M[np.ix_(free, free)], eigvals_only=True))


def test_the_closed_form_equation_has_its_limits():
    """kappa -> inf: 1 + cos cosh = 0, the clamped-free root 1.8751; kappa -> 0: the rigid crank on
    its spring, lambda^4 = 3 kappa (the pinned-free equation's lambda = 0 root), and the pinned-free
    first elastic root 3.9266 of tan = tanh is the equation's root at kappa = 0 above 1.8751."""
    assert spring_root_lambda(1e12) == pytest.approx(1.8751040687, rel=1e-9)
    assert spring_root_lambda(1e-8) ** 4 == pytest.approx(3e-8, rel=1e-6)
    pinned = brentq(lambda lam: np.sin(lam) * np.cosh(lam) - np.cos(lam) * np.sinh(lam), 3.0, 4.5)
    assert pinned == pytest.approx(3.9266023120, rel=1e-9)


def test_the_option_off_gives_todays_matrices_and_loads_bit_for_bit(paper):
    """No motor: the crank matrices are today's (node 0's rotations dropped), the boundary is today's
    and the chunk's loads are the crank's rigid loads on nodes 0 (translations) and 1..n."""
    jm = build_joint_model(paper, 4)
    Kc, Mc = scene_link_matrices(paper, "crank", 4)
    today = np.r_[0:3, 6:30]
    assert np.array_equal(jm.crank_K, Kc[np.ix_(today, today)])
    assert np.array_equal(jm.crank_M, Mc[np.ix_(today, today)])
    assert np.array_equal(jm.crank_boundary, np.r_[0:3, 21:24])
    assert jm.motor_stiffness is None and jm.motor_dof is None
    ch = _Chunk(paper, jm, np.linspace(0.1, 0.3, 3))
    from rss6core.assembly import link_frames, link_loads
    from rss6core.dynamics import platform_inertia_world
    motion = rigid_motion(paper, ch.t)
    Rc, Rr = link_frames(motion, paper.geometry)
    fc = link_loads(jm.elastic, motion, paper, Rc, Rr, platform_inertia_world(jm.platform_inertia,
                                                                              motion.platform.R))[0]
    crank = split(jm, ch.F)[0]
    assert np.array_equal(crank[..., :3], fc[..., :3]) and np.array_equal(crank[..., 3:], fc[..., 6:])


def test_the_motor_keeps_node_0s_rotation_about_w_with_its_spring(paper):
    """With k_m the crank gains node 0's r_y (index 3) whose stiffness is the beam's plus k_m and whose
    mass row is the beam's; every other entry and the boundary's nodal DOFs are those of the clamped crank."""
    k = 1e4
    jm = build_joint_model(paper, 4, motor_stiffness=k)
    Kc, Mc = scene_link_matrices(paper, "crank", 4)
    keep = _crank_keep(4, True)
    assert jm.crank_dofs == 28 and list(keep[:5]) == [0, 1, 2, 4, 6]
    spring = np.zeros((28, 28))
    spring[3, 3] = k
    assert np.array_equal(jm.crank_K, Kc[np.ix_(keep, keep)] + spring)
    assert np.array_equal(jm.crank_M, Mc[np.ix_(keep, keep)])
    assert list(keep[jm.crank_boundary]) == [0, 1, 2, 24, 25, 26]   # node 0 and node 4 translations


@pytest.mark.parametrize("k_m", [1e2, 1e3, 1e4, 1e5, 1e6])
def test_the_crank_on_its_motor_spring_matches_the_euler_bernoulli_closed_form(paper, k_m):
    """The lowest frequency of the crank (node 0's translations and tilts clamped, spring k_m about the
    motor axis y, tip free) is the closed form's, beam bending in the x-z plane (u_z, r_y: section
    inertia I_y about the crank's y axis) on the scene's 4 elements: kappa from 0.12 to 1160."""
    jm = build_joint_model(paper, 4, motor_stiffness=k_m)
    sec, mat, L = section_properties(paper.crank_section), paper.material, paper.geometry.crank_length
    EI, rhoA = mat.youngs_modulus * sec.Iy, mat.density * sec.area
    lam = spring_root_lambda(k_m * L / EI)
    want = lam ** 2 / L ** 2 * np.sqrt(EI / rhoA)
    assert _crank_frequencies(jm)[0] == pytest.approx(want, rel=1e-4)


def test_a_very_stiff_motor_is_the_clamped_crank(paper):
    """k_m = 1e10 N m/rad (1e5 times the root's bending stiffness 4 E I / l) gives the clamped crank's
    six lowest frequencies within 1e-3 (the released DOF's own mode goes to sqrt(k_m / J) ~ 1e6 rad/s)."""
    clamped = _crank_frequencies(build_joint_model(paper, 4))[:6]
    stiff = _crank_frequencies(build_joint_model(paper, 4, motor_stiffness=1e10))[:6]
    np.testing.assert_allclose(stiff, clamped, rtol=1e-3)
    assert not np.allclose(_crank_frequencies(build_joint_model(paper, 4, motor_stiffness=1e5))[:6], clamped,
                           rtol=1e-3)


def test_the_feed_forward_balances_the_rigid_crank(paper):
    """Along the rigid motion the released DOF's loads, over the crank's rigid rotation about w at A
    (u_z = -x theta, r_y = theta at every node), plus the moment of the rigid robot's force of the rod
    at C, leave (J_A - J_FE) alpha_w'': the beam's consistent mass carries no section rotary inertia,
    the rigid crank's J_A has m h^2 / 12 more (sections.crank_inertia).  So the feed-forward is the
    rigid robot's actuator torque, with its sign: the spring then carries only the dynamic deviation."""
    jm = build_joint_model(paper, 4, motor_stiffness=1e4)
    t = np.linspace(0.05, 1.95, 7)
    ch = _Chunk(paper, jm, t)
    n, L = jm.elements, paper.geometry.crank_length
    phi = np.zeros(6 * (n + 1))
    phi[2::6], phi[4::6] = -np.linspace(0, L, n + 1), 1.0
    rotation = (split(jm, ch.F)[0] * phi[jm.crank_keep]).sum(-1)            # (T, 6), N m about w
    motion = rigid_motion(paper, t)
    w, arm = paper.geometry.w, motion.c - paper.geometry.a
    rod = (w * np.cross(arm, -inverse_dynamics(paper, motion).force_C)).sum(-1)   # the rod on the crank at C
    alpha_w = motion.alpha_ddot * (crank_axes(paper.geometry) * w).sum(-1)     # rad/s^2 about w
    crank = crank_inertia(paper)
    want = crank.mass * paper.crank_section.height ** 2 / 12 * alpha_w
    scale = np.abs(rod).max()
    np.testing.assert_allclose(rotation + rod, want, rtol=0, atol=1e-9 * scale)
    assert np.abs(want).max() > 1e-6 * scale


def test_a_motor_on_a_craig_bampton_crank_is_refused(paper):
    scene = dataclasses.replace(paper, beam=dataclasses.replace(paper.beam, link_modes=2))
    with pytest.raises(ValueError, match="link_modes"):
        build_joint_model(scene, 4, motor_stiffness=1e4)
    with pytest.raises(ValueError, match="> 0"):
        build_joint_model(paper, 4, motor_stiffness=0.0)


SERVO = '\n[actuator]\ndrive = "servo"\nservo_stiffness_N_m_per_rad = 1.0e4\n'


@pytest.mark.parametrize("table, key", [
    ('[actuator]\ndrive = "servo"\n', "servo_stiffness_N_m_per_rad: a servo drive needs a positive"),
    ("[actuator]\nservo_stiffness_N_m_per_rad = 1.0e4\n", "servo_stiffness_N_m_per_rad: only with drive = 'servo'"),
    ('[actuator]\ndrive = "sevro"\n', "drive: 'sevro' is not one of"),
    ("[actuator]\nservo_stifness_N_m_per_rad = 1.0\n", "did you mean 'servo_stiffness_N_m_per_rad'"),
    (SERVO + "[beam]\nlink_modes = 4\n", "drive: 'servo' needs the full mesh"),
])
def test_an_actuator_table_mistake_is_one_line_naming_the_key(paper_text, table, key):
    from rss6core import SceneError, parse_scene
    with pytest.raises(SceneError, match=re.escape(key)) as caught:
        parse_scene(paper_text + "\n" + table)
    assert "[actuator]" in str(caught.value) and "\n" not in str(caught.value)


def test_a_servo_scene_runs_the_compliant_motor_at_the_contact_level(smoke, configs):
    """`[actuator] drive = "servo"` gives the contact level exactly build_joint_model's motor option
    (the product's path: prepare_level, the scene's start), and differs from the prescribed crank;
    the paper's scenes (no [actuator] table) keep the prescribed one."""
    from rss6core import parse_scene, prepare_level
    from rss6core.clearance import draw_clearances
    from rss6core.contact_dynamics import simulate_contact
    from rss6core.contact_start import contact_initial_state
    servo = parse_scene((configs / "smoke.toml").read_text() + SERVO)
    assert smoke.actuator.motor_stiffness is None and servo.actuator.motor_stiffness == 1.0e4
    level = prepare_level(servo, "contact")
    got = level.simulate(0, [0], None)[0]
    draws = [draw_clearances(smoke, 0, 0)]
    explicit = simulate_contact(smoke, draws, level.elements, level.integrator, level.dt, tolerance=level.tolerance,
                                refinements=level.refinements, initial=contact_initial_state,
                                model=build_joint_model(smoke, level.elements, motor_stiffness=1.0e4)).result(0)
    np.testing.assert_array_equal(got.acceleration, explicit.acceleration)
    prescribed = prepare_level(smoke, "contact").simulate(0, [0], None)[0]
    assert not np.allclose(got.acceleration, prescribed.acceleration, rtol=1e-3, atol=0)


def test_tradeoff_leaves_out_the_reduced_link_rows_of_a_servo_scene(configs):
    """`rss6 tradeoff`'s Craig-Bampton rows need the clamped journal; a servo scene gets none (its
    contact level would refuse the reduced crank), the prescribed scene gets them."""
    from pipeline.studies.tradeoff import _reduced_settings
    from rss6core import parse_scene
    text = (configs / "paper.toml").read_text()
    row = lambda model, **kw: (model, kw)   # noqa: E731
    assert _reduced_settings(parse_scene(text), row, 1e-8, 4)
    assert _reduced_settings(parse_scene(text + SERVO), row, 1e-8, 4) == []


def test_rss6_check_names_the_drive_and_the_crank_on_its_motor(configs, capsys):
    """`rss6 check` says how the cranks are driven; for a servo, the rigid crank's frequency on it,
    sqrt(k_m / J_A) / 2 pi with J_A = m (L^2 / 3 + h^2 / 12) about the motor axis at A."""
    from pipeline.cli import main
    from rss6core import parse_scene
    scene = parse_scene((configs / "paper.toml").read_text() + SERVO)
    c, L = scene.crank_section, scene.geometry.crank_length
    m = scene.material.density * c.axial_width * c.height * L
    f = np.sqrt(1.0e4 / (m * (L ** 2 / 3 + c.height ** 2 / 12))) / (2 * np.pi)
    assert main(["check", str(configs / "paper.toml")]) == 0
    assert "actuator: prescribed" in capsys.readouterr().out
    from pipeline.analysis.summary import actuator_summary
    assert actuator_summary(scene)["crank_on_motor_Hz"] == pytest.approx(f, rel=1e-12)
