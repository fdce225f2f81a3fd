"""Craig-Bampton reduced links ([beam] link_modes): against the full mesh and a closed form."""
import dataclasses

import numpy as np
import pytest
import scipy.linalg

from rss6core.assembly import build_elastic_model, dense_matrices, end_maps, rigid_loads
from rss6core.beam import link_matrices
from rss6core.elastic import simulate_elastic
from rss6core.kinematics import rigid_motion
from rss6core.link_reduction import craig_bampton, max_link_modes, reduce_pair
from rss6core.models import natural_frequencies
from rss6core.scene import Damping, SceneError, parse_scene
from rss6core.sections import section_properties


def _modes(scene, m: int):
    return dataclasses.replace(scene, beam=dataclasses.replace(scene.beam, link_modes=m))


def _clamped_crank(scene, elements: int):
    """The paper's crank clamped at node 0 (nodes 1..n, 6 n DOFs), free at its tip."""
    props = section_properties(scene.crank_section)
    mat = scene.material
    K, M = link_matrices(props, mat.youngs_modulus, mat.shear_modulus, mat.density, scene.geometry.crank_length,
                         elements)
    return K[6:, 6:], M[6:, 6:], props


def _hz(K, M, count):
    w2 = scipy.linalg.eigh(K, M, eigvals_only=True, subset_by_index=[0, count - 1])
    return np.sqrt(np.abs(w2)) / (2 * np.pi)   # a held rod's two pivot modes: zero to round-off


def test_clamped_free_first_bending_frequency_closed_form(paper):
    """Clamped-free beam: f1 = 1.875^2 sqrt(E I / (rho A L^4)) / (2 pi), I the weaker axis's; the full
    16-element mesh and its Craig-Bampton reduction to 4 modes (boundary: the free tip node, left free)
    both within 1 %."""
    K, M, props = _clamped_crank(paper, 16)
    mat, L = paper.material, paper.geometry.crank_length
    exact = 1.8751 ** 2 * np.sqrt(mat.youngs_modulus * min(props.Iy, props.Iz)
                                  / (mat.density * props.area * L ** 4)) / (2 * np.pi)
    T = craig_bampton(K, M, np.arange(K.shape[0] - 6, K.shape[0]), 4)
    Kr, Mr = reduce_pair(K, M, T)
    assert _hz(K, M, 1)[0] == pytest.approx(exact, rel=1e-2)
    assert _hz(Kr, Mr, 1)[0] == pytest.approx(exact, rel=1e-2)


@pytest.mark.parametrize("link", ["crank", "rod"])
def test_kept_modes_of_a_link_within_one_percent(paper, link):
    """16 elements, 8 modes kept: the reduced link's free-interface frequencies (crank clamped at A and
    free at its tip; rod with its C end's translations held and its B end free) never fall below the full
    mesh's (Rayleigh-Ritz) and match them within 1 % for the lowest 6 (the kept modes but the top pair,
    which the cut stiffens by up to 10 % on the rod: docs/model.md)."""
    model = build_elastic_model(paper, 16)
    reduced = build_elastic_model(_modes(paper, 8), 16)
    if link == "crank":
        full, red = (model.crank_K, model.crank_M), (reduced.crank_K, reduced.crank_M)
    else:   # hold the C end (3 translations): the rod still pivots about C, so its 2 zero modes are skipped
        keep_f = np.r_[0:model.rod_dofs, model.rod_dofs + 3:model.rod_dofs + 6]
        keep_r = np.r_[0:reduced.rod_dofs, reduced.rod_dofs + 3:reduced.rod_dofs + 6]
        full = tuple(A[np.ix_(keep_f, keep_f)] for A in (model.rod_K, model.rod_M))
        red = tuple(A[np.ix_(keep_r, keep_r)] for A in (reduced.rod_K, reduced.rod_M))
    skip = 0 if link == "crank" else 2
    f_full, f_red = _hz(*full, 8 + skip)[skip:], _hz(*red, 8 + skip)[skip:]
    print(f"{link}, 16 elements, 8 modes: lowest 6 within {np.abs(f_red[:6] / f_full[:6] - 1).max():.2%}, "
          f"top pair {(f_red[6:] / f_full[6:] - 1).max():.1%} high")   # pytest -s: docs/model.md section 5
    assert np.all(f_red >= f_full * (1 - 1e-9))
    assert np.abs(f_red[:6] / f_full[:6] - 1).max() < 1e-2


def test_assembled_robot_lowest_frequencies_within_one_percent(paper):
    """The whole robot at t = 0, 16 elements per link: 4 modes per link keep its 24 lowest
    frequencies (up to about 550 Hz) within 1 % (measured: 0.33 %)."""
    full = natural_frequencies(paper, 16)[:24]
    red = natural_frequencies(_modes(paper, 4), 16)[:24]
    print(f"robot, 16 elements, 4 modes per link: 24 lowest (to {full[-1] / (2 * np.pi):.0f} Hz) within "
          f"{np.abs(red / full - 1).max():.2%}")   # pytest -s: docs/model.md section 5
    assert np.all(red >= full * (1 - 1e-9))
    assert np.abs(red / full - 1).max() < 1e-2


def test_every_mode_kept_is_the_full_model(paper):
    """m = every interior DOF: T is square, so the reduced robot is the full one in other coordinates:
    its frequencies and its static response to the rigid loads at a moving instant agree to round-off."""
    m = max_link_modes(4)
    t = np.array([0.3])
    out = []
    for scene in (paper, _modes(paper, m)):
        model = build_elastic_model(scene, 4)
        maps = end_maps(model, rigid_motion(scene, t), scene.geometry)
        M, K = dense_matrices(model, maps[0])
        out.append((np.linalg.solve(K, rigid_loads(model, rigid_motion(scene, t), scene)[0])[-6:],
                    scipy.linalg.eigh(K, M, eigvals_only=True)))
    assert out[1][1].shape == out[0][1].shape
    assert np.abs(out[1][0] - out[0][0]).max() < 1e-10 * np.abs(out[0][0]).max()
    assert np.abs(out[1][1] / out[0][1] - 1).max() < 1e-10


def test_every_mode_kept_gives_the_full_run_on_a_still_robot(paper):
    """With the robot held still the end maps are constant, so the basis is too and the run (ringing from
    rest under gravity, undamped) is the full mesh's to round-off.  (A moving robot's rod basis turns with
    the end maps, whose rate the model drops as it drops eq. 26's frame terms: docs/model.md.)"""
    still = dataclasses.replace(
        paper, trajectory=dataclasses.replace(paper.trajectory, frequency=0.0, duration=0.1),
        damping=Damping(0.0, 0.0))
    runs = []
    for scene in (still, _modes(still, max_link_modes(4))):
        z = np.zeros(build_elastic_model(scene, 4).dofs)
        runs.append(simulate_elastic(scene, 4, initial=(z, z, z)))
    for q in ("displacement", "velocity", "acceleration"):
        a, b = getattr(runs[0], q), getattr(runs[1], q)
        assert np.abs(b - a).max() < 1e-8 * np.abs(a).max(), q


def test_few_modes_follow_the_full_run(paper):
    """On the moving robot 4 modes per link keep the platform's elastic displacement within 0.1 % of
    its largest value."""
    full, red = simulate_elastic(paper, 4), simulate_elastic(_modes(paper, 4), 4)
    assert np.abs(red.displacement - full.displacement).max() < 1e-3 * np.abs(full.displacement).max()


def test_default_is_the_full_mesh(paper):
    model = build_elastic_model(paper, 4)
    assert paper.beam.link_modes == 0 and model.crank_basis is None and model.rod_basis is None
    assert model.dofs == 6 * (24 + 19) + 6


@pytest.mark.parametrize("value, message", [(-1, "must be non-negative"), (15, "more than the 14"),
                                            (1.5, "expected an integer")])
def test_bad_link_modes_name_the_key(paper, value, message):
    text = paper.source_text.replace("elements_per_link = 4", "elements_per_link = 3") + \
        f"\n[beam]\nlink_modes = {value}\n"
    with pytest.raises(SceneError, match=rf"\[beam\] link_modes: .*{message}"):
        parse_scene(text)


def test_elements_option_below_the_scenes_link_modes_is_one_line(paper, tmp_path, capsys):
    """--elements that leaves a link fewer interior DOFs than the scene's link_modes: exit 2, one line."""
    from pipeline.cli import main
    scene = tmp_path / "reduced.toml"
    scene.write_text(paper.source_text + "\n[beam]\nlink_modes = 8\n")
    assert main(["simulate", str(scene), "--elements", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--elements 1" in err and "link_modes = 8" in err


def test_contact_displacement_maxima_within_the_tradeoff_tolerance(smoke):
    """The contact level (compiled steps) on 0.1 s of the smoke scene, 4 realisations: each realisation's
    displacement maxima (x, y, z, both windows) with 4 modes per link within the trade-off's 5 % of the
    full mesh's (measured 0.73 %), and closer with more modes (2, 4, 8: 3.2, 0.73, 0.31 %)."""
    from rss6core.clearance import draw_clearances
    from rss6core.contact_dynamics import simulate_contact
    scene = dataclasses.replace(smoke, trajectory=dataclasses.replace(smoke.trajectory, duration=0.1))
    draws = [draw_clearances(scene, 0, r) for r in range(4)]
    full = simulate_contact(scene, draws).peak[:, :, 0, :3].max(1)
    worst = []
    for m in (2, 4, 8):
        batch = simulate_contact(_modes(scene, m), draws)
        assert batch.status == ["finished"] * 4
        worst.append(float((np.abs(batch.peak[:, :, 0, :3].max(1) - full) / full).max()))
    assert worst[1] < 0.05
    assert worst[0] > worst[1] > worst[2]
