"""An interrupted `rss6 reliability` run resumes from OUT.checkpoint.nc to the result of an uninterrupted
one (the same seed schedule): interrupted deterministically, by a Ctrl-C raised in the evaluation of a
chosen batch (after level 0, or within level 1), not by timing. A checkpoint left behind is refused
without --resume, and a second run on a finished output is refused (exit 2)."""
import io
import json
import math
import re
from contextlib import redirect_stdout

import numpy as np
import pytest

import pipeline.studies.reliability as study
from pipeline.cli import main
from pipeline.files.reading import load_netcdf

RARE = "displacement:z>0.2mm"


def _argv(out, *extra):
    return ["reliability", "smoke", "--event", RARE, "-n", "200", "--workers", "1", "-o", str(out), "--json", *extra]


def _interrupt_at(monkeypatch, batch: int) -> list:
    """Ctrl-C when batch ``batch`` (0: level 0's draws) is evaluated; the sizes of the batches evaluated."""
    seen, evaluate = [], study.evaluate

    def stop(spec, window, z, client=None):
        if len(seen) == batch:
            raise KeyboardInterrupt
        seen.append(len(z))
        return evaluate(spec, window, z, client)
    monkeypatch.setattr(study, "evaluate", stop)
    return seen


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    """An uninterrupted run: its JSON, file and path."""
    out = tmp_path_factory.mktemp("whole") / "w.nc"
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(_argv(out)) == 0
    return json.loads(buf.getvalue()), load_netcdf(out), out


def _same_file(a, b) -> None:
    for name in ("z", "level", "max_abs_error"):
        assert np.array_equal(a[name].values, b[name].values, equal_nan=True), name
    assert json.loads(a.attrs["estimate"]) == json.loads(b.attrs["estimate"])


@pytest.mark.parametrize("batch", [1, 5])   # after level 0; after level 0 and 4 steps of level 1's chains
def test_a_run_interrupted_between_batches_resumes_to_the_uninterrupted_result(tmp_path, monkeypatch, capsys,
                                                                              whole, batch):
    out = tmp_path / "r.nc"
    seen = _interrupt_at(monkeypatch, batch)
    assert main(_argv(out)) == 130
    assert len(seen) == batch and not out.exists()
    assert "r.nc.checkpoint.nc; rerun the same command with --resume to continue" in capsys.readouterr().err
    monkeypatch.undo()
    computed = _interrupt_at(monkeypatch, 10 ** 6)   # only counts what the resumed run computes
    assert main(_argv(out, "--resume")) == 0
    res = json.loads(capsys.readouterr().out)
    assert res == whole[0] and res["si_unit"] == "m"   # RARE is a displacement: its thresholds are in m
    assert whole[1].attrs["event_limit_unit"] == "m"
    assert sum(computed) == res["evaluations"] - sum(seen)   # the stored batches were not computed again
    _same_file(load_netcdf(out), whole[1])
    assert out.read_bytes() == whole[2].read_bytes()   # no wall time or other run-dependent attribute
    assert not (tmp_path / "r.nc.checkpoint.nc").exists()


def test_a_left_checkpoint_needs_resume_and_a_finished_output_is_not_recomputed(tmp_path, monkeypatch, capsys):
    out = tmp_path / "r.nc"
    _interrupt_at(monkeypatch, 1)
    assert main(_argv(out)) == 130
    monkeypatch.undo()
    capsys.readouterr()
    assert main(_argv(out)) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "checkpoint; rerun the same command with --resume" in err
    assert main(_argv(out, "--resume", "--seed", "4")) == 2     # another request
    assert "made by a different request" in capsys.readouterr().err
    assert main(_argv(out, "--resume")) == 0
    answer = json.loads(capsys.readouterr().out)
    monkeypatch.setattr(study, "evaluate", lambda *a, **k: pytest.fail("evaluated again"))
    for extra in ([], ["--resume"]):   # the same request: answered from the file
        assert main(_argv(out, *extra)) == 0
        assert json.loads(capsys.readouterr().out) == answer
    assert main(_argv(out, "--seed", "4")) == 2
    assert "another rss6 reliability request (--seed 0 there, 4 now)" in capsys.readouterr().err


def test_a_tampered_answer_file_is_refused_before_it_is_said_to_answer(tmp_path, capsys, whole):
    """The rerun reads the file first: a changed estimate is one line naming it, not 'already answers'."""
    import shutil

    import netCDF4
    out = tmp_path / "t.nc"
    shutil.copy(whole[2], out)
    with netCDF4.Dataset(out, "a") as nc:
        nc.estimate = nc.estimate.replace('"pf": ', '"pf": 0.5, "was": ', 1)
    assert main(_argv(out)) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "attribute estimate" in err and "already answers" not in err, err


def test_resume_without_a_checkpoint_says_it_starts_from_the_first_batch(tmp_path, capsys, whole):
    out = tmp_path / "r.nc"
    assert main(_argv(out, "--resume")) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out) == whole[0]
    assert f"note: --resume found no checkpoint at {out}.checkpoint.nc: the run starts from its first batch" \
        in captured.err


# --cov: a CoV target (issue 40 "Rare events")

EVENT = "displacement:z>0.15mm"   # P about 0.1 at the smoke scene's quasi-static level


def _run_json(capsys, argv) -> dict:
    capsys.readouterr()
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_mc_adds_blocks_until_the_cov_target_and_no_further(tmp_path, capsys):
    """The CoV sqrt((1 - P) / (n P)), recomputed from the file after each block of 1000: above the
    target until the last block, at most the target after it; the draws are those of a plain run."""
    out = tmp_path / "m.nc"
    res = _run_json(capsys, ["reliability", "smoke", "--event", EVENT, "--method", "mc", "--cov", "0.06",
                             "--workers", "1", "-o", str(out), "--json"])
    hits = load_netcdf(out)["max_abs_error"].sel(quantity="displacement", direction="z").values > 1.5e-4
    n = len(hits)
    assert n % 1000 == 0 and res["evaluations"] == n and res["status"] == "converged"

    def cov(m):
        k = hits[:m].sum()
        return np.sqrt((1 - k / m) / k)
    assert cov(n) <= 0.06 < cov(n - 1000) and res["cov"] == pytest.approx(cov(n))
    plain = _run_json(capsys, ["reliability", "smoke", "--event", EVENT, "--method", "mc", "-n", str(n),
                               "--workers", "1", "-o", str(tmp_path / "p.nc"), "--json"])
    assert plain["pf"] == res["pf"] and plain["upper"] == res["upper"]


def test_subset_doubles_n_within_its_budget(tmp_path, capsys):
    """A target the first run meets: one run. An unreachable one: N = 200, 400, 800, ... each run taking at most
    the levels left in the budget (N, then (1 - p0) N per level), so the evaluations never exceed it."""
    base = ["reliability", "smoke", "--event", RARE, "-n", "200", "--workers", "1", "--json"]
    met = _run_json(capsys, base + ["--cov", "0.9", "-o", str(tmp_path / "a.nc")])
    assert met["status"] == "converged" and met["evaluations_per_level"][0] == 200 and met["cov"] <= 0.9
    assert "1 run(s) up to N = 200" in met["message"]
    capped = _run_json(capsys, base + ["--cov", "0.01", "--budget", "10000", "-o", str(tmp_path / "b.nc")])
    assert capped["status"] == "budget" and capped["cov"] > 0.01 and math.isfinite(capped["pf"])
    runs, n_last = re.search(r"(\d+) run\(s\) up to N = (\d+)", capped["message"]).groups()
    assert int(runs) >= 2 and int(n_last) == 200 * 2 ** (int(runs) - 1)
    spent = int(capped["message"].split("evaluations in all")[0].rsplit(", ", 1)[1])
    assert spent <= 10000 and "budget of 10000" in capped["message"]


def test_a_budget_below_the_first_subset_run_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    """N = 1000 needs 1000 + 900 = 1900 evaluations for its first level: --budget 1899 (or 5) cannot hold it, so
    no evaluation runs (it used to run 1900 and call them within a budget of 5)."""
    monkeypatch.setattr(study, "evaluate", lambda *a, **k: pytest.fail("work started"))
    for budget in ("5", "1899"):
        capsys.readouterr()
        code = main(["reliability", "smoke", "--event", EVENT, "--cov", "0.5", "--budget", budget,
                     "-o", str(tmp_path / "x.nc")])
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1, err
        assert f"--budget {budget}" in err and "N = 1000" in err and "1900" in err, err
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("extra, token", [
    (["--cov", "0"], "between 0 and 1"), (["--cov", "1"], "between 0 and 1"), (["--cov", "-0.2"], "between 0 and 1"),
    (["--budget", "5000"], "--budget: applies with --cov only"),
    (["--method", "mc", "--cov", "0.1", "-n", "5000"], "cap them with --budget"),
])
def test_a_bad_cov_request_is_one_line_exit_2(tmp_path, capsys, monkeypatch, extra, token):
    monkeypatch.setattr(study, "reliability", lambda *a, **k: pytest.fail("work started"))
    capsys.readouterr()
    try:
        code = main(["reliability", "smoke", "--event", EVENT, *extra, "-o", str(tmp_path / "x.nc")])
    except SystemExit as exc:   # argparse's refusal of a value
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and token in err, err


def test_mc_without_a_cov_target_claims_no_convergence(tmp_path, capsys):
    """A fixed -n of plain Monte Carlo is 'finished' (the draws asked for), not 'converged', which only
    a met CoV target or subset simulation's last level earns."""
    res = _run_json(capsys, ["reliability", "smoke", "--event", EVENT, "--method", "mc", "-n", "1000",
                             "--workers", "1", "-o", str(tmp_path / "m.nc"), "--json"])
    assert res["status"] == "finished" and res["evaluations"] == 1000


def test_a_rerun_of_the_same_request_answers_from_its_file_and_draws_the_missing_figure(tmp_path, capsys,
                                                                                        monkeypatch):
    """A run interrupted after writing its file (the figure deleted stands for it): the same command prints the
    answer from the file, evaluates nothing and draws the figure; another --event onto the file is refused in
    one line naming it (it used to refuse both: 'exists; rss6 reliability does not overwrite a file')."""
    out, png = tmp_path / "r.nc", tmp_path / "r.png"
    argv = ["reliability", "smoke", "--model", "quasi-static", "--event", EVENT, "-o", str(out), "--plot", str(png)]
    first = _run_json(capsys, argv + ["--json"])
    png.unlink()
    monkeypatch.setattr(study, "evaluate", lambda *a, **k: pytest.fail("evaluated again"))
    again = _run_json(capsys, argv + ["--json"])
    assert png.exists() and again == first
    capsys.readouterr()
    assert main(argv) == 0 and f"read back {out}" in capsys.readouterr().out
    other = ["reliability", "smoke", "--model", "quasi-static", "--event", RARE, "-o", str(out)]
    assert main(other) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"--event {EVENT} there, {RARE} now" in err, err


def test_an_event_far_beyond_every_response_says_so_and_a_rerun_reprints_it(tmp_path, capsys, monkeypatch):
    """z > 2 mm on the smoke scene, whose responses stay near 0.3 mm: the error names the largest response against
    the limit and that the event may be impossible (not only 'a larger -n may get one', which cannot), and the
    same command onto its file reprints it without evaluating."""
    out = tmp_path / "i.nc"
    argv = ["reliability", "smoke", "--model", "quasi-static", "--event", "displacement:z>2mm", "-n", "20",
            "--workers", "1", "-o", str(out)]
    capsys.readouterr()
    assert main(argv) == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if ": error: " in line]
    top = 1e3 * load_netcdf(out)["max_abs_error"].sel(quantity="displacement", direction="z").values.max()
    assert len(errors) == 1 and f"largest response of its 110 evaluations is {top:.4g} mm against the limit 2 mm" \
        in errors[0] and "may be impossible for scene smoke at the quasi-static level" in errors[0], errors
    monkeypatch.setattr(study, "evaluate", lambda *a, **k: pytest.fail("evaluated again"))
    assert main(argv) == 2
    assert [line for line in capsys.readouterr().err.splitlines() if ": error: " in line] == errors
