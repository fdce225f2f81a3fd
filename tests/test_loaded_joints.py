"""The note a designer's answer carries at a level that places the joints inside their play: which levels
leave the loaded joints out, and the loaded state's steady maxima it prints (the quasi-static reaction mode
at the nominal sizes of the nominal robot, docs/guide.md's "quasi-static (reaction)" row)."""
import json

import numpy as np
import pytest

from pipeline.commands.messages import note_loaded_joints
from pipeline.scenes.variant import scene_variant
from pipeline.analysis.exceedance import parse_event
from pipeline.analysis.spec import parse_spec
from pipeline.studies.loaded_joints import (leaves_out_loaded_joints, loaded_breaches, loaded_joint_maxima,
                                           loaded_joints_note)
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
    assert loaded_joints_note(reaction, "quasi-static") == [] and loaded_joints_note(paper, "contact") == []


def test_the_loaded_maxima_are_the_reaction_run_at_the_nominal_sizes(paper, configs):
    """The paper scene's steady maxima with the joints at their walls: the reaction run's own, z about 1 mm
    (docs/guide.md: 0.990 mm, the contact level 1.03 mm), 15 times a drawn run's; a scene drawing its
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
    assert got[2] / drawn == pytest.approx(15.07, rel=0.01)   # README: "15x the drawn level's" (0.0657 mm)
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
        err = capsys.readouterr().err.splitlines()   # the loaded smoke robot: z 0.975 mm, past the event's 0.1 mm
        assert err[0].startswith("rss6 stats: note: the quasi-static level places each joint")
        assert err[1:] == ([] if judge[:1] != ["--event"] else [
            "rss6 stats: warning: under its loads the nominal robot at its nominal sizes is past the limit of "
            "'displacement:z>0.1mm' (z 0.975 mm): judge it with quasi_static_eccentricity = \"reaction\" in the "
            "scene's [simulation] or at the contact level"])
    assert main(["stats", str(path), "--json", "--event", "displacement:z>0.1mm"]) == 0   # newcomer55: in JSON too
    out, err = capsys.readouterr()
    notes = json.loads(out)["notes"]
    assert notes[0].startswith("note: the quasi-static level places each joint") and notes[1].startswith("warning:")
    assert [f"rss6 stats: {line}" for line in notes] == err.splitlines()
    assert main(["reliability", "smoke", "--method", "mc", "-n", "64", "--event", "displacement:z>0.1mm", "--json",
                 "--workers", "1", "-o", str(tmp_path / "rel.nc")]) == 0
    assert json.loads(capsys.readouterr().out)["notes"][1].startswith("warning: under its loads")
    loaded = tmp_path / "loaded.toml"
    loaded.write_text(scene_variant((configs / "smoke.toml").read_text(),
                                    {"simulation": {"quasi_static_eccentricity": "reaction"}}, "smoke", add=True))
    assert main(["run", str(loaded), "-n", "4", "--model", "quasi-static", "--workers", "1",
                 "-o", str(tmp_path / "r.nc")]) == 0
    assert main(["stats", str(tmp_path / "r.nc")]) == 0
    assert "note:" not in capsys.readouterr().err


def test_the_limits_the_loaded_state_is_past_are_the_translation_maxima_over_their_limits():
    """Loaded steady maxima x, y, z = 0.01, 0.156, 0.99 mm against specs and events: a limit is named with the
    directions past it; rotations, velocities, means, the start-up window, a spread (@std) and a lower limit (the
    loaded joints only add error) are not the loaded state's."""
    maxima = np.array([0.01e-3, 0.156e-3, 0.99e-3])
    judged = ["displacement:x,y,z<=0.1mm@q95", "displacement:z<=1mm@q95", "displacement:z<0.99mm@q50",
              "displacement:z<=0.5mm@q95/startup", "displacement:rx<=0.001mrad@q95", "velocity:z<=1um/s@q95",
              "displacement:z<=0.5mm@q95:mean", "displacement:z<=0.06mm@std", "displacement:x>=1mm@q95",
              "displacement:x>1mm@q50"]
    assert loaded_breaches(maxima, [parse_spec(t) for t in judged]) == [
        "'displacement:x,y,z<=0.1mm@q95' (y 0.156 mm, z 0.99 mm)", "'displacement:z<0.99mm@q50' (z 0.99 mm)"]
    events = ["displacement:z>0.5mm/steady", "displacement:z>0.99mm", "displacement:x,y>0.1mm", "displacement:z>1mm"]
    assert loaded_breaches(maxima, [parse_event(t) for t in events]) == [
        "'displacement:z>0.5mm/steady' (z 0.99 mm)", "'displacement:x,y>0.1mm' (y 0.156 mm)"]


def test_budget_and_allocate_note_the_answers_robot_and_the_spec_it_is_past_under_load(tmp_path, capsys):
    """The answer's robot, not the scene's: budget's note gives the loaded maxima of its answer scene (the
    clearances scaled), allocate's of its allocated scene (the fits' middle sizes), each with the warning
    naming the spec the loaded robot is past."""
    from pipeline.cli import main
    from rss6core import load_scene
    spec, loose = "displacement:x,y,z<=0.01mm@q95", "displacement:x,y,z<=0.05mm@q95"   # smoke attains 0.035 mm
    assert main(["budget", "smoke", "--spec", spec, "-n", "64", "--workers", "1", "-o", str(tmp_path / "b")]) == 0
    err = capsys.readouterr().err.splitlines()[-2:]
    answer = load_scene(next((tmp_path / "b").glob("*_budget.toml")))
    x, y, z = 1e3 * loaded_joint_maxima(answer)
    assert err[0].startswith("rss6 budget: note:") and f"x, y, z = {x:.3g}, {y:.3g}, {z:.3g} mm" in err[0]
    assert "the answer's robot (clearances x " in err[0]
    assert err[1].startswith("rss6 budget: warning: under its loads the answer's robot") and f"'{spec}'" in err[1]
    assert main(["allocate", "smoke", "--spec", loose, "-n", "64", "--workers", "1", "-o", str(tmp_path / "a")]) == 0
    err = capsys.readouterr().err.splitlines()[-2:]
    x, y, z = 1e3 * loaded_joint_maxima(load_scene(tmp_path / "a" / "smoke_allocated.toml"))
    assert err[0].startswith("rss6 allocate: note:") and f"x, y, z = {x:.3g}, {y:.3g}, {z:.3g} mm" in err[0]
    assert err[1].startswith("rss6 allocate: warning: under its loads the answer's robot at its fits' middle sizes")
