"""Values changed after rss6 wrote them are caught: the checksums of a file's values (verified by
every reader), the bounds the summaries obey by construction, and a parts folder checked whole."""
import json
import os
import re
import shlex
import subprocess
from importlib import resources
from pathlib import Path

import netCDF4
import pytest
import xarray as xr

import pipeline.files.reading as reading
import pipeline.files.schema as schema
from pipeline.cli import main
from pipeline.files.outputs import PartsManifest
from pipeline.ensemble.run import EnsembleSpec, ensemble, parts_dir, run_chunk
from pipeline.scenes.catalogue import PACKAGE
from rss6core import __version__
from pipeline.files.checksums import file_checksums
from pipeline.files.opening import open_ensemble
from pipeline.files.reading import load_netcdf
from pipeline.files.schema import CHECKSUM, MIXED_UNITS, EnsembleFileError
from pipeline.files.writing import write_netcdf

SMOKE = Path(str(resources.files(PACKAGE))) / "smoke.toml"
N = 6


def _spec(store_mode: str = "summary") -> EnsembleSpec:
    return EnsembleSpec(SMOKE.read_text(), str(SMOKE), "quasi-static", "newmark", 1e-3, 4, 5, store_mode)


@pytest.fixture(scope="module")
def merged(tmp_path_factory, cluster_client):
    """A merged ensemble (N realisations, chunks of 2 on the shared 2-worker cluster)."""
    path = tmp_path_factory.mktemp("merged") / "ens.nc"
    ensemble(_spec(), N, path, chunk=2, progress=False, client=cluster_client)
    return path


def _edit(path: Path, variable: str, index: tuple, factor: float = 10.0, keep_checksum=True) -> None:
    """Multiply one stored value by ``factor`` in place, as netCDF4 would for a user; optionally
    delete the checksum attribute too (a file of an earlier rss6, or a thorough tamperer)."""
    with netCDF4.Dataset(path, "a") as nc:
        var = nc.variables[variable]
        var[index] = var[index] * factor
        if not keep_checksum:
            nc.delncattr(CHECKSUM)


def _one_line(capsys, *needles) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and re.match(r"rss6 [a-z]+: error: ", err) and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    return err


def _besides_the_loaded_joints(err: str) -> list[str]:
    """stderr's lines but the note every quasi-static (drawn) statistic carries (tests/test_loaded_joints.py)."""
    return [line for line in err.splitlines() if "level places each joint" not in line]


def _copy(src: Path, dst: Path) -> Path:
    dst.write_bytes(src.read_bytes())
    return dst


def test_a_variable_added_or_removed_after_writing_is_refused_naming_it(merged, tmp_path, capsys):
    """A variable the checksum attribute does not list, and one it lists that the file lacks."""
    added = _copy(merged, tmp_path / "added.nc")
    with netCDF4.Dataset(added, "a") as nc:
        nc.createVariable("my_note", "f8", ("realization",))[:] = 1.0
    assert main(["stats", str(added)]) == 2
    _one_line(capsys, f"{added}: variable my_note has no checksum in attribute {CHECKSUM}: it was added after")
    with xr.open_dataset(merged) as ds:
        ds.load().drop_vars("mean_abs_error_displacement_translation").to_netcdf(tmp_path / "removed.nc")
    assert main(["stats", str(tmp_path / "removed.nc")]) == 2
    _one_line(capsys, "variable mean_abs_error_displacement_translation has a checksum in attribute "
              f"{CHECKSUM} but is missing from the file")


def test_one_value_times_ten_is_refused_by_stats_plot_and_resume(merged, tmp_path, capsys):
    """The issue's case: one realisation's whole-run x maximum x 10, edited with netCDF4."""
    assert main(["stats", str(merged)]) == 0
    capsys.readouterr()
    bad = _copy(merged, tmp_path / "bad.nc")
    _edit(bad, "max_abs_error_displacement_translation", (0, 3, 0))
    assert main(["stats", str(bad)]) == 2
    _one_line(capsys, f"{bad}: variable max_abs_error_displacement_translation ", CHECKSUM)
    assert main(["plot", str(bad), "-o", str(tmp_path / "plots")]) == 2
    _one_line(capsys, f"{bad}: variable max_abs_error_displacement_translation ")
    with pytest.raises(EnsembleFileError, match=f"{bad}: variable max_abs_error_displacement_translation "):
        ensemble(_spec(), N + 2, bad, workers=1, progress=False)   # a resume reads it first
    assert not parts_dir(bad).exists()


def test_a_changed_history_value_is_refused_when_the_file_is_resumed(tmp_path):
    """The histories of a full file are read lazily, block by block, and checked all the same."""
    spec = _spec("full")
    out = tmp_path / "full.nc"
    ensemble(spec, 3, out, workers=1, progress=False)
    _edit(out, "error_acceleration_rotation", (2, 150, 1), factor=1.0 + 1e-12)   # one ulp-sized change
    with pytest.raises(EnsembleFileError, match=f"{out}: variable error_acceleration_rotation "):
        ensemble(spec, 4, out, workers=1, progress=False)


def test_the_checksum_is_the_same_for_any_chunking_and_a_rerun(merged, tmp_path):
    """Same seed, same values, same checksums: N realisations in chunks of 2 on 2 workers (the
    fixture), all in one chunk on 1 worker, and computed here in one process and written."""
    other = tmp_path / "one_chunk.nc"
    ensemble(_spec(), N, other, workers=1, chunk=N, progress=False)
    here = tmp_path / "here.nc"
    write_netcdf(run_chunk(_spec(), list(range(N))), here)
    sums = []
    for path in (merged, other, here):
        with netCDF4.Dataset(path) as nc:
            sums.append(json.loads(nc.getncattr(CHECKSUM)))
    assert sums[0] == sums[1] == sums[2]
    assert "max_abs_error_displacement_translation" in sums[0] and "status" in sums[0]
    import xarray as xr
    with xr.open_dataset(merged, engine="netcdf4", decode_times=False) as raw:   # what readers compute
        assert file_checksums(raw) == sums[0]


def test_history_checksums_do_not_depend_on_the_blocks_they_are_written_and_read_in(tmp_path, monkeypatch):
    """A merge streams the histories from the parts one block at a time (here one realisation):
    the checksums are those of the same values written at once, and they verify when the file is
    read whole and when it is read lazily in blocks."""
    monkeypatch.setattr(reading, "HISTORY_BLOCK", 1)
    spec = _spec("full")
    streamed = tmp_path / "streamed.nc"
    ensemble(spec, 4, streamed, workers=1, chunk=2, progress=False)
    at_once = tmp_path / "at_once.nc"
    write_netcdf(run_chunk(spec, [0, 1, 2, 3]), at_once)
    with netCDF4.Dataset(streamed) as a, netCDF4.Dataset(at_once) as b:
        assert json.loads(a.getncattr(CHECKSUM)) == json.loads(b.getncattr(CHECKSUM))
    assert load_netcdf(streamed).encoding.get("rss6_unverified") is None       # verified whole
    assert load_netcdf(streamed, lazy=True)["error"].data.numblocks[0] == 4     # and in blocks


# edits of a file without checksums (an earlier rss6's, or the attribute deleted): the bounds
# between the summaries catch what makes the values impossible. Each edit: (variable, index,
# new value from the file's variables), windows whole, startup, steady along the first axis.
def _times(factor, name, index):
    return lambda nc: nc[name][index] * factor


def _mean_between(nc):
    """A whole-run mean above both window means but below the maximum (only the bound that the
    whole-run mean is their weighted average catches it)."""
    mean, peak = nc["mean_abs_error_displacement_rotation"], nc["max_abs_error_displacement_rotation"]
    split = max(mean[1, 1, 1], mean[2, 1, 1])
    assert split < peak[0, 1, 1]
    return (split + peak[0, 1, 1]) / 2


IMPOSSIBLE = {
    "whole-run maximum x 10": (("max_abs_error_displacement_translation", (0, 3, 0)),
                               _times(10, "max_abs_error_displacement_translation", (0, 3, 0)),
                               "max_abs_error: the whole-run maximum"),
    "startup maximum above the whole run's": (("max_abs_error_velocity_rotation", (1, 2, 2)),
                                              _times(1.5, "max_abs_error_velocity_rotation", (0, 2, 2)),
                                              "max_abs_error: the startup maximum"),
    "steady maximum above the whole run's": (("max_abs_error_acceleration_translation", (2, 0, 1)),
                                             _times(1.01, "max_abs_error_acceleration_translation", (0, 0, 1)),
                                             "max_abs_error: the steady maximum"),
    "mean above its maximum": (("mean_abs_error_velocity_translation", (2, 4, 0)),
                               _times(1.01, "max_abs_error_velocity_translation", (2, 4, 0)),
                               "mean_abs_error: the mean"),
    "whole-run mean above both windows' means": (("mean_abs_error_displacement_rotation", (0, 1, 1)),
                                                 _mean_between, "mean_abs_error: the whole-run mean"),
}


@pytest.mark.parametrize("case", list(IMPOSSIBLE))
def test_impossible_values_are_refused_by_name(merged, tmp_path, capsys, case):
    (variable, index), value, message = IMPOSSIBLE[case]
    bad = _copy(merged, tmp_path / "bad.nc")
    with netCDF4.Dataset(bad, "a") as nc:
        nc[variable][index] = value(nc)
        nc.delncattr(CHECKSUM)           # as if an earlier rss6 had written it: the bounds still hold
        nc.rss6_version = "0.2.0"
    assert main(["stats", str(bad)]) == 2
    _one_line(capsys, f"{bad}: {message}", "cannot happen")


def test_a_file_without_checksums_is_read_with_a_note(merged, tmp_path, capsys):
    """An earlier rss6's file: its results stay usable (they may have cost hours), with one note."""
    old = _copy(merged, tmp_path / "old.nc")
    with netCDF4.Dataset(old, "a") as nc:
        nc.delncattr(CHECKSUM)
        nc.rss6_version = "0.2.0"
    assert main(["stats", str(old), "--json"]) == 0
    out = capsys.readouterr()
    assert json.loads(out.out)["n_finished"] == N
    assert _besides_the_loaded_joints(out.err) == [f"rss6: note: {old}: no checksum of its values ({CHECKSUM}; "
                                                   "written by an earlier rss6 or by another program): checked for "
                                                   "consistency only"]


def test_a_checksum_removed_from_a_file_of_a_version_that_writes_it_is_refused(merged, tmp_path, capsys):
    """Deleting the attribute is no way around the check: this rss6 writes it, so its absence in a
    file of this version means the file was altered."""
    bare = _copy(merged, tmp_path / "bare.nc")
    _edit(bare, _first_error_variable(bare), (0, 0, 0), keep_checksum=False)
    assert main(["stats", str(bare)]) == 2
    _one_line(capsys, str(bare), CHECKSUM, "is missing")


def _first_error_variable(path: Path) -> str:
    with netCDF4.Dataset(path) as nc:
        return next(v for v in nc.variables if v.startswith("max_abs_error_"))


def test_a_file_in_the_layout_before_the_split_by_unit_is_read(tmp_path, capsys, monkeypatch):
    """rss6 up to 0.2.0 wrote each error variable whole (per-element units in 'unit', no CF units)
    and no checksums: such a file reads as the same Dataset, with the note."""
    ds = run_chunk(_spec(), [0, 1, 2])
    old = tmp_path / "old.nc"
    with monkeypatch.context() as m:
        m.setattr(schema, "_split_units", lambda d: d)
        write_netcdf(ds, old)
    with netCDF4.Dataset(old, "a") as nc:
        assert nc.variables["max_abs_error"].rss6_units == MIXED_UNITS
        nc.delncattr(CHECKSUM)
        nc.rss6_version = "0.2.0"
    import xarray as xr
    xr.testing.assert_identical(open_ensemble(old), ds.assign_attrs(rss6_version="0.2.0"))
    assert main(["stats", str(old)]) == 0
    assert "no checksum" in capsys.readouterr().err


def _three_parts(out: Path) -> PartsManifest:
    manifest = PartsManifest(parts_dir(out), _spec().attrs())
    for r in (0, 2, 4):
        manifest.write(run_chunk(_spec(), [r, r + 1]), f"chunk-{r:07d}-{r + 1:07d}.nc")
    return manifest


def test_two_tampered_parts_are_named_in_one_run_with_the_command_that_recovers(merged, tmp_path):
    out = tmp_path / "out.nc"
    manifest = _three_parts(out)
    first, _, last = manifest.parts()
    _edit(first, "mean_abs_error_displacement_translation", (0, 1, 2))
    _edit(last, "steps", (0,), factor=2)
    with pytest.raises(EnsembleFileError) as exc:
        ensemble(_spec(), N, out, workers=1, progress=False)
    message = str(exc.value)
    assert len(message.splitlines()) == 1 and message.startswith(f"{manifest.folder}: 2 of 3 stored parts")
    assert f"{first.name}: changed since it was written" in message and "realisations 0-1" in message
    assert f"{last.name}: changed since it was written" in message and "realisations 4-5" in message
    command = message.split("recover with `")[1].split("`")[0]
    assert command == f"rm {shlex.quote(str(first))} {shlex.quote(str(last))}"
    subprocess.run(command, shell=True, check=True)   # the one command, then the same rerun
    outcome = ensemble(_spec(), N, out, workers=1, progress=False)
    assert outcome.stored_before == 2 and outcome.computed == 4
    with netCDF4.Dataset(out) as a, netCDF4.Dataset(merged) as b:
        assert a.getncattr(CHECKSUM) == b.getncattr(CHECKSUM)   # the same values as a clean run


@pytest.mark.parametrize("loss", ["deleted", "unreadable", "parts a list", "an entry a number", "no provenance",
                                  "an entry without its checksum"])
def test_parts_whose_manifest_is_lost_are_verified_and_kept(merged, tmp_path, loss):
    """A deleted or unreadable manifest.json costs no finished work (bad-input audit: it had thrown
    away every stored chunk): each part's own checksums and identity are checked, the good ones are
    vouched for again and the rerun computes nothing, giving the clean run's values."""
    out = tmp_path / "out.nc"
    manifest = _three_parts(out)
    data = json.loads(manifest.path.read_text())
    first = next(iter(data["parts"]))
    edits = {"parts a list": lambda d: d | {"parts": []},   # a reviewer's edits: each had ended in a traceback
             "an entry a number": lambda d: d | {"parts": d["parts"] | {first: 5}},
             "no provenance": lambda d: {"parts": d["parts"]},   # had read "made with different settings"
             "an entry without its checksum": lambda d: d | {"parts": d["parts"] | {first: {"realizations": [0]}}}}
    if loss == "deleted":
        manifest.path.unlink()
    elif loss == "unreadable":
        manifest.path.write_text('{"parts": {"chunk-0000000')
    else:
        manifest.path.write_text(json.dumps(edits[loss](data)))
    outcome = ensemble(_spec(), N, out, workers=1, progress=False)
    assert outcome.stored_before == N and outcome.computed == 0
    with netCDF4.Dataset(out) as a, netCDF4.Dataset(merged) as b:
        assert a.getncattr(CHECKSUM) == b.getncattr(CHECKSUM)
    assert not manifest.folder.exists()   # the finished file's parts, the set-aside manifest too, are gone


def test_a_part_without_its_manifest_is_still_refused_if_its_values_changed(tmp_path):
    out = tmp_path / "out.nc"
    manifest = _three_parts(out)
    first, *_ = manifest.parts()
    manifest.path.unlink()
    _edit(first, "mean_abs_error_displacement_translation", (0, 1, 2))
    with pytest.raises(EnsembleFileError) as exc:
        ensemble(_spec(), N, out, workers=1, progress=False)
    message = str(exc.value)
    assert message.startswith(f"{manifest.folder}: 1 of 3 stored parts") and first.name in message
    assert "mean_abs_error_displacement_translation" in message and len(message.splitlines()) == 1


# global attributes edited with netCDF4 after rss6 wrote the file: (attribute, edit, what the one
# line says of it); each fixes the file's meaning (IDENTITY, PROVENANCE) or adds to it
ATTRIBUTE_EDITS = {
    "seed": ("seed", lambda nc: nc.setncattr("seed", 12345), "is 12345 (int64), not the value"),
    "scene_toml": ("scene_toml", lambda nc: nc.setncattr("scene_toml", nc.scene_toml.replace("0.", "0.0", 1)),
                   "is '# rss6 scene"),
    "time_step_s": ("time_step_s", lambda nc: nc.setncattr("time_step_s", 2e-3), "is 0.002 (float64)"),
    "model": ("model", lambda nc: nc.delncattr("model"), "missing, although"),
    "sampler added": ("sampler", lambda nc: nc.setncattr("sampler", "qmc"), "was added after rss6 wrote"),
}


@pytest.mark.parametrize("case", list(ATTRIBUTE_EDITS))
def test_an_edited_global_attribute_is_refused_by_stats_plot_and_resume(merged, tmp_path, capsys, case):
    name, edit, says = ATTRIBUTE_EDITS[case]
    bad = _copy(merged, tmp_path / "bad.nc")
    with netCDF4.Dataset(bad, "a") as nc:
        edit(nc)
    assert main(["stats", str(bad)]) == 2
    _one_line(capsys, f"{bad}: attribute {name} {says}", CHECKSUM, "altered after rss6 wrote it")
    assert main(["plot", str(bad), "-o", str(tmp_path / "plots")]) == 2
    _one_line(capsys, f"{bad}: attribute {name} ")
    with pytest.raises(EnsembleFileError, match=f"{bad}: attribute {name} "):
        ensemble(_spec(), N + 2, bad, workers=1, progress=False)


@pytest.mark.parametrize("attribute, value", [("rss6_part_of", "mean_abs_error"), ("rss6_part_of", None),
                                              ("rss6_dims", "window direction"), ("rss6_quantity", "velocity")])
def test_an_edited_split_variable_attribute_is_named_as_an_alteration(merged, tmp_path, capsys, attribute, value):
    """A split variable's own rss6 attributes (which join it back) edited after rss6 wrote the file:
    one line saying so, not the joining's internal error (a new user's review)."""
    bad = _copy(merged, tmp_path / "bad.nc")
    with netCDF4.Dataset(bad, "a") as nc:
        var = nc["max_abs_error_displacement_translation"]
        var.delncattr(attribute) if value is None else var.setncattr(attribute, value)
    for command in (["stats", str(bad)], ["plot", str(bad), "-o", str(tmp_path / "plots")]):
        assert main(command) == 2
        err = _one_line(capsys, str(bad), "altered after rss6 wrote it")
        assert "Error" not in err, err


def test_the_history_may_be_appended_to(merged, tmp_path):
    """CF tools append their command to ``history``: the one global attribute left unchecked."""
    noted = _copy(merged, tmp_path / "noted.nc")
    with netCDF4.Dataset(noted, "a") as nc:
        nc.history += "\nncatted -a comment,global,c,c,x noted.nc"
    assert open_ensemble(noted).encoding.get("rss6_unverified") is None


def _without_attribute_checksums(path: Path, version: str = "0.3.0") -> None:
    """The checksum attribute without its global attributes' entry, as rss6 0.3.0 wrote it (the
    file's rss6_version set to ``version``)."""
    with netCDF4.Dataset(path, "a") as nc:
        sums = json.loads(nc.getncattr(CHECKSUM))
        del sums["/attributes"]
        nc.setncattr(CHECKSUM, json.dumps(sums, sort_keys=True))
        nc.setncattr("rss6_version", version)


def test_a_file_of_a_version_that_writes_the_attribute_checksums_is_refused_without_them(merged, tmp_path, capsys):
    """From rss6 0.3.1 on, a file without the entry had it removed."""
    bad = _copy(merged, tmp_path / "bad.nc")
    _without_attribute_checksums(bad, version=__version__)
    assert main(["stats", str(bad)]) == 2
    _one_line(capsys, f"{bad}: attribute {CHECKSUM} lacks its /attributes entry, although rss6 {__version__} writes it")


def test_a_file_written_before_the_attribute_checksums_is_read_as_before(merged, tmp_path, capsys):
    """Its variables are verified (no note), its attributes cross-checked only; a changed value is
    refused as ever."""
    old = _copy(merged, tmp_path / "old.nc")
    _without_attribute_checksums(old)
    with netCDF4.Dataset(old, "a") as nc:
        nc.setncattr("seed", 12345)   # not cross-checked against anything: accepted, as before
    assert main(["stats", str(old), "--json"]) == 0
    out = capsys.readouterr()
    assert json.loads(out.out)["n_finished"] == N and _besides_the_loaded_joints(out.err) == []
    assert load_netcdf(old).attrs["seed"] == 12345
    _edit(old, "max_abs_error_displacement_translation", (0, 3, 0))
    assert main(["stats", str(old)]) == 2
    _one_line(capsys, f"{old}: variable max_abs_error_displacement_translation ", CHECKSUM)


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="lists open files through /proc")
def test_a_lazily_opened_file_is_closed_by_its_dataset_or_a_view_of_it(merged):
    """load_netcdf(lazy=True) leaves the file open for its dask arrays; closing the Dataset, or a
    selection from it, closes the file (not the garbage collector, which may run at any time)."""
    fds = Path("/proc/self/fd")

    def is_open() -> bool:
        return any(os.path.realpath(fds / fd) == os.path.realpath(merged) for fd in os.listdir(fds))
    for close in (lambda ds: ds.close(), lambda ds: ds.sel(realization=[0, 1]).close()):
        ds = load_netcdf(merged, lazy=True)
        assert is_open()
        close(ds)
        assert not is_open()
