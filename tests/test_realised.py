"""The realised robot driven by the nominal controller: its geometric error against closed forms."""
import dataclasses

import numpy as np
import pytest

from rss6core import parse_scene, rigid_motion, simulate
from rss6core.assembly import build_elastic_model
from rss6core.elastic import simulate_elastic
from rss6core.kinematics import leg_jacobian
from rss6core.realised import linear_length_error, motion_error, realised_motion


def _table(name, key, law_lines, each="leg"):
    return f'\n[uncertain.{name}]\nparameter = "{key}"\neach = "{each}"\n{law_lines}\n'


def _lengths(text, h):
    """Crank and rod lengths per leg, uniform deviations in [-h, h] m."""
    law = f'law = "uniform"\nlow_m = {-h!r}\nhigh_m = {h!r}'
    return parse_scene(text + _table("crank", "geometry.crank_length_m", law)
                       + _table("rod", "geometry.rod_length_m", law), "s.toml")


@pytest.fixture(scope="module")
def smoke_text(configs):
    return (configs / "smoke.toml").read_text()


def test_rigid_error_of_length_deviations_is_the_linear_error_model_to_second_order(smoke_text):
    """J_x dx = J_g dg (realised.linear_length_error) against the realised forward kinematics: the
    residual is second order, so it shrinks 4x when the deviations halve (same uniforms, half width)."""
    residual, size = [], []
    for h in (2e-4, 1e-4):
        scene = _lengths(smoke_text, h)
        result = simulate(scene, "rigid", seed=4, realization=1)
        linear = linear_length_error(scene.geometry, rigid_motion(scene), result.inputs.of("crank"),
                                     result.inputs.of("rod"))
        residual.append(np.abs(result.displacement - linear).max())
        size.append(np.abs(result.displacement).max())
    assert size[0] > 1e-4 and residual[0] < 1e-2 * size[0]
    assert residual[0] / residual[1] == pytest.approx(4.0, rel=0.05)


def test_actuator_offsets_give_the_inverse_jacobian_error(smoke_text):
    """Only offsets drawn: dx = J^-1 d alpha to first order (J the leg Jacobian, alpha' = J twist)."""
    residual = []
    for h in (0.02, 0.01):
        scene = parse_scene(smoke_text + _table("zero", "geometry.actuator_offsets_deg",
                                                f'law = "uniform"\nlow_deg = {-h}\nhigh_deg = {h}'))
        result = simulate(scene, "rigid", seed=2, realization=0)
        m = rigid_motion(scene)
        linear = np.linalg.solve(m.jacobian, np.broadcast_to(result.inputs.of("zero"), m.alpha.shape)[..., None])
        residual.append(np.abs(result.displacement - linear[..., 0]).max())
        assert residual[-1] < 1e-2 * np.abs(result.displacement).max()
    assert residual[0] / residual[1] == pytest.approx(4.0, rel=0.1)


def test_realised_rates_are_the_derivatives_of_the_realised_pose(smoke_text):
    scene = _lengths(smoke_text, 1e-3)
    m = rigid_motion(scene)
    rng = np.random.default_rng(0)
    geo = dataclasses.replace(scene.geometry, crank_length=scene.geometry.crank_length + rng.uniform(-1e-3, 1e-3, 6),
                              base_angles=scene.geometry.base_angles + rng.uniform(-1e-2, 1e-2, 6),
                              actuator_offsets=rng.uniform(-1e-2, 1e-2, 6))
    p = realised_motion(geo, m).platform
    h = m.t[1] - m.t[0]
    for x, rate in ((p.pose, p.pose_rate), (p.pose_rate, p.pose_acc)):
        central = (x[2:] - x[:-2]) / (2 * h)      # error h^2 x''' / 6
        third = np.abs(np.diff(x, 3, axis=0)).max() / h ** 3
        assert np.abs(central - rate[1:-1]).max() < 2 * h ** 2 * third / 6 + 1e-9


def test_the_nominal_robot_has_zero_error(smoke_text):
    """A zero-width law: exactly zero rigid error and the nominal scene's quasi-static bits; the
    realised kinematics of the nominal geometry itself (no shortcut) stays at rounding level."""
    zero = parse_scene(smoke_text + _table("crank", "geometry.crank_length_m", 'law = "normal"\nstd_m = 0.0'))
    rigid = simulate(zero, "rigid", seed=1, realization=3)
    assert not np.any(rigid.displacement) and not np.any(rigid.acceleration)
    a, b = simulate(zero, "quasi-static", seed=1, realization=3), simulate(parse_scene(smoke_text), "quasi-static",
                                                                             seed=1, realization=3)
    for f in ("displacement", "velocity", "acceleration"):
        assert np.array_equal(getattr(a, f), getattr(b, f))
    m = rigid_motion(zero)
    d, v, acc = motion_error(realised_motion(zero.geometry, m), m)
    assert np.abs(d).max() < 1e-14 and np.abs(v).max() < 1e-13 and np.abs(acc).max() < 1e-12


def test_per_leg_geometry_of_nominal_values_keeps_every_bit(smoke_text):
    scene = parse_scene(smoke_text)
    g = scene.geometry
    legs = dataclasses.replace(g, **{f: np.full(6, getattr(g, f)) for f in
                                     ("crank_length", "rod_length", "base_radius", "platform_radius")})
    a, b = rigid_motion(scene), rigid_motion(dataclasses.replace(scene, geometry=legs))
    for f in ("alpha", "alpha_dot", "alpha_ddot", "c", "c_ddot", "b", "jacobian"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
    assert np.array_equal(leg_jacobian(g, a.b, a.r, a.alpha), leg_jacobian(legs, a.b, a.r, a.alpha))


def _modulus(factor, each="link"):
    """Young's modulus times ``factor`` on every link (a point lognormal law: a factor, no spread)."""
    return _table("E", "material.youngs_modulus_Pa", f'law = "lognormal"\nsigma = 0.0\nmedian = {factor!r}', each)


def test_elastic_sag_scales_as_one_over_the_modulus(smoke_text):
    """Only the modulus drawn (per link, so each leg its own matrices): halving E doubles the elastic
    error and doubling it halves it, to the dynamic amplification's change (slow motion: < 1 %)."""
    nominal = simulate(parse_scene(smoke_text), "elastic").displacement
    for factor in (0.5, 2.0):
        scene = parse_scene(smoke_text + _modulus(factor))
        d = simulate(scene, "elastic").displacement
        assert np.abs(d * factor - nominal).max() < 1e-2 * np.abs(nominal).max()


def test_elastic_error_of_a_stiff_realised_robot_is_its_rigid_error(smoke_text):
    """Lengths drawn, modulus x 28 (2e12 Pa, the stiffest MAGNITUDES allows): the elastic level's error is
    the rigid level's geometric error plus an elastic part 28 times below the nominal robot's."""
    stiffer = 28.0
    scene = parse_scene(smoke_text + _table(
        "crank", "geometry.crank_length_m", 'law = "uniform"\nlow_m = -2e-4\nhigh_m = 2e-4')
        + _table("rod", "geometry.rod_length_m", 'law = "uniform"\nlow_m = -2e-4\nhigh_m = 2e-4') + _modulus(stiffer))
    rigid, elastic = simulate(scene, "rigid", seed=3, realization=1), simulate(scene, "elastic", seed=3, realization=1)
    nominal = np.abs(simulate(parse_scene(smoke_text), "elastic").displacement).max()
    assert np.abs(rigid.displacement).max() > 10 * nominal
    elastic_part = np.abs(elastic.displacement - rigid.displacement).max()
    assert 0.97 * nominal / stiffer < elastic_part < 1.03 * nominal / stiffer


def test_a_realised_elastic_robot_of_nominal_values_keeps_the_bits_and_per_leg_matrices_agree(smoke_text):
    """Zero-width laws: the nominal elastic run's bits.  Per-leg link matrices of the nominal values (the
    realised model's other path) agree with the shared ones to rounding."""
    plain = simulate(parse_scene(smoke_text), "elastic")
    zero = parse_scene(smoke_text + _table("crank", "geometry.crank_length_m", 'law = "normal"\nstd_m = 0.0')
                       + _modulus(1.0, "one"))
    same = simulate(zero, "elastic", seed=5, realization=2)
    for f in ("displacement", "velocity", "acceleration"):
        assert np.array_equal(getattr(plain, f), getattr(same, f)), f
    scene = parse_scene(smoke_text)
    legs = dataclasses.replace(scene, material=dataclasses.replace(
        scene.material, youngs_modulus=np.full(12, scene.material.youngs_modulus)))
    assert build_elastic_model(legs, 4).crank_K.shape == (6, 24, 24)
    per_leg = simulate_elastic(legs, 4, dt=scene.simulation.time_step)
    assert np.abs(per_leg.displacement - plain.displacement).max() < 1e-9 * np.abs(plain.displacement).max()


CLEARANCE_KEYS = ("revolute_radial", "revolute_axial", "spherical_C", "spherical_B")


def test_drawn_clearance_sizes_scale_the_quasi_static_error_and_are_the_draws_sizes(smoke_text):
    """The quasi-static error is linear in the clearances (eccentricities scale with the sizes): every
    size x1.5 (a point lognormal factor) gives 1.5 x the nominal error to rounding; sizes drawn per
    joint are the draw's sizes, and a zero-width law keeps the nominal bits."""
    nominal = simulate(parse_scene(smoke_text), "quasi-static", seed=2, realization=5)
    factor = "".join(_table(f, f"clearance.{f}_m", 'law = "lognormal"\nsigma = 0.0\nmedian = 1.5', "one")
                     for f in CLEARANCE_KEYS)
    scaled = simulate(parse_scene(smoke_text + factor), "quasi-static", seed=2, realization=5)
    assert np.abs(scaled.displacement - 1.5 * nominal.displacement).max() < 1e-12 * np.abs(nominal.displacement).max()
    assert np.array_equal(scaled.draw.size_C, np.full(6, 1.5 * 0.25e-3))
    joint = simulate(parse_scene(smoke_text + _table("c", "clearance.spherical_C_m", 'law = "uniform"\nlow_m = -1e-5\n'
                                                     'high_m = 1e-5', "joint")), "quasi-static", seed=2, realization=5)
    assert np.array_equal(joint.draw.size_C, 0.25e-3 + joint.inputs.of("c"))
    assert len(set(joint.draw.size_C)) == 6 and np.array_equal(joint.draw.size_B, nominal.draw.size_B)
    zero = simulate(parse_scene(smoke_text + _table("r", "clearance.revolute_radial_m", 'law = "normal"\nstd_m = 0.0',
                                                    "joint")), "quasi-static", seed=2, realization=5)
    assert np.array_equal(zero.displacement, nominal.displacement)
