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
Realisation r draws from the stream (seed, r) only (with ``--sampler qmc`` from a
fixed point of a fixed scrambling, pipeline/sampler.py), so the file does not
depend on the chunk size or the number of workers.
"""
from __future__ import annotations

import contextlib
import functools
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

from rss6core import FAILED, SimulationResult, __version__, parse_scene, prepare_level, stored_draw, time_grid

from ..files.outputs import OutputLock, PartsManifest
from ..files.opening import open_ensemble
from ..files.reading import load_netcdf
from ..files.records import chunk_dataset, finish_ensemble
from ..files.schema import EnsembleFileError, ensemble_identity, identity
from ..files.writing import sigint_deferred, write_netcdf

__all__ = ["EnsembleSpec", "EnsembleOutcome", "ensemble", "run_chunk", "run_ensemble", "default_chunk",
           "local_cluster", "dask_client", "BLAS_ENV", "SchedulerUnavailable", "parts_dir", "compile_note"]

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
    qmc_replicates: int | None = None   # None: plain Monte Carlo; else R of pipeline/sampler.py

    def scene(self):
        return parse_scene(self.scene_text, self.source)

    def design(self):
        """The QMC design (the draws' ``uniforms`` callback), or None for plain Monte Carlo."""
        from .sampler import QMCDesign
        return None if self.qmc_replicates is None else QMCDesign(self.seed, self.qmc_replicates)

    def sampler_attrs(self) -> dict:
        """The sampler's file attributes; none for mc, so its files stay as they were."""
        design = self.design()
        return {} if design is None else design.attrs()

    def attrs(self) -> dict:
        return ensemble_identity(self.scene_text, **_kw(self))


NUMERICAL_FAILURES = (ArithmeticError, np.linalg.LinAlgError)   # recorded as a failed realisation
# For tests only, read by :func:`_hold` alone: "R:PATH" makes every chunk whose first realisation is
# R or more wait, before it computes, until the file PATH exists, so that a test can interrupt or
# kill a run in a known state (R realisations stored, the next chunk in flight) whatever the
# machine's speed.  Unset (always, outside tests/), it costs one environment look-up per chunk.
TEST_HOLD_ENV = "RSS6_TEST_HOLD"


def run_chunk(spec: EnsembleSpec, realizations: list[int]):
    """Simulate the given realisations; returns their ensemble Dataset (a dask task).

    A numerical failure raised by the batch is traced to its realisations by running each alone:
    only those that fail alone are recorded as failed (with the reason), the others are kept, so
    the file does not depend on how the realisations were cut into chunks."""
    _hold(realizations)
    scene = spec.scene()
    try:
        results = _simulate(spec, realizations)
    except NUMERICAL_FAILURES:
        results = [_alone(scene, spec, r) for r in realizations]
    # the clearance levels hand back their draws; drawn here only without clearances or on failure
    draws = [result.draw if result.draw is not None
             else stored_draw(scene, spec.model, spec.seed, r, spec.dt, spec.design())
             for r, result in zip(realizations, results)]
    chunk = chunk_dataset(results, draws, realizations, spec.store, scene.simulation.settle_time,
                          scene.simulation.steady_after)
    return _finish([chunk], scene, spec)


def _hold(realizations: list[int]) -> None:
    """Test-only (TEST_HOLD_ENV): wait, before computing, until the release file exists."""
    hold = os.environ.get(TEST_HOLD_ENV)
    if hold:
        first, _, release = hold.partition(":")
        while realizations[0] >= int(first) and not os.path.exists(release):
            time.sleep(0.05)


def _finish(parts: list, scene, spec: EnsembleSpec):
    """The realisations as one ensemble Dataset with the spec's provenance and sampler."""
    return finish_ensemble(parts, scene, **_kw(spec))


def _simulate(spec: EnsembleSpec, realizations: list[int]) -> list:
    level = _level(spec.scene_text, spec.source, spec.model, spec.integrator, spec.dt, spec.elements)
    return level.simulate(spec.seed, realizations, spec.design())


@functools.lru_cache(maxsize=1)
def _level(scene_text: str, source: str, model: str, integrator: str, dt: float, elements: int):
    """The level every chunk of an ensemble shares, prepared once per worker process (the paper
    level's elastic run took a third of each chunk's time when every chunk computed it)."""
    return prepare_level(parse_scene(scene_text, source), model, integrator, dt, elements)


def _alone(scene, spec: EnsembleSpec, realization: int):
    """Realisation ``realization`` by itself; a numerical failure becomes its failed result."""
    try:
        return _simulate(spec, [realization])[0]
    except NUMERICAL_FAILURES as exc:
        t = time_grid(scene.trajectory.duration, spec.dt)
        nan = np.full((len(t), 6), np.nan)
        return SimulationResult(t, nan, nan, nan, FAILED, f"{type(exc).__name__}: {exc}", 0)


def _kw(spec: EnsembleSpec) -> dict:
    return dict(model=spec.model, integrator=spec.integrator, dt=spec.dt,
                elements=spec.elements, seed=spec.seed, store=spec.store, sampler=spec.sampler_attrs())


def _check_identity(path, attrs: dict, spec: EnsembleSpec) -> None:
    theirs, ours = identity(attrs), identity(spec.attrs())
    diff = [k for k in ours if str(theirs[k]) != str(ours[k])]
    if diff:
        what = ", ".join(f"{k} ({theirs[k]!r} there, {ours[k]!r} here)" if k != "scene_toml"
                         else "scene_toml (a different scene file)" for k in diff)
        raise EnsembleFileError(f"{path}: refusing to mix ensembles: it was made with a different "
                                f"{what}; choose another output file or the same settings")
    _check_version(path, attrs)


def _check_version(path, attrs: dict) -> None:
    """Refuse to extend a file (or part) another rss6 version wrote: the merged file would hold two
    versions' results under this version's name."""
    theirs = str(attrs.get("rss6_version"))
    if theirs != __version__:
        raise EnsembleFileError(f"{path}: written by rss6 {theirs}, this is rss6 {__version__}; resuming it "
                                "would mix results of two versions in one file: choose another -o")


def _stored(output: Path, spec: EnsembleSpec, manifest: PartsManifest) -> tuple[list, set]:
    """Datasets already stored for this ensemble (final file and verified parts, their histories
    left on disk), and their realisations.

    Each realisation is taken once: parts left beside a finished file (a run stopped
    between writing it and removing the parts) add only what the file lacks.
    """
    pieces, done = [], set()
    parts = _checked_parts(manifest, spec)
    final = [(output, open_ensemble(output, lazy=True))] if output.exists() else []
    for path, ds in final:
        _check_identity(path, ds.attrs, spec)
    for _, ds in final + parts:
        new = [int(r) for r in ds["realization"].values if int(r) not in done]
        if new:
            pieces.append(ds.sel(realization=new))
            done.update(new)
    return pieces, done


def _checked_parts(manifest: PartsManifest, spec: EnsembleSpec) -> list:
    """Every stored part with its Dataset (histories on disk), after checking them all: the bad
    ones are named together in one EnsembleFileError (:meth:`PartsManifest.refuse`). A part the
    manifest vouches for is not read again for its checksums (its bytes were)."""
    problems, parts = {}, []
    for path in manifest.parts():
        problems[path] = manifest.problem(path)
        if problems[path] is None:
            try:
                ds = open_ensemble(path, lazy=True, verify=False)
                _check_identity(path, ds.attrs, spec)
                parts.append((path, ds))
            except EnsembleFileError as exc:
                problems[path] = str(exc).removeprefix(f"{path}: ")
    manifest.refuse(problems)
    return parts


def parts_dir(output: Path) -> Path:
    """The folder OUTPUT.parts where a run keeps its finished chunks until the merged file is written."""
    return output.with_name(output.name + ".parts")


_COMPILE_NOTED: list = []   # the kernels a compile note of this process named (said once per command)


def compile_note(kernels: list[str]) -> str:
    """The one line that says kernels are being compiled (rss6 run and rss6 simulate)."""
    return (f"compiling {', '.join(kernels)} first: numba's cache holds no copy for this machine and "
            "rss6 version; this takes minutes once (rss6 warm pays it up front)")


class _Progress:
    """A bar on a terminal, plain lines otherwise; a first line at once (starting workers), a line
    when the workers compile kernels (:meth:`compiling`), then done/total with the elapsed time and
    an ETA."""

    def __init__(self, total: int, done: int, stream=None):
        self.total, self.done, self.stream = total, done, stream or sys.stderr
        self.tty, self.start, self.last = self.stream.isatty(), time.perf_counter(), 0.0
        self.first = done

    def begin(self, chunks: int, where: str) -> None:
        self.stream.write(f"rss6 run: {self.total - self.done} realisations to compute in {chunks} "
                          f"chunks on {where}" + (f" ({self.done} stored)" if self.done else "")
                          + "; starting workers\n")
        self.stream.flush()

    def compiling(self, kernels: list[str]) -> None:
        """Say, once per process (a command's batches share it), that the workers compile
        ``kernels`` before their first chunk (none: nothing said)."""
        if not kernels or _COMPILE_NOTED:
            return
        _COMPILE_NOTED.append(kernels)
        self.stream.write(f"rss6 run: {compile_note(kernels)}\n")
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


def _kernels_to_compile(client, model: str) -> list[str]:
    """The compiled kernels of ``model`` that any of the client's workers would compile first (each
    worker asked, from its own cache); none for levels without kernels, without asking, and none
    when a worker cannot answer (lost meanwhile: the run itself reports that)."""
    from rss6core import level_kernels, kernels_to_compile
    if not level_kernels(model):
        return []
    try:
        answers = client.run(kernels_to_compile, model)
    except (OSError, TimeoutError):
        return []
    return sorted({name for names in answers.values() for name in names})


def local_cluster(workers: int):
    """A dask LocalCluster of ``workers`` single-threaded worker processes, one BLAS thread each.

    dask starts its workers with MALLOC_TRIM_THRESHOLD_=65536, which also fixes glibc's mmap
    threshold at 128 KiB: every larger temporary array is then mapped and faulted in afresh,
    which costs the paper level 25-30 % more CPU time per realisation. These workers keep glibc's
    default (a value set in the environment by the user still applies). The cluster's own logs
    are silenced below CRITICAL: closing it races with the workers' heartbeats, which then log a
    traceback although nothing failed; rss6 reports every task's failure itself.

    The workers are forked from a server process that imports rss6 and its libraries once
    (:func:`_preload_worker_imports`), not started afresh: each fresh worker spent seconds importing
    them, and closing the cluster took seconds more. The cluster has no dashboard, so what only
    feeds one is off or slowed (QUIET_CLUSTER). Its scheduler still serves dask's health routes
    over HTTP, on a free local port: by default it takes 8787 and warns "Port 8787 is already in
    use" whenever another cluster (a second rss6 run) holds it.
    """
    import dask
    from dask.distributed import LocalCluster
    os.environ.update(BLAS_ENV)  # inherited by the worker processes
    settings = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                "distributed.worker.multiprocessing-method": "forkserver", **QUIET_CLUSTER}
    with dask.config.set(settings), _workers_ignore_ctrl_c():
        _preload_worker_imports()
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                            dashboard_address=None, host="127.0.0.1", silence_logs=logging.CRITICAL,
                            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})


# a local cluster without a dashboard: no statistical profiler in the workers (a stack sample of
# the running task every 10 ms), and the monitors that feed the dashboard (event-loop tick, system
# and memory) at a tenth of their rates: idle, 2 workers and the main process then take 0.2 s of CPU
# per 10 s instead of 1.1 s, CPU taken from the realisations once both cores compute
# (docs/performance.md, section 18)
QUIET_CLUSTER = {"distributed.worker.profile.enabled": False,
                 "distributed.admin.tick.interval": "200ms",
                 "distributed.admin.system-monitor.interval": "2s",
                 "distributed.worker.memory.monitor-interval": "1s"}
# what a worker needs: rss6core, numpy, xarray, ... through pipeline.ensemble.run; xarray imports dask.array
# at its first Dataset, the level's design pipeline.ensemble.sampler (0.2-0.3 s per worker in its first task)
WORKER_IMPORTS = ["distributed", "pipeline.ensemble.run", "dask.array", "pipeline.ensemble.sampler"]


def _preload_worker_imports() -> None:
    """Make the fork server that starts the workers import WORKER_IMPORTS first (effective until it
    starts, at the first worker: it then lives as long as this process and forks every worker).

    It starts in the environment of that moment (one BLAS thread, SIGINT ignored: see the caller)."""
    from distributed.utils import get_mp_context
    get_mp_context().set_forkserver_preload(WORKER_IMPORTS)   # after dask's own, which it replaces


@contextlib.contextmanager
def _workers_ignore_ctrl_c():
    """Worker processes started in this block inherit an ignored SIGINT: a terminal's Ctrl-C reaches
    the whole process group, and only this process should act on it (the cluster is closed from
    here); otherwise each worker prints its own traceback. The disposition is the process's, so a
    Ctrl-C while the local cluster starts (1-3 s) is lost; blocking SIGINT instead does not reach
    the workers (dask starts them from threads that do not block it)."""
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


@contextlib.contextmanager
def dask_client(workers: int = 2, scheduler: str | None = None):
    """A dask client on a new local cluster of ``workers`` (or on ``scheduler``), closed with its
    cluster at the end of the block: one cluster for many ensembles (``client=`` of :func:`ensemble`)."""
    client, cluster = _client(workers, scheduler)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


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


def _finished(client, futures: list, scheduler: str | None, worker_timeout: float,
              interrupted: list):
    """The chunk results as they finish, waiting at most POLL_S at a time: KeyboardInterrupt is
    raised here, between waits, once ``interrupted`` holds a Ctrl-C (never inside dask's client,
    where it could leave a lock held and hang the cluster's shutdown). On an external scheduler
    the workers are counted and SchedulerUnavailable is raised once it has had none for
    ``worker_timeout`` s."""
    if scheduler:
        _quiet_lost_results()
    pending, idle_since = set(futures), None
    while pending:
        if interrupted:
            raise KeyboardInterrupt
        got = list(_gathered(client, pending))
        yield from got
        if not scheduler or got or client.nthreads():
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
# the contact level computes its fine-grid loads and joint maps once per batch (1.9 s CPU, as much
# as 8 realisations' steps): twice the batch halves that share (docs/performance.md, section 14);
# a paper-level chunk of 128 is about 1 s of work, and the main process's work per chunk (writing
# its part, 15-20 ms CPU, and dask's messages), taken from the workers' cores, is then half as
# often paid (section 18)
MAX_AUTO_CHUNK_BY_MODEL = {"contact": 128, "paper": 128}


def default_chunk(n: int, workers: int, model: str | None = None) -> int:
    """Realisations per task: every worker busy, batches large, little work lost on an interrupt.

    The n realisations are cut into a multiple of ``workers`` chunks of nearly equal size (at most
    MAX_AUTO_CHUNK, or the model's entry in MAX_AUTO_CHUNK_BY_MODEL), so that the workers finish
    together: 400 on two workers are 8 chunks of 50, not 6 of 64 and one of 16.
    """
    largest = MAX_AUTO_CHUNK_BY_MODEL.get(model, MAX_AUTO_CHUNK)
    rounds = -(-n // (workers * largest))
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
             worker_timeout: float = WORKER_TIMEOUT_S, client=None) -> EnsembleOutcome:
    """Run realisations 0..n-1 not yet stored in ``output`` (one writer at a time: OUT.lock).

    ``annotate(dataset) -> dict``, if given, adds global attributes (e.g. requirement verdicts)
    computed from the finished ensemble before it is written; the file is rewritten only if they
    change it. ``worker_timeout`` (s): how long an external ``scheduler`` may have no workers
    before SchedulerUnavailable is raised. ``client``: an open dask client to run on (see
    :func:`dask_client`; ``workers`` then only sizes the default chunks, and ``scheduler`` says
    whether it is external); without one, a cluster is started for this call and closed after."""
    if n < 1:
        raise ValueError(f"the number of realisations must be at least 1, got {n}")
    chunk = default_chunk(n, workers, spec.model) if chunk is None else chunk
    if chunk < 1 or workers < 1:
        raise ValueError("--chunk and --workers must be at least 1")
    if not worker_timeout > 0:
        raise ValueError(f"--worker-timeout must be positive, got {worker_timeout}")
    output = Path(output)
    with OutputLock(output):
        manifest = PartsManifest(parts_dir(output), spec.attrs())
        pieces, done = _stored(output, spec, manifest)
        todo = [r for r in range(n) if r not in done]
        if todo:
            chunks = [todo[i:i + chunk] for i in range(0, len(todo), chunk)]
            bar = _Progress(n, n - len(todo)) if progress else None
            if bar:
                bar.begin(len(chunks), f"scheduler {scheduler}" if scheduler else f"{workers} workers")
            pieces += _compute(spec, chunks, manifest, workers, scheduler, bar, worker_timeout, client)
        up_to_date = not todo and len(pieces) == 1 and output.exists()  # the file alone holds all
        merged = pieces[0] if up_to_date else _merged(pieces, spec)
        extra = annotate(merged) if annotate else {}
        annotated = any(str(merged.attrs.get(k)) != str(v) for k, v in extra.items())
        if not up_to_date or annotated:
            write_netcdf(merged.assign_attrs(extra), output)   # streams the histories from the parts
            merged = open_ensemble(output, lazy=True, verify=False)   # just written
        if manifest.folder.exists():
            shutil.rmtree(manifest.folder)
    return EnsembleOutcome(merged, len(todo), len(done), not up_to_date)


def _merged(pieces: list, spec: EnsembleSpec):
    """The stored pieces as one ensemble, in realisation order; histories stay lazy (on disk)."""
    pieces = sorted(pieces, key=lambda ds: int(ds["realization"][0]))
    return _finish(pieces, spec.scene(), spec)


def _compute(spec: EnsembleSpec, chunks: list, manifest: PartsManifest, workers: int,
             scheduler: str | None, bar, worker_timeout: float = WORKER_TIMEOUT_S, client=None) -> list:
    """Run the chunks on dask (on ``client``, else on a cluster of this call); each finished chunk
    is stored as a part at once. Returns the parts: a chunk of summaries as it came (a few hundred
    kB; the merged file has the same bytes as from the part read back, tests/test_merge.py), a
    chunk with histories as read back from its part, lazily, while the workers compute the others
    (histories stay on disk). The merged file is checked (:func:`ensemble`), the parts are not."""
    written, shared = [], client is not None
    with contextlib.nullcontext(client) if shared else dask_client(workers, scheduler) as client:
        if bar:
            with sigint_deferred():   # a Ctrl-C meanwhile is raised after it, not inside dask's client
                kernels = _kernels_to_compile(client, spec.model)
            bar.compiling(kernels)
        futures = [client.submit(run_chunk, spec, c, pure=False, retries=2) for c in chunks]
        try:
            with sigint_deferred() as interrupted:   # Ctrl-C is acted on in _finished
                for ds in _finished(client, futures, scheduler, worker_timeout, interrupted):
                    first, last = int(ds.realization[0]), int(ds.realization[-1])
                    path = manifest.write(ds, f"chunk-{first:07d}-{last:07d}.nc")
                    written.append(load_netcdf(path, lazy=True, verify=False) if "time" in ds.dims
                                   else ds)
                    if bar:
                        bar.advance(ds.sizes["realization"])
        except BaseException:
            if shared:   # the cluster outlives this call: leave it none of this call's work
                client.cancel(futures)
            raise
    return written


def run_ensemble(spec: EnsembleSpec, n: int, output, workers: int = 2, scheduler: str | None = None,
                 chunk: int | None = None, progress: bool = True,
                 worker_timeout: float = WORKER_TIMEOUT_S, client=None):
    """Run realisations 0..n-1 not yet stored in ``output``; return the merged Dataset. ``client``:
    an open dask client to reuse (:func:`dask_client`), else a cluster is started for this call."""
    return ensemble(spec, n, output, workers, scheduler, chunk, progress,
                    worker_timeout=worker_timeout, client=client).dataset
