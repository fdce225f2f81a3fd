"""rss6 reliability end to end on the smoke scene's quasi-static level: the JSON fields, the file of
every evaluation (its z, level and maxima reproduce the estimate), plain Monte Carlo's exact interval,
and one-line refusals (exit 2) of a bad event, p0 or N, and of a level without random inputs."""
import json
import re

import numpy as np
import pytest
from scipy import stats as sps

from pipeline.cli import main
from pipeline.files.reading import load_netcdf

EVENT = "displacement:z>0.15mm"   # P about 0.1 at the smoke scene's quasi-static level
RARE = "displacement:z>0.2mm"


@pytest.fixture(scope="module")
def subset_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("rel") / "s.nc"
    return out, ["reliability", "smoke", "--event", RARE, "-n", "200", "--workers", "1", "-o", str(out), "--json"]


def test_subset_json_has_the_fields_and_the_file_every_evaluation(subset_run, capsys):
    out, argv = subset_run
    capsys.readouterr()
    assert main(argv) == 0
    res = json.loads(capsys.readouterr().out)
    assert {"pf", "lower", "upper", "confidence", "cov", "evaluations", "method"} <= set(res)
    assert res["method"] == "subset" and res["pf"] > 0
    # N = 200 per level: below the N from which the interval's coverage is measured, so none is given
    assert res["lower"] is None and res["upper"] is None and "below N = 300" in res["interval"]
    ds = load_netcdf(out)
    assert ds.sizes["evaluation"] == res["evaluations"] == sum(res["evaluations_per_level"])
    level = ds["level"].values
    m = len(res["evaluations_per_level"])
    assert m >= 2, "pick an event rarer than p0 so that the test sees a subset level"
    assert np.bincount(level).tolist() == res["evaluations_per_level"] == [200] + [180] * (m - 1)
    assert res["thresholds"][-1] == pytest.approx(2e-4) and np.all(np.diff(res["thresholds"]) > 0)
    # P = p0^(m-1) x (k of the last level's 200 states above the limit)
    k = res["pf"] / 0.1 ** (m - 1) * 200
    assert k == pytest.approx(round(k)) and 1 <= round(k) <= 200
    # level 0's draws: the first threshold is the mean of their 20th and 21st largest responses
    z0 = np.sort(ds["max_abs_error"].sel(quantity="displacement", direction="z").values[level == 0])[::-1]
    assert res["thresholds"][0] == pytest.approx((z0[19] + z0[20]) / 2)


def test_mc_gives_the_exact_interval_of_its_count(tmp_path, capsys):
    out = tmp_path / "m.nc"
    capsys.readouterr()
    assert main(["reliability", "smoke", "--event", EVENT, "--method", "mc", "-n", "300", "--workers", "1",
                 "-o", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    z = load_netcdf(out)["max_abs_error"].sel(quantity="displacement", direction="z").values
    k = int(np.count_nonzero(z > 1.5e-4))
    assert res["pf"] == k / 300 and res["evaluations"] == 300
    assert res["upper"] == pytest.approx(sps.beta.ppf(0.975, k + 1, 300 - k))


@pytest.mark.parametrize("extra, token", [
    (["--event", "displacement:w>1mm"], "unknown direction 'w'"),
    (["--event", "displacement:z>1mm/later"], "unknown window 'later'"),
    (["--event", "displacement:z>1"], "missing unit"),
    (["--event", "force:z>1mm"], "unknown quantity 'force'"),
    (["--event", EVENT, "--p0", "0.7"], "p0 0.7"),
    (["--event", EVENT, "-n", "1005"], "N p0 must be an integer"),
    (["--event", EVENT, "--method", "mc", "--p0", "0.2"], "--p0: applies with --method subset only"),
    (["--event", EVENT, "--model", "rigid"], "no uncertain input"),
    (["--event", EVENT, "--model", "paper"], "redraws its clearances every step"),
])
def test_bad_input_is_one_line_exit_2_before_any_work(tmp_path, capsys, extra, token, monkeypatch):
    import pipeline.studies.reliability as study
    monkeypatch.setattr(study, "reliability", lambda *a, **k: pytest.fail("work started"))
    capsys.readouterr()
    assert main(["reliability", "smoke", *extra, "-o", str(tmp_path / "x.nc")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and token in err, err
    assert not (tmp_path / "x.nc").exists()


def test_a_stalled_subset_run_is_one_line_exit_2_and_keeps_its_evaluations(tmp_path, capsys):
    """Too few chains per level for this event (a new user's review: -n 20 on the paper scene): the
    thresholds stop rising, there is no estimate; not "P = nan" with exit 0."""
    out = tmp_path / "s.nc"
    capsys.readouterr()
    assert main(["reliability", "paper", "--model", "quasi-static", "--event", "displacement:z>0.285mm", "-n", "20",
                 "--workers", "1", "-o", str(out)]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and "no estimate of P(displacement:z>0.285mm) (stalled" in err, err
    threshold = re.search(r"the threshold (\S+) mm does not rise", err)   # in the event's unit
    assert threshold and 0.01 < float(threshold.group(1)) < 0.285, err
    assert "nan" not in captured.out and str(out) in err
    assert load_netcdf(out)["max_abs_error"].sizes["evaluation"] > 20


@pytest.mark.slow
def test_the_same_seed_gives_the_same_file_on_two_workers_as_in_this_process(tmp_path, capsys):
    """Batches of 300 rows are cut into chunks on 2 dask workers, or evaluated here: same bits."""
    runs = []
    for workers in ("1", "2"):
        out = tmp_path / f"w{workers}.nc"
        assert main(["reliability", "smoke", "--event", EVENT, "--method", "mc", "-n", "300", "--workers", workers,
                     "-o", str(out)]) == 0
        runs.append(load_netcdf(out))
    assert np.array_equal(runs[0]["max_abs_error"].values, runs[1]["max_abs_error"].values, equal_nan=True)
    assert np.array_equal(runs[0]["z"].values, runs[1]["z"].values)


def test_a_level_without_clearances_takes_the_uncertain_inputs_after_the_clearance_coordinates(tmp_path, capsys,
                                                                                              configs):
    """The rigid level of a scene with [uncertain.*] inputs: the inputs sit where the core reads them,
    after a clearance draw's coordinates (unused at this level), and the estimate is the exact count
    of its evaluations' geometric errors above the limit."""
    from rss6core import parse_scene, uniform_dimension
    from pipeline.studies.reliability import input_dimension, input_labels
    text = (configs / "smoke.toml").read_text() + (
        '\n[uncertain.crank]\nparameter = "geometry.crank_length_m"\neach = "leg"\nlaw = "uniform"\n'
        'low_m = -0.1e-3\nhigh_m = 0.1e-3\n')
    scene_file = tmp_path / "u.toml"
    scene_file.write_text(text)
    scene = parse_scene(text)
    assert input_dimension(scene, "rigid") == uniform_dimension(None) + 6 == len(input_labels(scene, "rigid")[0])
    assert input_labels(scene, "rigid")[0][uniform_dimension(None)] == "crank[leg 1]"
    out = tmp_path / "r.nc"
    capsys.readouterr()
    assert main(["reliability", str(scene_file), "--model", "rigid", "--event", "displacement:z>0.02mm",
                 "--method", "mc", "-n", "200", "--workers", "1", "-o", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    z = load_netcdf(out)["max_abs_error"].sel(quantity="displacement", direction="z").values
    assert 0 < res["pf"] < 1 and res["pf"] == np.count_nonzero(z > 2e-5) / 200


def test_the_response_of_an_event_over_several_directions_is_their_largest_maximum():
    """reliability's limit state for 'displacement:x,y,z>...' is the largest of the three maxima (the
    union of the directions' events); a realisation failed in any of them (NaN) counts as exceeding."""
    from pipeline.analysis.exceedance import parse_event
    from pipeline.studies.reliability import _response
    maxima = np.zeros((3, 3, 6))                  # rows, quantity, direction
    maxima[0, 0, :3] = (1.0, 3.0, 2.0)
    maxima[1, 0, :3] = (0.5, 0.2, 0.1)
    maxima[1, 0, 4] = 9.0                         # a rotation: not in the event
    maxima[2, 0, 1] = np.nan
    r = _response(parse_event("displacement:x,y,z>1mm"), maxima)
    np.testing.assert_array_equal(r, [3.0, 0.5, np.inf])
    np.testing.assert_array_equal(_response(parse_event("displacement:x>1mm"), maxima), [1.0, 0.5, 0.0])


@pytest.mark.parametrize("method", ["subset", "mc"])
def test_an_event_every_draw_exceeds_has_no_cov_and_stops_the_cov_rule(tmp_path, capsys, method):
    """P = 1 at 1000 of 1000: the plug-in CoV sqrt((1 - P) / (N P)) is 0, a certainty no N reaches; the answer
    gives none (JSON null) beside the exact interval, and the CoV rule still stops after the first block."""
    out = tmp_path / f"{method}.nc"
    argv = ["reliability", "smoke", "--event", "displacement:z>0.000001mm", "--method", method, "--cov", "0.1",
            "--workers", "1", "-o", str(out)]
    capsys.readouterr()
    assert main([*argv, "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert (res["pf"], res["cov"], res["evaluations"]) == (1.0, None, 1000), res
    assert res["status"] == ("certain" if method == "subset" else "converged")
    assert res["lower"] == pytest.approx(0.025 ** (1 / 1000), rel=1e-9) and res["upper"] == 1.0
    assert main([*argv[:-1], str(tmp_path / "text.nc")]) == 0
    assert "no CoV" in capsys.readouterr().out


def test_a_subset_interval_at_another_level_says_its_coverage_was_measured_at_95_only(tmp_path, capsys):
    """Review 63b #3: a 99 % (or 75 %) subset interval was printed from a floor and a log-normal interval measured
    at 95 % only, without a note; now the text, the JSON and the file say so. Exact binomial intervals (mc, or a
    level 0 that decides) hold at any level and get no note; nor does a 95 % one."""
    from dataclasses import replace

    from pipeline.studies.reliability import coverage_note, estimate_from_dataset
    out = tmp_path / "s99.nc"
    capsys.readouterr()
    assert main(["reliability", "smoke", "--event", RARE, "-n", "300", "--confidence", "0.99", "--workers", "1",
                 "-o", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["lower"] is not None and res["coverage_note"].startswith("99 % interval: coverage measured at "
                                                                         "95 % only")
    ds = load_netcdf(out)
    assert ds.attrs["interval_coverage"] == res["coverage_note"]
    est = estimate_from_dataset(ds)
    assert main(["reliability", "smoke", "--event", RARE, "-n", "300", "--confidence", "0.99", "--workers", "1",
                 "-o", str(out)]) == 0   # read back: the text says it too
    assert f"note: {res['coverage_note']}" in capsys.readouterr().out.splitlines()
    assert coverage_note(replace(est, confidence=0.95)) is None
    assert coverage_note(replace(est, confidence=0.75)).startswith("75 % interval: coverage measured at 95 % only")
    assert coverage_note(replace(est, method="mc", interval="Clopper-Pearson exact binomial interval")) is None
    assert coverage_note(replace(est, interval="exact binomial (Clopper-Pearson) of 3 of 300 level-0 draws")) is None
