"""Rigid inverse dynamics against conservation laws and closed forms."""
import dataclasses

import numpy as np
import pytest

from rss6core.dynamics import inverse_dynamics, mechanical_energy
from rss6core.kinematics import rigid_motion
from rss6core.sections import crank_inertia, rectangle_torsion_constant, rod_inertia, section_properties


def _energy(scene, t):
    kinetic, potential = mechanical_energy(scene, rigid_motion(scene, t))
    return kinetic + potential


def test_actuator_power_equals_energy_rate(paper):
    """sum tau_i alpha_i' = d(T + V)/dt; the rate by a 4th-order central difference (h = 1e-4 s)."""
    t, h = paper.times, 1e-4
    m = rigid_motion(paper, t)
    power = np.sum(inverse_dynamics(paper, m).torque * m.alpha_dot, axis=1)
    rate = (8 * (_energy(paper, t + h) - _energy(paper, t - h))
            - (_energy(paper, t + 2 * h) - _energy(paper, t - 2 * h))) / (12 * h)
    relative = np.abs(power - rate).max() / np.abs(power).max()
    print(f"actuator power against the energy rate: {relative:.1g} relative")   # pytest -s: docs/guide.md
    assert relative < 1e-8


def test_base_reactions_balance_momentum_rate(paper):
    """sum F_A = sum m_k a_k - M g: linear momentum of all bodies, from kinematics alone."""
    m = rigid_motion(paper)
    loads = inverse_dynamics(paper, m)
    mc, mr, mp = crank_inertia(paper).mass, rod_inertia(paper).mass, paper.platform.mass
    g = paper.gravity_vector
    momentum_rate = (mc * 0.5 * m.c_ddot + mr * 0.5 * (m.c_ddot + m.b_ddot)).sum(1) + mp * m.platform.a
    total_mass = 6 * (mc + mr) + mp
    assert np.abs(loads.force_A.sum(1) - momentum_rate + total_mass * g).max() < 1e-10


def test_revolute_reaction_moment_is_normal_to_its_axis(paper):
    loads = inverse_dynamics(paper, rigid_motion(paper))
    axial = np.einsum("tli,li->tl", loads.moment_A, paper.geometry.w)
    assert np.abs(axial).max() < 1e-12 * np.abs(loads.moment_A).max()


def test_static_torques_by_virtual_work(paper):
    """At rest tau = dV/dalpha: the potential energy's gradient through the platform Jacobian."""
    still = dataclasses.replace(paper, trajectory=dataclasses.replace(paper.trajectory, frequency=0.0))
    m = rigid_motion(still, np.array([0.0]))
    tau = inverse_dynamics(still, m).torque[0]
    # V(alpha): move each crank by +-h, solve FK for the pose, and difference V
    from rss6core.kinematics import forward_kinematics, crank_points, platform_joints
    from rss6core.trajectory import rotation
    geo, h = still.geometry, 1e-6
    mc, mr, mp, g = crank_inertia(still).mass, rod_inertia(still).mass, still.platform.mass, still.gravity

    def V(alpha):
        pose, _ = forward_kinematics(geo, alpha[None], m.platform.pose)
        c = crank_points(geo, alpha[None])[0][0]
        b = platform_joints(geo, pose[:, :3], rotation(pose[:, 3:]))[0][0]
        z = mc * 0.5 * (geo.a + c)[:, 2].sum() + mr * 0.5 * (c + b)[:, 2].sum() + mp * pose[0, 2]
        return g * z
    grad = [(V(m.alpha[0] + h * e) - V(m.alpha[0] - h * e)) / (2 * h) for e in np.eye(6)]
    assert tau == pytest.approx(grad, rel=1e-6)


def test_rectangle_torsion_constant_limits():
    # square: J = 0.1406 a^4 (Roark); thin strip: J -> a b^3 / 3
    assert rectangle_torsion_constant(1.0, 1.0) == pytest.approx(0.140577, rel=1e-5)
    assert rectangle_torsion_constant(100.0, 1.0) == pytest.approx(100 / 3 * (1 - 0.630 / 100), rel=1e-4)


def test_link_masses_from_density_and_section(paper):
    assert crank_inertia(paper).mass == pytest.approx(2700 * 0.04 * 0.02 * 0.216)
    assert rod_inertia(paper).mass == pytest.approx(2700 * np.pi * (0.0125 ** 2 - 0.005 ** 2) * 0.5)
    tube = section_properties(paper.rod_section)
    assert tube.J == pytest.approx(2 * tube.Iy)
