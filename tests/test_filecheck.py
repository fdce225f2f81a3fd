"""Files that are readable but wrong: one line naming the file and the problem, exit code 2."""
from importlib import resources
from pathlib import Path
import json

import numpy as np
import pytest

from rss6core import __version__

from pipeline.cli import main
from pipeline.ensemble.run import EnsembleSpec, run_ensemble
from pipeline.files.opening import open_ensemble
from pipeline.files.reading import load_netcdf
from pipeline.files.schema import ENSEMBLE_ATTRS, PROVENANCE, EnsembleFileError
from pipeline.files.writing import write_netcdf
from pipeline.scenes.catalogue import PACKAGE

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


def _attrs(**changes):
    """Global attributes set (None: deleted), as an edit with netCDF4 would."""
    def change(ds):
        for key, value in changes.items():
            if value is None:
                del ds.attrs[key]
            else:
                ds.attrs[key] = value
        return ds
    return change


def _forces(ds):
    return ds.assign(max_contact_force=(("realization", "joint"), np.ones((ds.sizes["realization"], 18))))


def _failed_with_nan(ds):
    ds["status"].values[1] = "failed"
    ds["max_abs_error"].loc[{"realization": 1}] = np.nan
    return ds.assign_attrs(n_failed=1)


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
    "n_realizations": (_attrs(n_realizations=40), "attribute n_realizations is 40, but the file holds 6 "
                                                  "realisations"),
    "n_failed": (_attrs(n_failed=3), r"attribute n_failed is 3, but the file holds 0 failed realisations"),
    "count not an integer": (_attrs(n_realizations="6"), "attribute n_realizations is '6'; expected an integer"),
    "model of another level": (_attrs(model="contact"), "attribute model is 'contact', but the file has no "
                                                        "max_contact_force"),
    "model no level": (_attrs(model="fast"), "attribute model is 'fast'; expected one of rigid, quasi-static"),
    "forces at a level without them": (_forces, "attribute model is 'quasi-static', but the file holds "
                                                "max_contact_force"),
    "scene_toml not TOML": (_attrs(scene_toml="garbage = ["), "attribute scene_toml is not a scene rss6 "
                                                              "reads: not valid TOML"),
    "scene_toml not a scene": (_attrs(scene_toml='name = "smoke"'), "attribute scene_toml is not a scene "
                                                                    "rss6 reads: missing key"),
    "scene_name": (_attrs(scene_name="paper"), "attribute scene_name is 'paper', but scene_toml is scene "
                                               "'smoke'"),
    "settle_time_s": (_attrs(settle_time_s=0.05), "attribute settle_time_s is 0.05 s, but scene_toml says 0 s"),
    "time_step_s": (_attrs(time_step_s=7e-4), r"attribute time_step_s \(0.0007 s\) does not divide"),
    "integrator": (_attrs(integrator="euler"), "attribute integrator is 'euler'; expected one of newmark"),
    "elements_per_link": (_attrs(elements_per_link=0), "attribute elements_per_link is 0; expected an "
                                                       "integer >= 1"),
    "seed": (_attrs(seed=-1), "attribute seed is -1; expected an integer >= 0"),
    "store": (_attrs(store="full"), "attribute store is 'full', but the file has no histories"),
    "contact_start": (_attrs(contact_start="drawn"), "attribute contact_start in a quasi-static-level file"),
    "sampler": (_attrs(sampler="sobol"), "attribute sampler is 'sobol'; expected 'qmc'"),
    "replicates without sampler": (_attrs(qmc_replicates=4), "attribute qmc_replicates without sampler"),
    "no rss6_version": (_attrs(rss6_version=None), r"not an rss6 ensemble file \(missing rss6 attributes\)"),
    **{f"no {key}": (_attrs(**{key: None}), f"attribute {key} missing")
       for key in PROVENANCE + ENSEMBLE_ATTRS if key != "rss6_version"},
}


def _drop_attributes_the_writer_restored(path, changed) -> None:
    """rss6's writer (which adds the checksums) sets Conventions and source itself: a case that
    removed one removes it from the written file, as a user editing it with netCDF4 would."""
    import netCDF4
    with netCDF4.Dataset(path, "a") as nc:
        for name in ("Conventions", "source"):
            if name not in changed.attrs and name in nc.ncattrs():
                nc.delncattr(name)


@pytest.mark.parametrize("case", list(CASES))
def test_wrong_file_is_one_line_and_exit_2(good, tmp_path, capsys, case):
    change, message = CASES[case]
    bad = tmp_path / "bad.nc"
    changed = change(load_netcdf(good).copy(deep=True))
    write_netcdf(changed, bad)
    _drop_attributes_the_writer_restored(bad, changed)
    with pytest.raises(EnsembleFileError, match=message):
        open_ensemble(bad)
    assert main(["stats", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"rss6 stats: error: {bad}: ") and "Traceback" not in err


def test_the_untampered_file_and_failed_runs_with_nan_are_accepted(good, tmp_path, capsys):
    assert main(["stats", str(good)]) == 0
    capsys.readouterr()
    mixed = tmp_path / "mixed.nc"
    write_netcdf(_failed_with_nan(load_netcdf(good).copy(deep=True)), mixed)
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
    write_netcdf(ds, bad)
    assert main(["stats", str(bad)]) == 2
    assert "bad-run.nc: max_abs_error has negative values" in capsys.readouterr().err


def test_a_simulate_file_with_a_wrong_attribute_is_refused(single_run, tmp_path, capsys):
    bad = tmp_path / "bad-attr.nc"
    write_netcdf(load_netcdf(single_run).assign_attrs(model="contact"), bad)
    assert main(["stats", str(bad)]) == 2
    assert "bad-attr.nc: attribute model is 'contact', but the file has no max_contact_force" in capsys.readouterr().err


def test_resuming_a_file_of_another_rss6_version_is_refused(good, tmp_path, capsys):
    """Merging would file one version's realisations under another's name: one line, nothing run."""
    old = tmp_path / "old.nc"
    write_netcdf(_attrs(rss6_version="9.9.9", source="rss6 9.9.9")(load_netcdf(good)), old)
    before = old.read_bytes()
    assert main(["stats", str(old)]) == 0                    # reading it is fine
    capsys.readouterr()
    assert main(["run", str(SMOKE), "-n", "8", "--model", "quasi-static", "--workers", "1", "-o", str(old)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"rss6 run: error: {old}: written by rss6 9.9.9, this is "
                                                         f"rss6 {__version__}") and "another -o" in err
    assert old.read_bytes() == before and not (tmp_path / "old.nc.parts").exists()


def test_a_split_variables_units_edited_on_disk_are_refused(good, tmp_path, capsys):
    """A CF reader trusts a variable's units: m edited to mm (a new user's review) would make it read
    the values 1000x off while rss6's own numbers stayed; the edit is now named, exit 2."""
    import shutil

    import netCDF4
    bad = tmp_path / "units.nc"
    shutil.copy(good, bad)
    with netCDF4.Dataset(bad, "a") as nc:
        assert nc["max_abs_error_displacement_translation"].units == "m"
        nc["max_abs_error_displacement_translation"].units = "mm"
    assert main(["stats", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "attribute units of variable max_abs_error_displacement_translation is 'mm'" in err, err
    assert err.count(str(bad)) == 1 and "altered after rss6 wrote it" in err and "Error" not in err, err


VARIABLE_ATTRIBUTE_EDITS = {   # (edit, what the one line says); the helper review's cases passed unseen
    "units of a coordinate": (lambda nc: nc["clearance_size"].setncattr("units", "mm"),
                              "attribute units of variable clearance_size is 'mm'"),
    "cell_methods": (lambda nc: nc["max_abs_error_displacement_translation"].setncattr("rss6_cell_methods",
                                                                                        "time: mean"),
                     "attribute rss6_cell_methods of variable max_abs_error_displacement_translation is 'time: mean'"),
    "long_name": (lambda nc: nc["steps"].setncattr("long_name", "anything"), "attribute long_name of variable steps"),
    "added": (lambda nc: nc["status"].setncattr("comment", "edited"), "attribute comment of variable status was added"),
    "removed": (lambda nc: nc["steps"].delncattr("long_name"), "attribute long_name of variable steps was removed"),
}


@pytest.mark.parametrize("case", list(VARIABLE_ATTRIBUTE_EDITS))
def test_an_edited_variable_attribute_is_refused(good, tmp_path, capsys, case):
    """Every variable's attributes carry checksums (the CHECKSUM entry /variable_attributes), so an edit
    that changes a value's meaning (its units, what it reduces) is refused naming variable and attribute;
    a file whose checksums lack the entry (an earlier rss6's) is read as before."""
    import json
    import shutil

    import netCDF4
    from pipeline.files.checksums import VARIABLE_ATTRIBUTES
    from pipeline.files.schema import CHECKSUM
    edit, says = VARIABLE_ATTRIBUTE_EDITS[case]
    bad = tmp_path / "edited.nc"
    shutil.copy(good, bad)
    with netCDF4.Dataset(bad, "a") as nc:
        edit(nc)
    assert main(["stats", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err and "altered after rss6 wrote it" in err, err
    older = tmp_path / "older.nc"
    shutil.copy(good, older)
    with netCDF4.Dataset(older, "a") as nc:
        sums = json.loads(nc.getncattr(CHECKSUM))
        del sums[VARIABLE_ATTRIBUTES]
        nc.setncattr(CHECKSUM, json.dumps(sums, sort_keys=True))
        edit(nc)
    assert main(["stats", str(older)]) == 0, capsys.readouterr().err
