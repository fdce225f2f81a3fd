"""The contact level on realised robots (issue 38): geometry, material, payload, friction and
restitution per realisation, checked against the nominal run, superposition and the numpy engine."""
import dataclasses

import numpy as np
import pytest

from rss6core import draw_clearances, parse_scene, simulate
from rss6core.contact_dynamics import simulate_contact
from rss6core.contact_numpy import NumpyStepper
from rss6core.realised import ReferenceMotion, realised_contact_laws, realised_geometry
from rss6core.uncertain import draw_inputs


def _table(name, key, law_lines, each="leg"):
    return f'\n[uncertain.{name}]\nparameter = "{key}"\neach = "{each}"\n{law_lines}\n'


@pytest.fixture(scope="module")
def smoke_text(configs):
    return (configs / "smoke.toml").read_text()


def _offsets(text, h):
    """Actuator zero offsets per leg, uniform in [-h, h] deg."""
    return parse_scene(text + _table("zero", "geometry.actuator_offsets_deg",
                                     f'law = "uniform"\nlow_deg = {-h!r}\nhigh_deg = {h!r}'), "s.toml")


def test_zero_width_laws_keep_the_nominal_contact_run_bit_for_bit(smoke_text):
    """Lengths, modulus, payload, friction and restitution drawn with zero width: the nominal robot
    (one batch about the nominal motion, per-joint laws equal to the scene's), the same bits."""
    zero = "".join(_table(n, k, law, each) for n, k, law, each in (
        ("crank", "geometry.crank_length_m", 'law = "normal"\nstd_m = 0.0', "leg"),
        ("E", "material.youngs_modulus_Pa", 'law = "lognormal"\nsigma = 0.0', "one"),
        ("mass", "platform.mass_kg", 'law = "normal"\nstd_kg = 0.0', "one"),
        ("mu", "contact.friction_coefficient", 'law = "normal"\nstd = 0.0', "joint"),
        ("xi", "contact.restitution", 'law = "normal"\nstd = 0.0', "joint")))
    plain = simulate(parse_scene(smoke_text), "contact", seed=4, realization=1)
    same = simulate(parse_scene(smoke_text + zero, "s.toml"), "contact", seed=4, realization=1)
    for f in ("displacement", "velocity", "acceleration", "peak_abs_error", "contact_force_peak"):
        assert np.array_equal(getattr(plain, f), getattr(same, f)), f
    assert same.inputs is not None


def test_realised_contact_error_is_the_nominal_one_plus_the_geometric_error(smoke_text):
    """Actuator offsets only: the realised robot's contact-level error equals the nominal robot's (same
    clearance draw) plus its rigid geometric error, up to their coupling, which is of second order:
    under 1 % of the geometric error, and it shrinks when the offsets halve."""
    nominal = simulate(parse_scene(smoke_text), "contact", seed=1, realization=0)
    late = nominal.t >= 0.1
    residual = []
    for h in (0.05, 0.025):
        scene = _offsets(smoke_text, h)
        real, rigid = simulate(scene, "contact", seed=1, realization=0), simulate(scene, "rigid", seed=1, realization=0)
        geometric = np.abs(rigid.displacement[late]).max(0)
        rest = np.abs(real.displacement - nominal.displacement - rigid.displacement)[late].max(0)
        assert rest[:3].max() < 1e-2 * geometric[:3].max() and rest[3:].max() < 1e-2 * geometric[3:].max()
        assert geometric.max() > 10 * rest.max()
        residual.append(rest)
    assert np.all(residual[1] < 0.75 * residual[0])


def test_realised_contact_peaks_include_the_geometric_error(smoke_text):
    """The peaks over every internal step hold the geometric error too: never below the output
    histories' maxima, which include it, and above the nominal robot's peaks where it dominates (x)."""
    scene = _offsets(smoke_text, 0.05)
    real = simulate(scene, "contact", seed=1, realization=0)
    nominal = simulate(parse_scene(smoke_text), "contact", seed=1, realization=0)
    steady = real.t >= scene.simulation.steady_after
    for q, f in enumerate(("displacement", "velocity", "acceleration")):
        hist = np.abs(getattr(real, f)[steady]).max(0)
        assert np.all(real.peak_abs_error[1, q] >= hist * (1 - 1e-12)), f
    assert real.peak_abs_error[1, 0, 0] > 2 * nominal.peak_abs_error[1, 0, 0]


def test_per_joint_friction_and_restitution_agree_with_the_numpy_engine(smoke_text):
    """Friction coefficient and restitution drawn per joint, on a realised robot (offsets, payload):
    the compiled kernel against the numpy engine, equal to round-off (as the nominal engines test);
    and the drawn laws matter (the run differs from the scene's laws)."""
    text = smoke_text + "".join(_table(n, k, law, each) for n, k, law, each in (
        ("mu", "contact.friction_coefficient", 'law = "uniform"\nlow = -0.08\nhigh = 0.1', "joint"),
        ("xi", "contact.restitution", 'law = "uniform"\nlow = -0.5\nhigh = 0.05', "joint"),
        ("zero", "geometry.actuator_offsets_deg", 'law = "uniform"\nlow_deg = -0.05\nhigh_deg = 0.05', "leg"),
        ("mass", "platform.mass_kg", 'law = "uniform"\nlow_kg = 0.0\nhigh_kg = 0.5', "one")))
    scene = parse_scene(text.replace("duration_s = 0.2", "duration_s = 0.02"), "s.toml")
    base = parse_scene(smoke_text.replace("duration_s = 0.2", "duration_s = 0.02"), "s.toml")
    inputs = draw_inputs(scene, 3, 0, None, offset=0)
    laws = realised_contact_laws(scene, inputs)
    assert len(np.unique(laws.friction)) == 18 and np.all(laws.restitution <= 0.95)
    realised = dataclasses.replace(scene, geometry=realised_geometry(scene.geometry, inputs))
    draws = [draw_clearances(base, 3, 0)]
    kw = dict(reference=ReferenceMotion(base, realised.geometry), laws=[laws], tolerance=1e-8, refinements=3)
    compiled = simulate_contact(realised, draws, **kw)
    reference = simulate_contact(realised, draws, stepper=NumpyStepper, **kw)
    plain = simulate_contact(realised, draws, **dict(kw, laws=None))
    assert compiled.status == reference.status == ["finished"]
    for q in ("displacement", "velocity", "acceleration", "peak", "contact_peak"):
        a, b = getattr(compiled, q), getattr(reference, q)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * np.abs(b).max())
    assert np.abs(plain.acceleration - compiled.acceleration).max() > 1e-3 * np.abs(compiled.acceleration).max()


def test_the_contact_level_refuses_per_link_material_draws(smoke_text):
    scene = parse_scene(smoke_text + _table("E", "material.youngs_modulus_Pa", 'law = "uniform"\nlow_Pa = -1e9\n'
                                            'high_Pa = 1e9', "link"), "s.toml")
    with pytest.raises(ValueError, match=r'^\[uncertain.E\] each = "link": the contact level takes one shared'):
        simulate(scene, "contact")
