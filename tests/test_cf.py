"""Every kind of file rss6 writes is CF-1.10 by the IOOS compliance-checker, and reads back as the
same in-memory Dataset the rest of rss6 works with."""
from pathlib import Path

from importlib import resources
import pytest
import xarray as xr

from pipeline.cli import main
from pipeline.run import EnsembleSpec, run_chunk
from pipeline.store import load_netcdf, write_netcdf
from pipeline.scenes import PACKAGE

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
    from pipeline.multifidelity import multifidelity_dataset
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
