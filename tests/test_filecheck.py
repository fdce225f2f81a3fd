"""Files that are readable but wrong: one line naming the file and the problem, exit code 2."""
from importlib import resources
from pathlib import Path
import json

import numpy as np
import pytest

from pipeline.cli import main
from pipeline.run import EnsembleSpec, run_ensemble
from pipeline.store import EnsembleFileError, load_netcdf, open_ensemble
from pipeline.scenes import PACKAGE

CONFIGS = Path(str(resources.files(PACKAGE)))  # the shipped scenes

SMOKE = CONFIGS / "smoke.toml"


@pytest.fixture(scope="module")
def good(tmp_path_factory, cluster_client):
    path = tmp_path_factory.mktemp("good") / "good.nc"
    spec = EnsembleSpec(SMOKE.read_text(), str(SMOKE), "quasi-static", "newmark", 1e-3, 4, 0, "summary")
    run_ensemble(spec, 6, path, progress=False, client=cluster_client)
    return path


def _set(name, index, value):
    def change(ds):
        ds[name].loc[index] = value
        return ds
    return change


def _attr(name, units):
    def change(ds):
        ds[name].attrs["units"] = units
        return ds
    return change


def _unit(i, j, unit):
    def change(ds):
        table = ds["unit"].transpose("quantity", "direction").values.copy()
        table[i, j] = unit
        return ds.assign_coords(unit=(("quantity", "direction"), table))
    return change


def _failed_with_nan(ds):
    ds["status"].values[1] = "failed"
    ds["max_abs_error"].loc[{"realization": 1}] = np.nan
    return ds


CASES = {
    "duplicate": (lambda ds: ds.assign_coords(realization=[0, 1, 2, 2, 4, 5]),
                  "realisation index 2 appears 2 times"),
    "negative": (_set("max_abs_error", {"realization": 3, "quantity": "velocity", "direction": "y"}, -1.0),
                 "max_abs_error has negative values"),
    "infinite": (_set("mean_abs_error", {"realization": 0, "quantity": "displacement", "direction": "z"},
                      np.inf), "mean_abs_error has infinite values"),
    "nan in a finished run": (_set("max_abs_error", {"realization": 4}, np.nan),
                              "max_abs_error is not finite in finished realisation 4"),
    "renamed dimension": (lambda ds: ds.rename({"direction": "axis"}),
                          r"max_abs_error has dimensions \(window, quantity, realization, axis\)"),
    "relabelled quantity": (lambda ds: ds.assign_coords(quantity=["displacement", "speed",
                                                                  "acceleration"]),
                            "'quantity' labels are displacement, speed, acceleration"),
    "relabelled direction": (lambda ds: ds.assign_coords(direction=["x", "y", "z", "a", "b", "c"]),
                             "'direction' labels are x, y, z, a, b, c"),
    "variable units": (_attr("mean_abs_error", "mm"), "mean_abs_error has units 'mm'"),
    "element unit": (_unit(0, 0, "mm"), "unit of displacement x is 'mm'; expected 'm'"),
    "element unit inside the table": (_unit(2, 4, "m s-2"), "unit of acceleration ry is 'm s-2'; "
                                                            "expected 'rad s-2'"),
    "unit over one dimension": (lambda ds: ds.assign_coords(unit=(("quantity",), ["m", "m s-1", "m s-2"])),
                                r"'unit' has dimensions \(quantity\); expected quantity, direction"),
    "no unit coordinate": (lambda ds: ds.drop_vars("unit"), "no 'unit' coordinate"),
    "unknown status": (_set("status", {"realization": 2}, "done"), "unknown status 'done'"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_wrong_file_is_one_line_and_exit_2(good, tmp_path, capsys, case):
    change, message = CASES[case]
    bad = tmp_path / "bad.nc"
    change(load_netcdf(good).copy(deep=True)).to_netcdf(bad)
    with pytest.raises(EnsembleFileError, match=message):
        open_ensemble(bad)
    assert main(["stats", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"rss6: error: {bad}: ") and "Traceback" not in err


def test_the_untampered_file_and_failed_runs_with_nan_are_accepted(good, tmp_path, capsys):
    assert main(["stats", str(good)]) == 0
    capsys.readouterr()
    mixed = tmp_path / "mixed.nc"
    _failed_with_nan(load_netcdf(good).copy(deep=True)).to_netcdf(mixed)
    assert main(["stats", str(mixed), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["n_finished"] == 5 and js["n_failed"] == 1


@pytest.fixture(scope="module")
def single_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("run") / "run.nc"
    assert main(["simulate", str(SMOKE), "--model", "quasi-static", "-o", str(path)]) == 0
    return path


def test_stats_of_a_simulate_file_gives_estimates_without_intervals(single_run, capsys):
    capsys.readouterr()
    assert main(["stats", str(single_run), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    stored = load_netcdf(single_run)["max_abs_error"].sel(window="whole", quantity="displacement",
                                                          direction="z")
    cell = js["max_abs_error"]["displacement"]["z"]
    assert js["n_finished"] == 1 and js["n_failed"] == 0
    for stat in ("mean", "q05", "q50", "q95", "q99", "max"):
        assert cell[stat]["estimate"] == float(stored)
        assert cell[stat]["lower"] is None and cell[stat]["upper"] is None
    assert cell["std"]["estimate"] is None


def test_a_tampered_simulate_file_is_refused(single_run, tmp_path, capsys):
    bad = tmp_path / "bad-run.nc"
    ds = load_netcdf(single_run).copy(deep=True)
    ds["max_abs_error"].values[1, 2] = -3.0
    ds.to_netcdf(bad)
    assert main(["stats", str(bad)]) == 2
    assert "bad-run.nc: max_abs_error has negative values" in capsys.readouterr().err
