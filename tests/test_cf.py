"""Every kind of file rss6 writes is CF-1.10 by the IOOS compliance-checker, and reads back as the
same in-memory Dataset the rest of rss6 works with."""
from pathlib import Path

from importlib import resources
import pytest
import xarray as xr

from pipeline.cli import main
from pipeline.ensemble.run import EnsembleSpec, run_chunk
from pipeline.files.reading import load_netcdf
from pipeline.files.writing import write_netcdf
from pipeline.scenes.catalogue import PACKAGE

CONFIGS = Path(str(resources.files(PACKAGE)))  # the shipped scenes

import compliance_checker  # noqa: F401,E402  (a declared test dependency: missing is an error, not a skip)
SMOKE = CONFIGS / "smoke.toml"


def cf_errors(path) -> list[str]:
    """compliance-checker's cf:1.10 errors (its highest priority) for ``path``, and any check that
    crashed (a crash hides what it would have found); the lead can call it for the statistics file."""
    from compliance_checker.runner import CheckSuite
    suite = CheckSuite()
    suite.load_all_available_checkers()
    results, crashed = suite.run_all(suite.load_dataset(str(path)), ["cf:1.10"], skip_checks=[])["cf:1.10"]
    errors = []
    for r in results:
        score = r.value if isinstance(r.value, tuple) else (int(bool(r.value)), 1)
        if r.weight == 3 and score[0] < score[1]:
            errors.append(f"{r.name}: {'; '.join(r.msgs)}")
    with xr.open_dataset(path, engine="netcdf4") as ds:   # the claim the checker takes on trust
        if ds.attrs.get("Conventions") != "CF-1.10":
            errors.append(f"Conventions is {ds.attrs.get('Conventions')!r}, not 'CF-1.10'")
    return errors + [f"checker crashed in {name}: {exc}" for name, exc in crashed.items()]


def _ensemble(store: str) -> xr.Dataset:
    spec = EnsembleSpec(SMOKE.read_text(), str(SMOKE), "quasi-static", "newmark", 1e-3, 4, 0, store)
    return run_chunk(spec, [0, 1])


@pytest.mark.parametrize("store", ["summary", "full"])
def test_ensemble_files_are_cf_and_read_back_unchanged(store, tmp_path):
    ds = _ensemble(store)
    path = tmp_path / f"{store}.nc"
    write_netcdf(ds, path)
    assert cf_errors(path) == []
    xr.testing.assert_identical(load_netcdf(path), ds)


def test_simulate_file_is_cf_and_reads_back_unchanged(tmp_path, capsys):
    path = tmp_path / "sim.nc"
    assert main(["simulate", str(SMOKE), "--model", "quasi-static", "-o", str(path)]) == 0
    assert cf_errors(path) == []
    ds = load_netcdf(path)
    assert list(ds["direction"].values) == ["x", "y", "z", "rx", "ry", "rz"]
    assert ds["time"].attrs["units"] == "s" and ds["time"].dtype.kind == "f"


def test_the_raw_schema_is_what_the_checker_rejects(tmp_path):
    """The check can fail: the in-memory schema written as it is (no CF mapping) has errors."""
    raw = tmp_path / "raw.nc"
    _ensemble("full").to_netcdf(raw, engine="netcdf4")
    assert cf_errors(raw)


def test_statistics_file_is_cf(tmp_path):
    """The fourth kind of file: `rss6 stats F -o S.nc` (the statistics Dataset, with verdicts)."""
    ens = tmp_path / "ens.nc"
    write_netcdf(_ensemble("summary"), ens)
    out = tmp_path / "stats.nc"
    assert main(["stats", str(ens), "-o", str(out), "--require", "displacement:x<=1m@q50"]) in (0, 1, 3)
    assert cf_errors(out) == []


def test_multifidelity_file_is_cf(tmp_path):
    """`rss6 multifidelity -o F.nc`: the combined Dataset of two smoke ensembles on the same draws."""
    from pipeline.studies.multifidelity import multifidelity_dataset
    spec = EnsembleSpec(SMOKE.read_text(), str(SMOKE), "paper", "newmark", 1e-3, 4, 0, "summary")
    path = tmp_path / "mf.nc"
    low = run_chunk(EnsembleSpec(SMOKE.read_text(), str(SMOKE), "quasi-static", "newmark", 1e-3, 4,
                                 0, "summary"), [0, 1, 2, 3])
    write_netcdf(multifidelity_dataset(run_chunk(spec, [0, 1, 2]), low, cost_high_over_low=3.0), path)
    assert cf_errors(path) == []
    ds = load_netcdf(path)
    assert ds["max_abs_error_mean"].attrs["units"] == "m or rad, per direction (see coordinate " \
                                                      "'unit'); time derivatives thereof"


def test_sensitivity_file_is_cf(tmp_path):
    """`rss6 sensitivity -o S.nc`: the Sobol' indices with their string group labels."""
    out = tmp_path / "sobol.nc"
    assert main(["sensitivity", str(SMOKE), "-n", "64", "--workers", "1", "--no-plots",
                 "-o", str(out)]) == 0
    assert cf_errors(out) == []


def test_reliability_file_is_cf(tmp_path):
    """`rss6 reliability -o R.nc`: every evaluation's inputs, level and maxima."""
    out = tmp_path / "rel.nc"
    assert main(["reliability", str(SMOKE), "--event", "displacement:z>0.2mm", "-n", "100", "--workers", "1",
                 "-o", str(out)]) == 0
    assert cf_errors(out) == []


# --- what a plain netCDF or xarray user sees -------------------------------------------------------

def test_label_selection_with_plain_xarray_and_one_line(tmp_path):
    """The README's line: ``labelled(xr.open_dataset(f))`` gives label selection on every
    dimension (quantity, direction, window; statistic and bound in a statistics file)."""
    from pipeline import labelled
    ens = tmp_path / "ens.nc"
    ds = _ensemble("summary")
    write_netcdf(ds, ens)
    with xr.open_dataset(ens) as raw:
        picked = labelled(raw).max_abs_error.sel(quantity="displacement", direction="x", window="whole")
        assert picked.dims == ("realization",)
        assert picked.values.tolist() == ds["max_abs_error"].sel(
            quantity="displacement", direction="x", window="whole").values.tolist()
    stats = tmp_path / "stats.nc"
    assert main(["stats", str(ens), "-o", str(stats)]) == 0
    with xr.open_dataset(stats) as raw:
        cell = labelled(raw).mean_abs_error.sel(quantity="velocity", direction="rz", statistic="q50",
                                                bound="estimate", window="steady")
        want = float(ds["mean_abs_error"].sel(quantity="velocity", direction="rz", window="steady").median())
        assert float(cell) == pytest.approx(want, rel=1e-14)


def test_every_variable_has_one_cf_unit(tmp_path):
    """The error variables, whose unit depends on quantity and direction, are stored one variable
    per quantity and direction family, each with its UDUNITS unit."""
    path = tmp_path / "full.nc"
    write_netcdf(_ensemble("full"), path)
    with xr.open_dataset(path) as raw:
        units = {name: var.attrs.get("units") for name, var in raw.variables.items()
                 if var.dtype.kind in "fiu" and name != "realization"}   # an index has no unit
        assert None not in units.values(), units
        assert units["error_velocity_translation"] == "m s-1"
        assert units["error_acceleration_rotation"] == "rad s-2"
        assert units["max_abs_error_displacement_translation"] == "m"
        assert list(raw["rotation_label"].values) == ["rx", "ry", "rz"]


def test_a_statistics_file_says_where_it_comes_from_without_a_folder(tmp_path, monkeypatch):
    """`rss6 stats F -o S`: title, its ensemble's scene, level, seed, version and file name, and the
    ensemble's history with its own line appended; no absolute path anywhere."""
    import netCDF4
    from rss6core import __version__
    folder = tmp_path / "deep" / "folder"
    folder.mkdir(parents=True)
    ens = folder / "ens.nc"
    write_netcdf(_ensemble("summary"), ens)
    monkeypatch.chdir(tmp_path)
    assert main(["stats", str(ens.resolve()), "-o", "s.nc"]) == 0
    with netCDF4.Dataset(ens) as source, netCDF4.Dataset(tmp_path / "s.nc") as nc:
        attrs = {k: nc.getncattr(k) for k in nc.ncattrs()}
        assert attrs["title"] == "rss6 statistics of ens.nc: quasi-static level, scene 'smoke'"
        assert (attrs["scene_name"], attrs["model"], attrs["seed"]) == ("smoke", "quasi-static", 0)
        assert attrs["source_file"] == "ens.nc" and attrs["source_rss6_version"] == __version__
        assert attrs["source"] == f"rss6 {__version__}"
        lines = attrs["history"].splitlines()
        assert lines[:-1] == source.history.splitlines() and lines[0].startswith("rss6 run smoke ")
        assert lines[-1] == "rss6 stats ens.nc --confidence 0.95 (finished realisations only)"
        assert not [k for k, v in attrs.items() if str(tmp_path) in str(v)]


def test_the_public_names_import_from_pipeline_lazily():
    """`from pipeline import open_ensemble, ensemble_stats, run_ensemble`; `import pipeline` alone
    (every rss6 command, --help included) loads neither xarray nor dask."""
    import subprocess
    import sys
    code = ("import sys, pipeline; assert 'xarray' not in sys.modules and 'dask' not in sys.modules; "
            "from pipeline import open_ensemble, ensemble_stats, run_ensemble, labelled; "
            "print(open_ensemble.__module__, ensemble_stats.__module__, run_ensemble.__module__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["pipeline.files.opening", "pipeline.analysis.stats", "pipeline.ensemble.run"]


def _every_kind(folder: Path) -> dict:
    """One file of each kind rss6 writes, on small settings (quasi-static smoke, a few realisations;
    the multi-fidelity file pairs 3 paper with 6 quasi-static realisations)."""
    files = {kind: folder / f"{kind}.nc" for kind in
             ("ensemble", "full", "simulate", "stats", "sensitivity", "multifidelity")}
    qs = ["smoke", "--model", "quasi-static"]
    commands = {"ensemble": ["run", *qs, "-n", "4", "--workers", "1"],
                "full": ["run", *qs, "-n", "4", "--workers", "1", "--store", "full"],
                "simulate": ["simulate", *qs],
                "stats": ["stats", str(files["ensemble"])],
                "sensitivity": ["sensitivity", *qs, "-n", "64", "--workers", "1", "--no-plots"],
                "multifidelity": ["multifidelity", "smoke", "--high", "paper", "--low", "quasi-static",
                                  "-n", "3", "--low-n", "6", "--workers", "1"]}
    for kind, command in commands.items():
        assert main([*command, "-o", str(files[kind])]) == 0, kind
    return files | _study_files(folder)


def _study_files(folder: Path) -> dict:
    """tradeoff.nc of two quasi-static settings, and stability.nc of two made-up sweep rows (the
    real sweeps take minutes; the file's form is the same)."""
    from pipeline.scenes.catalogue import find_scene
    from pipeline.studies.setting import Setting
    from pipeline.studies.stability import _stability_dataset, write_stability
    from pipeline.studies.tradeoff import tradeoff, write_tradeoff
    scene = find_scene("smoke")
    settings = [Setting("quasi-static", "newmark", 2e-3, 4), Setting("quasi-static", "newmark", 1e-3, 4)]
    write_tradeoff(tradeoff(scene, 1, 0, settings, settings[1], log=lambda *a: None), folder, 0.05)
    row = dict(level="elastic", integrator="newmark", dt_s=1e-3, stiffness_scale=1.0, horizon_s=0.2,
               status="stable", max_rel_change=0.01, seconds_per_realization=0.1,
               velocity_mean_peak=1e-3, reason="")
    rows = [row, row | dict(dt_s=2e-3, status="failed", reason="diverged")]
    write_stability(_stability_dataset(rows, 1e-4, 0.05, 1, 0, scene), folder)
    return {"tradeoff": folder / "tradeoff.nc", "stability": folder / "stability.nc"}


@pytest.mark.slow   # six commands and two studies, the multi-fidelity one at the paper level: 1-2 minutes
def test_compliance_checker_exits_0_on_every_kind_of_file(tmp_path, capsys):
    """`compliance-checker --test=cf:1.10 FILE` at its default criteria (a warning fails it too) on
    each kind, and each has title, history and source without a folder in them."""
    import subprocess
    import sys
    files = _every_kind(tmp_path)
    capsys.readouterr()
    import shutil
    # the command beside this Python (its environment's), else the one on PATH
    checker = Path(sys.executable).with_name("compliance-checker")
    checker = str(checker) if checker.exists() else shutil.which("compliance-checker")
    assert checker, "compliance-checker (a declared test dependency) is not installed"
    for kind, path in files.items():
        proc = subprocess.run([checker, "--test=cf:1.10", str(path)], capture_output=True, text=True)
        assert proc.returncode == 0, f"{kind}: {proc.stdout[-2000:]} {proc.stderr[-2000:]}"
        with xr.open_dataset(path) as raw:
            for key in ("title", "history", "source", "Conventions"):
                assert str(raw.attrs.get(key, "")).strip(), f"{kind}: no {key}"
            assert not [k for k, v in raw.attrs.items() if str(tmp_path) in str(v)], kind
