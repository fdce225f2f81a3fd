"""Analysis windows (startup t < steady_after_s, steady t >= steady_after_s, whole run): the reductions
against closed forms, the scene key, the contact level's per-window peaks against its histories, and
the windows through files, rss6 stats and its --require gate."""
import dataclasses
import json

import numpy as np
import pytest

from pipeline.cli import main
from pipeline.files.opening import open_results
from pipeline.analysis.stats import ensemble_stats, in_window, to_json
from pipeline.files.records import window_label, window_masks, window_summaries
from pipeline.files.schema import cf_encode
from pipeline.files.writing import write_netcdf
from pipeline.vocabulary import WINDOWS
from rss6core import SimulationResult, parse_scene
from rss6core.clearance import draw_clearances
from rss6core.contact_dynamics import CompiledStepper, simulate_contact
from rss6core.contact_numpy import NumpyStepper
from rss6core.scene import SceneError

T = np.round(np.arange(11) * 0.1, 12)                            # 0, 0.1, ..., 1.0 s
#                 startup (t < 0.5)       | steady (t >= 0.5)
ABS_X = np.array([0.0, 1.0, 5.0, 1.0, 0.0, 2.0, 3.0, 2.0, 3.0, 2.0, 3.0])


def _result(x, peak=None) -> SimulationResult:
    """A run whose displacement x error is ``x`` (signs alternate: the summaries take |error|)."""
    hist = np.zeros((len(T), 6))
    hist[:, 0] = x * (-1.0) ** np.arange(len(T))
    return SimulationResult(T, hist, 2 * hist, 3 * hist, "finished", "", len(T) - 1,
                            peak_abs_error=peak)


def test_window_maxima_and_means_are_the_closed_form_ones():
    peak, mean = window_summaries(_result(ABS_X), settle=0.0, steady_after=0.5)
    assert peak.shape == mean.shape == (3, 3, 6)
    np.testing.assert_allclose(peak[:, 0, 0], [5.0, 5.0, 3.0])          # whole, startup, steady
    np.testing.assert_allclose(mean[:, 0, 0], [22 / 11, 7 / 5, 15 / 6])
    np.testing.assert_allclose(peak[:, 2, 0], [15.0, 15.0, 9.0])        # acceleration = 3 x
    # the sample at t = steady_after belongs to steady; settle leaves t < 0.2 s out of every window
    peak, mean = window_summaries(_result(ABS_X), settle=0.2, steady_after=0.6)
    np.testing.assert_allclose(peak[:, 0, 0], [5.0, 5.0, 3.0])
    np.testing.assert_allclose(mean[:, 0, 0], [(6 + 2 + 13) / 9, 8 / 4, 13 / 5])
    assert window_masks(T, 0.0, 0.5)[2].tolist() == [False] * 5 + [True] * 6


def test_empty_and_half_computed_windows():
    """No startup when steady_after <= settle: NaN there; a failed run's NaN samples are left out."""
    peak, mean = window_summaries(_result(ABS_X), settle=0.3, steady_after=0.0)
    assert np.isnan(peak[1]).all() and np.isnan(mean[1]).all()
    np.testing.assert_allclose(peak[[0, 2], 0, 0], [3.0, 3.0])
    failed = np.where(T < 0.75, ABS_X, np.nan)
    peak, mean = window_summaries(_result(failed), settle=0.0, steady_after=0.5)
    np.testing.assert_allclose(peak[:, 0, 0], [5.0, 5.0, 3.0])
    np.testing.assert_allclose(mean[2, 0, 0], 7 / 3)


def test_finer_peaks_replace_the_output_grid_maxima_per_window():
    """The contact level's peaks (startup, steady) over internal steps; whole = the larger."""
    finer = np.zeros((2, 3, 6))
    finer[0, 0, 0], finer[1, 0, 0] = 6.0, 7.0
    peak, _ = window_summaries(_result(ABS_X, finer), settle=0.0, steady_after=0.5)
    np.testing.assert_allclose(peak[:, 0, 0], [7.0, 6.0, 7.0])


def test_steady_after_key(paper_text):
    assert parse_scene(paper_text).simulation.steady_after == 0.75        # measured default
    short = paper_text.replace("duration_s = 2.0", "duration_s = 1.0")
    assert parse_scene(short).simulation.steady_after == 0.5              # at most half the run
    given = paper_text.replace("time_step_s = 1.0e-3", "time_step_s = 1.0e-3\nsteady_after_s = 0.0")
    assert parse_scene(given).simulation.steady_after == 0.0
    for value, what in (("2.0", "must be shorter than"), ("-0.1", "steady_after_s")):
        bad = paper_text.replace("time_step_s = 1.0e-3",
                                 f"time_step_s = 1.0e-3\nsteady_after_s = {value}")
        with pytest.raises(SceneError, match=r"\[simulation\] steady_after_s") as err:
            parse_scene(bad)
        assert what in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("stepper", [CompiledStepper, NumpyStepper], ids=["compiled", "numpy"])
def test_contact_peaks_per_window_are_the_histories_maxima(smoke, stepper):
    """A fixed step recorded at every step: the per-window peaks over internal steps are exactly the
    maxima of the histories in each window (the initial state in startup)."""
    sim = dataclasses.replace(smoke.simulation, steady_after=0.01)
    scene = dataclasses.replace(smoke, simulation=sim, trajectory=dataclasses.replace(
        smoke.trajectory, duration=0.02))
    draws = [draw_clearances(scene, 1, r) for r in range(2)]
    run = simulate_contact(scene, draws, dt=2e-4, output_step=2e-4, refinements=0, stepper=stepper)
    assert run.status == ["finished"] * 2 and run.peak.shape == (2, 2, 3, 6)
    hist = np.abs(np.stack([run.displacement, run.velocity, run.acceleration], 1))  # (R, 3, T, 6)
    steady = run.t >= 0.01 - 1e-12
    np.testing.assert_array_equal(run.peak[:, 0], hist[:, :, ~steady].max(2))
    np.testing.assert_array_equal(run.peak[:, 1], hist[:, :, steady].max(2))
    assert (run.peak[:, 0] != run.peak[:, 1]).all()      # every cell: the windows hold other steps


@pytest.fixture(scope="module")
def ensemble_file(tmp_path_factory, configs):
    path = tmp_path_factory.mktemp("windows") / "qs.nc"
    assert main(["run", str(configs / "smoke.toml"), "--model", "quasi-static", "-n", "12",
                 "--workers", "1", "-o", str(path)]) == 0
    return path


def test_ensemble_file_carries_the_windows(ensemble_file):
    ds = open_results(ensemble_file)
    assert ds["max_abs_error"].dims == ("window", "quantity", "realization", "direction")
    assert [str(w) for w in ds["window"].values] == list(WINDOWS)
    assert ds.attrs["steady_after_s"] == 0.1 and ds.attrs["settle_time_s"] == 0.0
    whole, parts = ds["max_abs_error"].sel(window="whole"), ds["max_abs_error"].sel(
        window=["startup", "steady"])
    np.testing.assert_array_equal(whole, parts.max("window"))
    one = in_window(ds, "steady")
    assert "window" not in one.dims and "window" not in one.coords
    assert in_window(one, "steady") is one                 # no windows: as it is
    with pytest.raises(ValueError, match="unknown window 'warmup'"):
        in_window(ds, "warmup")
    encoded, _ = cf_encode(ds)
    assert "window_label" in encoded and "window" not in encoded.coords


def test_stats_shows_and_selects_the_windows(ensemble_file, capsys):
    capsys.readouterr()
    assert main(["stats", str(ensemble_file), "--quantity", "displacement"]) == 0
    out = capsys.readouterr().out
    for label in ("window: whole run", "window: startup (t < 0.1 s)", "window: steady (t >= 0.1 s)"):
        assert out.count(label) == 1
    assert main(["stats", str(ensemble_file), "--json", "--window", "steady"]) == 0
    js = json.loads(capsys.readouterr().out)
    want = to_json(ensemble_stats(open_results(ensemble_file), window="steady"))
    assert js["window"] == "steady" and js["max_abs_error"] == want["max_abs_error"]
    assert js["max_abs_error"] != to_json(ensemble_stats(open_results(ensemble_file)))["max_abs_error"]
    assert main(["stats", str(ensemble_file), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["window"] == "whole" and js["by_window"]["steady"]["max_abs_error"] == want["max_abs_error"]


def test_require_judges_the_window_it_names(ensemble_file, tmp_path, capsys):
    """Startup maxima made 100 times larger: a limit between the two windows' medians passes in
    steady and fails in startup, whether the window comes from '/WINDOW' or from --window; a spec
    without either is judged on the whole run."""
    ds = open_results(ensemble_file)
    peak = ds["max_abs_error"]
    peak.loc[{"window": "startup"}] = 100 * peak.sel(window="startup")
    peak.loc[{"window": "whole"}] = peak.sel(window=["startup", "steady"]).max("window")
    path = tmp_path / "scaled.nc"
    write_netcdf(ds, path)
    med = ensemble_stats(ds, window=None)["max_abs_error"].sel(
        statistic="q50", bound="estimate", quantity="displacement", direction="z")
    limit = f"{1e3 * 10 * float(med.sel(window='steady')):.6f}mm"   # 10 x steady, 0.1 x startup
    capsys.readouterr()
    assert main(["stats", str(path), "--require", f"displacement:z<={limit}@q50/steady"]) == 0
    assert main(["stats", str(path), "--require", f"displacement:z<={limit}@q50/startup"]) == 1
    assert main(["stats", str(path), "--require", f"displacement:z<={limit}@q50"]) == 1   # whole
    assert main(["stats", str(path), "--window", "steady", "--require",
                 f"displacement:z<={limit}@q50"]) == 0
    capsys.readouterr()
    assert main(["stats", str(path), "--window", "warmup"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "unknown window 'warmup'" in err


def test_a_file_without_windows_is_a_one_line_error(ensemble_file, tmp_path, capsys):
    """A file as rss6 wrote it before the windows (its summaries over the whole run only)."""
    path = tmp_path / "legacy.nc"
    write_netcdf(in_window(open_results(ensemble_file), "whole"), path)
    capsys.readouterr()
    assert main(["stats", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "max_abs_error has no analysis windows" in err


@pytest.mark.parametrize("tamper, message", [
    (lambda ds: ds["max_abs_error"].loc.__setitem__({"window": "steady", "realization": 2}, np.nan),
     "max_abs_error is not finite in finished realisation 2"),
    (lambda ds: ds.attrs.pop("steady_after_s"), "attribute steady_after_s missing"),
    (lambda ds: ds.attrs.__setitem__("settle_time_s", -1.0), "attribute settle_time_s is -1.0"),
])
def test_filecheck_checks_every_window(ensemble_file, tmp_path, capsys, tamper, message):
    ds = open_results(ensemble_file)
    tamper(ds)
    path = tmp_path / "tampered.nc"
    write_netcdf(ds, path)
    capsys.readouterr()
    assert main(["stats", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err


def test_window_labels_name_the_times_each_window_covers():
    """settle_time_s leaves [0, settle) out of every window, and the labels say so; a startup window with
    steady_after_s <= settle_time_s says it is empty."""
    assert [window_label(w, 0.5) for w in WINDOWS] == ["whole run", "startup (t < 0.5 s)", "steady (t >= 0.5 s)"]
    assert [window_label(w, 0.5, 0.2) for w in WINDOWS] == [
        "whole run (t >= 0.2 s)", "startup (0.2 s <= t < 0.5 s)", "steady (t >= 0.5 s)"]
    assert window_label("startup", 0.1, 0.15) == "startup (empty: steady_after_s 0.1 s <= settle_time_s 0.15 s)"
    assert window_label("steady", 0.1, 0.15) == "steady (t >= 0.15 s)"


def test_an_empty_startup_window_is_refused_for_every_claim_before_work(smoke, tmp_path, capsys):
    """A scene whose settle_time_s reaches past steady_after_s has no startup sample: a requirement, an
    event or --window there is one line and exit 2 (it gave NaN, 'undecided' and 0/n with an interval)."""
    text = smoke.source_text.replace("time_step_s = 1.0e-3", "time_step_s = 1.0e-3\nsettle_time_s = 0.15\n"
                                     "steady_after_s = 0.1", 1)
    scene, out = tmp_path / "late.toml", tmp_path / "late.nc"
    scene.write_text(text)
    startup_spec = ["--require", "displacement:z<=1mm@q50/startup"]

    def refused(argv, *words):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and all(w in err[0] for w in words), err

    refused(["run", str(scene), "-n", "4", "--model", "quasi-static", "-o", str(out), *startup_spec],
            "--require", "startup window is empty")
    assert not out.exists()
    assert main(["run", str(scene), "-n", "4", "--model", "quasi-static", "-o", str(out)]) == 0
    capsys.readouterr()
    refused(["stats", str(out), *startup_spec], "--require", "startup window is empty")
    refused(["stats", str(out), "--event", "displacement:z>0.01mm/startup"], "--event", "startup window is empty")
    refused(["stats", str(out), "--window", "startup"], "--window startup", "startup window is empty")
    assert main(["stats", str(out), "--window", "steady"]) == 0
    assert "window: steady (t >= 0.15 s)" in capsys.readouterr().out


@pytest.mark.parametrize("settle, steady_after, holds", [(0.3002, 0.3008, False), (0.3002, 0.301, False),
                                                        (0.3, 0.3005, True), (0.3, 0.301, True), (0.4, 0.3, None)])
def test_a_startup_window_between_two_output_samples_is_refused_by_the_scene(paper_text, settle, steady_after, holds):
    """[settle, steady_after) inside one 1 ms output step held no sample: the run computed every realisation,
    then refused its own file for NaN maxima. Now the scene names the key; holds None: no start-up asked."""
    text = paper_text.replace("time_step_s = 1.0e-3", f"time_step_s = 1.0e-3\nsettle_time_s = {settle}\n"
                                                       f"steady_after_s = {steady_after}", 1)
    if holds is False:
        with pytest.raises(SceneError, match=r"\[simulation\] steady_after_s: the start-up window .* holds no output"):
            parse_scene(text)
        return
    scene = parse_scene(text)
    startup = window_masks(scene.times, settle, steady_after)[WINDOWS.index("startup")]
    assert startup.any() == bool(holds)
