"""The paper level on realised robots (issue 38): its elastic run, the paper's closure about the
realised motion, and the drawn sizes and restitutions, against the nominal run and limits."""
import numpy as np
import pytest

from rss6core import parse_scene, simulate

CLEARANCES = ("revolute_radial_m", "revolute_axial_m", "spherical_C_m", "spherical_B_m")


def _table(name, key, law_lines, each="leg"):
    return f'\n[uncertain.{name}]\nparameter = "{key}"\neach = "{each}"\n{law_lines}\n'


@pytest.fixture(scope="module")
def smoke_text(configs):
    return (configs / "smoke.toml").read_text()


def _offsets(h):
    return _table("zero", "geometry.actuator_offsets_deg", f'law = "uniform"\nlow_deg = {-h!r}\nhigh_deg = {h!r}')


def test_zero_width_laws_keep_the_nominal_paper_run_bit_for_bit(smoke_text):
    zero = (_table("crank", "geometry.crank_length_m", 'law = "normal"\nstd_m = 0.0')
            + _table("xi", "contact.restitution", 'law = "normal"\nstd = 0.0', "joint"))
    plain = simulate(parse_scene(smoke_text), "paper", seed=3, realization=2)
    same = simulate(parse_scene(smoke_text + zero, "s.toml"), "paper", seed=3, realization=2)
    for f in ("displacement", "velocity", "acceleration", "contact_force_peak"):
        assert np.array_equal(getattr(plain, f), getattr(same, f)), f
    assert same.inputs is not None


def test_without_clearances_the_realised_paper_level_is_the_realised_elastic_level(smoke_text):
    """Zero clearances: the paper closure adds nothing, so the paper level of a realised robot is its
    elastic level (geometric error included), to rounding."""
    text = smoke_text
    for key in CLEARANCES:
        text = text.replace(f"{key} = 0.25e-3", f"{key} = 0.0")
    scene = parse_scene(text + _offsets(0.05), "s.toml")
    paper, elastic = simulate(scene, "paper", seed=1, realization=4), simulate(scene, "elastic", seed=1, realization=4)
    scale = np.abs(elastic.displacement).max()
    assert scale > 1e-5
    assert np.abs(paper.displacement - elastic.displacement).max() <= 1e-12 * scale


def test_the_closure_follows_the_realised_motion_to_second_order(smoke_text):
    """Offsets drawn: the realised paper error minus its elastic part equals the nominal robot's
    closure error (the same per-step draw) up to the closure's change with the motion, second
    order: under 2 % of the closure error, and smaller when the offsets halve."""
    nominal = parse_scene(smoke_text)
    closure = (simulate(nominal, "paper", seed=2, realization=1).displacement
               - simulate(nominal, "elastic").displacement)
    rest = []
    for h in (0.2, 0.1):
        scene = parse_scene(smoke_text + _offsets(h), "s.toml")
        real = simulate(scene, "paper", seed=2, realization=1).displacement - \
            simulate(scene, "elastic", seed=2, realization=1).displacement
        rest.append(np.abs(real - closure).max())
    assert rest[0] < 2e-2 * np.abs(closure).max() and rest[1] < 0.75 * rest[0], rest


def test_restitution_per_joint_sets_the_paper_levels_contact_forces(smoke_text):
    """paper_contact_forces with one restitution per joint: the scene's value at every joint gives
    the scalar law's bits; another value at one joint changes that joint's force only (its damping
    term), on a draw whose C joints press into their walls at a varying depth."""
    import dataclasses
    from rss6core.paper_method import CENTRAL_PAD, paper_contact_forces, paper_draw
    scene = parse_scene(smoke_text)
    draw = paper_draw(scene, 0, 0, 50)
    depth = 1.0 + 1e-4 * (1.0 + np.sin(np.arange(50 + 2 * CENTRAL_PAD) / 3.0))[:, None, None]
    e_C = draw.e_C / np.linalg.norm(draw.e_C, axis=-1, keepdims=True) * draw.size_C[None, :, None] * depth
    pressed = dataclasses.replace(draw, e_C=e_C)
    plain = paper_contact_forces(scene, pressed, 1e-3)
    xi = np.full(18, scene.contact.restitution)
    assert plain[:, 6:12].min() > 0 and np.array_equal(paper_contact_forces(scene, pressed, 1e-3, xi), plain)
    xi[8] = 0.3                                         # joint C3
    other = paper_contact_forces(scene, pressed, 1e-3, xi)
    changed = np.flatnonzero((other != plain).any(0))
    assert list(changed) == [8]
