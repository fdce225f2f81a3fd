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
depend on the chunk size or the number of workers.  The cluster and client come from
pipeline/ensemble/cluster.py, the progress lines from pipeline/ensemble/progress.py.
"""
from __future__ import annotations

import contextlib
import functools
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rss6core import (FAILED, MODEL_LEVELS, SimulationResult, __version__, parse_scene, prepare_level, stored_draw,
                      stored_inputs, time_grid)

from ..files.outputs import OutputLock, PartsManifest, parts_dir
from ..files.opening import open_ensemble
from ..files.reading import SUMMARY_BLOCK, load_netcdf
from ..files.records import finish_ensemble, chunk_dataset
from ..files.schema import EnsembleFileError, ensemble_identity, identity
from ..files.writing import sigint_deferred, write_netcdf
from .cluster import WORKER_TIMEOUT_S, dask_client, results_as_finished
from .progress import _kernels_to_compile, _Progress, cluster_label, compile_apart

__all__ = ["EnsembleSpec", "EnsembleOutcome", "ensemble", "run_chunk", "run_ensemble", "default_chunk", "shared_level",
           "parts_dir", "MAX_AUTO_CHUNK", "MAX_AUTO_CHUNK_BY_MODEL", "MAX_AUTO_CHUNKS"]


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
    inputs = [result.inputs if result.inputs is not None else stored_inputs(scene, spec.seed, r, spec.design())
              for r, result in zip(realizations, results)] if scene.uncertain else None
    chunk = chunk_dataset(results, draws, realizations, spec.store, scene.simulation.settle_time,
                          scene.simulation.steady_after, inputs)
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
    return shared_level(spec).simulate(spec.seed, realizations, spec.design())


def shared_level(spec: EnsembleSpec):
    """The spec's level from this process's cache (:func:`_level`), prepared at the first call: in a
    worker at its first chunk, or, for ``rss6 run``, in the fork server before it forks the workers,
    which then inherit it (pipeline/commands/prepare_ahead.py)."""
    return _level(spec.scene_text, spec.source, spec.model, spec.integrator, spec.dt, spec.elements)


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


def _stored(output: Path, spec: EnsembleSpec, manifest: PartsManifest, summary_block: int | None = None
            ) -> tuple[list, set]:
    """Datasets already stored for this ensemble (final file and verified parts, their histories
    left on disk, and their summaries too beyond ``summary_block`` realisations, see
    :func:`_summary_block`), and their realisations.

    Each realisation is taken once: parts left beside a finished file (a run stopped
    between writing it and removing the parts) add only what the file lacks.
    """
    pieces, done = [], set()
    parts = _checked_parts(manifest, spec, summary_block)
    final = [(output, open_ensemble(output, lazy=True))] if output.exists() else []
    for path, ds in final:
        _check_identity(path, ds.attrs, spec)
    for _, ds in final + parts:
        new = [int(r) for r in ds["realization"].values if int(r) not in done]
        if new:
            pieces.append(ds.sel(realization=new))
            done.update(new)
    return pieces, done


def _checked_parts(manifest: PartsManifest, spec: EnsembleSpec, summary_block: int | None = None) -> list:
    """Every stored part with its Dataset (histories on disk), each one an ensemble of ``spec``'s
    identity (:meth:`PartsManifest.checked_parts`)."""
    def open_part(path, verify: bool):
        ds = open_ensemble(path, lazy=True, verify=verify, summary_block=summary_block)
        _check_identity(path, ds.attrs, spec)
        return ds
    return manifest.checked_parts(open_part)


MAX_AUTO_CHUNK = 64   # batching gains little beyond this; an interrupted run loses at most 2 chunks
# the contact level computes its fine-grid loads and joint maps once per batch (as much CPU as several
# realisations' steps): twice the batch halves that share (docs/performance.md, section 14);
# the main process's work per chunk (writing its part and dask's messages), taken from the
# workers' cores, is paid less often with larger chunks (section 18); a paper-level chunk of 256,
# which redraws its clearances every step, is a short task still (section 34)
MAX_AUTO_CHUNK_INTEGRATED = 128
MAX_AUTO_CHUNK_REDRAWN = 256
# a larger run has larger chunks: every chunk is a part file that the merge opens (section 26)
MAX_AUTO_CHUNKS = 1024
# the cap of the levels that integrate the flexible links for every clearance draw, by name, the
# dearest first (as the --chunk help names them)
MAX_AUTO_CHUNK_BY_MODEL = {name: MAX_AUTO_CHUNK_REDRAWN if level.redraws_every_step else MAX_AUTO_CHUNK_INTEGRATED
                           for name, level in reversed(MODEL_LEVELS.items())
                           if level.elastic_links and level.draws_clearances}


def default_chunk(n: int, workers: int, model: str | None = None) -> int:
    """Realisations per task: every worker busy, batches large, little work lost on an interrupt.

    The n realisations are cut into a multiple of ``workers`` chunks of nearly equal size (at most
    MAX_AUTO_CHUNK, or the model's entry in MAX_AUTO_CHUNK_BY_MODEL, unless that makes more than
    about MAX_AUTO_CHUNKS chunks), so that the workers finish together: 400 on two workers are 8
    chunks of 50, not 6 of 64 and one of 16.
    """
    largest = max(MAX_AUTO_CHUNK_BY_MODEL.get(model, MAX_AUTO_CHUNK), -(-n // MAX_AUTO_CHUNKS))
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
        summary_block = _summary_block(n)
        pieces, done = _stored(output, spec, manifest, summary_block)
        todo = [r for r in range(n) if r not in done]
        if todo:
            chunks = [todo[i:i + chunk] for i in range(0, len(todo), chunk)]
            bar = _Progress(n, n - len(todo)) if progress else None
            if bar:
                bar.begin(len(chunks), cluster_label(workers, scheduler), starting=client is None)
            pieces += _compute(spec, chunks, manifest, workers, scheduler, bar, worker_timeout, client,
                               summary_block)
        up_to_date = not todo and len(pieces) == 1 and output.exists()  # the file alone holds all
        merged = pieces[0] if up_to_date else _merged(pieces, spec)
        extra = annotate(merged) if annotate else {}
        annotated = any(str(merged.attrs.get(k)) != str(v) for k, v in extra.items())
        if not up_to_date or annotated:
            write_netcdf(merged.assign_attrs(extra), output)   # streams the histories from the parts
            for piece in pieces:   # their files stay open until closed; the parts are deleted below
                piece.close()
            merged = open_ensemble(output, lazy=True, verify=False)   # just written
        if manifest.folder.exists():
            shutil.rmtree(manifest.folder)
    return EnsembleOutcome(merged, len(todo), len(done), not up_to_date)


def _summary_block(n: int) -> int | None:
    """The ``summary_block`` of :func:`load_netcdf` for the pieces of an n-realisation run (None: its
    default; 0: every piece's summaries stay on disk): none are
    held in memory beyond SUMMARY_BLOCK realisations (the pieces of a 1,000,000-realisation run
    took 8 kB each, section 26); the file then is written from them block by block."""
    return None if n <= SUMMARY_BLOCK else 0


def _merged(pieces: list, spec: EnsembleSpec):
    """The stored pieces as one ensemble, in realisation order; histories stay lazy (on disk)."""
    pieces = sorted(pieces, key=lambda ds: int(ds["realization"][0]))
    return _finish(pieces, spec.scene(), spec)


class _Groups:
    """The finished chunks of a large run, held in memory until their group of consecutive chunks
    (about SUMMARY_BLOCK realisations) is complete, then written as one scratch file in
    OUT.nc.parts/merge/ and read back lazily: the final merge opens a few files, not about
    MAX_AUTO_CHUNKS (beyond xarray's 128 open files it reopened them by turns, for every variable:
    the merge of 100,000 realisations took minutes, section 26). Scratch files are not parts: a
    resumed run reads the parts, and the folder goes with OUT.nc.parts."""

    def __init__(self, chunks: list, folder: Path, spec: EnsembleSpec):
        per = max(1, SUMMARY_BLOCK // max(len(c) for c in chunks))
        self.group = {c[0]: i // per for i, c in enumerate(chunks)}
        self.left = {}
        for g in self.group.values():
            self.left[g] = self.left.get(g, 0) + 1
        self.held, self.folder, self.spec = {}, folder, spec

    def add(self, ds) -> list:
        """The chunk ``ds`` taken in; its group read back from its scratch file if it is now complete."""
        g = self.group[int(ds["realization"][0])]
        self.held.setdefault(g, []).append(ds)
        self.left[g] -= 1
        if self.left[g]:
            return []
        merged = _merged(self.held.pop(g), self.spec)
        first, last = int(merged["realization"][0]), int(merged["realization"][-1])
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / f"group-{first:07d}-{last:07d}.nc"
        write_netcdf(merged, path)
        return [load_netcdf(path, lazy=True, verify=False, summary_block=0)]


def _compute(spec: EnsembleSpec, chunks: list, manifest: PartsManifest, workers: int,
             scheduler: str | None, bar, worker_timeout: float = WORKER_TIMEOUT_S, client=None,
             summary_block: int | None = None) -> list:
    """Run the chunks on dask (on ``client``, else on a cluster of this call); each finished chunk
    is stored as a part at once. Returns the parts: a chunk of summaries as it came (a few hundred
    kB; the merged file has the same bytes as from the part read back, tests/test_merge.py), in a
    run of more than ``summary_block`` realisations (``summary_block`` 0) in groups left on disk
    (:class:`_Groups`), a chunk with histories as read back from its part, lazily, while the
    workers compute the others (histories stay on disk). The merged file is checked
    (:func:`ensemble`), the parts are not."""
    written, shared = [], client is not None
    groups = _Groups(chunks, manifest.folder / "merge", spec) if summary_block == 0 else None
    with contextlib.nullcontext(client) if shared else dask_client(workers, scheduler) as client:
        with sigint_deferred() as interrupted:   # a Ctrl-C meanwhile is raised after it, not inside dask's client
            kernels = _kernels_to_compile(client, spec.model)
            if bar:
                bar.compiling(kernels)
            compile_apart(client, kernels, scheduler, interrupted)
        futures = [client.submit(run_chunk, spec, c, pure=False, retries=2) for c in chunks]
        try:
            with sigint_deferred() as interrupted:   # Ctrl-C is acted on in results_as_finished
                for ds in results_as_finished(client, futures, scheduler, worker_timeout, interrupted):
                    first, last = int(ds.realization[0]), int(ds.realization[-1])
                    path = manifest.write(ds, f"chunk-{first:07d}-{last:07d}.nc")
                    if "time" in ds.dims:
                        written.append(load_netcdf(path, lazy=True, verify=False))
                    else:
                        written += groups.add(ds) if groups else [ds]
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
    """Run realisations 0..n-1 not yet stored in ``output``; return the merged Dataset, every realisation
    the file holds (more than n where an earlier run stored more: ``.isel(realization=slice(n))``). ``client``:
    an open dask client to reuse (:func:`dask_client`), else a cluster is started for this call."""
    return ensemble(spec, n, output, workers, scheduler, chunk, progress,
                    worker_timeout=worker_timeout, client=client).dataset
