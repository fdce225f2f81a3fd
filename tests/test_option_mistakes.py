"""Every option mistake of every command ends in one line on stderr and exit code 2, before any
work: a loop over the parser's commands and options, each given a value it must refuse, and the
combinations of options that cannot work together."""
import argparse

import pytest

from pipeline.cli import build_parser, main

# a value each free-text option must refuse (options not listed take any text, e.g. paths)
BAD_TEXT = {"require": "displacement:x<=1parsec@q95", "event": "displacement:z>1parsec",
            "until": "displacement:x@q95<=5 furlongs",
            "spec": "displacement:x<=1mm@q101", "quantity": "torque", "direction": "w", "window": "midnight",
            "output": "{missing}/out", "classes": "H7/x6", "costs": "{missing}/costs.toml",
            "plots": None, "data": None, "configs": None, "file": None, "config": None, "plot": "{missing}/fig.png"}
# options that size the work: each has a ceiling, so a huge value is refused before it exhausts memory
COUNTS = {"n", "low_n", "family_n", "budget", "workers", "elements"}
# per command, what else must be given for the option to be judged (a file to read, a required option)
ANY_TEXT = {("report", "output")}   # report creates its output folder, parents included
NEEDS = {"stats": ["{file}"], "plot": ["{file}"], "budget": ["--spec", "displacement:x<=1mm@q95"],
         "allocate": ["--spec", "displacement:x<=1mm@q95"],
         "multifidelity": ["-o", "{tmp}/mf.nc"], "report": ["smoke"],
         "reliability": ["smoke", "--event", "displacement:z>0.1mm"]}
# the entry points that compute (budget and sensitivity check their request first, so they stay)
WORK = ("pipeline.ensemble.run.ensemble", "pipeline.analysis.until.run_until", "rss6core.simulate",
        "pipeline.studies.report.write_report", "pipeline.studies.tradeoff.tradeoff",
        "pipeline.studies.stability.stability", "rss6core.compile_kernels",
        "pipeline.studies.workspace_map.workspace_map", "pipeline.studies.allocation.responses",
        "pipeline.studies.allocation_joints.joint_responses", "pipeline.studies.reliability.reliability")


def _commands() -> dict[str, argparse.ArgumentParser]:
    return next(a for a in build_parser()._actions if a.dest == "command").choices


def _bad_values(action) -> list[str]:
    """Values ``action`` must refuse: outside its choices, not a number, below its range, bad text."""
    if action.nargs == 0:
        return []
    if action.choices:
        return ["no-such-choice"]
    if action.type is not None and action.dest == "seed":
        return ["x", "-1", str(2 ** 64)]   # above 2^63 - 1 the file's int64 attribute would fail at the end
    if action.dest in COUNTS:
        return ["x", "-1", "inf", "nan", str(10 ** 11)]   # 10^11: each had run out of memory in a traceback
    if action.type is not None:
        return ["x", "-1", "inf", "nan"] if action.type is not str else []
    bad = BAD_TEXT.get(action.dest, "?")
    assert bad != "?", f"no bad value known for {action.option_strings or action.dest}: add it to BAD_TEXT"
    return [] if bad is None else [bad]


def _cases():
    for name, parser in _commands().items():
        for action in parser._actions:
            if not action.option_strings or action.dest == "help":
                continue
            for bad in [] if (name, action.dest) in ANY_TEXT else _bad_values(action):
                yield pytest.param(name, action.option_strings[-1], bad, id=f"{name} {action.option_strings[-1]} {bad}")


@pytest.fixture(scope="module")
def small_file(tmp_path_factory):
    """A one-run file (rss6 simulate -o), which stats and plot read like an ensemble."""
    out = tmp_path_factory.mktemp("run") / "r.nc"
    assert main(["simulate", "smoke", "--model", "quasi-static", "-o", str(out)]) == 0
    return out


@pytest.fixture
def no_work(monkeypatch):
    """Every entry point that computes raises: a mistake must be refused before it.  Every pipeline
    module is imported first, so none first imported during a test binds a stub for good (a module
    level ``from ..ensemble.run import ensemble`` would keep it after the patch is undone)."""
    import importlib
    import pkgutil

    import pipeline
    for info in pkgutil.walk_packages(pipeline.__path__, "pipeline."):
        importlib.import_module(info.name)
    for target in WORK:
        module, _, name = target.rpartition(".")
        monkeypatch.setattr(importlib.import_module(module), name,
                            lambda *a, **k: pytest.fail("work started before the mistake was refused"))


def _run(argv: list[str], capsys, tmp_path, small_file) -> tuple[int, list[str]]:
    fill = {"file": str(small_file), "tmp": str(tmp_path), "missing": str(tmp_path / "no" / "such")}
    argv = [a.format(**fill) for a in argv]
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    return code, [line for line in capsys.readouterr().err.splitlines() if line.strip()]


@pytest.mark.parametrize("command, option, bad", list(_cases()))
def test_an_option_mistake_is_one_line_and_exit_2(command, option, bad, capsys, tmp_path, small_file, no_work):
    code, err = _run([command, *NEEDS.get(command, []), option, bad], capsys, tmp_path, small_file)
    assert code == 2 and len(err) == 1, err
    assert option in err[0] or bad.format(missing="") in err[0] or "no" in err[0], err


@pytest.mark.parametrize("argv, says, not_says", [
    (["run", "smoke", "-n", "100000000"], "at most 10000000 per ensemble (a rare event: rss6 reliability",
     "evaluations"),
    (["reliability", *NEEDS["reliability"], "--budget", "100000000"], "at most 10000000 model evaluations",
     "rare event"),
    (["reliability", *NEEDS["reliability"], "-n", "100000000"], "at most 10000000 model evaluations",
     "rare event")])
def test_a_size_past_its_ceiling_says_what_the_command_counts(argv, says, not_says, capsys, tmp_path, small_file,
                                                              no_work):
    """rss6 reliability counts model evaluations and is itself the rare-event route: its ceiling does not
    point to itself as an ensemble's does."""
    code, err = _run(argv, capsys, tmp_path, small_file)
    assert code == 2 and len(err) == 1 and says in err[0] and not_says not in err[0], err


COMBINATIONS = [
    ["run", "smoke", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"],
    ["run", "smoke", "--worker-timeout", "5"],
    ["run", "smoke", "--model", "quasi-static", "--replicates", "4"],
    ["run", "smoke", "--model", "quasi-static", "--undecided", "pass"],
    ["run", "smoke", "--model", "quasi-static", "--start", "drawn"],
    ["run", "smoke", "--model", "elastic", "--sampler", "qmc"],
    ["run", "smoke", "--model", "quasi-static", "--dt", "0.0007"],
    ["run", "smoke", "--model", "quasi-static", "-n", "10", "--sampler", "qmc", "--replicates", "4"],
    ["stats", "{file}", "--undecided", "fail"],
    ["stats", "{file}", "--require", "displacement:x<=1mm@q95", "--confidence", "0.3"],
    ["multifidelity", "-o", "{tmp}/m.nc", "--high", "paper", "--low", "paper"],
    ["multifidelity", "-o", "{tmp}/m.nc", "--low", "elastic"],
    ["multifidelity", "-o", "{tmp}/m.nc", "-n", "8", "--low-n", "4"],
    ["multifidelity", "-o", "{tmp}/m.nc", "--width", "0.1"],
    ["report", "smoke", "--worker-timeout", "5"],
    ["allocate", "smoke", "--spec", "displacement:x<=1mm@q95", "--per-joint", "--model", "contact"],
    ["allocate", "smoke", "--spec", "displacement:x<=1mm@pf<=1e-2", "-n", "100", "--per-joint"],
    ["sensitivity", "smoke", "-n", "100"],
    ["simulate", "smoke", "--model", "elastic", "--start", "equilibrium"],
    ["map", "smoke", "--model", "elastic"],
    ["map", "smoke", "--grid", "y:-0.05:0.05:5"],
    ["map", "smoke", "--grid", "y:-0.05:0.05:5", "--grid", "y:-0.01:0.01:5"],
    ["map", "smoke", "--grid", "y:0.05:-0.05:5", "--grid", "z:-0.4:-0.3:5"],
    ["map", "smoke", "--grid", "n1:-10:10:1", "--grid", "z:-0.4:-0.3:5"],
    # values past what a run can hold or mean (bad-input audit: each had run out of memory, hung or
    # ended in a traceback)
    ["run", "smoke", "--elements", "65"],
    ["run", "smoke", "--workers", "257"],
    ["run", "smoke", "-n", "10000001"],
    ["run", "smoke", "--model", "quasi-static", "--dt", "0.1"],
    ["run", "smoke", "--model", "quasi-static", "--dt", "1e9"],
    ["run", "smoke", "--model", "quasi-static", "--dt", "1e-8"],
    ["run", "smoke", "--model", "quasi-static", "--dt", "1e-12"],   # counted, not built: 1.5 TiB of grid
    ["simulate", "smoke", "--realization", str(2 ** 63)],
    ["budget", "smoke", "--spec", "displacement:z<=0mm@q95"],
    ["stats", "{file}", "--require", "displacement:x<=-1mm@q95"],
    ["stats", "{file}", "--event", "displacement:z>-1mm"],
    ["map", "smoke", "--grid", "x:-0.01:0.01:100000", "--grid", "y:-0.01:0.01:5"],
    ["run", "smoke", "--model", "quasi-static", "--integrator", "hht"],
    ["allocate", "smoke", "--spec", "displacement:x<=1mm@q95", "--classes", ""],
    ["reliability", "smoke", "--event", "displacement:z>0.1mm", "-n", "10000001"],
    ["budget", "smoke", "--spec", "displacement:x<=1mm@q95", "-n", "10000001"],
    ["allocate", "smoke", "--spec", "displacement:x<=1mm@q95", "-n", "10000001"],
    ["allocate", "smoke", "--spec", "displacement:x<=1mm@q95", "--classes", " , "],
    ["simulate", "smoke", "--model", "rigid", "--integrator", "newmark"],
    ["report", "smoke", "-o", "{file}"],
    ["report", "smoke", "-o", "{tmp}/r", "--data", "{file}"],
    ["sensitivity", "smoke", "-n", "64", "-o", "{tmp}/s.nc", "--plots", "{file}"],
    ["sensitivity", "smoke", "-n", "64", "-o", "{tmp}/s.nc", "--plots", "{tmp}/p", "--no-plots"],
    ["sensitivity", "smoke", "-n", str(2 ** 40)],             # a power of 2: past the form's own check
    ["reliability", "smoke", "--event", "displacement:z>0.1mm", "--cov", "0.1", "--budget", str(10 ** 11)],
    ["multifidelity", "-o", "{tmp}/m.nc", "-n", str(10 ** 11), "--low-n", str(10 ** 11)],
]


@pytest.mark.parametrize("argv", COMBINATIONS, ids=" ".join)
def test_options_that_cannot_work_together_are_one_line_and_exit_2(argv, capsys, tmp_path, small_file, no_work):
    code, err = _run(argv, capsys, tmp_path, small_file)
    assert code == 2 and len(err) == 1 and err[0].startswith("rss6"), err


def test_the_loop_covers_every_command_and_the_seed_of_each():
    cases = {(c.values[0], c.values[1]) for c in _cases()}
    assert {c for c, _ in cases} == set(_commands()) - {"check", "warm", "plot"} | {"plot"}
    assert {c for c, o in cases if o == "--seed"} >= {"tradeoff", "stability", "report", "run", "simulate"}


@pytest.mark.parametrize("argv, says", [
    (["run", "smoke", "--event", "displacement:z>0.1mm"],
     "rss6 run: error: unrecognized arguments: --event displacement:z>0.1mm; --event is an option of "
     "rss6 stats, rss6 reliability (see rss6 run -h)"),
    (["run", "smoke", "--workrs=2"], "rss6 run: error: unrecognized arguments: --workrs=2; run has no --workrs; "
                                     "did you mean --workers? (see rss6 run -h)"),
    (["check", "smoke", "--zzz"],
     "rss6 check: error: unrecognized arguments: --zzz; check has no --zzz (see rss6 check -h)"),
    (["stats", "{file}", "extra"], "rss6 stats: error: unrecognized arguments: extra (see rss6 stats -h)"),
], ids=["another command's option", "a typo", "nothing near", "a value"])
def test_an_option_the_command_does_not_take_names_the_commands_that_do_or_the_nearest(argv, says, capsys, tmp_path,
                                                                                    small_file, no_work):
    code, err = _run(argv, capsys, tmp_path, small_file)
    assert code == 2 and err == [says], err


def test_a_negative_value_read_as_an_option_says_how_to_write_it(capsys, tmp_path, small_file, no_work):
    """argparse takes "-1e-6" for an option; the line says to write --dt=-1e-6, which then names the value."""
    code, err = _run(["simulate", "smoke", "--dt", "-1e-6"], capsys, tmp_path, small_file)
    assert code == 2 and err == ["rss6 simulate: error: argument --dt: expected one argument; a value that starts "
                                 "with '-' (-1e-6) is read as an option: write --dt=-1e-6 "
                                 "(see rss6 simulate -h)"], err
    code, err = _run(["simulate", "smoke", "--dt"], capsys, tmp_path, small_file)   # a value simply missing
    assert code == 2 and err == ["rss6 simulate: error: argument --dt: expected one argument "
                                 "(see rss6 simulate -h)"], err
    code, err = _run(["simulate", "smoke", "--dt=-1e-6"], capsys, tmp_path, small_file)
    assert code == 2 and len(err) == 1 and "--dt: must be a finite positive number, got -1e-6" in err[0], err


def test_report_checks_every_scene_before_it_makes_a_folder(configs, tmp_path, capsys):
    """A scene with a typo is refused before OUT/results exists (bad-input audit)."""
    bad = tmp_path / "bad.toml"
    bad.write_text((configs / "smoke.toml").read_text().replace("duration_s", "duration_sec", 1))
    assert main(["report", str(configs / "smoke.toml"), str(bad), "-o", str(tmp_path / "R")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad.toml" in err and not (tmp_path / "R").exists(), err


@pytest.mark.parametrize("command", ["stats", "plot"])
def test_a_folder_given_as_a_file_is_named_as_a_folder(command, tmp_path, capsys):
    """As rss6 run says it, not netCDF's "Unknown file format" (bad-input audit)."""
    assert main([command, str(tmp_path)]) == 2
    assert capsys.readouterr().err.strip() == (f"rss6 {command}: error: {tmp_path}: is a folder; give an rss6 "
                                               "netCDF file")


def test_a_file_of_another_kind_is_named_by_what_wrote_it(tmp_path, small_file, capsys):
    """A statistics file (rss6 stats -o) given to stats names the command that wrote it and its title, a
    scene (text) given for a netCDF file says it is text, and a netCDF file cut short stays 'truncated or
    corrupt?' (newcomer55: all three had said 'not an rss6 ensemble file' or 'truncated or corrupt?')."""
    stats_file, scene, cut = tmp_path / "s.nc", tmp_path / "scene.toml", tmp_path / "cut.nc"
    assert main(["stats", str(small_file), "-o", str(stats_file)]) == 0
    scene.write_text("[geometry]\nbase_radius_m = 0.2\n")
    cut.write_bytes(small_file.read_bytes()[:1000])
    capsys.readouterr()
    said = {}
    for path in (stats_file, scene, cut):
        code, err = _run(["stats", str(path)], capsys, tmp_path, small_file)
        assert code == 2 and len(err) == 1, err
        said[path] = err[0]
    assert f"{stats_file}: not an rss6 ensemble file (rss6 run -o) but \"rss6 statistics of" in said[stats_file]
    assert f"{scene}: not a netCDF file but text (a scene file?" in said[scene]
    assert f"{cut}: not a readable netCDF file (truncated or corrupt?)" in said[cut]


@pytest.mark.parametrize("argv, says", [
    (["check", "{tmp}"], "is a folder; give a scene file (.toml) or a shipped scene (paper,"),
    (["check", "configs/paper.toml"], "no such scene file; the shipped scene of that name is 'paper'"),
    (["run", "smoke", "--require", "displacement:z<=1mm@q95/stedy"], "--require 'displacement:z<=1mm@q95/stedy': "
                                                                     "unknown window 'stedy'")])
def test_a_scene_or_window_mistake_says_what_was_meant(argv, says, capsys, tmp_path, small_file, no_work, monkeypatch):
    """newcomer55: a folder given as a scene, the repository's path of a shipped scene used from another folder,
    and a spec's window typo, each one line naming what is wrong."""
    monkeypatch.chdir(tmp_path)
    code, err = _run(argv, capsys, tmp_path, small_file)
    assert code == 2 and len(err) == 1 and says in err[0], err


def test_a_folder_named_like_a_shipped_scene_leaves_the_name_to_the_scene(tmp_path, monkeypatch, capsys):
    """A folder 'paper' in the working folder (an output folder, say) does not hide the shipped scene."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "paper").mkdir()
    assert main(["check", "paper"]) == 0
    assert capsys.readouterr().out.startswith("scene 'paper' (paper): valid\n")


@pytest.mark.parametrize("argv", [["run", "smoke", "--model", "quasi-static", "-n", "2"], ["simulate", "smoke"],
                                  ["plot", "x.nc"], ["map", "smoke"]])
@pytest.mark.parametrize("output, says", [("", "-o: the path is empty"), (" ", "-o: the path is empty"),
                                          (" x.nc", "starts or ends with whitespace"),
                                          ("sub/x.nc ", "starts or ends with whitespace")])
def test_an_empty_or_padded_output_path_is_refused(argv, output, says, tmp_path, monkeypatch, capsys):
    """`-o ''` (an unset shell variable, say) had silently written the default file or folder; a name with
    a leading space, which the netCDF library strips, had ended in a traceback and stray files."""
    monkeypatch.chdir(tmp_path)
    assert main([*argv, "-o", output]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err, err
    assert list(tmp_path.iterdir()) == []
