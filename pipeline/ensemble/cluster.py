"""The dask side of an ensemble: rss6's one cluster-and-client helper, and waiting for results.

:func:`dask_client` is the one way the pipeline gets a dask client: on a new local cluster
(:func:`local_cluster`: single-threaded workers with one BLAS thread, forked from a server that
imported rss6 once, quiet, deaf to a terminal's Ctrl-C) or on an external scheduler.
:func:`results_as_finished` yields the chunk results as they finish, acting on a Ctrl-C between waits and
giving up on an external scheduler that has had no workers for too long (SchedulerUnavailable).
"""
from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
import time

__all__ = ["local_cluster", "dask_client", "start_worker_server", "stop_worker_server", "results_as_finished",
           "BLAS_ENV", "QUIET_CLUSTER", "NANNY_HASH_SEED", "WORKER_IMPORTS", "SchedulerUnavailable",
           "CONNECT_TIMEOUT_S", "WORKER_TIMEOUT_S", "POLL_S"]

BLAS_ENV = {v: "1" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                             "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")}


def local_cluster(workers: int):
    """A dask LocalCluster of ``workers`` single-threaded worker processes, one BLAS thread each.

    dask starts its workers with MALLOC_TRIM_THRESHOLD_=65536, which also fixes glibc's mmap
    threshold at 128 KiB: every larger temporary array is then mapped and faulted in afresh,
    which costs the paper level a quarter more CPU time per realisation (docs/performance.md).
    These workers keep glibc's default (a value set in the environment by the user still applies).
    The cluster's own logs are silenced below CRITICAL: closing it races with the workers'
    heartbeats, which then log a traceback although nothing failed; rss6 reports every task's
    failure itself.

    The workers are forked from a server process that imports rss6 and its libraries once
    (:func:`start_worker_server`), not started afresh: each fresh worker spent seconds importing
    them, and closing the cluster took seconds more. The cluster has no dashboard, so what only
    feeds one is off or slowed (QUIET_CLUSTER). Its scheduler still serves dask's health routes
    over HTTP, on a free local port: by default it takes 8787 and warns "Port 8787 is already in
    use" whenever another cluster (a second rss6 run) holds it.
    """
    import dask
    from dask.distributed import LocalCluster

    from ..files.writing import sigint_deferred
    settings = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                "distributed.worker.multiprocessing-method": "forkserver", **QUIET_CLUSTER}
    start_worker_server()   # the workers fork from it and ignore Ctrl-C as it does
    with dask.config.set(settings), sigint_deferred() as interrupted:   # a Ctrl-C meanwhile: raised after
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, host="127.0.0.1", silence_logs=logging.CRITICAL,
                               scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})
        if interrupted:
            cluster.close()
    return cluster


# a local cluster without a dashboard: no statistical profiler in the workers (a stack sample of
# the running task every 10 ms), and the monitors that feed the dashboard (event-loop tick, system
# and memory) at a tenth of their rates: idle, the workers and the main process then take a fifth of
# the CPU they took, CPU taken from the realisations once both cores compute (docs/performance.md,
# section 18)
QUIET_CLUSTER = {"distributed.worker.profile.enabled": False,
                 "distributed.admin.tick.interval": "200ms",
                 "distributed.admin.system-monitor.interval": "2s",
                 "distributed.worker.memory.monitor-interval": "1s"}
# what a worker needs: rss6core, numpy, xarray, ... through pipeline.ensemble.run; xarray imports dask.array
# at its first Dataset, the level's design pipeline.ensemble.sampler (else paid by each worker in its first task),
# the draws' compiled arithmetic rss6core.draw_kernel (numba, loaded or compiled once in the server)
WORKER_IMPORTS = ["distributed", "pipeline.ensemble.run", "dask.array", "pipeline.ensemble.sampler",
                  "rss6core.draw_kernel"]


# the hash seed dask's nanny gives its workers (distributed/nanny.py, dask/distributed#8400): a
# worker's string hashes, hence the order of any set of strings, are the same in every run
NANNY_HASH_SEED = "6640"


def start_worker_server(then_import: tuple = (), environment: dict | None = None) -> None:
    """Start the fork server that forks the local cluster's workers, if it is not running: it imports
    WORKER_IMPORTS and then ``then_import`` once, in the environment of this moment (one BLAS
    thread, the nanny's hash seed, SIGINT ignored, and ``environment``, set for the server only),
    and then lives as long as this process. Started before this process's own imports (the
    ``rss6`` command does so, :func:`pipeline.cli.main`), the two import side by side.

    Every worker inherits the server's environment as it was at its start: what a nanny sets just
    before it starts a worker (PYTHONHASHSEED among it) reaches the workers only if set here too.

    The server is a ``python -c`` process, which puts the working directory first on its module path
    (Python 3.11's server ignores the path it is handed): started from a folder holding a
    ``pipeline`` or ``rss6core`` (another checkout of rss6, or a user's own package of that name),
    the workers imported that. PYTHONSAFEPATH, set for the server only, keeps the folder out."""
    import multiprocessing
    from multiprocessing import forkserver
    os.environ.update(BLAS_ENV)
    os.environ["PYTHONHASHSEED"] = NANNY_HASH_SEED   # the nanny sets it in this process too, later
    preload = WORKER_IMPORTS + list(then_import)
    multiprocessing.get_context("forkserver").set_forkserver_preload(preload)  # replaces dask's own
    with _environment({"PYTHONSAFEPATH": "1", **(environment or {})}), _workers_ignore_ctrl_c():
        forkserver.ensure_running()


@contextlib.contextmanager
def _environment(values: dict):
    """``values`` set in this process's environment inside the block only (a child started there
    inherits them), each variable restored or removed after."""
    before = {name: os.environ.get(name) for name in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for name, value in before.items():
            if value is None:
                del os.environ[name]
            else:
                os.environ[name] = value


def stop_worker_server() -> None:
    """Stop this process's fork server (at exit: a server started ahead of a command that then
    stopped early would otherwise finish importing, seconds of CPU, before it noticed)."""
    from multiprocessing import forkserver
    pid = getattr(forkserver._forkserver, "_forkserver_pid", None)
    if pid is not None:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGTERM)


@contextlib.contextmanager
def _workers_ignore_ctrl_c():
    """Processes started in this block inherit an ignored SIGINT: the fork server, and through it every
    worker it forks. A terminal's Ctrl-C reaches the whole process group, and only this process should
    act on it (the cluster is closed from here); otherwise each worker prints its own traceback.
    Blocking SIGINT instead does not reach the workers (dask starts them from threads that do not
    block it). The cluster itself then starts with this process's Ctrl-C held, not ignored
    (:func:`local_cluster`)."""
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
POLL_WAIT_S = 0.02        # how often, s, the chunks' futures are looked at


class SchedulerUnavailable(RuntimeError):
    """The external dask scheduler cannot be reached, or has had no workers for too long (an
    environment problem: the finished chunks stay in OUT.nc.parts)."""


@contextlib.contextmanager
def dask_client(workers: int = 2, scheduler: str | None = None):
    """A dask client on a new local cluster of ``workers`` (or on ``scheduler``), closed with its
    cluster at the end of the block: one cluster for many ensembles (``client=`` of
    pipeline.ensemble.run.ensemble). Every client of the pipeline comes from here."""
    client, cluster = _client(workers, scheduler)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@contextlib.contextmanager
def optional_client(workers: int):
    """:func:`dask_client` on ``workers`` local processes, or None (work in this process) for one."""
    if workers <= 1:
        yield None
        return
    with dask_client(workers) as client:
        yield client


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


def results_as_finished(client, futures: list, scheduler: str | None, worker_timeout: float,
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
    gathering would wait for that); such a future stays in ``pending``. The futures' states are
    looked at every POLL_WAIT_S: a dask ``wait`` that timed out left one waiter per pending future
    behind, so that with ~1000 chunks pending the main process grew by megabytes a second
    (docs/performance.md section 26)."""
    deadline = time.monotonic() + POLL_S
    done = [f for f in pending if f.done()]
    while not done and time.monotonic() < deadline:
        time.sleep(POLL_WAIT_S)
        done = [f for f in pending if f.done()]
    if not done:
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
        future.release()   # the worker may drop it: a 1,000,000-realisation run held them all
        yield result
