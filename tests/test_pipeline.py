"""Ensembles: reproducibility across workers and chunks, resume, refusal, file checks, statistics."""
import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import netCDF4
import numpy as np
import pytest

from pipeline.cli import main
from pipeline.files.outputs import PartsManifest
from pipeline.ensemble.run import (MAX_AUTO_CHUNK, MAX_AUTO_CHUNK_BY_MODEL, TEST_HOLD_ENV, EnsembleSpec, default_chunk,
                                   run_chunk, run_ensemble)
from pipeline.analysis.stats import ensemble_stats
from pipeline.files.opening import open_ensemble
from pipeline.files.schema import EnsembleFileError
from pipeline.files.writing import write_netcdf
from pipeline.scenes.catalogue import scene_text

SMOKE = "smoke"                    # the shipped scene, by name
SMOKE_TEXT = scene_text(SMOKE)


def _spec(seed=3, model="quasi-static", store="summary", text=None):
    return EnsembleSpec(text or SMOKE_TEXT, SMOKE, model, "newmark", 1e-3, 4, seed, store)


def error_summaries(ds):
    return np.concatenate([ds["max_abs_error"].values.ravel(), ds["mean_abs_error"].values.ravel(),
                           ds["eccentricity"].values.ravel()])


@pytest.mark.parametrize("model", [None, "paper", "contact"])
@pytest.mark.parametrize("n, workers", [(1, 2), (5, 4), (10, 2), (128, 2), (129, 2), (400, 2),
                                        (1000, 2), (1000, 3), (65, 1), (257, 2)])
def test_default_chunks_are_equal_and_a_multiple_of_the_workers(n, workers, model):
    """At most MAX_AUTO_CHUNK per chunk (the contact and paper levels: their own, larger cap), as few rounds of
    one chunk per worker as that allows, and the chunks of one size but the last, which is short by
    less than one realisation per chunk."""
    size = default_chunk(n, workers, model)
    largest = MAX_AUTO_CHUNK_BY_MODEL.get(model, MAX_AUTO_CHUNK)
    chunks = -(-n // size)
    rounds = -(-n // (workers * largest))
    assert 1 <= size <= largest
    assert chunks <= rounds * workers and (chunks == rounds * workers or n < rounds * workers * size)
    assert n - (chunks - 1) * size > size - chunks     # the short last chunk
    assert default_chunk(400, 2) == 50 and default_chunk(1000, 2) == 63 and default_chunk(128, 2) == 64
    assert default_chunk(1000, 2, "contact") == 125 and default_chunk(256, 2, "contact") == 128
    assert default_chunk(1000, 2, "paper") == 250 and default_chunk(1000, 2, "elastic") == 63


@pytest.fixture(scope="module")
def reference(tmp_path_factory, cluster_client):
    path = tmp_path_factory.mktemp("ref") / "ref.nc"
    return run_ensemble(_spec(), 10, path, workers=2, chunk=4, progress=False, client=cluster_client), path


def test_same_seed_same_summaries_any_workers_and_chunks(reference, tmp_path, cluster_client):
    ref, _ = reference
    one = run_ensemble(_spec(), 10, tmp_path / "one.nc", workers=1, chunk=3, progress=False)
    assert np.array_equal(error_summaries(one), error_summaries(ref))
    assert list(one.realization.values) == list(range(10))
    other_seed = run_ensemble(_spec(seed=4), 10, tmp_path / "s4.nc", chunk=10, progress=False,
                              client=cluster_client)
    assert not np.array_equal(error_summaries(other_seed), error_summaries(ref))


def test_file_reads_correctly_with_netcdf4_directly(reference):
    ref, path = reference
    with netCDF4.Dataset(path) as nc:
        assert nc.Conventions == "CF-1.10" and nc.model == "quasi-static" and nc.seed == 3
        assert "[simulation]" in nc.scene_toml
        # one unit per CF variable: the error summaries split by quantity and direction family
        var = nc.variables["max_abs_error_velocity_rotation"]
        assert var.dimensions == ("window", "realization", "rotation") and var.units == "rad s-1"
        assert nc.variables["max_abs_error_displacement_translation"].units == "m"
        assert nc.variables["mean_abs_error_acceleration_translation"].units == "m s-2"
        assert list(nc.variables["rotation_label"][:]) == ["rx", "ry", "rz"]
        assert list(nc.variables["window_label"][:]) == ["whole", "startup", "steady"]
        assert nc.steady_after_s == 0.1 and nc.settle_time_s == 0.0   # default: half of 0.2 s
        assert nc.variables["unit"][:].tolist()[0] == ["m"] * 3 + ["rad"] * 3
        assert nc.variables["realization"].rss6_axis == "E"
        assert nc.variables["clearance_size"].units == "m"
        assert np.array_equal(var[:], ref["max_abs_error"].sel(quantity="velocity", direction=["rx", "ry", "rz"])
                              .transpose("window", "realization", "direction").values)
        assert list(nc.variables["status"][:]) == ["finished"] * 10


def test_statistics_dataset_of_an_ensemble_file(reference):
    """The estimates are the numpy ones of the file's values (the intervals are checked by
    coverage in test_stats.py); 10 realisations: no interval for the mean (from 16), q05/q95/q99, std or
    max."""
    ref, path = reference
    out = ensemble_stats(open_ensemble(path))
    x = ref["max_abs_error"].sel(window="whole", quantity="velocity", direction="y").values
    s = out["max_abs_error"].sel(quantity="velocity", direction="y")
    est = s.sel(bound="estimate")
    assert float(est.sel(statistic="mean")) == pytest.approx(np.mean(x), rel=1e-14)
    assert float(est.sel(statistic="std")) == pytest.approx(np.std(x, ddof=1), rel=1e-14)
    assert float(est.sel(statistic="q95")) == pytest.approx(np.quantile(x, 0.95), rel=1e-14)
    assert float(est.sel(statistic="max")) == np.max(x)
    for stat in ("mean", "std", "q05", "q95", "q99", "max"):
        assert np.isnan(s.sel(statistic=stat, bound=["lower", "upper"]).values).all(), stat
    assert out.attrs["n_finished"] == 10 and out.attrs["n_failed"] == 0


def test_different_seed_or_config_is_refused(reference, tmp_path):
    _, path = reference
    with pytest.raises(EnsembleFileError, match=r"refusing to mix ensembles.*seed"):
        run_ensemble(_spec(seed=99), 12, path, progress=False)
    other = SMOKE_TEXT.replace("mass_kg = 1.366", "mass_kg = 1.5")
    with pytest.raises(EnsembleFileError, match=r"refusing to mix.*different scene file"):
        run_ensemble(_spec(text=other), 12, path, progress=False)


def test_truncated_and_foreign_files_are_named(reference, tmp_path):
    _, path = reference
    cut = tmp_path / "cut.nc"
    cut.write_bytes(path.read_bytes()[:2000])
    with pytest.raises(EnsembleFileError, match=r"cut.nc: not a readable netCDF"):
        open_ensemble(cut)
    foreign = tmp_path / "foreign.nc"
    with netCDF4.Dataset(foreign, "w") as nc:
        nc.createDimension("x", 3)
        nc.createVariable("t", "f8", ("x",))[:] = [1, 2, 3]
    with pytest.raises(EnsembleFileError, match=r"foreign.nc: not an rss6 ensemble"):
        open_ensemble(foreign)
    assert main(["stats", str(foreign)]) == 2


def test_extending_an_ensemble_keeps_what_is_stored(reference, tmp_path, cluster_client):
    ref, _ = reference
    path = tmp_path / "grow.nc"
    run_ensemble(_spec(), 4, path, chunk=2, progress=False, client=cluster_client)
    grown = run_ensemble(_spec(), 10, path, chunk=2, progress=False, client=cluster_client)
    assert np.array_equal(error_summaries(grown), error_summaries(ref))


def test_parts_left_beside_a_finished_file_add_no_duplicates(reference, tmp_path, cluster_client):
    """A run stopped between writing OUT.nc and removing OUT.nc.parts: the rerun takes each once."""
    ref, _ = reference
    path = tmp_path / "left.nc"
    run_ensemble(_spec(), 10, path, chunk=5, progress=False, client=cluster_client)
    parts = Path(str(path) + ".parts")
    part = open_ensemble(path).isel(realization=[0, 1]).assign_attrs(n_realizations=2)   # as a chunk's
    PartsManifest(parts, _spec().attrs()).write(part, "chunk-0000000-0000001.nc")
    again = run_ensemble(_spec(), 10, path, chunk=5, progress=False, client=cluster_client)
    assert list(again.realization.values) == list(range(10)) and not parts.exists()
    assert np.array_equal(error_summaries(open_ensemble(path)), error_summaries(ref))


def _cli(*args):
    return [sys.executable, "-m", "pipeline.cli", *args]


@pytest.mark.slow
def test_killed_run_resumes_to_the_same_file(tmp_path):
    """Kill -9 the whole run once 3 chunks are stored and the others wait (TEST_HOLD_ENV); the
    rerun ends identical."""
    args = ["run", SMOKE, "-n", "12", "--chunk", "1", "--workers", "1", "--model", "elastic",
            "--seed", "5"]
    killed = tmp_path / "killed.nc"
    proc = subprocess.Popen(_cli(*args, "-o", str(killed)), start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=dict(os.environ, **{TEST_HOLD_ENV: f"3:{tmp_path / 'never'}"}))
    parts = Path(str(killed) + ".parts")
    while len(list(parts.glob("*.nc"))) < 3:
        assert proc.poll() is None, "the run ended before it was killed"
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert len(list(parts.glob("*.nc"))) == 3 and not killed.exists()
    subprocess.run(_cli(*args, "-o", str(killed)), check=True, capture_output=True)
    whole = tmp_path / "whole.nc"
    subprocess.run(_cli(*args, "-o", str(whole)), check=True, capture_output=True)
    a, b = open_ensemble(killed), open_ensemble(whole)
    assert np.array_equal(error_summaries(a), error_summaries(b)) and not parts.exists()


def test_scheduler_address_runs_on_an_existing_cluster(reference, tmp_path):
    from dask.distributed import LocalCluster
    ref, _ = reference
    with LocalCluster(n_workers=1, threads_per_worker=1, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        ds = run_ensemble(_spec(), 10, tmp_path / "sched.nc", scheduler=cluster.scheduler_address,
                          chunk=5, progress=False)
    assert np.array_equal(error_summaries(ds), error_summaries(ref))


def _in_the_workers(client, function) -> list:
    """``function()`` run in every worker, sent by value: the workers cannot import this test module
    (the tests run from a temporary folder against the installed package)."""
    import cloudpickle
    module = sys.modules[__name__]
    cloudpickle.register_pickle_by_value(module)
    try:
        return list(client.run(function).values())
    finally:
        cloudpickle.unregister_pickle_by_value(module)


def _imports_of_a_first_chunk() -> list:
    """The modules a worker imports in its first paper-level task (run in the worker)."""
    before = set(sys.modules)
    run_chunk(_spec(model="paper"), [0])
    return sorted(set(sys.modules) - before)


def test_local_workers_keep_glibc_malloc_and_writes_take_no_cluster_lock(reference, tmp_path,
                                                                         monkeypatch):
    """rss6's own workers start without dask's MALLOC_TRIM_THRESHOLD_ (with it glibc maps and
    faults in every array over 128 KiB afresh), with one BLAS thread and without the profiler; with a client open, a
    netCDF write takes no distributed lock (a scheduler round trip per variable)."""
    import dask
    from dask.distributed import Client, Lock

    from pipeline.ensemble.cluster import QUIET_CLUSTER, local_cluster
    ref, _ = reference
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    taken = []
    monkeypatch.setattr(Lock, "acquire", lambda self, *a, **k: taken.append(self.name) or True)
    monkeypatch.setattr(Lock, "release", lambda self: None)
    keys = ("MALLOC_TRIM_THRESHOLD_", "OPENBLAS_NUM_THREADS")
    with local_cluster(1) as cluster, Client(cluster) as client:
        env = list(client.run(lambda: {k: os.environ.get(k) for k in keys}).values())
        quiet = list(client.run(lambda: {k: dask.config.get(k) for k in QUIET_CLUSTER}).values())
        imported = _in_the_workers(client, _imports_of_a_first_chunk)
        write_netcdf(ref, tmp_path / "with-client.nc")
    assert env == [{"MALLOC_TRIM_THRESHOLD_": None, "OPENBLAS_NUM_THREADS": "1"}]
    assert quiet == [QUIET_CLUSTER]   # no profiler, slower monitors: in the worker processes
    assert imported == [[]]           # the fork server imported everything a task needs
    assert taken == []
    assert np.array_equal(error_summaries(open_ensemble(tmp_path / "with-client.nc")),
                          error_summaries(ref))


_HASHES = """
import os
from pipeline.ensemble.cluster import dask_client, start_worker_server
if __name__ == "__main__":
    start_worker_server()   # as the rss6 command does, before dask's nanny sets the workers' environment
    with dask_client(1) as client:
        (seed, value), = client.run(lambda: (os.environ["PYTHONHASHSEED"], hash("rss6"))).values()
        print(seed, value)
"""


def test_workers_forked_from_a_server_started_ahead_hash_strings_with_the_nannys_seed(tmp_path):
    """A fork server started before the cluster (rss6's command line does so) gives its workers the
    hash seed dask's nanny gives them: a worker hashes a string as a fresh interpreter does with the
    PYTHONHASHSEED the nanny set in its environment (without it, each run's workers drew their own)."""
    script = tmp_path / "hashes.py"
    script.write_text(_HASHES)
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, check=True).stdout
    seed, worker_hash = out.split()
    fresh = subprocess.run([sys.executable, "-c", "print(hash('rss6'))"], capture_output=True, text=True,
                           check=True, env={**os.environ, "PYTHONHASHSEED": seed}).stdout
    assert int(worker_hash) == int(fresh)


def test_workers_import_the_installed_rss6_not_a_package_of_the_same_name_in_the_working_folder(tmp_path):
    """A run started from a folder holding packages named ``pipeline`` and ``rss6core`` (another
    checkout, or a user's own package) computes with the installed rss6: the workers' fork server
    imported the folder's (its ``python -c`` puts the folder first), and the decoys here would
    have marked themselves and failed the run."""
    import shutil
    for name in ("pipeline", "rss6core"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text(
            f"open({str(tmp_path / (name + '.imported'))!r}, 'w').close()\nraise RuntimeError('decoy {name}')\n")
    exe = shutil.which("rss6")
    assert exe, "the rss6 console script (pip install -e .) runs without the working folder on its path"
    out = subprocess.run([exe, "run", "smoke", "-n", "2", "--model", "quasi-static", "--workers", "1", "-o", "s.nc"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert not list(tmp_path.glob("*.imported"))


def test_a_second_local_cluster_starts_without_a_port_warning():
    """Two rss6 runs at once: the second cluster's scheduler finds dask's default HTTP port 8787
    taken (held here by a socket, or by whatever holds it already) and starts without the
    "Port 8787 is already in use" warning dask prints by default."""
    import socket
    import warnings

    from pipeline.ensemble.cluster import local_cluster
    with socket.socket() as holder, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with contextlib.suppress(OSError):      # already taken: the same situation
            holder.bind(("127.0.0.1", 8787))
            holder.listen()
        with local_cluster(1) as cluster:
            assert cluster.scheduler.http_server is not None
    assert not [w for w in caught if "8787" in str(w.message)], [str(w.message) for w in caught]


def test_smoke_ensemble_through_the_cli(tmp_path, capsys):
    """What CI runs: 8 realisations, 2 workers, then stats and plot."""
    out = tmp_path / "smoke.nc"
    assert main(["run", SMOKE, "-n", "8", "--workers", "2", "--model", "quasi-static",
                 "--store", "full", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "displacement" in printed and "velocity" not in printed.split("(displacement only")[0]
    assert f"rss6 stats {out} shows velocity and acceleration too" in printed
    assert "window: whole run" in printed and "window: steady" not in printed
    assert main(["stats", str(out), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["n_finished"] == 8
    entry = js["max_abs_error"]["displacement"]["z"]
    assert set(entry) == {"mean", "std", "q05", "q50", "q95", "q99", "max"}
    assert set(entry["q50"]) == {"estimate", "lower", "upper"}
    assert main(["stats", str(out), "--quantity", "velocity", "--direction", "rx"]) == 0
    assert "velocity" in capsys.readouterr().out
    assert main(["plot", str(out), "-o", str(tmp_path / "plots")]) == 0
    pngs = sorted(p.name for p in (tmp_path / "plots").glob("*.png"))
    assert len(pngs) == 9 and all((tmp_path / "plots" / p).stat().st_size > 10_000 for p in pngs)


def test_failed_realisations_are_recorded_and_the_ensemble_goes_on(tmp_path, cluster_client):
    """Central difference at 1 ms (500x its critical step) diverges: stored as failed, with its message."""
    spec = EnsembleSpec(SMOKE_TEXT, SMOKE, "elastic", "central-difference", 1e-3, 1, 0)
    ds = run_ensemble(spec, 2, tmp_path / "fail.nc", chunk=2, progress=False, client=cluster_client)
    assert list(ds["status"].values) == ["failed", "failed"]
    assert all("exceeds the 1 m divergence limit" in m and ", step " in m and "at t = " in m
               for m in ds["status_message"].values)
    assert ds.attrs["n_failed"] == 2
    assert ensemble_stats(open_ensemble(tmp_path / "fail.nc")).attrs["n_finished"] == 0
