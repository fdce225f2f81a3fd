"""An ensemble of more than SUMMARY_BLOCK realisations is merged, checked and summarised without
holding its summaries in memory: its pieces are read back from their parts lazily, the file is
written from them block by block and read back in blocks, and its statistics are taken one quantity
at a time. Here SUMMARY_BLOCK is made tiny, so that six realisations take that path: the file is
byte for byte the one of the in-memory path, and the statistics are those of all values at once."""
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

import pipeline.ensemble.run as run
import pipeline.files.check as check
import pipeline.files.reading as reading
from pipeline.analysis.estimators import estimates_and_bounds
from pipeline.analysis.stats import ensemble_stats, finished_values
from pipeline.ensemble.run import EnsembleSpec, default_chunk, ensemble
from pipeline.files.opening import open_ensemble
from pipeline.scenes.catalogue import PACKAGE
from pipeline.vocabulary import SUMMARIES

SMOKE = Path(str(resources.files(PACKAGE))) / "smoke.toml"
N = 6


def _spec():
    return EnsembleSpec(SMOKE.read_text(), str(SMOKE), "quasi-static", "newmark", 1e-3, 4, 3, "summary")


def _small_blocks(monkeypatch, rows: int = 2) -> None:
    """Every module's SUMMARY_BLOCK set to ``rows``: N realisations are then a 'large' run."""
    for module in (run, check, reading):
        monkeypatch.setattr(module, "SUMMARY_BLOCK", rows)


@pytest.fixture(scope="module")
def in_memory(tmp_path_factory, cluster_client) -> Path:
    """The ensemble written the usual way (summaries in memory)."""
    out = tmp_path_factory.mktemp("mem") / "mem.nc"
    ensemble(_spec(), N, out, chunk=2, progress=False, client=cluster_client)
    return out


def test_a_run_of_more_than_a_block_writes_the_same_file_from_groups_left_on_disk(tmp_path, in_memory,
                                                                                  cluster_client, monkeypatch):
    """Blocks of 4: the chunks of 2 come back in groups of two chunks (realisations 0-3, 4-5), each
    written to a scratch file and read back with its summaries on disk; the file is the same."""
    _small_blocks(monkeypatch, 4)
    read = []
    load = reading.load_netcdf

    def spy(path, lazy=False, verify=True, summary_block=None):
        ds = load(path, lazy, verify, summary_block)
        read.append((Path(path).name, ds["max_abs_error"].chunks is not None))
        return ds
    monkeypatch.setattr(run, "load_netcdf", spy)
    out = tmp_path / "large.nc"
    outcome = ensemble(_spec(), N, out, chunk=2, progress=False, client=cluster_client)
    assert sorted(read) == [("group-0000000-0000003.nc", True), ("group-0000004-0000005.nc", True)]
    assert outcome.dataset["max_abs_error"].chunks is not None   # the file read back so too
    assert out.read_bytes() == in_memory.read_bytes()
    assert not Path(str(out) + ".parts").exists()


def test_the_statistics_of_a_file_read_in_blocks_are_those_of_all_values_at_once(in_memory, monkeypatch):
    """The one-quantity-at-a-time statistics of the blocked file equal the in-memory file's and an
    independent computation over every (quantity, direction) cell at once, exactly."""
    whole = ensemble_stats(open_ensemble(in_memory), window=None)
    _small_blocks(monkeypatch)
    lazy = open_ensemble(in_memory, lazy=True)
    assert lazy["max_abs_error"].chunks is not None
    blocked = ensemble_stats(lazy, window=None)
    for name in SUMMARIES:
        assert np.array_equal(blocked[name].values, whole[name].values, equal_nan=True)
        x = finished_values(open_ensemble(in_memory), name, "steady").transpose("realization", "quantity",
                                                                                  "direction").values
        cells = estimates_and_bounds(x.reshape(x.shape[0], -1), 0.95).reshape(blocked[name].shape[1:])
        assert np.array_equal(blocked[name].sel(window="steady").values, cells, equal_nan=True)


def test_a_blocked_file_with_a_changed_value_is_refused(in_memory, tmp_path, monkeypatch):
    """The checks run block by block still see a value in the last block (a mean above its maximum)."""
    from pipeline.files.schema import EnsembleFileError
    _small_blocks(monkeypatch)
    ds = open_ensemble(in_memory).load()
    ds["mean_abs_error"][0, 0, -1, 0] = ds["max_abs_error"][0, 0, -1, 0] * 2
    with pytest.raises(EnsembleFileError, match="realisation 5"):
        check.check_ensemble(ds.chunk({"realization": 2}), "f.nc")


def test_a_large_run_is_cut_into_at_most_about_max_auto_chunks_chunks():
    assert default_chunk(20_000, 2, "quasi-static") == 64   # as before
    chunk = default_chunk(1_000_000, 2, "quasi-static")
    assert -(-1_000_000 // chunk) <= run.MAX_AUTO_CHUNKS and chunk == 977


def test_a_resumed_large_run_with_a_part_inside_a_group_writes_the_same_file(tmp_path, in_memory, cluster_client,
                                                                             monkeypatch):
    """Realisations 2-3 stored by an earlier run: the group of the chunks computed now (0-1, 4-5)
    surrounds that part; the merge puts them in order and the file is the uninterrupted one."""
    from pipeline.ensemble.run import run_chunk
    from pipeline.files.outputs import PartsManifest
    _small_blocks(monkeypatch, 4)
    out = tmp_path / "resumed.nc"
    PartsManifest(Path(str(out) + ".parts"), _spec().attrs()).write(run_chunk(_spec(), [2, 3]),
                                                                      "chunk-0000002-0000003.nc")
    outcome = ensemble(_spec(), N, out, chunk=2, progress=False, client=cluster_client)
    assert outcome.stored_before == 2 and outcome.computed == 4
    assert out.read_bytes() == in_memory.read_bytes()
