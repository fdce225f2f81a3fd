"""The command line guards its user: options and output paths checked before work, one writer per
output, failures shown, resumed parts verified, a quiet exit on Ctrl-C and on a closed pipe."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from pipeline.cli import main
from pipeline.commands.messages import warn_oversubscription
from pipeline.files.outputs import OutputLock, PartsManifest
from pipeline.ensemble.run import TEST_HOLD_ENV, EnsembleSpec, ensemble, run_chunk
from pipeline.files.opening import open_ensemble
from pipeline.files.schema import EnsembleFileError
from pipeline.files.writing import write_netcdf
from pipeline.analysis.summary import failure_reasons
from pipeline.vocabulary import OptionError
from importlib import resources

from pipeline.scenes.catalogue import PACKAGE

CONFIGS = Path(str(resources.files(PACKAGE)))

SMOKE = CONFIGS / "smoke.toml"
QS = ["run", str(SMOKE), "--model", "quasi-static", "--workers", "1"]


def _spec(n_seed=3):
    return EnsembleSpec(SMOKE.read_text(), str(SMOKE), "quasi-static", "newmark", 1e-3, 4, n_seed)


def _holding(first: int, release: Path) -> dict:
    """The environment of a run whose chunks from realisation ``first`` on wait until ``release``
    exists (pipeline.ensemble.run.TEST_HOLD_ENV): a test then acts in a known state, not after a time."""
    return dict(os.environ, **{TEST_HOLD_ENV: f"{first}:{release}"})


def _held_run(out: Path, n: int, first: int, release: Path) -> subprocess.Popen:
    """`rss6 run` of n realisations, a chunk each, into ``out`` in a process of its own, its chunks from
    realisation ``first`` on waiting until ``release`` exists (:func:`_holding`)."""
    return subprocess.Popen([sys.executable, "-m", "pipeline.cli", *QS, "-n", str(n), "--chunk", "1", "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_holding(first, release))


def _wait_for(state, proc) -> None:
    """Until ``state()`` holds; fails if ``proc`` ends first."""
    while not state():
        assert proc.poll() is None, f"the run ended first: {proc.communicate()}"
        time.sleep(0.02)


def _one_line_error(capsys, *words):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    return err


def _error_after_progress(capsys, *words):
    """A run's stderr: its progress lines, then one line of error naming ``words``, no traceback."""
    err = capsys.readouterr().err.strip().splitlines()
    assert not any("Traceback" in line for line in err), err
    assert [line for line in err if "error:" in line] == err[-1:], err
    assert all(w in err[-1] for w in words), err


def _exit_code(argv) -> int:
    """main's return value, or argparse's exit code for a rejected option."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


@pytest.mark.parametrize("option, words", [(["--dt", "0.003"], ["--dt", "does not divide"]),
                                           (["--seed", "-1"], ["--seed", "0 or more"]),
                                           (["--workers", "0"], ["--workers"])])
def test_bad_option_values_stop_before_any_work(option, words, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert _exit_code(["run", "paper", "--model", "paper", *option, "-o", "x.nc"]) == 2
    _one_line_error(capsys, *words)
    assert list(tmp_path.iterdir()) == []


def test_missing_output_folder_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    """Refused before the simulation starts (a state, not a time: no simulate call at all)."""
    import rss6core

    def simulate(*args, **kwargs):
        raise AssertionError("simulated before the output path was checked")
    monkeypatch.setattr(rss6core, "simulate", simulate)
    assert main(["simulate", "paper", "-o", "/nonexistent/x.nc"]) == 2
    _one_line_error(capsys, "/nonexistent", "--parents")
    assert main([*QS, "-n", "2", "-o", str(tmp_path / "a" / "typo" / "out.nc")]) == 2
    _one_line_error(capsys, "does not exist")
    assert not (tmp_path / "a").exists()


def test_parents_creates_the_folder(tmp_path, capsys):
    out = tmp_path / "new" / "sim.nc"
    assert main(["simulate", "smoke", "--model", "rigid", "-o", str(out), "--parents"]) == 0
    assert out.exists()


def test_read_only_folder_is_refused(tmp_path, capsys):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        if os.access(folder, os.W_OK):
            pytest.skip("running as a user who can write anywhere")
        assert main(["simulate", "smoke", "--model", "rigid", "-o", str(folder / "x.nc")]) == 2
        _one_line_error(capsys, "not writable")
    finally:
        folder.chmod(0o700)


@pytest.fixture(scope="module")
def small_ensemble(tmp_path_factory):
    path = tmp_path_factory.mktemp("ens") / "qs.nc"
    assert main([*QS, "-n", "4", "-o", str(path)]) == 0
    return path


@pytest.mark.parametrize("argv, words", [
    (["stats", "{ens}", "-o", "{ens}"], ["rss6 stats does not overwrite"]),
    (["simulate", "smoke", "--model", "rigid", "-o", "{ens}"], ["rss6 simulate does not overwrite"]),
    (["multifidelity", "smoke", "--high", "paper", "-n", "3", "--low-n", "3", "-o", "{ens}"],
     ["not an rss6 multi-fidelity file"]),
    (["run", "smoke", "--model", "quasi-static", "-n", "2", "-o", "{sim}"], ["not an rss6 ensemble file"]),
    (["stats", "{ens}", "-o", "{dir}/missing/s.nc"], ["does not exist", "--parents"]),
    (["plot", "{ens}", "-o", "{ens}"], ["not a folder"]),
    (["tradeoff", "smoke", "-o", "{ens}/sub"], ["is a file, not a folder"]),
    (["stability", "smoke", "-o", "{ens}"], ["not a folder"]),
    (["budget", "smoke", "--spec", "displacement:x<=1mm@q50", "-o", "{dir}/missing/b"], ["does not exist"]),
    (["plot", "{ens}", "-o", "{dir}/missing/p"], ["folder", "missing does not exist", "--parents"]),
    (["stability", "smoke", "-o", "{dir}/missing/s"], ["does not exist", "--parents"]),
    (["map", "smoke", "-o", "{ens}"], ["not a folder"]),
    (["map", "smoke", "-o", "{dir}/missing/m"], ["does not exist", "--parents"]),
])
def test_an_existing_file_or_a_bad_output_folder_is_refused_before_work(argv, words, small_ensemble, tmp_path,
                                                                        capsys):
    """Outputs checked before any work: a command that writes a new file overwrites no existing one
    (an ensemble given as its own -o survives byte for byte); a figure or study folder that is a file,
    or lies below one, is one line and exit 2, not a traceback after the work."""
    sim = tmp_path / "sim.nc"
    assert main(["simulate", "smoke", "--model", "rigid", "-o", str(sim)]) == 0
    before = small_ensemble.read_bytes(), sim.read_bytes()
    capsys.readouterr()
    names = {"ens": small_ensemble, "sim": sim, "dir": tmp_path}
    assert _exit_code([a.format(**names) for a in argv]) == 2
    _one_line_error(capsys, *words)
    assert (small_ensemble.read_bytes(), sim.read_bytes()) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sim.nc"]


@pytest.mark.parametrize("argv, words", [
    (["simulate", "smoke", "--model", "quasi-static", "--start", "equilibrium"],
     ["--start equilibrium: sets the contact level's initial state; this run is the quasi-static level"]),
    ([*QS, "-n", "2", "--start", "drawn", "-o", "{dir}/x.nc"], ["--start drawn", "quasi-static level"]),
    ([*QS, "-n", "2", "--elements", "3", "-o", "{dir}/x.nc"], ["--elements 3", "quasi-static level's links are rigid"]),
    ([*QS, "-n", "2", "--undecided", "pass", "-o", "{dir}/x.nc"], ["--undecided pass: applies with --require only"]),
    (["stats", "{ens}", "--undecided", "fail"], ["--undecided fail: applies with --require only"]),
])
def test_an_option_that_does_not_apply_is_refused_not_ignored(argv, words, small_ensemble, tmp_path, capsys):
    assert _exit_code([a.format(ens=small_ensemble, dir=tmp_path) for a in argv]) == 2
    _one_line_error(capsys, *words)
    assert list(tmp_path.iterdir()) == []


def test_plot_parents_creates_the_missing_folders(small_ensemble, tmp_path, capsys):
    assert main(["plot", str(small_ensemble), "-o", str(tmp_path / "a" / "b"), "--parents"]) == 0
    assert any((tmp_path / "a" / "b").glob("*.png"))


def test_a_rerun_rewrites_its_own_multifidelity_file(tmp_path, capsys):
    """The one output a second run may replace: F.nc of rss6 multifidelity (its ensembles resume)."""
    argv = ["multifidelity", "smoke", "--high", "paper", "--low", "quasi-static", "-n", "3", "--low-n", "4",
            "-o", str(tmp_path / "F.nc"), "--workers", "1"]
    assert main(argv) == 0
    first = xr.open_dataset(tmp_path / "F.nc").load()
    assert "realisations to compute" in capsys.readouterr().err
    assert main(argv) == 0
    assert "realisations to compute" not in capsys.readouterr().err   # both ensembles resumed whole
    xr.testing.assert_identical(xr.open_dataset(tmp_path / "F.nc").load().drop_attrs(), first.drop_attrs())


def test_elastic_default_without_clearances_is_refused(tmp_path, capsys):
    assert main(["run", str(SMOKE), "-n", "2", "-o", str(tmp_path / "e.nc")]) == 2
    _one_line_error(capsys, "'elastic'", "--model")
    assert list(tmp_path.iterdir()) == []


def test_workers_beyond_the_cores_are_warned_about(capsys):
    warn_oversubscription((os.cpu_count() or 1) + 1, None)
    assert "exceeds" in capsys.readouterr().err
    warn_oversubscription(1, None)
    warn_oversubscription(1000, "tcp://elsewhere:8786")  # an external cluster has its own cores
    assert capsys.readouterr().err == ""


# --- one writer per output -------------------------------------------------------------------

def test_a_live_lock_refuses_a_second_writer_and_a_stale_one_is_taken_over(tmp_path, capsys):
    out = tmp_path / "locked.nc"
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        Path(str(out) + ".lock").write_text(
            f'{{"pid": {holder.pid}, "host": "{os.uname().nodename}", "since": "now"}}')
        assert main([*QS, "-n", "2", "-o", str(out)]) == 2
        _one_line_error(capsys, f"process {holder.pid}", "being written")
    finally:
        holder.kill()
        holder.wait()
    assert main([*QS, "-n", "2", "-o", str(out)]) == 0   # the holder is gone: its lock is stale
    assert "taking over the stale lock" in capsys.readouterr().err
    assert open_ensemble(out).sizes["realization"] == 2 and not Path(str(out) + ".lock").exists()


def test_two_concurrent_runs_the_second_names_the_first(tmp_path, capsys):
    """The first run holds its lock while its chunks wait (TEST_HOLD_ENV) until the second is refused."""
    out, release = tmp_path / "both.nc", tmp_path / "release"
    first = _held_run(out, 6, 0, release)
    lock = Path(str(out) + ".lock")
    try:
        _wait_for(lock.exists, first)
        assert main([*QS, "-n", "6", "--chunk", "1", "-o", str(out)]) == 2
        _one_line_error(capsys, f"process {first.pid}")
    finally:
        release.touch()
    assert first.wait(120) == 0
    assert open_ensemble(out).sizes["realization"] == 6 and not lock.exists()


def test_stats_of_an_output_a_run_is_still_writing_says_so(tmp_path, capsys):
    """The run holds its lock and has stored parts (its chunks from realisation 2 on wait): reading
    its output names the run, the lock and the parts, not a missing file; once done, it reads."""
    out, release = tmp_path / "wip.nc", tmp_path / "release"
    run = _held_run(out, 4, 2, release)
    parts = Path(str(out) + ".parts")
    try:
        _wait_for(lambda: len(list(parts.glob("*.nc"))) == 2, run)
        assert main(["stats", str(out)]) == 2
        _one_line_error(capsys, f"{out}: not written yet: process {run.pid} ", "is still writing it",
                        f"lock {out}.lock", f"finished parts in {parts}")
    finally:
        release.touch()
    assert run.wait(120) == 0
    assert main(["stats", str(out)]) == 0


def test_stats_of_an_output_whose_run_stopped_names_its_parts(tmp_path, capsys):
    out = tmp_path / "stopped.nc"
    Path(str(out) + ".parts").mkdir()
    assert main(["stats", str(out)]) == 2
    _one_line_error(capsys, f"{out}: not written yet: the run writing it stopped", f"parts in {out}.parts",
                    "rerun the command")
    Path(str(out) + ".parts").rmdir()
    assert main(["stats", str(out)]) == 2
    assert capsys.readouterr().err.strip() == f"rss6 stats: error: {out}: no such file"


def test_lock_is_released_by_its_owner_only(tmp_path):
    lock = OutputLock(tmp_path / "x.nc")
    with lock:
        assert lock.path.exists()
        with pytest.raises(EnsembleFileError, match="already being written"):
            OutputLock(tmp_path / "x.nc").acquire()
    assert not lock.path.exists()


# --- failures shown ---------------------------------------------------------------------------

def test_failure_reasons_count_each_reason_whatever_its_numbers():
    """Messages alike but for their numbers (time, step, size) are one reason, shown by its first."""
    status = np.array(["failed", "finished", "failed", "failed", "failed", "failed"], dtype=object)
    newton = "Newton did not converge in 60 iterations at t = 0.5 s"
    size = "size 1.15 exceeds 1 m at t = 0.002 s, step 2"
    message = np.array([newton, "", size, size, "size 2.5e+01 exceeds 1 m at t = 0.013 s, step 13",
                        "Newton did not converge in 60 iterations at t = 1.25 s"], dtype=object)
    ds = xr.Dataset({"status": ("realization", status), "status_message": ("realization", message)})
    same = " (the first; the rest differ only in their numbers)"
    assert failure_reasons(ds) == ["5 of 6 realisations failed:", f"  3 x {size}{same}", f"  2 x {newton}{same}"]
    assert failure_reasons(ds.isel(realization=[0, 1])) == ["1 of 2 realisations failed:", f"  1 x {newton}"]
    assert failure_reasons(ds.isel(realization=[1])) == []


def test_all_realisations_failing_is_one_line_exit_2_and_the_file_keeps_them(tmp_path, capsys):
    """Newmark with beta = 0.01 (conditionally stable) at 1 ms diverges at the elastic level: the run writes
    the file (no finished work lost) and ends in one line naming it and the reason, exit 2, with or
    without --require (whose verdicts' missing estimates had broken the file's strict-JSON attribute);
    stats, --event and plot refuse the file in one line too."""
    out = tmp_path / "fail.nc"
    scene = tmp_path / "beta.toml"
    scene.write_text(SMOKE.read_text().replace("newmark_beta = 0.25", "newmark_beta = 0.01", 1))
    diverging = ["--model", "elastic", "--workers", "1"]
    assert main(["run", str(scene), *diverging, "-n", "2", "-o", str(out)]) == 2
    _error_after_progress(capsys, f"{out}: all 2 realisations failed", "2 of 2: elastic displacement",
                          "divergence limit")
    assert xr.open_dataset(out).attrs["n_failed"] == 2
    required = tmp_path / "required.nc"
    assert main(["run", str(scene), *diverging, "-n", "2", "--require", "displacement:z<=1mm@q95",
                 "-o", str(required)]) == 2
    _error_after_progress(capsys, f"{required}: all 2 realisations failed")
    assert json.loads(xr.open_dataset(required).attrs["requirements"])[0]["estimate"] is None
    until = tmp_path / "until.nc"
    assert main(["run", str(scene), *diverging, "-n", "16", "--until", "displacement:z@mean<=1%",
                 "-o", str(until)]) == 2
    _error_after_progress(capsys, f"{until}: all 16 realisations failed")
    assert json.loads(xr.open_dataset(until).attrs["until_widths"])[0]["estimate"] is None
    for argv in (["stats", str(out)], ["stats", str(out), "--event", "displacement:z>1mm"]):
        assert main(argv) == 2
        _one_line_error(capsys, f"{out}: all 2 realisations failed")
    assert main(["plot", str(out), "-o", str(tmp_path / "plots")]) == 2
    _one_line_error(capsys, "nothing to plot", "divergence limit")
    single = tmp_path / "single.nc"
    assert main(["simulate", str(scene), "--model", "elastic", "-o", str(single)]) == 2
    said = capsys.readouterr()
    assert said.out == "" and len(said.err.strip().splitlines()) == 1, said   # no table of diverged maxima
    assert all(w in said.err for w in ("the elastic run failed", "divergence limit", f"{single} keeps its status"))
    assert xr.open_dataset(single).attrs["status"] == "failed"
    assert main(["simulate", str(scene), "--model", "elastic", "--json"]) == 2
    said = capsys.readouterr()   # a script reads the status from stdout; the error stays one line on stderr
    printed = json.loads(said.out)
    assert printed["status"] == "failed" and "divergence limit" in printed["message"], printed
    assert "max_abs_error" not in printed and len(said.err.strip().splitlines()) == 1, said
    for argv in (["stats", str(single)], ["stats", str(single), "--event", "displacement:z>1mm"]):
        assert main(argv) == 2   # a single run's file: it had printed a table of dashes and 0/0 = nan
        _one_line_error(capsys, f"{single}: the run failed, so it has no statistics")


# --- resume: manifest, -n, nothing to do ------------------------------------------------------

def _parts_of(out: Path, spec, realizations):
    manifest = PartsManifest(Path(str(out) + ".parts"), spec.attrs())
    return manifest, manifest.write(run_chunk(spec, realizations),
                                    f"chunk-{realizations[0]:07d}-{realizations[-1]:07d}.nc")


def test_verified_parts_resume_to_the_same_file(tmp_path):
    spec = _spec()
    whole = ensemble(spec, 4, tmp_path / "whole.nc", workers=1, progress=False)
    out = tmp_path / "resumed.nc"
    _parts_of(out, spec, [0, 1])
    resumed = ensemble(spec, 4, out, workers=1, progress=False)
    assert resumed.stored_before == 2 and resumed.computed == 2
    assert np.array_equal(resumed.dataset["max_abs_error"].values,
                          whole.dataset["max_abs_error"].values)


@pytest.mark.parametrize("tamper", ["scaled", "variable removed", "unlisted"])
def test_a_tampered_part_is_refused_by_name(tamper, tmp_path):
    spec, out = _spec(), tmp_path / "t.nc"
    _, part = _parts_of(out, spec, [0, 1])
    ds = open_ensemble(part)
    if tamper == "scaled":
        ds["max_abs_error"] = ds["max_abs_error"] * 1000
    elif tamper == "variable removed":
        ds = ds.drop_vars("eccentricity")
    else:
        part = part.with_name("chunk-0000002-0000003.nc")
    write_netcdf(ds, part)
    with pytest.raises(EnsembleFileError, match=part.name) as exc:
        ensemble(spec, 4, out, workers=1, progress=False)
    assert "recover with `rm " in str(exc.value) and not out.exists()


def test_fewer_or_as_many_realisations_as_stored_leave_the_file_alone(tmp_path, capsys):
    out = tmp_path / "keep.nc"
    assert main([*QS, "-n", "4", "-o", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    before = out.read_bytes()
    assert main([*QS, "-n", "4", "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert "nothing to do" in said and "wrote" not in said
    assert main([*QS, "-n", "2", "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert "-n 2 is fewer than the 4 stored" in said and "np." not in said
    assert out.read_bytes() == before


# --- terminal behaviour -----------------------------------------------------------------------

def test_closed_pipe_ends_quietly():
    proc = subprocess.Popen([sys.executable, "-m", "pipeline.cli", "check", "smoke"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()   # like `| head` gone before rss6 writes
    err = proc.stderr.read().decode()
    assert proc.wait(120) == 141 and "Traceback" not in err and "BrokenPipe" not in err, err


def test_ctrl_c_exits_130_without_traceback_and_keeps_the_parts(tmp_path):
    """Ctrl-C to the whole group once two chunks are stored and the others wait (TEST_HOLD_ENV)."""
    out = tmp_path / "int.nc"
    proc = subprocess.Popen([sys.executable, "-m", "pipeline.cli", *QS, "-n", "4", "--chunk",
                             "1", "-o", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True, env=_holding(2, tmp_path / "never"))
    parts = Path(str(out) + ".parts")
    try:
        _wait_for(lambda: len(list(parts.glob("*.nc"))) == 2, proc)
        os.killpg(proc.pid, signal.SIGINT)   # what a terminal's Ctrl-C does: the whole group
        _, err = proc.communicate(timeout=60)   # one Ctrl-C is enough
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    err = err.decode()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err, err
    assert len(list(parts.glob("*.nc"))) == 2 and not Path(str(out) + ".lock").exists()


def test_report_refuses_to_overwrite_tracked_files(tmp_path, capsys):
    repo = tmp_path / "repo"
    (repo / "docs").mkdir(parents=True)
    (repo / "docs" / "results.md").write_text("committed\n")
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-C", str(repo)]
    subprocess.run(["git", "init", "-q", str(repo)], check=True)
    subprocess.run([*git, "add", "docs/results.md"], check=True)
    subprocess.run([*git, "commit", "-qm", "x"], check=True)
    assert main(["report", "smoke", "-o", str(repo / "docs"), "-n", "2"]) == 2
    _one_line_error(capsys, "results.md", "git tracks", "--overwrite-tracked")
    assert (repo / "docs" / "results.md").read_text() == "committed\n"
    from pipeline.cli import build_parser
    assert build_parser().parse_args(["report", "smoke"]).output == "rss6-report"


def test_progress_starts_at_once_and_gives_an_eta():
    import io

    from pipeline.ensemble.progress import _Progress
    stream = io.StringIO()
    bar = _Progress(10, 2, stream)
    bar.begin(4, "2 workers")
    assert stream.getvalue().startswith("rss6 run: 8 realisations to compute in 4 chunks on 2 workers")
    assert "(2 stored)" in stream.getvalue() and "compil" not in stream.getvalue()   # said where it holds
    bar.start -= 4.0          # 4 s for the first 2 computed: 6 left take about 12 s
    bar.advance(2)
    assert "4/10" in stream.getvalue() and "about 12 s left" in stream.getvalue()


def test_check_shows_clearances_laws_contact_and_the_run_default(capsys):
    import json
    assert main(["check", "paper_050", "--json"]) == 0
    wide = json.loads(capsys.readouterr().out)
    assert main(["check", "paper", "--json"]) == 0
    paper = json.loads(capsys.readouterr().out)
    assert wide["clearances_m"]["spherical_B"] == pytest.approx(2 * paper["clearances_m"]["spherical_B"])
    assert paper["sampling"]["direction"] in ("uniform", "paper")
    assert paper["contact"]["restitution"] == 0.9 and paper["run_default_level"] is None
    assert main(["check", "paper_050"]) == 0
    text = capsys.readouterr().out
    assert "clearances [mm]: revolute_radial 0.5" in text and "asks for --model" in text


def test_full_disk_is_one_line_and_keeps_the_parts(tmp_path, monkeypatch, capsys):
    """The merge needs the ensemble's size free; with less the run stops before writing, in one line."""
    import shutil
    from collections import namedtuple
    spec, out = _spec(), tmp_path / "full.nc"
    _parts_of(out, spec, [0, 1])
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10 ** 9, 10 ** 9, 1000))
    assert main([*QS, "--seed", "3", "-n", "2", "-o", str(out)]) == 2
    _one_line_error(capsys, "not enough disk space", "MiB free")
    assert not out.exists() and len(list(Path(str(out) + ".parts").glob("*.nc"))) == 1


def test_simulate_on_a_full_disk_prints_its_answer_before_the_one_line(tmp_path, monkeypatch, capsys):
    """rss6 simulate -o on a full disk: the run's summary is printed (its work is not lost), then one line, exit 2."""
    import shutil
    from collections import namedtuple
    monkeypatch.setattr(shutil, "disk_usage", lambda p: namedtuple("u", "total used free")(0, 0, 1000))
    assert main(["simulate", "smoke", "--model", "quasi-static", "--json", "-o", str(tmp_path / "one.nc")]) == 2
    captured = capsys.readouterr()
    assert json.loads(captured.out)["status"] == "finished"
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and "not enough disk space" in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_write_failing_on_a_full_disk_says_so(tmp_path, monkeypatch):
    import shutil
    from collections import namedtuple
    ds = run_chunk(_spec(), [0])
    free = iter([10 ** 9, 1000])   # room before the write, none after it failed
    monkeypatch.setattr(shutil, "disk_usage", lambda p: namedtuple("u", "total used free")(0, 0, next(free)))
    monkeypatch.setattr(xr.Dataset, "dump_to_store", lambda *a, **k: (_ for _ in ()).throw(
        RuntimeError("NetCDF: HDF error")))
    with pytest.raises(EnsembleFileError, match="not enough disk space"):
        write_netcdf(ds, tmp_path / "x.nc")
    assert list(tmp_path.iterdir()) == []


def test_help_gives_every_default():
    from pipeline.cli import build_parser
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for name in ("run", "simulate", "sensitivity", "budget"):
        for action in sub.choices[name]._actions:
            if action.option_strings and action.nargs != 0:   # options taking a value
                assert "default" in (action.help or ""), f"rss6 {name} {action.option_strings[0]}"


def test_an_explicit_step_above_the_critical_one_is_refused_before_work(tmp_path, capsys):
    """Central differences at the smoke scene's 1 ms (about 500x 2/omega_max) would diverge in every
    realisation: refused in one line naming the option, exit 2, no file; a step below the critical one
    resolves (the bound is the undamped elastic robot's, scipy's eigenvalues of K, M)."""
    from pipeline.ensemble.settings import resolve_level
    from pipeline.scenes.catalogue import find_scene
    from rss6core import natural_frequencies
    out = tmp_path / "cd.nc"
    assert main(["run", str(SMOKE), "--model", "elastic", "--integrator", "central-difference", "-n", "2",
                 "--workers", "1", "-o", str(out)]) == 2
    _one_line_error(capsys, "--integrator central-difference at the elastic level's step 0.001 s",
                    "explicit critical step 1.89e-06 s")
    assert not out.exists() and not Path(str(out) + ".parts").exists()
    scene = find_scene(str(SMOKE))
    critical = 2.0 / natural_frequencies(scene)[-1]
    duration = scene.trajectory.duration
    below, above = duration / np.ceil(duration / critical), duration / np.floor(duration / (1.01 * critical))
    assert resolve_level(scene, SMOKE, model="paper", integrator="central-difference", dt=below).dt == below
    with pytest.raises(OptionError, match=r"--dt .* with central differences: 1.0\dx the explicit critical"):
        resolve_level(scene, SMOKE, model="paper", integrator="central-difference", dt=above)
    explicit_newmark = tmp_path / "beta0.toml"   # Newmark's beta = 0 with gamma = 1/2 is central differences
    explicit_newmark.write_text(SMOKE.read_text().replace("newmark_beta = 0.25", "newmark_beta = 0.0", 1))
    assert main(["simulate", str(explicit_newmark), "--model", "elastic"]) == 2
    _one_line_error(capsys, "[simulation] integrator = 'newmark' (Newmark with beta = 0, gamma = 0.5)",
                    "528x the explicit critical step 1.89e-06 s")


@pytest.mark.parametrize("model", ["quasi-static", "paper"])
def test_a_files_history_is_a_command_that_reruns_it(model, tmp_path, capsys):
    """The history names the options that fix the results, and only those the level takes (a quasi-static
    file's named --integrator and --elements, which rss6 refuses there): rerun, it gives the same values."""
    import shlex
    first = tmp_path / "first.nc"
    assert main(["run", str(SMOKE), "--model", model, "-n", "2", "--workers", "1", "-o", str(first)]) == 0
    history = xr.open_dataset(first).attrs["history"]
    argv = shlex.split(history)[1:]
    assert argv[:2] == ["run", "smoke"] and ("--integrator" in argv) == (model == "paper"), history
    again = tmp_path / "again.nc"
    assert main([*argv, "--workers", "1", "-o", str(again)]) == 0, capsys.readouterr().err
    xr.testing.assert_identical(open_ensemble(again).drop_attrs(), open_ensemble(first).drop_attrs())
