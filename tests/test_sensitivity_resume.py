"""rss6 sensitivity keeps its finished evaluation chunks in OUT.parts and resumes from them: an interrupted
run rerun gives the indices of an uninterrupted one, evaluating only the missing rows; other settings,
changed parts and failed rows are refused as `rss6 run` refuses them."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import pipeline.studies.sensitivity as sens
from pipeline.cli import main
from pipeline.ensemble.run import EnsembleSpec
from pipeline.files.reading import load_netcdf

ARGS = ["-n", "64", "--per-joint", "--no-plots"]   # 64 (4 + 2) + 64 (18 + 2) = 1664 rows
# in this process the default chunk is a quarter of a design's rows (at most 256): families 4 x 96,
# joints 5 chunks (4 x 256, 256)
FAMILY_ROWS, JOINT_CHUNK = 64 * 6, 256


def _argv(configs, out, *extra, workers="1"):
    return ["sensitivity", str(configs / "smoke.toml"), *ARGS, "--workers", workers, "-o", str(out), *extra]


def _counting(monkeypatch, stop_at: int | None = None) -> list:
    """Wrap the chunk evaluation: record each chunk's row count; with ``stop_at``, that call (1-based)
    raises KeyboardInterrupt instead, as Ctrl-C while it computes would."""
    calls, evaluate = [], sens._evaluate_chunk

    def wrapped(spec, inputs, u, window="whole"):
        if stop_at is not None and len(calls) + 1 == stop_at:
            raise KeyboardInterrupt
        calls.append(len(u))
        return evaluate(spec, inputs, u, window)
    monkeypatch.setattr(sens, "_evaluate_chunk", wrapped)
    return calls


def _parts(out: Path) -> Path:
    return out.with_name(out.name + ".parts")


@pytest.fixture(scope="module")
def whole(tmp_path_factory, configs):
    """One uninterrupted run."""
    out = tmp_path_factory.mktemp("whole") / "s.nc"
    assert main(_argv(configs, out)) == 0
    return out


@pytest.fixture
def interrupted(configs, tmp_path, monkeypatch, capsys):
    """A run stopped by Ctrl-C in its sixth chunk: the four family chunks and the first joint chunk stored."""
    out = tmp_path / "s.nc"
    _counting(monkeypatch, stop_at=6)
    assert main(_argv(configs, out)) == 130
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and err.splitlines()[-1] == (
        f"rss6: interrupted; finished chunks are kept in {_parts(out)}; rerun the same command to continue")
    monkeypatch.undo()
    return out


def _same_indices(a: Path, b: Path) -> None:
    """The same file: every variable, coordinate and attribute (bits)."""
    xr.testing.assert_identical(load_netcdf(a), load_netcdf(b))


@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_rerun_evaluates_only_the_missing_rows_and_gives_the_uninterrupted_indices(
        interrupted, whole, configs, monkeypatch, capsys, workers):
    """Five chunks were stored (4 x 96 family rows, 256 joint rows): the rerun evaluates the other 1024
    rows (in this process, or on two dask workers in other chunks) and writes the uninterrupted run's
    indices; the parts folder is then gone."""
    out, parts = interrupted, _parts(interrupted)
    assert not out.exists()
    manifest = json.loads((parts / "manifest.json").read_text())
    assert sorted(manifest["parts"]) == sorted(p.name for p in parts.glob("*.nc"))
    assert sorted(manifest["parts"]) == [f"families-{i:07d}-{i + 95:07d}.nc" for i in range(0, 384, 96)] + [
        "joints-0000000-0000255.nc"]
    calls = _counting(monkeypatch)
    assert main(_argv(configs, out, workers=workers)) == 0
    if workers == "1":   # on dask the chunks are evaluated in the workers, out of sight of the wrapper
        assert sum(calls) == 64 * 20 - JOINT_CHUNK and len(calls) == 4
    assert not parts.exists()
    err = capsys.readouterr().err
    assert f"families: 384 evaluations of the quasi-static level (4 groups, N = 64) on {workers} worker(s); 384 " \
           f"stored in {parts}\n" in err and "joints: 1280 evaluations" in err and f"; 256 stored in {parts}\n" in err
    _same_indices(out, whole)


def test_the_stored_rows_are_the_rows_of_any_chunking(configs):
    """A row's statistics do not depend on the chunk it is evaluated in (nor on what else is in it): chunks
    of 7 rows and one chunk of all give the same bits, so resumed rows match an uninterrupted run's."""
    text = (configs / "smoke.toml").read_text()
    spec = EnsembleSpec(text, str(configs / "smoke.toml"), "quasi-static", "newmark", 1e-3, 4, 0)
    inputs = sens.clearance_inputs(spec.scene())
    u = sens.sample_design(sens.designs(inputs, False)[0], 64, 0)[:40]
    np.testing.assert_array_equal(sens.evaluate_statistics(spec, inputs, u, chunk=7),
                                  sens.evaluate_statistics(spec, inputs, u, chunk=40))


def test_the_chunks_of_the_missing_rows_stay_within_their_runs():
    assert sens._chunks(np.arange(10), 4) == [slice(0, 4), slice(4, 8), slice(8, 10)]
    assert sens._chunks(np.array([2, 3, 4, 8, 9]), 2) == [slice(2, 4), slice(4, 5), slice(8, 10)]
    assert sens._chunks(np.array([], int), 4) == []


@pytest.mark.parametrize("change", [["--seed", "1"], ["--window", "startup"], ["--confidence", "0.9", "--seed", "2"]])
def test_other_settings_on_the_same_output_are_refused_with_one_line(interrupted, configs, capsys, change):
    """The run's one-line refusal (exit 2) before any work; the stored parts are left as they were."""
    parts = _parts(interrupted)
    before = {p.name: p.read_bytes() for p in parts.iterdir()}
    assert main(_argv(configs, interrupted, *change)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the parts were made with different settings" in err[0], err
    assert "seed, -n, --per-joint or --window" in err[0]
    assert {p.name: p.read_bytes() for p in parts.iterdir()} == before and not interrupted.exists()


def test_a_changed_part_is_named_in_one_line(interrupted, configs, capsys):
    """A part whose bytes changed since it was written: the run's one-line refusal naming it (exit 2)."""
    part = _parts(interrupted) / "families-0000096-0000191.nc"
    data = bytearray(part.read_bytes())
    data[-100] ^= 1
    part.write_bytes(bytes(data))
    assert main(_argv(configs, interrupted)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "families-0000096-0000191.nc: changed since it was written" in err[0], err
    assert "rows 96-191" in err[0] and f"rm {part}" in err[0]


def test_a_failed_row_keeps_the_finished_chunks(configs, tmp_path, monkeypatch, capsys):
    """A row that fails: SensitivityError (exit 2, no indices), the chunks without a failure stored, the
    failing one not (a rerun evaluates it again and reports it again)."""
    out, evaluate, calls = tmp_path / "s.nc", sens._evaluate_chunk, []

    def failing(spec, inputs, u, window="whole"):   # the first row of the second chunk fails
        calls.append(len(u))
        stats, messages = evaluate(spec, inputs, u, window)
        return stats, (["diverged"] + messages[1:]) if len(calls) == 2 else messages
    monkeypatch.setattr(sens, "_evaluate_chunk", failing)
    assert main(_argv(configs, out)) == 2
    err = capsys.readouterr().err.strip()
    assert "1 of 384 evaluations of the quasi-static level failed (first: diverged)" in err, err
    assert sorted(p.name for p in _parts(out).glob("*.nc")) == [
        "families-0000000-0000095.nc", "families-0000192-0000287.nc", "families-0000288-0000383.nc"]
    assert not out.exists()


def test_ctrl_c_on_dask_is_raised_between_waits_after_the_finished_chunks_are_kept(monkeypatch, tmp_path):
    """On a dask client a Ctrl-C arriving while rss6 waits for the workers is held and raised by
    pipeline.ensemble.cluster.results_as_finished before its next wait (never inside dask's client, as for
    `rss6 run`); the chunk that had finished is stored first."""
    import os
    import signal

    import pipeline.ensemble.cluster as cluster
    from pipeline.files.outputs import PartsManifest

    class Client:   # stands for a dask client: each chunk is computed at once, its "future" a number
        results = []

        def submit(self, function, *args, pure):
            self.results.append(function(*args))
            return len(self.results) - 1

        def nthreads(self):
            return {"worker": 1}
    waits = []

    def wait_in_dask(client, pending):   # stands for cluster._gathered: the first chunk, then Ctrl-C
        waits.append(1)
        assert len(waits) < 3, "the held Ctrl-C was not acted on"
        os.kill(os.getpid(), signal.SIGINT)
        first = min(pending)
        pending.remove(first)
        return [client.results[first]]
    monkeypatch.setattr(cluster, "_gathered", wait_in_dask)
    monkeypatch.setattr(sens, "_evaluate_chunk", lambda spec, inputs, u, window: (np.zeros((len(u), 2, 3, 6)),
                                                                                  [""] * len(u)))
    parts = sens.RowParts(PartsManifest(tmp_path / "p", {}, index="row", items="rows"), "families")
    with pytest.raises(KeyboardInterrupt) as caught:
        sens.evaluate_statistics(None, None, np.zeros((8, 3)), Client(), chunk=4, parts=parts)
    assert len(waits) == 1 and caught.traceback[-1].name == "results_as_finished"
    assert [p.name for p in parts.manifest.parts()] == ["families-0000000-0000003.nc"]


def test_a_designs_stored_rows_and_their_count_come_from_its_own_chunks(tmp_path):
    """RowParts.count (the manifest's rows, announced on a resume) and RowParts.stored (the chunks
    read) name the same rows of the same design, and none of the other design's."""
    from pipeline.files.outputs import PartsManifest
    manifest = PartsManifest(tmp_path / "p", {}, index="row", items="rows")
    families, joints = sens.RowParts(manifest, "families"), sens.RowParts(manifest, "joints")
    stats = np.arange(13 * 36, dtype=float).reshape(13, 2, 3, 6)
    families.keep(slice(8, 12), stats[:4])
    joints.keep(slice(0, 5), stats[4:9])
    families.keep(slice(0, 4), stats[9:])
    for parts, rows in ((families, [(0, 4), (8, 12)]), (joints, [(0, 5)])):
        stored = parts.stored()
        assert [(r.start, r.stop) for r, _ in stored] == rows
        assert parts.count() == sum(r.stop - r.start for r, _ in stored)
    assert np.array_equal(families.stored()[0][1], stats[9:]) and np.array_equal(joints.stored()[0][1], stats[4:9])


@pytest.mark.parametrize("loss", ["deleted", "unreadable"])
def test_a_lost_manifest_costs_no_finished_chunk(interrupted, whole, configs, monkeypatch, capsys, loss):
    """A deleted or unreadable manifest: each chunk is read with its values' checksums and its settings
    compared, then adopted; the rerun evaluates only the missing rows and writes the uninterrupted indices."""
    manifest = _parts(interrupted) / "manifest.json"
    if loss == "deleted":
        manifest.unlink()
    else:
        manifest.write_text("{not json")
    calls = _counting(monkeypatch)
    assert main(_argv(configs, interrupted)) == 0, capsys.readouterr().err
    assert sum(calls) == 64 * 20 - JOINT_CHUNK
    _same_indices(interrupted, whole)


def test_a_lost_manifests_chunk_with_changed_values_or_other_settings_is_refused(interrupted, configs, capsys):
    """Without the manifest a chunk is adopted only if its values match their checksums and it names the
    rerun's settings: a flipped value, or a rerun with another seed, is refused in one line (exit 2)."""
    parts = _parts(interrupted)
    (parts / "manifest.json").unlink()
    assert main(_argv(configs, interrupted, "--seed", "1")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "made with other settings (scene, model" in err[0], err
    part = parts / "joints-0000000-0000255.nc"
    with xr.open_dataset(part) as ds:
        ds = ds.load()
    name = next(v for v in ds.data_vars if ds[v].dtype.kind == "f")
    ds[name].values.flat[3] += 1e-3
    (parts / "manifest.json").unlink(missing_ok=True)
    ds.to_netcdf(part)   # keeps the attributes, so the checksums of the old values
    assert main(_argv(configs, interrupted)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "joints-0000000-0000255.nc" in err[0] and "families-" not in err[0], err


def test_a_lost_manifests_chunk_without_checksums_is_refused(interrupted, configs, capsys):
    """Without the manifest a chunk's own checksums are the only evidence that rss6 wrote its values: a
    chunk without them is refused by name in one line (exit 2), as ``rss6 run`` refuses such a part."""
    import netCDF4
    from pipeline.files.schema import CHECKSUM
    parts = _parts(interrupted)
    (parts / "manifest.json").unlink()
    part = parts / "joints-0000000-0000255.nc"
    with netCDF4.Dataset(part, "a") as nc:
        nc.delncattr(CHECKSUM)
    assert main(_argv(configs, interrupted)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{part.name}: carries no checksums of its values" in err[0], err
    assert "families-" not in err[0], err


def test_a_rerun_of_the_same_request_answers_from_its_file_and_draws_the_charts(configs, tmp_path, monkeypatch,
                                                                                capsys):
    """A run interrupted after writing its file, before its charts (the charts deleted stand for it): the same
    command evaluates nothing, prints the indices from the file and draws the charts; another -n onto the file is
    refused in one line naming it (both used to be refused: 'exists; rss6 sensitivity does not overwrite a file')."""
    out = tmp_path / "s.nc"
    argv = ["sensitivity", str(configs / "smoke.toml"), "-n", "64", "--workers", "1", "-o", str(out)]
    assert main(argv) == 0
    table = capsys.readouterr().out.split("\n", 1)[1]
    charts = sorted(p.name for p in (tmp_path / "s_plots").glob("sobol_*.png"))
    for name in charts[1:]:
        (tmp_path / "s_plots" / name).unlink()
    _counting(monkeypatch, stop_at=1)   # any evaluation is a Ctrl-C: exit 130
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert said.startswith(f"read back {out}") and said.split("\n", 1)[1] == table
    assert sorted(p.name for p in (tmp_path / "s_plots").glob("sobol_*.png")) == charts
    assert main(argv[:-2] + ["-n", "128", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "-n 64 there, 128 now" in err, err
