"""The formulas of issue 43's candidate switches (benchmarks/acceleration_candidates.py) against closed forms:
the friction moment's power, a rod's spin-up under one slipping joint, and its spin where two joints' moments
balance."""
from pathlib import Path

import numpy as np
import pytest

from rss6core import load_scene

from .conftest import load_benchmark

@pytest.fixture(scope="module")
def candidates():
    return load_benchmark("acceleration_candidates")


@pytest.fixture(scope="module")
def contact():
    return load_scene(Path(__file__).resolve().parents[1] / "configs" / "paper.toml").contact


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_the_friction_moment_carries_the_friction_power_of_the_relative_rotation(candidates, contact):
    """f_t . (de + R omega x n) = f_t . de + omega . m for the friction of eq. 18, and it dissipates."""
    rng = np.random.default_rng(3)
    n, de, omega = _unit(rng.normal(size=(50, 3))), 1e-3 * rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    radius, force = 0.01, rng.uniform(1.0, 20.0, 50)
    f_t = candidates.friction(contact, n, force, de, omega, radius)
    pair = f_t - force[:, None] * n                   # normal part plus friction, on the + element
    m = candidates.friction_moment(radius, n, pair)
    sliding = de + radius * np.cross(omega, n)
    power = (f_t * sliding).sum(-1)
    assert np.allclose(power, (f_t * de).sum(-1) + (omega * m).sum(-1), rtol=1e-12, atol=1e-15)
    assert (power <= 0).all() and (power < 0).any()


def _one_rod(force_c, force_b, w_c, w_b):
    """Rod along z, joint C's normal along x and B's along y, relative rotations about the axis (6 legs alike)."""
    axis = np.tile([0.0, 0.0, 1.0], (6, 1))
    normal = np.tile(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), (6, 1, 1))
    omega = np.tile(np.array([[0.0, 0.0, w_c], [0.0, 0.0, w_b]]), (6, 1, 1))
    return dict(normal=normal, force=np.tile([force_c, force_b], (6, 1)), de=np.zeros((6, 2, 3)), omega=omega,
                axis=axis)


def test_a_rod_slipping_in_one_joint_spins_up_at_mu_f_r_over_j(candidates, contact):
    """Full slip at C only (R w = 5 v1): backward Euler gives J (s - 0) / h = -mu F R exactly; then, in
    eq. 18's ramp (time constant J (v1 - v0) / (mu F R^2), 4.6 ms here), the slip decays to v0."""
    radius, J, h, F, w = 0.01, 5.1e-5, 2e-4, 11.0, 5.0
    s = candidates.spin_step(contact, np.zeros(6), h, J, radius=radius, **_one_rod(F, 0.0, w, 0.0))
    expected = -h * contact.friction_coefficient * F * radius / J
    assert np.allclose(s, expected, rtol=1e-10)
    for _ in range(600):       # 0.12 s: spin-up in 23 ms, then 20 time constants in the ramp
        s = candidates.spin_step(contact, s, h, J, radius=radius, **_one_rod(F, 0.0, w, 0.0))
    assert np.all(radius * np.abs(w + s) <= contact.stick_velocity * 1.001)


def test_without_inertia_a_rod_turns_with_the_joint_that_holds_it_harder(candidates, contact):
    """J = 0, F_C > F_B, both relative rotations large: B slips fully, so C's ramp factor is F_B / F_C and
    R |w_C + s| = v0 + (v1 - v0) F_B / F_C (eq. 18), closed form."""
    radius, F_c, F_b, w_c, w_b = 0.01, 12.0, 5.0, 3.0, -40.0
    s = candidates.spin_step(contact, np.zeros(6), 2e-4, 0.0, radius=radius, **_one_rod(F_c, F_b, w_c, w_b))
    v0, v1 = contact.stick_velocity, contact.slip_velocity
    expected = -w_c + (v0 + (v1 - v0) * F_b / F_c) / radius   # B's friction (w_B < 0) pushes the rod along +axis
    assert np.allclose(s, expected, rtol=1e-9)


def test_the_journal_friction_torque_is_mu_f_r_against_the_turn(candidates, contact):
    """A journal turning at s w in its bearing (radial normal n normal to w, sliding at R s w x n, past
    eq. 18's ramp) with normal force F and an axial face force along w: the moment about w is
    -mu F R sign(s), the friction's power s w . m = f_t . (R s w x n), and the normal and axial forces
    add nothing."""
    rng = np.random.default_rng(5)
    w = _unit(rng.normal(size=(40, 3)))
    n = _unit(np.cross(w, rng.normal(size=(40, 3))))
    s, force, radius = rng.choice([-1, 1], 40) * rng.uniform(2.0, 5.0, 40), rng.uniform(1.0, 20.0, 40), 0.01
    f_t = candidates.friction(contact, n, force, np.zeros((40, 3)), s[:, None] * w, radius)
    pair = f_t - force[:, None] * n + rng.normal(size=(40, 1)) * w
    torque = candidates.journal_friction_torque(radius, n, pair, w)
    np.testing.assert_allclose(torque, -contact.friction_coefficient * force * radius * np.sign(s), rtol=1e-12)
    np.testing.assert_allclose(torque * s, (f_t * np.cross(radius * s[:, None] * w, n)).sum(-1), rtol=1e-12)


def test_the_link_frames_rates_are_the_cranks_angular_velocity(candidates):
    """frame_rates' Om = R^T R' of the crank frames is the skew matrix of R^T (alpha' e), the crank's angular
    velocity in its own axes (kinematics, closed form), to 1e-6 of its size (central differences over 0.1 ms),
    and skew to the same accuracy, at three instants of the paper scene."""
    from rss6core.assembly import link_frames
    from rss6core.kinematics import crank_axes
    from rss6core.realised import ReferenceMotion

    scene = load_scene(Path(__file__).resolve().parents[1] / "configs" / "paper.toml")
    reference = ReferenceMotion(scene)
    for t in (0.2, 0.8, 1.7):
        Om, _ = candidates.frame_rates(reference, scene.geometry, t)
        motion = reference.at(np.array([t])).motion
        crank = link_frames(motion, scene.geometry)[0][0]
        expected = np.einsum("lji,lj->li", crank, motion.alpha_dot[0, :, None] * crank_axes(scene.geometry))
        vector = np.stack([Om[0][:, 2, 1], Om[0][:, 0, 2], Om[0][:, 1, 0]], -1)
        size = np.abs(expected).max()
        assert np.abs(vector - expected).max() < 1e-6 * size
        assert np.abs(Om + np.swapaxes(Om, -1, -2)).max() < 1e-6 * size
