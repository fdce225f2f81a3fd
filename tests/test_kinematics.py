"""Ideal kinematics against independent computations: FK(IK), finite differences."""
import numpy as np
import pytest

from rss6core.kinematics import forward_kinematics, inverse_kinematics, platform_joints, rigid_motion
from rss6core.trajectory import platform_motion, rotation


def _rx(a):
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def _ry(a):
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def _rz(a):
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def test_rotation_is_rz_ry_rx():
    rng = np.random.default_rng(1)
    n = rng.uniform(-1, 1, (20, 3))
    expected = np.stack([_rz(c) @ _ry(b) @ _rx(a) for a, b, c in n])
    assert np.abs(rotation(n) - expected).max() < 1e-15


def test_home_crank_angles(paper):
    m = rigid_motion(paper, np.array([0.0]))
    assert np.degrees(m.alpha[0]) == pytest.approx([-5.02] * 6, abs=0.01)


def test_ik_closes_every_leg(paper):
    m = rigid_motion(paper)
    assert np.abs(np.linalg.norm(m.c - m.b, axis=-1) - paper.geometry.rod_length).max() < 1e-14


def test_fk_inverts_ik_along_the_trajectory(paper):
    m = rigid_motion(paper)
    # start Newton from a pose 5 mm and 2 deg away from the truth
    guess = m.platform.pose + np.r_[5e-3, -5e-3, 5e-3, np.radians([2, -2, 2])]
    pose, iterations = forward_kinematics(paper.geometry, m.alpha, guess)
    err = pose - m.platform.pose
    assert np.abs(err[:, :3]).max() < 1e-9 and np.abs(err[:, 3:]).max() < 1e-9
    assert iterations < 10


def _central(f, t, h):
    return (f(t + h) - f(t - h)) / (2 * h)


def test_angular_velocity_and_acceleration_match_rotation_derivatives(paper):
    t, h = np.linspace(0, 2, 37), 1e-5
    R = lambda s: platform_motion(paper.trajectory, s).R  # noqa: E731
    m = platform_motion(paper.trajectory, t)
    Rdot = _central(R, t, h)
    skew = np.einsum("tij,tkj->tik", Rdot, m.R)  # R' R^T = [omega]x
    omega_fd = np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], -1)
    assert np.abs(omega_fd - m.omega).max() < 1e-8 * np.abs(m.omega).max()
    wd_fd = _central(lambda s: platform_motion(paper.trajectory, s).omega, t, h)
    assert np.abs(wd_fd - m.omega_dot).max() < 1e-7 * np.abs(m.omega_dot).max()


def test_jacobian_matches_finite_differences(paper):
    """d alpha = J [d o, d theta]: perturb the pose along each twist direction."""
    m = rigid_motion(paper, np.linspace(0, 2, 9))
    geo, h = paper.geometry, 1e-6
    for k in range(6):
        dt = np.zeros(6)
        dt[k] = h

        def alpha(sign, dt=dt):
            o = m.platform.o + sign * dt[:3]
            rot = np.einsum("ij,tjk->tik", _axis_angle(sign * dt[3:]), m.platform.R)
            return inverse_kinematics(geo, platform_joints(geo, o, rot)[0])
        fd = (alpha(1) - alpha(-1)) / (2 * h)
        assert np.abs(fd - m.jacobian[:, :, k]).max() < 1e-7 * np.abs(m.jacobian).max()


def _axis_angle(v):
    ang = np.linalg.norm(v)
    if ang == 0:
        return np.eye(3)
    k = v / ang
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(ang) * K + (1 - np.cos(ang)) * K @ K


def test_crank_rates_and_accelerations_match_finite_differences(paper):
    t, h = np.linspace(0.01, 1.99, 41), 1e-5
    m = rigid_motion(paper, t)
    alpha = lambda s: rigid_motion(paper, s).alpha  # noqa: E731
    rate = lambda s: rigid_motion(paper, s).alpha_dot  # noqa: E731
    assert np.abs(_central(alpha, t, h) - m.alpha_dot).max() < 1e-8 * np.abs(m.alpha_dot).max()
    assert np.abs(_central(rate, t, h) - m.alpha_ddot).max() < 1e-7 * np.abs(m.alpha_ddot).max()
    cdot = lambda s: rigid_motion(paper, s).c_dot  # noqa: E731
    assert np.abs(_central(cdot, t, h) - m.c_ddot).max() < 1e-7 * np.abs(m.c_ddot).max()


def _static(paper_text, z=-0.387, **geometry):
    """The paper scene held still at height z (m), with geometry keys replaced."""
    text = paper_text.replace("position_amplitude_m = [0.0, 0.050, 0.080]",
                              "position_amplitude_m = [0.0, 0.0, 0.0]")
    text = text.replace("angle_amplitude_deg = [20.0, 20.0, 0.0]", "angle_amplitude_deg = [0.0, 0.0, 0.0]")
    text = text.replace("position_offset_m = [0.0, 0.0, -0.387]", f"position_offset_m = [0.0, 0.0, {z!r}]")
    for key, (old, new) in geometry.items():
        assert f"{key} = {old}" in text, key
        text = text.replace(f"{key} = {old}", f"{key} = {new}")
    return text


def test_check_workspace_names_a_leg_at_its_crank_rod_singularity(paper, paper_text):
    """Lowered until crank and rod line up (|K/rho| = 1 - 1e-10, just inside reach): the
    transmission n . dc vanishes and the scene is refused; at |K/rho| = 0.99 it is accepted."""
    from scipy.optimize import brentq

    from rss6core import SceneError, parse_scene
    from rss6core.kinematics import _reach

    def reach(z):
        b, _ = platform_joints(paper.geometry, np.array([[0.0, 0.0, z]]), np.eye(3)[None])
        return np.abs(_reach(paper.geometry, b)[2]).max()
    z_near = brentq(lambda z: reach(z) - 0.99, -0.72, -0.6)
    z_sing = brentq(lambda z: reach(z) - (1 - 1e-10), z_near, -0.75, xtol=1e-15)
    parse_scene(_static(paper_text, z_near))
    with pytest.raises(SceneError, match=r"workspace: leg \d is at its crank-rod singularity "
                                         r"at t = 0\.0000 s"):
        parse_scene(_static(paper_text, z_sing))


def test_check_workspace_refuses_a_singular_and_an_ill_conditioned_platform(paper_text):
    """All six rods meeting in one platform point cannot resist a moment about it (singular);
    shrinking the platform radius to r scales the moment rows by r: condition ~ 1/r, refused
    above 1e8 (r = 1 nm), accepted at r = 0.1 um (condition ~ 1e7)."""
    from rss6core import SceneError, parse_scene
    one_point = {"platform_angles_deg": ("[-80.0, 80.0, 40.0, 200.0, 160.0, 320.0]",
                                         "[0.0, 0.0, 0.0, 0.0, 0.0, 0.0]")}
    with pytest.raises(SceneError, match=r"the platform is singular \(condition number \d\.\d+e\+(\d\d)\)"):
        parse_scene(_static(paper_text, **one_point))
    tiny = {"platform_radius_m": ("0.064", "1e-9")}
    with pytest.raises(SceneError, match=r"platform is singular \(condition number 1\.\d+e\+09\) at t = 0"):
        parse_scene(_static(paper_text, **tiny))
    parse_scene(_static(paper_text, platform_radius_m=("0.064", "1e-7")))
