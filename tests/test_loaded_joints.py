"""The note a designer's answer carries at a level that places the joints inside their play: which levels
leave the loaded joints out, and the loaded state's steady maxima it prints (the quasi-static reaction mode
at the nominal sizes of the nominal robot, docs/guide.md's "quasi-static (reaction)" row)."""
import numpy as np
import pytest

from pipeline.commands.messages import note_loaded_joints
from pipeline.scenes.variant import scene_variant
from pipeline.studies.loaded_joints import leaves_out_loaded_joints, loaded_joint_maxima, loaded_joints_note
from rss6core import load_scene, parse_scene, simulate


@pytest.fixture(scope="module")
def paper(configs):
    return load_scene(configs / "paper.toml")


def test_which_levels_leave_the_loaded_joints_out(paper):
    reaction = parse_scene(scene_variant(paper.source_text, {"simulation": {"quasi_static_eccentricity": "reaction"}},
                                         "paper", add=True))
    assert leaves_out_loaded_joints(paper, "quasi-static") and leaves_out_loaded_joints(paper, "paper")
    assert not any(leaves_out_loaded_joints(paper, m) for m in ("rigid", "elastic", "contact"))
    assert not leaves_out_loaded_joints(reaction, "quasi-static")
    assert loaded_joints_note(reaction, "quasi-static") is None and loaded_joints_note(paper, "contact") is None


def test_the_loaded_maxima_are_the_reaction_run_at_the_nominal_sizes(paper, configs):
    """The paper scene's steady maxima with the joints at their walls: the reaction run's own, z about 1 mm
    (docs/guide.md: 0.990 mm, the contact level 1.03 mm), ten times the drawn level's; a scene drawing its
    sizes from bands (paper_tolerance, nominal 0.25 mm as paper) and one with [uncertain.*] geometry
    (paper_manufacturing, whose nominal robot is paper's) give the same, at the nominal sizes."""
    reaction = parse_scene(scene_variant(paper.source_text, {"simulation": {"quasi_static_eccentricity": "reaction"}},
                                         "paper", add=True))
    run = simulate(reaction, "quasi-static")
    steady = run.t >= paper.simulation.steady_after
    want = np.abs(run.displacement[steady][:, :3]).max(axis=0)
    got = loaded_joint_maxima(paper)
    np.testing.assert_array_equal(got, want)
    assert got[2] == pytest.approx(0.990e-3, rel=0.01)
    drawn = np.abs(simulate(paper, "quasi-static").displacement[steady][:, 2]).max()
    assert got[2] > 5 * drawn
    for name in ("paper_tolerance", "paper_manufacturing"):
        np.testing.assert_allclose(loaded_joint_maxima(load_scene(configs / f"{name}.toml")), got, rtol=1e-12)


def test_the_note_is_one_line_naming_the_assumption_and_the_loaded_maxima(paper, capsys):
    note_loaded_joints("budget", paper, "quasi-static")
    err = capsys.readouterr().err
    x, y, z = 1e3 * loaded_joint_maxima(paper)
    assert err.count("\n") == 1 and err.startswith("rss6 budget: note: the quasi-static level places each joint")
    assert 'quasi_static_eccentricity = "drawn"' in err and f"x, y, z = {x:.3g}, {y:.3g}, {z:.3g} mm" in err
    note_loaded_joints("budget", paper, "contact")
    assert capsys.readouterr().err == ""


def test_run_and_stats_end_with_the_note_on_a_drawn_level_and_not_on_the_loaded_one(tmp_path, capsys, configs):
    """rss6 run at the quasi-static (drawn) level ends with the note, after its statistics and verdicts, and
    so does rss6 stats on its file (plain, or judging with --event or --require); at the "reaction" mode
    (the loaded joints) neither does."""
    from pipeline.cli import main
    path = tmp_path / "qs.nc"
    assert main(["run", "smoke", "-n", "4", "--model", "quasi-static", "--workers", "1", "-o", str(path),
                 "--require", "displacement:z<=1mm@q95"]) == 3   # undecided at n = 4
    out, err = capsys.readouterr()
    assert "displacement:z<=1mm@q95" in out
    notes = [line for line in err.splitlines() if "note:" in line]   # after the run's progress lines
    assert len(notes) == 1 and notes[0].startswith("rss6 run: note: the quasi-static level places each joint")
    assert err.splitlines()[-1] == notes[0]
    for judge in ([], ["--event", "displacement:z>0.1mm"], ["--require", "displacement:z<=1mm@q95"]):
        assert main(["stats", str(path), *judge]) == (3 if judge[:1] == ["--require"] else 0)
        err = capsys.readouterr().err
        assert err.startswith("rss6 stats: note: the quasi-static level places each joint") and err.count("\n") == 1
    loaded = tmp_path / "loaded.toml"
    loaded.write_text(scene_variant((configs / "smoke.toml").read_text(),
                                    {"simulation": {"quasi_static_eccentricity": "reaction"}}, "smoke", add=True))
    assert main(["run", str(loaded), "-n", "4", "--model", "quasi-static", "--workers", "1",
                 "-o", str(tmp_path / "r.nc")]) == 0
    assert main(["stats", str(tmp_path / "r.nc")]) == 0
    assert "note:" not in capsys.readouterr().err
