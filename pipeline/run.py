"""Monte Carlo ensembles on dask: realisations in chunks, finished chunks written durably.

``run_ensemble`` runs realisations 0..N-1 of a scene in chunks, each chunk a dask
task, on a local cluster of W single-threaded workers (BLAS pinned to one
thread) or on an existing dask.distributed scheduler.  Each finished chunk is
written at once to ``OUT.nc.parts/`` (write to a temporary name, then rename),
so an interrupted run (Ctrl-C, a killed process, a crashed worker) loses at
most the chunks in flight; rerunning the same command skips what is stored,
checks every stored part against the manifest written with it (checksum,
provenance) and refuses pieces from a different scene, model or seed.  One
process writes an output at a time (``OUT.nc.lock``).  When all realisations
are stored they are merged into OUT.nc and the parts are removed.
Realisation r draws from the stream (seed, r) only, so the file does not depend
on the chunk size or the number of workers.
"""
from __future__ import annotations

import contextlib
import logging
import os
import shutil
import signal
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rss6core import parse_scene
from rss6core.models import simulate_batch, stored_draw

from .outputs import OutputLock, PartsManifest
from .store import (EnsembleFileError, finish_ensemble, identity, open_ensemble,
                    realization_dataset, write_netcdf)

__all__ = ["EnsembleSpec", "EnsembleOutcome", "ensemble", "run_chunk", "run_ensemble", "default_chunk",
           "local_cluster", "BLAS_ENV", "SchedulerUnavailable"]

BLAS_ENV = {v: "1" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                             "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")}


@dataclass(frozen=True)
class EnsembleSpec:
    """What an ensemble computes (everything but its size and where it runs)."""
    scene_text: str
    source: str
    model: str
    integrator: str
    dt: float
    elements: int
    seed: int
    store: str = "summary"

    def scene(self):
        return parse_scene(self.scene_text, self.source)

    def attrs(self) -> dict:
        return {"scene_toml": self.scene_text, "model": self.model, "integrator": self.integrator,
                "time_step_s": self.dt, "elements_per_link": self.elements, "seed": self.seed,
                "store": self.store}


def run_chunk(spec: EnsembleSpec, realizations: list[int]):
    """Simulate the given realisations; returns their ensemble Dataset (a dask task)."""
    scene = spec.scene()
    try:
        results = simulate_batch(scene, spec.model, spec.integrator, spec.dt, spec.elements,
                                 spec.seed, realizations)
    except (ArithmeticError, np.linalg.LinAlgError) as exc:  # numerical failure: record it
        from rss6core.results import SimulationResult, time_grid
        t = time_grid(scene.trajectory.duration, spec.dt)
        nan = np.full((len(t), 6), np.nan)
        results = [SimulationResult(t, nan, nan, nan, "failed", f"{type(exc).__name__}: {exc}", 0)
                   ] * len(realizations)
    # the clearance levels hand back their draws; drawn here only without clearances or on failure
    parts = [realization_dataset(result, result.draw if result.draw is not None
                                 else stored_draw(scene, spec.model, spec.seed, r, spec.dt), r,
                                 spec.store, scene.simulation.settle_time)
             for r, result in zip(realizations, results)]
    return finish_ensemble(parts, scene, **_kw(spec))


def _kw(spec: EnsembleSpec) -> dict:
    return dict(model=spec.model, integrator=spec.integrator, dt=spec.dt,
                elements=spec.elements, seed=spec.seed, store=spec.store)


def _check_identity(path, attrs: dict, spec: EnsembleSpec) -> None:
    theirs, ours = identity(attrs), identity(spec.attrs())
    diff = [k for k in ours if str(theirs[k]) != str(ours[k])]
    if diff:
        what = ", ".join(f"{k} ({theirs[k]!r} there, {ours[k]!r} here)" if k != "scene_toml"
                         else "scene_toml (a different scene file)" for k in diff)
        raise EnsembleFileError(f"{path}: refusing to mix ensembles: it was made with a different "
                                f"{what}; choose another output file or the same settings")


def _stored(output: Path, spec: EnsembleSpec, manifest: PartsManifest) -> tuple[list, set]:
    """Datasets already stored for this ensemble (final file and verified parts), their realisations.

    Each realisation is taken once: parts left beside a finished file (a run stopped
    between writing it and removing the parts) add only what the file lacks.
    """
    pieces, done = [], set()
    for path in manifest.parts():
        manifest.verify(path)
    candidates = ([output] if output.exists() else []) + manifest.parts()
    for path in candidates:
        ds = open_ensemble(path)
        _check_identity(path, ds.attrs, spec)
        new = [int(r) for r in ds["realization"].values if int(r) not in done]
        if new:
            pieces.append(ds.sel(realization=new))
            done.update(new)
    return pieces, done


def _parts_dir(output: Path) -> Path:
    return output.with_name(output.name + ".parts")


class _Progress:
    """A bar on a terminal, plain lines otherwise; a first line at once (starting workers, compiling
    kernels on a cold cache), then done/total with the elapsed time and an ETA."""

    def __init__(self, total: int, done: int, stream=None):
        self.total, self.done, self.stream = total, done, stream or sys.stderr
        self.tty, self.start, self.last = self.stream.isatty(), time.perf_counter(), 0.0
        self.first = done

    def begin(self, chunks: int, where: str) -> None:
        self.stream.write(f"rss6 run: {self.total - self.done} realisations to compute in {chunks} "
                          f"chunks on {where}" + (f" ({self.done} stored)" if self.done else "")
                          + "; starting workers (the first chunk also compiles kernels on a cold "
                            "cache)\n")
        self.stream.flush()

    def _eta(self, elapsed: float) -> str:
        computed = self.done - self.first
        if computed <= 0 or self.done >= self.total:
            return ""
        return f", about {elapsed / computed * (self.total - self.done):.0f} s left"

    def advance(self, n: int) -> None:
        self.done += n
        elapsed = time.perf_counter() - self.start
        frac = self.done / max(self.total, 1)
        if self.tty:
            bar = "#" * int(30 * frac)
            self.stream.write(f"\r[{bar:<30s}] {self.done}/{self.total} realisations, "
                              f"{elapsed:.1f} s{self._eta(elapsed)}   ")
            if self.done >= self.total:
                self.stream.write("\n")
        elif elapsed - self.last >= 2.0 or self.done >= self.total:
            self.last = elapsed
            self.stream.write(f"rss6 run: {self.done}/{self.total} realisations "
                              f"({100 * frac:.0f} %), {elapsed:.1f} s{self._eta(elapsed)}\n")
        self.stream.flush()


def local_cluster(workers: int):
    """A dask LocalCluster of ``workers`` single-threaded worker processes, one BLAS thread each.

    dask starts its workers with MALLOC_TRIM_THRESHOLD_=65536, which also fixes glibc's mmap
    threshold at 128 KiB: every larger temporary array is then mapped and faulted in afresh,
    which costs the paper level 25-30 % more CPU time per realisation. These workers keep glibc's
    default (a value set in the environment by the user still applies). The cluster's own logs
    are silenced below CRITICAL: closing it races with the workers' heartbeats, which then log a
    traceback although nothing failed; rss6 reports every task's failure itself.
    """
    import dask
    from dask.distributed import LocalCluster
    os.environ.update(BLAS_ENV)  # inherited by the worker processes
    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}), \
            _workers_ignore_ctrl_c():
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                            dashboard_address=None, host="127.0.0.1", silence_logs=logging.CRITICAL)


@contextlib.contextmanager
def _workers_ignore_ctrl_c():
    """Worker processes started in this block inherit an ignored SIGINT: a terminal's Ctrl-C reaches
    the whole process group, and only this process should act on it (the cluster is closed from
    here); otherwise each worker prints its own traceback."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


CONNECT_TIMEOUT_S = 5.0   # an external scheduler that does not answer in this time is unreachable
WORKER_TIMEOUT_S = 60.0   # default wait, s, for an external scheduler that has no workers
POLL_S = 1.0              # how often, s, the workers of an external scheduler are counted


class SchedulerUnavailable(RuntimeError):
    """The external dask scheduler cannot be reached, or has had no workers for too long (an
    environment problem: the finished chunks stay in OUT.nc.parts)."""


def _client(workers: int, scheduler: str | None):
    from dask.distributed import Client
    if scheduler:
        try:
            return Client(scheduler, timeout=CONNECT_TIMEOUT_S), None
        except ValueError as exc:  # a malformed address
            raise SchedulerUnavailable(f"--scheduler {scheduler!r}: {exc}; the address reads e.g. "
                                       "tcp://HOST:8786") from None
        except OSError:  # refused or timed out
            raise SchedulerUnavailable(
                f"cannot reach the dask scheduler at {scheduler} within {CONNECT_TIMEOUT_S:g} s; "
                "check the address (e.g. tcp://HOST:8786) and that the scheduler is running"
            ) from None
    cluster = local_cluster(workers)
    return Client(cluster), cluster


def _finished(client, futures: list, scheduler: str | None, worker_timeout: float):
    """The chunk results as they finish; on an external scheduler the workers are counted every
    POLL_S and SchedulerUnavailable is raised once it has had none for ``worker_timeout`` s."""
    from dask.distributed import as_completed
    if not scheduler:
        for future in as_completed(futures):
            yield future.result()
        return
    _quiet_lost_results()
    pending, idle_since = set(futures), None
    while pending:
        got = list(_gathered(client, pending))
        yield from got
        if got or client.nthreads():
            idle_since = None
            continue
        idle_since = time.monotonic() if idle_since is None else idle_since
        if time.monotonic() - idle_since >= worker_timeout:
            raise SchedulerUnavailable(
                f"the dask scheduler at {scheduler} has had no workers for "
                f"{time.monotonic() - idle_since:.0f} s (--worker-timeout {worker_timeout:g})")


def _lost_result_record(record) -> bool:
    """False for dask's log records about a result lost with its worker, which _gathered handles:
    "Couldn't gather ... rescheduling", and the gather left waiting for it that ends with AllExit
    when the client closes."""
    text = record.getMessage()
    return not ("Couldn't gather" in text or ("never retrieved" in text and "AllExit" in text))


def _quiet_lost_results() -> None:
    import logging
    for name in ("distributed.client", "asyncio"):
        logger = logging.getLogger(name)
        if _lost_result_record not in logger.filters:
            logger.addFilter(_lost_result_record)


def _gathered(client, pending: set):
    """Results of the futures in ``pending`` that finish within about POLL_S, removed from it.

    A result held by a worker that has died cannot be gathered (dask computes it again, and
    gathering would wait for that); such a future stays in ``pending``."""
    from dask.distributed import wait
    try:
        done = wait(pending, timeout=POLL_S, return_when="FIRST_COMPLETED").done
    except TimeoutError:
        return
    held = client.who_has(list(done))
    for future in done:
        if future.status == "finished" and not held.get(future.key):
            continue   # its worker is gone
        try:
            result = future.result(timeout=POLL_S)
        except TimeoutError:   # the worker died just now: ask again who holds the others
            return
        pending.discard(future)
        yield result


MAX_AUTO_CHUNK = 64   # batching gains little beyond this; an interrupted run loses at most 2 chunks


def default_chunk(n: int, workers: int) -> int:
    """Realisations per task: every worker busy, batches large, little work lost on an interrupt.

    The n realisations are cut into a multiple of ``workers`` chunks of nearly equal size (at most
    MAX_AUTO_CHUNK), so that the workers finish together: 400 on two workers are 8 chunks of 50,
    not 6 of 64 and one of 16.
    """
    rounds = -(-n // (workers * MAX_AUTO_CHUNK))
    return max(1, -(-n // (rounds * workers)))


@dataclass(frozen=True)
class EnsembleOutcome:
    """What a call of :func:`ensemble` did: the ensemble, how many realisations it computed now,
    how many were stored before, and whether it (re)wrote the output file."""
    dataset: object
    computed: int
    stored_before: int
    written: bool


def ensemble(spec: EnsembleSpec, n: int, output, workers: int = 2, scheduler: str | None = None,
             chunk: int | None = None, progress: bool = True, annotate=None,
             worker_timeout: float = WORKER_TIMEOUT_S) -> EnsembleOutcome:
    """Run realisations 0..n-1 not yet stored in ``output`` (one writer at a time: OUT.lock).

    ``annotate(dataset) -> dict``, if given, adds global attributes (e.g. requirement verdicts)
    computed from the finished ensemble before it is written; the file is rewritten only if they
    change it. ``worker_timeout`` (s): how long an external ``scheduler`` may have no workers
    before SchedulerUnavailable is raised."""
    if n < 1:
        raise ValueError(f"the number of realisations must be at least 1, got {n}")
    chunk = default_chunk(n, workers) if chunk is None else chunk
    if chunk < 1 or workers < 1:
        raise ValueError("--chunk and --workers must be at least 1")
    if not worker_timeout > 0:
        raise ValueError(f"--worker-timeout must be positive, got {worker_timeout}")
    output = Path(output)
    with OutputLock(output):
        manifest = PartsManifest(_parts_dir(output), spec.attrs())
        pieces, done = _stored(output, spec, manifest)
        todo = [r for r in range(n) if r not in done]
        if todo:
            chunks = [todo[i:i + chunk] for i in range(0, len(todo), chunk)]
            bar = _Progress(n, n - len(todo)) if progress else None
            if bar:
                bar.begin(len(chunks), f"scheduler {scheduler}" if scheduler else f"{workers} workers")
            pieces += _compute(spec, chunks, manifest, workers, scheduler, bar, worker_timeout)
        up_to_date = not todo and len(pieces) == 1 and output.exists()  # the file alone holds all
        merged = pieces[0] if up_to_date else finish_ensemble(pieces, spec.scene(), **_kw(spec))
        extra = annotate(merged) if annotate else {}
        annotated = any(str(merged.attrs.get(k)) != str(v) for k, v in extra.items())
        merged = merged.assign_attrs(extra)
        if not up_to_date or annotated:
            write_netcdf(merged, output)
        if manifest.folder.exists():
            shutil.rmtree(manifest.folder)
    return EnsembleOutcome(merged, len(todo), len(done), not up_to_date)


def _compute(spec: EnsembleSpec, chunks: list, manifest: PartsManifest, workers: int,
             scheduler: str | None, bar, worker_timeout: float = WORKER_TIMEOUT_S) -> list:
    """Run the chunks on dask; each finished chunk is stored as a part at once."""
    client, cluster = _client(workers, scheduler)
    pieces = []
    try:
        futures = [client.submit(run_chunk, spec, c, pure=False, retries=2) for c in chunks]
        for ds in _finished(client, futures, scheduler, worker_timeout):
            first, last = int(ds.realization[0]), int(ds.realization[-1])
            manifest.write(ds, f"chunk-{first:07d}-{last:07d}.nc")
            pieces.append(ds)
            if bar:
                bar.advance(ds.sizes["realization"])
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return pieces


def run_ensemble(spec: EnsembleSpec, n: int, output, workers: int = 2, scheduler: str | None = None,
                 chunk: int | None = None, progress: bool = True):
    """Run realisations 0..n-1 not yet stored in ``output``; return the merged Dataset."""
    return ensemble(spec, n, output, workers, scheduler, chunk, progress).dataset
