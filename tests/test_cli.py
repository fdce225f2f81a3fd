"""End-to-end: the rss6 command line as a user calls it."""
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.cli import main
from pipeline.scenes.catalogue import scene_names


def test_check_json_paper(configs, capsys):
    assert main(["check", str(configs / "paper.toml"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    # golden values (README): home angle -5.024 deg, max torque 3.17 N m on leg 4, link masses
    assert out["home_crank_angles_deg"] == pytest.approx([-5.024] * 6, rel=1e-3)
    assert len(out["crank_angle_range_deg"]) == 6
    assert all(lo < -5.024 < hi for lo, hi in out["crank_angle_range_deg"])
    torque = out["max_actuator_torque_Nm"]
    assert len(torque) == 6 and max(torque) == pytest.approx(3.17, rel=1e-2)
    assert int(np.argmax(torque)) + 1 == 4
    assert out["link_masses_kg"] == pytest.approx({"crank": 0.467, "rod": 0.557, "platform": 1.366},
                                                  rel=1e-2)


def test_check_text_names_the_scene(capsys):
    assert main(["check", "smoke"]) == 0
    assert "scene 'smoke'" in capsys.readouterr().out


def test_check_warns_near_a_crank_rod_singularity(configs, tmp_path, capsys):
    """The smoke scene lowered to z = -0.7027 m passes the workspace check (every pose reachable) but a
    leg comes within 1.4 deg of its singularity (crank torques 12 kN m; the elastic level gave NaN at
    its first step, the helper review's case): check warns naming the leg, the index and the time; the
    shipped scenes (transmission index 0.336 and up) get no warning."""
    low = tmp_path / "low.toml"
    low.write_text((configs / "smoke.toml").read_text().replace("position_offset_m = [0.0, 0.0, -0.387]",
                                                              "position_offset_m = [0.0, 0.0, -0.7027]", 1))
    assert main(["check", str(low)]) == 0
    warned = [line for line in capsys.readouterr().out.splitlines() if line.startswith("warning:")]
    assert len(warned) == 1 and "leg 6 comes within 1.4 deg" in warned[0] and "index 0.0253 < 0.1" in warned[0]
    for name in scene_names():
        assert main(["check", name]) == 0
        assert "warning:" not in capsys.readouterr().out, name


def test_top_level_help_lists_every_shipped_scene(configs, capsys):
    names = scene_names()
    assert names == sorted(p.stem for p in configs.glob("*.toml"))   # every file under configs/
    with pytest.raises(SystemExit) as exit_:
        main(["--help"])
    assert exit_.value.code == 0
    words = set(re.findall(r"[\w.-]+", capsys.readouterr().out))
    assert [name for name in names if name not in words] == []


def test_check_shows_the_bands_clearance_sizes_are_drawn_from(configs, capsys):
    """configs/paper_tolerance.toml draws each joint's size from its family's [tolerance.*] band: check
    says so (mm in the text, m in --json), and says a scene without bands keeps nominal sizes."""
    assert main(["check", str(configs / "paper_tolerance.toml")]) == 0
    line = [s for s in capsys.readouterr().out.splitlines() if s.startswith("clearance sizes drawn")][0]
    assert line == ("clearance sizes drawn per joint [mm]: revolute_radial normal 0.11-0.37 (std 0.0433), "
                    "revolute_axial uniform 0.15-0.35, spherical_C uniform 0.15-0.35, spherical_B uniform 0.15-0.35")
    assert main(["check", str(configs / "paper_tolerance.toml"), "--json"]) == 0
    bands = json.loads(capsys.readouterr().out)["size_bands_m"]
    assert bands["revolute_radial"] == {"law": "normal", "low": 0.110e-3, "high": 0.370e-3, "std": 0.0433e-3}
    assert main(["check", "smoke"]) == 0
    assert "clearance sizes drawn per joint [mm]: none" in capsys.readouterr().out


def test_bad_config_is_a_usage_error(configs, tmp_path, capsys):
    bad = tmp_path / "typo.toml"
    bad.write_text((configs / "paper.toml").read_text().replace("mass_kg", "mas_kg"))
    assert main(["check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "typo.toml" in err and "mas_kg" in err and "Traceback" not in err


def test_console_script_is_installed():
    script = shutil.which("rss6", path=os.pathsep.join([str(Path(sys.executable).parent),
                                                       os.environ.get("PATH", "")]))
    assert script, "no rss6 console script on PATH or beside the interpreter; pip install ."
    proc = subprocess.run([script, "check", "paper", "--json"],
                          capture_output=True, text=True, check=True)
    assert json.loads(proc.stdout)["scene"] == "paper"


def test_check_json_reports_modal_data(capsys):
    assert main(["check", "smoke", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["dof"] == 264 and len(out["natural_frequencies_Hz"]) == 12
    assert out["natural_frequencies_Hz"] == sorted(out["natural_frequencies_Hz"])
    assert 0 < out["critical_time_step_s"] < 1e-4


def test_simulate_json_and_netcdf(configs, tmp_path, capsys):
    import netCDF4
    out_file = tmp_path / "run.nc"
    assert main(["simulate", str(configs / "smoke.toml"), "--model", "elastic",
                 "-o", str(out_file), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for stat in ("max_abs_error", "mean_abs_error"):
        assert set(out[stat]) == {"displacement", "velocity", "acceleration"}
        assert set(out[stat]["velocity"]) == {"x", "y", "z", "rx", "ry", "rz"}
    assert out["wall_time_s"] > 0 and out["status"] == "finished"
    assert out["unit"]["acceleration"]["z"] == "m s-2" and out["unit"]["velocity"]["rx"] == "rad s-1"   # SI, named
    with netCDF4.Dataset(out_file) as nc:
        assert nc.Conventions == "CF-1.10" and nc.model == "elastic"
        assert nc.variables["error_velocity_rotation"].dimensions == ("elapsed_time", "rotation")
        assert nc.variables["error_velocity_rotation"].units == "rad s-1"   # one unit per variable
        assert nc.variables["elapsed_time"].units == "s"  # CF keeps "time" for calendar times
        stored = nc.variables["max_abs_error_displacement_translation"][:]   # (window, x y z)
        assert "elements_per_link" in nc.scene_toml
    # the file's summaries are the JSON's numbers
    assert stored[0, 2] == pytest.approx(out["max_abs_error"]["displacement"]["z"], rel=1e-12)
    by_window = out["max_abs_error_by_window"]       # windows whole, startup, steady in the file
    assert set(by_window) == {"startup", "steady"}
    for k, window in ((1, "startup"), (2, "steady")):
        assert stored[k, 2] == by_window[window]["displacement"]["z"]
    assert np.array_equal(stored[0], np.maximum(stored[1], stored[2]))
    again = tmp_path / "again.nc"
    assert main(["simulate", str(configs / "smoke.toml"), "--model", "elastic", "-o", str(again)]) == 0
    assert again.read_bytes() == out_file.read_bytes()   # no wall time in the file: the same run, the same bytes


def test_simulate_rigid_is_the_reference(capsys):
    assert main(["simulate", "smoke", "--model", "rigid", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert all(v == 0 for q in out["max_abs_error"].values() for v in q.values())


def test_simulate_paper_says_why_its_contact_forces_are_zero(capsys):
    """The paper's method keeps every eccentricity inside its clearance: eq. 17 gives no force, and
    the printout says so rather than reporting bare zeros."""
    assert main(["simulate", "smoke", "--model", "paper"]) == 0
    line = [s for s in capsys.readouterr().out.splitlines() if s.startswith("max contact force")][0]
    assert line == ("max contact force (N): A 0, C 0, B 0 (the paper's method keeps every joint inside its "
                    "clearance, so eq. 17 gives none)")


def test_simulate_bad_time_step_is_a_usage_error(capsys):
    assert main(["simulate", "smoke", "--dt", "0.0003"]) == 2
    assert "does not divide" in capsys.readouterr().err


def _short_scene(configs, tmp_path, duration="0.02"):
    path = tmp_path / "short.toml"
    text = (configs / "smoke.toml").read_text()
    path.write_text(text.replace("duration_s = 0.2", f"duration_s = {duration}"))
    return path


@pytest.mark.parametrize("model", ["paper", "contact"])
def test_simulate_clearance_levels_report_contact_forces_per_family(configs, tmp_path, capsys, model):
    path = _short_scene(configs, tmp_path)
    assert main(["simulate", str(path), "--model", model, "--json", "--realization", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["model"] == model and out["status"] == "finished"
    forces = out["max_contact_force_N"]
    assert set(forces) == {"A", "C", "B"}
    if model == "contact":   # joints settle under gravity: they touch and carry the robot
        assert out["time_step_s"] == 1e-4
        assert all(f > 1.0 for f in forces.values())
    else:                    # the paper's draws never penetrate (README: where L3 is ill-posed)
        assert all(f == 0.0 for f in forces.values())
    assert set(out["max_abs_error"]) == {"displacement", "velocity", "acceleration"}


def test_contact_ensemble_stores_contact_force_peaks(configs, tmp_path):
    import xarray as xr
    path = _short_scene(configs, tmp_path)
    out = tmp_path / "c.nc"
    assert main(["run", str(path), "--model", "contact", "-n", "3", "--workers", "1",
                 "--chunk", "2", "-o", str(out)]) == 0
    with xr.open_dataset(out) as ds:
        peaks = ds["max_contact_force"]
        assert peaks.attrs["units"] == "N" and peaks.shape == (3, 18)
        assert np.all(peaks.values > 0)
        assert list(ds["status"].values) == ["finished"] * 3


@pytest.mark.parametrize("argv, ahead", [
    (["run", "paper", "-n", "4"], True),
    (["reliability", "paper", "--workers", "2"], True),
    (["reliability", "paper", "--workers", "1"], False),                 # 1: in this process, no cluster
    (["sensitivity", "paper", "--workers=1"], False),
    (["run", "paper", "--workers", "1"], True),                          # one local worker
    (["run", "paper", "--scheduler", "tcp://127.0.0.1:8786"], False),   # its workers are not ours
    (["run", "paper", "--scheduler=tcp://127.0.0.1:8786"], False),
    (["run", "-h"], False),
    (["stats", "x.nc"], False),                                          # no cluster at all
    ([], False),
])
def test_the_rss6_command_starts_its_workers_server_before_its_imports_only_for_a_local_cluster(
        monkeypatch, argv, ahead):
    """`rss6 CMD ...` (main without argv) starts the local workers' fork server before it imports
    the commands, so both import side by side, and stops it at exit; main(argv) from Python does not."""
    import pipeline.cli as cli
    started, stopping = [], []
    monkeypatch.setattr(cli, "start_worker_server", lambda *preload: started.append(True))
    monkeypatch.setattr(cli.atexit, "register", stopping.append)
    monkeypatch.setattr(sys, "argv", ["rss6", *argv])
    monkeypatch.setattr(cli, "build_parser", lambda: (_ for _ in ()).throw(SystemExit(0)))
    with pytest.raises(SystemExit):
        cli.main()
    assert started == ([True] if ahead else [])
    assert stopping == ([cli.stop_worker_server] if ahead else [])
    started.clear()
    with pytest.raises(SystemExit):
        cli.main(argv)
    assert started == []


def test_a_ctrl_c_no_command_handles_is_one_line_and_exit_130(monkeypatch, capsys):
    """Ctrl-C while the commands are imported (the first second or two of every command) gave a
    KeyboardInterrupt traceback (a new user's review)."""
    import pipeline.cli as cli

    def interrupted_import():
        raise KeyboardInterrupt
    monkeypatch.setattr(cli, "build_parser", interrupted_import)
    try:
        code = cli.main(["stats", "x.nc"])
    except KeyboardInterrupt:
        pytest.fail("the Ctrl-C escaped rss6's main")
    assert code == 130
    assert capsys.readouterr().err == "rss6: interrupted\n"


def test_the_rss6_executable_runs_its_exit_handlers_flushes_and_exits_with_the_commands_code(tmp_path):
    """`rss6` ends its process without the interpreter's module teardown (pipeline.cli._end), but
    only after the exit handlers (the workers' server is stopped by one) and with its buffered
    output flushed: stdout to a pipe is block-buffered, so an unflushed line would be lost."""
    script = ("import atexit, sys\n"
              "import pipeline.cli as cli\n"
              "atexit.register(lambda: print('handler ran'))\n"
              "print('buffered line')\n"
              "sys.argv = ['rss6', 'stats', 'no_such_file.nc']\n"
              "cli.command()\n"
              "print('not reached')\n")
    buffered = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}   # some shells set it
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path, timeout=120,
                         env=buffered)
    assert out.returncode == 2
    assert out.stdout.splitlines() == ["buffered line", "handler ran"]
    assert out.stderr.startswith("rss6 stats: error:") and "no_such_file.nc" in out.stderr


def test_every_options_help_states_its_default():
    """The README: "every command's -h gives each option's default" (stats -o and --event, reliability
    --cov and --plot gave none). Flags, required options and those with choices shown are exempt."""
    import argparse

    from pipeline.cli import build_parser
    subparsers = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    silent = [f"{name} {a.option_strings[-1]}" for name, parser in subparsers.choices.items() for a in parser._actions
              if a.option_strings and not isinstance(a, (argparse._HelpAction, argparse._StoreTrueAction))
              and not a.required and "default" not in (a.help or "")]
    assert silent == []


def test_simulate_names_an_integrator_only_where_the_level_integrates(capsys):
    """The rigid-link levels integrate nothing in time: their header names no integrator or mesh."""
    assert main(["simulate", "smoke", "--model", "quasi-static"]) == 0
    assert capsys.readouterr().out.startswith("scene 'smoke', model quasi-static, dt = 0.001 s, rigid links: finished")
    assert main(["simulate", "smoke", "--model", "paper"]) == 0
    out = capsys.readouterr().out
    assert "model paper, newmark, dt = 0.001 s, 4 elements per link: finished" in out
    assert out.splitlines()[-1].startswith("note: paper level: its velocity and acceleration errors")
    assert main(["simulate", "smoke", "--model", "paper", "--json"]) == 0
    assert "they measure the step, not the robot" in json.loads(capsys.readouterr().out)["notes"][0]


def test_a_bare_shipped_name_beside_a_copy_of_its_file_says_which_it_reads(configs, tmp_path, monkeypatch, capsys):
    """`rss6 check paper` in a folder holding an edited paper.toml reads the shipped scene (a reviewer's silent
    surprise): it says so once, and `paper.toml` reads the copy."""
    from pipeline.scenes.catalogue import _note_shipped_over_local
    _note_shipped_over_local.cache_clear()   # said once per process
    monkeypatch.chdir(tmp_path)
    (tmp_path / "paper.toml").write_text((configs / "paper.toml").read_text())
    assert main(["check", "paper"]) == 0
    err = capsys.readouterr().err
    assert err.count("note: 'paper' is the shipped scene; paper.toml in this folder is not read") == 1, err
    assert main(["check", "paper.toml"]) == 0 and "shipped" not in capsys.readouterr().err


def test_config_help_names_the_scene_of_an_output_name_only_where_a_default_output_uses_it():
    """A command's CONFIG help says its name is the SCENE of a default output name only where another
    option's help gives such a default (SCENE in it)."""
    import argparse

    from pipeline.cli import build_parser
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    for name, command in sub.choices.items():
        config = [a for a in command._actions if a.dest == "config"]
        others = " ".join(a.help or "" for a in command._actions if a.dest != "config")
        if config:
            assert ("SCENE" in config[0].help) == ("SCENE" in others), name
