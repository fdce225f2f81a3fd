"""`rss6 report`: results.md and its figures from the files it wrote, on the smoke scene."""
import gc
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.cli import main
from pipeline.studies.report import OFF, PAPER_VALUES, _only, with_clearance
from pipeline.files.opening import open_ensemble
from pipeline.files.schema import EnsembleFileError
from pipeline.vocabulary import QUANTITIES
from rss6core import parse_scene


def test_with_clearance_sets_only_the_clearance_keys(smoke):
    """Made on the parsed data: the two keys change, every other scene value stays, and the
    text's first line records the override (it reaches the ensemble file's scene_toml)."""
    import dataclasses
    text = with_clearance(smoke.source_text, {"spherical_C_m": 1e-5, "revolute_axial_m": 2e-5}, "smoke")
    scene = parse_scene(text)
    assert scene.clearance == dataclasses.replace(smoke.clearance, spherical_C=1e-5,
                                                  revolute_axial=2e-5)
    for field in dataclasses.fields(smoke):
        if field.name not in ("clearance", "source_text", "source_path"):
            assert repr(getattr(scene, field.name)) == repr(getattr(smoke, field.name)), field.name
    assert text.splitlines()[0] == ("# rss6 variant of smoke: [clearance] spherical_C_m = 1e-05, "
                                    "revolute_axial_m = 2e-05")
    with pytest.raises(ValueError, match="spherical_D_m"):
        with_clearance(smoke.source_text, {"spherical_D_m": 1e-5})


def test_family_runs_of_a_tolerance_scene_switch_the_other_bands_off(configs):
    """A switched-off family must lose its [tolerance.<family>] band too, or the band would still
    draw its sizes (0.15-0.35 mm) and the 'only B' run would measure every family."""
    from rss6core.clearance import draw_clearances
    tolerance = parse_scene((configs / "paper_tolerance.toml").read_text())
    only_b = parse_scene(_only(tolerance.source_text, "B", "paper_tolerance"))
    assert only_b.tolerance.spherical_B == tolerance.tolerance.spherical_B
    assert (only_b.tolerance.revolute_radial, only_b.tolerance.revolute_axial,
            only_b.tolerance.spherical_C) == (None, None, None)
    draw = draw_clearances(only_b, 0, 3)
    assert np.all(draw.radial_size == OFF) and np.all(draw.axial_size == OFF) and np.all(draw.size_C == OFF)
    assert np.array_equal(draw.size_B, draw_clearances(tolerance, 0, 3).size_B)   # same stream, same B sizes
    assert "without [tolerance.revolute_radial]" in _only(tolerance.source_text, "B", "x").splitlines()[0]


@pytest.fixture(scope="module")
def report(configs, tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    assert main(["report", str(configs / "smoke.toml"), "-o", str(out), "-n", "3",
                 "--family-n", "2"]) == 0
    return out


@pytest.mark.slow   # the report's runs: 1.5-2 minutes on 2 shared cores
def test_report_links_figures_it_wrote(report):
    md = (report / "results.md").read_text()
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert len(links) == 4          # rigid motion, displacement, velocity, acceleration
    for link in links:
        png = report / link
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


@pytest.mark.slow   # the report's runs: 1.5-2 minutes on 2 shared cores
def test_report_numbers_come_from_its_files(report):
    md = (report / "results.md").read_text()
    data = report / "results-data"
    contact = open_ensemble(data / "smoke_contact.nc")
    assert contact.sizes["realization"] == 3
    # the contact median of the per-realisation max |z displacement| in mm, as the table prints it
    z = contact["max_abs_error"].sel(window="whole", quantity="displacement", direction="z").values
    row = next(line for line in md.splitlines() if line.startswith("| max \\|displacement error\\| | z |"))
    cells = [c.strip() for c in row.strip("|").split(" | ")]
    assert cells[3] == "0.0047"                                   # the paper's value
    assert float(cells[8].split(" [")[0]) == pytest.approx(np.median(z) * 1e3, rel=5e-3)
    # the window table: startup, steady and whole medians of the same statistic, labelled
    windows = md.split("### Start-up and steady operation (contact level)")[1]
    assert "steady (t >= 0.1 s): median [95 % CI]" in windows
    assert ", drawn start, " in md                                  # the run line names the start
    runs = next(line for line in md.splitlines() if line.startswith("Runs: ")).split("; ")
    assert [r.split(":")[0] for r in runs if " start, " in r] == ["contact"]   # of the level that has one
    assert "would be the same to the last bit" in windows
    row = next(line for line in windows.splitlines() if line.startswith("| max \\|displacement error\\| | z |"))
    cells = [c.strip() for c in row.strip("|").split(" | ")]
    for k, window in ((3, "startup"), (4, "steady"), (5, "whole")):
        want = np.median(contact["max_abs_error"].sel(window=window, quantity="displacement",
                                                      direction="z").values) * 1e3
        assert float(cells[k].split(" [")[0]) == pytest.approx(want, rel=5e-3)
    steady = contact["max_abs_error"].sel(window="steady", quantity="displacement", direction="z").values * 1e3
    lo, hi = (float(c) for c in cells[6].split(" - "))           # the steady spread, 5 % - 95 %
    assert steady.min() * 0.995 <= lo <= np.median(steady) * 1.005 <= hi * 1.01 <= steady.max() * 1.015
    # family runs: the other families at OFF, this one at the scene's clearance
    only_c = open_ensemble(data / "smoke_contact_onlyC.nc")
    sizes = only_c["clearance_size"].values
    assert np.all(sizes[:, 6:12] == pytest.approx(0.25e-3)) and np.all(sizes[:, 12:] == OFF)
    assert len(PAPER_VALUES) == 12 and md.count("| max \\|acceleration error\\|") >= 6


@pytest.mark.slow   # the report's runs: 1.5-2 minutes on 2 shared cores
def test_report_reuses_its_files_and_names_a_corrupt_one(configs, report, tmp_path):
    copy = tmp_path / "again"
    shutil.copytree(report, copy)
    (copy / "results.md").unlink()
    before = {p.name: p.stat().st_mtime_ns for p in (copy / "results-data").iterdir()}
    assert main(["report", str(configs / "smoke.toml"), "-o", str(copy), "-n", "3",
                 "--family-n", "2"]) == 0
    after = {p.name: p.stat().st_mtime_ns for p in (copy / "results-data").iterdir()}
    assert after == before                                        # nothing rerun
    assert (copy / "results.md").read_text() == (report / "results.md").read_text().replace(
        str(report), str(copy))
    elastic = copy / "results-data" / "smoke_elastic.nc"
    elastic.write_bytes(elastic.read_bytes()[:500])
    with pytest.raises(EnsembleFileError, match="smoke_elastic.nc"):
        from pipeline.studies.report import ReportPlan, write_report
        write_report([str(configs / "smoke.toml")], copy, ReportPlan(3, 2))


@pytest.mark.slow   # reuses the report fixture's runs, then grows them by one realisation
def test_a_report_after_a_larger_n_reads_the_first_n_as_its_command_says(configs, report, tmp_path):
    """-n 4 grows the report's ensembles; -n 3 again wrote a document whose header said -n 3 and whose runs
    said 4 finished. It now reads the first -n (--family-n) realisations: the -n 3 document again."""
    copy = tmp_path / "grown"
    shutil.copytree(report, copy)
    argv = ["report", str(configs / "smoke.toml"), "-o", str(copy), "--family-n", "2"]
    assert main(argv + ["-n", "4"]) == 0
    assert main(argv + ["-n", "3"]) == 0
    assert (copy / "results.md").read_text() == (report / "results.md").read_text().replace(str(report), str(copy))


def test_kept_studies_are_the_text_from_the_marker_on(tmp_path):
    from pipeline.studies.report import KEPT_MARKER, kept_studies
    path = tmp_path / "results.md"
    assert kept_studies(path) == ""                           # no file yet
    path.write_text("# generated\n\ntable\n")
    assert kept_studies(path) == ""                           # no marker: nothing is kept
    tail = KEPT_MARKER + "\n\n## Map\n\nnumbers\n"
    path.write_text("# generated\n\ntable\n\n" + tail)
    assert kept_studies(path) == tail


@pytest.mark.slow   # reuses the report fixture's runs
def test_report_keeps_the_sections_below_its_marker(configs, report, tmp_path):
    """Regenerating results.md keeps the studies written by hand from other commands (rss6 map)."""
    from pipeline.studies.report import KEPT_MARKER
    copy = tmp_path / "kept"
    shutil.copytree(report, copy)
    generated = (copy / "results.md").read_text().replace(str(report), str(copy))
    tail = KEPT_MARKER + "\n\n## A study from another command\n\nits numbers\n"
    (copy / "results.md").write_text(generated + tail)
    assert main(["report", str(configs / "smoke.toml"), "-o", str(copy), "-n", "3", "--family-n", "2"]) == 0
    assert (copy / "results.md").read_text() == generated + tail


def test_the_command_results_md_quotes_regenerates_it():
    """The quoted command carries what the run was given beyond the defaults: a seed, and
    --overwrite-tracked (without it the command refuses a folder git tracks, such as docs/)."""
    from pipeline.studies.report import ReportPlan, report_command
    assert report_command(["paper"], "out", ReportPlan(8, 2)) == "rss6 report paper -o out -n 8 --family-n 2"
    assert report_command(["paper", "smoke"], "docs", ReportPlan(8, 2, seed=3, overwrite_tracked=True)) == (
        "rss6 report paper smoke -o docs -n 8 --family-n 2 --seed 3 --overwrite-tracked")


def _open_files_under(folder) -> list[str]:
    """The files under ``folder`` this process holds open (Linux: /proc/self/fd)."""
    fds = Path("/proc/self/fd")
    names = [os.readlink(fds / fd) for fd in os.listdir(fds) if (fds / fd).is_symlink()]
    return [n for n in names if n.startswith(str(folder))]


@pytest.mark.slow   # 7 small ensembles on the shared cluster
@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="lists open files through /proc")
def test_running_the_reports_files_leaves_none_of_them_open(configs, cluster_client, tmp_path):
    """run_scene lets go of every file it ran or resumed, closed when done and not left to the garbage
    collector (with files left open, a resumed report intermittently failed to read an intact one: HDF error)."""
    from pipeline.studies.report import ReportPlan, run_scene
    gc.disable()   # cycles would close them only when collected
    try:
        for _ in range(2):   # run, then resume
            run_scene(configs / "smoke.toml", tmp_path, ReportPlan(3, 2), cluster_client)
            assert _open_files_under(tmp_path) == []
    finally:
        gc.enable()


def test_the_reports_window_prose_follows_the_scenes_settle_time():
    """With settle_time_s > 0 the report said 'startup, t < 0.5 s' and called its start-up peaks impacts,
    which settle_time_s had left out of every window; the paper scene's text (settle 0) is unchanged."""
    from pipeline.studies import report_text as text
    from pipeline.studies.report_text import start_text as _start_text, window_times as _window_times
    paper, settled = {"steady_after_s": 0.75, "settle_time_s": 0.0}, {"steady_after_s": 0.5, "settle_time_s": 0.3}
    assert [_window_times(w, paper) for w in ("startup", "steady")] == ["t < 0.75 s", "t >= 0.75 s"]
    assert [_window_times(w, settled) for w in ("startup", "steady")] == ["0.3 s <= t < 0.5 s", "t >= 0.5 s"]
    assert _start_text(text.START_PEAKS, "drawn", paper).startswith("The start-up peaks are impacts")
    assert _start_text(text.START_PEAKS, "drawn", settled).startswith("This scene leaves t < 0.3 s")
    assert "impacts" not in _start_text(text.START, "drawn", settled)


def test_a_scene_with_uncertain_inputs_has_its_family_runs_at_nominal_inputs(configs):
    """paper_manufacturing's family runs drew its manufacturing inputs too, and the report called their
    medians the clearances' contributions ('only A' above 'all joints'): they now hold the inputs at
    nominal, and the labels say which numbers hold clearances + manufacturing inputs."""
    from pipeline.studies import report_text as text
    from pipeline.studies.report import _nominal_inputs
    scene = parse_scene((configs / "paper_manufacturing.toml").read_text())
    assert scene.uncertain
    for family in "ACB":
        assert not parse_scene(_only(scene.source_text, family, "m")).uncertain
    nominal = _nominal_inputs(scene.source_text, "m")
    assert not parse_scene(nominal).uncertain and "without [uncertain.crank_length]" in nominal.splitlines()[0]
    assert text.labelled("contact", scene) == "contact (clearances + manufacturing inputs)"
    assert text.labelled("elastic", scene, nominal=True) == "elastic (manufacturing inputs at nominal)"
    paper = parse_scene((configs / "paper.toml").read_text())
    assert text.labelled("contact", paper) == "contact" and "uncertain" not in _only(paper.source_text, "B", "p")


def test_the_comparison_table_marks_what_measures_the_step_or_start_up_impacts():
    """docs/results.md set the contact level's whole-run acceleration maxima (start-up impacts) and the paper
    level's accelerations (the step) beside the paper's numbers with no window and no mark: the cells that do
    not measure the robot now carry level_notes' marks, the same notes as rss6 stats."""
    from types import SimpleNamespace
    from pipeline.analysis.stats import level_notes
    from pipeline.studies.report import _level_marks
    windows = {"steady_after_s": 0.75, "settle_time_s": 0.0}
    st = {"quasi-static": SimpleNamespace(attrs={"model": "quasi-static", **windows}),
          "paper": SimpleNamespace(attrs={"model": "paper", **windows}),
          "contact": SimpleNamespace(attrs={"model": "contact", "contact_start": "drawn", **windows})}
    marks, notes = _level_marks(st)
    assert {k: v for k, v in marks.items() if v} == {("paper", "velocity"): "†", ("paper", "acceleration"): "†",
                                                      **{("contact", q): "‡" for q in QUANTITIES}}
    assert notes == [f"{m} {n}." for m, n in zip("†‡", level_notes(st["paper"].attrs, {"velocity"}, {"whole"})
                                                   + level_notes(st["contact"].attrs, {"velocity"}, {"whole"}))]
    st["contact"].attrs["contact_start"] = "equilibrium"   # no start-up impacts: nothing of the contact level
    assert not any(v for (level, _), v in _level_marks(st)[0].items() if level == "contact")


def _with_failure(ds):
    """``ds`` with its realisation 1 failed, as the contact level records a Newton failure."""
    import xarray as xr
    status, message = ds["status"].values.astype(object), ds["status_message"].values.astype(object)
    status[1], message[1] = "failed", "Newton on the contact forces did not converge in 60 iterations at t = 0.0093 s"
    return ds.assign(status=xr.DataArray(status, dims="realization"),
                     status_message=xr.DataArray(message, dims="realization"))


def test_a_failed_realisation_is_said_on_stderr_with_stats_note_and_its_reason(smoke, monkeypatch, capsys, tmp_path):
    """The family table's head said '7 finished / 8' and nothing else: neither the console nor results.md
    said a realisation failed, why, or that the statistics leave it out. Both now say it, in rss6 stats' words."""
    import xarray as xr
    from pipeline.analysis.stats import left_out_note
    from pipeline.studies import report, report_text
    ok = xr.Dataset({"status": ("realization", ["finished"] * 3), "status_message": ("realization", [""] * 3)},
                    coords={"realization": [0, 1, 2]})
    paths = {"contact": tmp_path / "smoke_contact.nc", "onlyA": tmp_path / "smoke_contact_onlyA.nc"}
    monkeypatch.setattr(report, "run_scene", lambda *a: paths)
    monkeypatch.setattr(report, "open_ensemble", lambda p: _with_failure(ok) if p == paths["onlyA"] else ok)
    opened = report._open_scene("smoke", tmp_path, report.ReportPlan(3, 3), None)
    err = capsys.readouterr().err.splitlines()
    assert err == [f"rss6 report: {paths['onlyA']}: {left_out_note(1, 3)}. Why: 1 x Newton on the contact forces "
                   "did not converge in 60 iterations at t = 0.0093 s"]
    notes = report_text.failure_notes([(name, opened[role]) for name, role in report._family_runs(smoke)
                                       if role in opened])
    assert notes == ["", f"- only A: {left_out_note(1, 3)}. Why: 1 x Newton on the contact forces did not converge "
                         "in 60 iterations at t = 0.0093 s."]
    assert report_text.failure_notes([("contact", ok)]) == []


@pytest.mark.slow   # reuses the report fixture's runs
def test_results_md_names_a_failed_realisation_under_each_table_with_its_run(configs, report, tmp_path, monkeypatch):
    """A failed realisation of a family run is named under the family table (count, reason, what the medians
    leave out), and under no other table."""
    from pipeline.studies import report as module
    copy = tmp_path / "failed"
    shutil.copytree(report, copy)
    real = module.open_ensemble
    monkeypatch.setattr(module, "open_ensemble",
                        lambda p: _with_failure(real(p)) if str(p).endswith("_onlyC.nc") else real(p))
    assert main(["report", str(configs / "smoke.toml"), "-o", str(copy), "-n", "3", "--family-n", "2"]) == 0
    md = (copy / "results.md").read_text()
    family = md.split("### Which joint family contributes most")[1].split("###")[0]
    assert "only C (1 finished / 2)" in family
    assert "\n- only C: 1 of 2 realisations failed and are in no statistic or bound" in family
    assert "Why: 1 x Newton on the contact forces did not converge" in family and md.count("realisations failed") == 1


@pytest.mark.slow   # reuses the report fixture's runs, then reruns one family run's recorded command (2 realisations)
def test_a_family_runs_history_reruns_its_file(report, tmp_path, monkeypatch):
    """The family runs' history named the shipped scene ('rss6 run smoke --model contact ...'), whose rerun is
    the all-joints ensemble; it now runs the variant's scene file written beside the data, and gives the file."""
    import shlex
    import xarray as xr
    data = report / "results-data"
    for family in "ACB":
        ds = open_ensemble(data / f"smoke_contact_only{family}.nc")
        argv = shlex.split(ds.attrs["history"])
        assert argv[:3] == ["rss6", "run", f"smoke_contact_only{family}.toml"]
        assert (data / argv[2]).read_text() == ds.attrs["scene_toml"]
    monkeypatch.chdir(data)   # the history names the scene file beside the data
    assert main(argv[1:] + ["-o", str(tmp_path / "again.nc"), "--workers", "1"]) == 0
    again = open_ensemble(tmp_path / "again.nc")
    xr.testing.assert_identical(again.drop_attrs(), ds.drop_attrs())
    assert {k: str(v) for k, v in again.attrs.items() if k != "history"} == {
        k: str(v) for k, v in ds.attrs.items() if k != "history"}


def test_the_nominal_inputs_elastic_runs_history_reruns_it(configs, tmp_path, monkeypatch):
    """Of a scene with uncertain inputs, the elastic run holds them at nominal: its history named the shipped
    scene (whose elastic run draws them); it now runs the nominal variant's scene file written beside it,
    which gives the same run."""
    import shlex
    import xarray as xr
    from pipeline.studies.report import _elastic_run
    from pipeline.scenes.catalogue import find_scene
    path = _elastic_run(find_scene(str(configs / "paper_manufacturing.toml")), tmp_path)
    ds = xr.load_dataset(path)
    argv = shlex.split(ds.attrs["history"])
    assert argv[:3] == ["rss6", "simulate", "paper_manufacturing_elastic_nominal-inputs.toml"]
    assert (tmp_path / argv[2]).read_text() == ds.attrs["scene_toml"]
    monkeypatch.chdir(tmp_path)
    assert main(argv[1:] + ["-o", "again.nc"]) == 0
    xr.testing.assert_identical(xr.load_dataset("again.nc").drop_attrs(), ds.drop_attrs())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["again.nc", path.name, argv[2]]


def test_the_largest_family_is_said_unresolved_where_its_median_interval_does_not_clear_the_others():
    """The report names the family with the largest median peak; where its median's lower bound does not
    clear another's upper bound, it says so (a review found A over B at n = 8 with overlapping intervals)."""
    import xarray as xr

    from pipeline.studies.report import _largest_family

    def stats(median, lower, upper, n=8):
        values = np.full((1, 3, 1, 1), np.nan)
        values[0, :, 0, 0] = (median, lower, upper)
        return xr.Dataset({"max_abs_error": (("statistic", "bound", "quantity", "direction"), values)},
                          coords={"statistic": ["q50"], "bound": ["estimate", "lower", "upper"],
                                  "quantity": ["acceleration"], "direction": ["z"]}, attrs={"n_finished": n})
    st = {"onlyA": stats(97.1, 39.6, 126.9), "onlyB": stats(91.6, 50.2, 108.8), "onlyC": stats(30.9, 20.0, 35.0)}
    family, share, said = _largest_family(st, "max", "acceleration", "z")
    assert (family, round(share, 3)) == ("A", round(97.1 / (97.1 + 91.6 + 30.9), 3))
    assert said == "; not resolved at n = 8: its median's interval does not clear B's"
    st["onlyB"] = stats(30.0, 20.0, 39.0, 100)
    assert _largest_family(st, "max", "acceleration", "z")[2] == ""
