"""Benchmark: where a paper-level `rss6 run` spends its time, robust to a loaded machine.

``python benchmarks/paper_run.py run [--rss6 PATH] [-n N]`` runs ``rss6 run configs/paper.toml -n N
--model paper --store summary --workers 2`` once and prints its wall time and the CPU seconds (user +
system) of the whole process tree (main process, fork server, workers; each process sampled from
/proc every 0.02 s, its last sample counted). On a shared 2-core machine the wall time follows the
other load; the CPU seconds much less. ``--rss6`` names another install's executable (A/B runs).

``python benchmarks/paper_run.py phases [-n N]`` runs the same command inside this process (the
``rss6`` of this interpreter) and prints the wall-clock time of its phases: imports, settings,
cluster start, first and last chunk back, merge, final write, statistics.

``python benchmarks/paper_run.py parts`` prints the CPU milliseconds per realisation (median of
three chunks of 63) of the paper level's parts in one process: the per-step draw, the contact
forces of eq. 17, the error (leg closure, central differences, elastic part added) and the chunk's
Dataset (window reductions, provenance). Run it with each install's interpreter for an A/B.

``python benchmarks/paper_run.py floor`` prints the CPU milliseconds per realisation of what the
per-step draw cannot do without while its bits stay those of numpy and scipy: the uniforms from the
realisation's stream (9 per joint-step), the 6 sines and cosines of the three azimuths (glibc's, as
numpy's float64 sin and cos are), the 2 inverse normal CDFs (scipy's ndtri) and the 2 square roots of
the uniform sphere's polar sines per joint-step, each over the 12 030 joint-steps of
configs/paper.toml (median of 7 repeats).

``python benchmarks/paper_run.py cluster [-n N]`` starts a local cluster of two workers, then runs
the paper level's N realisations on it three times (``run_ensemble``, fresh files; the first run's
workers prepare the level, the later ones have it) and prints, per run, the wall time and the CPU
seconds of this process (the client, the scheduler's thread and the chunks' writes) and of each
worker: where a 2-core machine's 2 x wall CPU seconds go.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "paper.toml"
TICK = os.sysconf("SC_CLK_TCK")


def _stat_fields(stat: Path) -> list[str]:
    """The fields of a /proc/PID/stat file after the command name (state, ppid, ...)."""
    return stat.read_text().rsplit(")", 1)[1].split()


def _cpu_s(fields: list[str]) -> float:
    """User + system CPU seconds from a process's stat fields."""
    return (int(fields[11]) + int(fields[12])) / TICK


def process_cpu(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far (Linux /proc; also used by
    benchmarks/cluster_cost.py)."""
    return _cpu_s(_stat_fields(Path(f"/proc/{pid}/stat")))


def _cpu_by_parent() -> dict:
    """{parent pid: [(pid, CPU s)]} of every process (Linux /proc)."""
    out = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = _stat_fields(stat)
            out.setdefault(int(fields[1]), []).append((int(stat.parent.name), _cpu_s(fields)))
        except (OSError, IndexError, ValueError):
            continue
    return out


def _sample(root: int, seen: dict, stop: threading.Event) -> None:
    """Record the CPU seconds of ``root``'s descendants in ``seen`` until ``stop`` is set."""
    while not stop.is_set():
        children, todo = _cpu_by_parent(), [root]
        while todo:
            for pid, cpu in children.get(todo.pop(), []):
                seen[pid] = max(seen.get(pid, 0.0), cpu)
                todo.append(pid)
        time.sleep(0.02)


def whole_run(rss6: str, n: int) -> dict:
    """Wall time (s) and process-tree CPU (s) of one `rss6 run` of the paper level."""
    with tempfile.TemporaryDirectory() as tmp:
        seen, stop = {}, threading.Event()
        start = time.perf_counter()
        proc = subprocess.Popen([rss6, "run", str(CONFIG), "-n", str(n), "--model", "paper",
                                 "--store", "summary", "--workers", "2", "-o", f"{tmp}/p.nc"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        sampler = threading.Thread(target=_sample, args=(proc.pid, seen, stop))
        sampler.start()
        own = 0.0
        while proc.poll() is None:   # the main process's own CPU, read until it exits
            try:
                own = process_cpu(proc.pid)
            except OSError:
                pass
            time.sleep(0.02)
        wall = time.perf_counter() - start
        stop.set()
        sampler.join()
    return {"n": n, "wall_s": round(wall, 2), "cpu_s": round(own + sum(seen.values()), 2),
            "rc": proc.returncode, "load": round(os.getloadavg()[0], 2)}


def phases(n: int) -> list:
    """Wall-clock seconds at each phase of `rss6 run` (run in this process, its steps wrapped)."""
    start, marks = time.perf_counter(), []

    def mark(what: str) -> None:
        marks.append((what, round(time.perf_counter() - start, 2)))

    import pipeline.cli as cli
    argv = ["run", str(CONFIG), "-n", str(n), "--model", "paper", "--store", "summary", "--workers", "2"]
    if hasattr(cli, "_start_workers_ahead"):   # as the rss6 command does, before its imports
        cli._start_workers_ahead(argv)
    import pipeline.ensemble.cluster as cluster
    import pipeline.ensemble.run as run
    cli.build_parser()
    mark("imports done")
    client, finished = cluster._client, run.results_as_finished

    def timed_client(*args, **kw):
        mark("settings and stored parts done; cluster starts")
        out = client(*args, **kw)
        mark("cluster up")
        return out

    def timed_finished(*args, **kw):
        for k, ds in enumerate(finished(*args, **kw)):
            if k == 0:
                mark("first chunk back")
            yield ds
        mark("last chunk back")

    def timed_write(ds, path, write=run.write_netcdf):
        mark("merged; final write starts")
        write(ds, path)
        mark("final write done")

    cluster._client, run.results_as_finished, run.write_netcdf = timed_client, timed_finished, timed_write
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        code = cli.main(argv + ["-o", f"{tmp}/p.nc"])
    mark(f"statistics printed (exit {code})")
    return marks


def _cpu_ms(f, items) -> tuple[float, list]:
    """CPU milliseconds per item of ``f`` over ``items``, and its results."""
    start = time.process_time()
    out = [f(i) for i in items]
    return (time.process_time() - start) / len(items) * 1e3, out


def _chunk_parts(scene, level, spec, realizations: list) -> dict:
    """CPU ms per realisation of each part of the paper level for one chunk."""
    from pipeline.ensemble.run import run_chunk
    from rss6core.paper_method import output_step, paper_contact_forces, paper_draw, paper_result
    steps, k = len(level.elastic.t), range(len(realizations))
    t_draw, draws = _cpu_ms(lambda r: paper_draw(scene, 0, r, steps), realizations)
    t_force, forces = _cpu_ms(lambda i: paper_contact_forces(scene, draws[i], level.dt), k)
    t_error, _ = _cpu_ms(lambda i: paper_result(level.elastic, level.closure, draws[i], forces[i],
                                                output_step(draws[i])), k)
    t_chunk, _ = _cpu_ms(lambda _: run_chunk(spec, realizations), [0])
    return {"draw": t_draw, "forces": t_force, "error": t_error,   # chunk: the rest of run_chunk
            "chunk": t_chunk / len(realizations) - t_draw - t_force - t_error}


def parts() -> dict:
    """CPU ms per realisation of the paper level's parts (median of three chunks of 63)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = "1"
    from pipeline.ensemble.run import EnsembleSpec, run_chunk
    from rss6core import load_scene
    from rss6core.models import prepare_level
    scene = load_scene(CONFIG)
    level = prepare_level(scene, "paper")
    spec = EnsembleSpec(scene.source_text, str(CONFIG), "paper", "newmark", level.dt, level.elements, 0)
    run_chunk(spec, [0])   # the worker's one-off level preparation, off the clock
    runs = [_chunk_parts(scene, level, spec, list(range(63 * k, 63 * k + 63))) for k in range(3)]
    return {key: round(statistics.median(r[key] for r in runs), 2) for key in runs[0]}


def floor() -> dict:
    """CPU ms per realisation of the per-step draw's unavoidable arithmetic (see the module doc)."""
    import numpy as np
    from scipy.special import ndtri
    n = 6 * 2005                                   # 2001 output steps and 2 x 2 pads, 6 legs
    rng = np.random.default_rng(0)
    u = rng.random(n)
    angle = 2.0 * np.pi * u                        # the azimuths' range; the polar angles' is [0, pi]
    parts = {"uniforms": lambda: rng.random(9 * n), "sin_cos": lambda: [np.sin(angle) for _ in range(6)],
             "ndtri": lambda: [ndtri(u) for _ in range(2)], "sqrt": lambda: [np.sqrt(u) for _ in range(2)]}
    out = {}
    for name, f in parts.items():
        times = []
        for _ in range(7):
            start = time.process_time()
            f()
            times.append((time.process_time() - start) * 1e3)
        out[name] = round(statistics.median(times), 3)
    out["sum"] = round(sum(out.values()), 3)
    return out


def _on_cluster(client, address: str, n: int, folder: str, k: int) -> dict:
    """One run of N paper realisations on the started cluster: wall s, CPU s here and per worker."""
    from pipeline.ensemble.run import EnsembleSpec, default_chunk, run_ensemble
    from rss6core import load_scene
    from rss6core.models import default_integrator, default_time_step
    scene = load_scene(CONFIG)
    spec = EnsembleSpec(scene.source_text, str(CONFIG), "paper", default_integrator(scene, "paper"),
                        default_time_step(scene, "paper"), scene.simulation.elements_per_link, 0)
    workers = client.run(os.getpid)
    before = {w: process_cpu(pid) for w, pid in workers.items()}
    own, start = time.process_time(), time.perf_counter()
    run_ensemble(spec, n, Path(folder) / f"p{k}.nc", scheduler=address, chunk=default_chunk(n, 2, "paper"),
                 progress=False)
    wall, own = time.perf_counter() - start, time.process_time() - own
    return {"run": k, "wall_s": round(wall, 3), "this_process_cpu_s": round(own, 3),
            "workers_cpu_s": [round(process_cpu(pid) - before[w], 3) for w, pid in workers.items()],
            "load": round(os.getloadavg()[0], 2)}


def on_cluster(n: int) -> list:
    """:func:`_on_cluster` three times on one local cluster of two workers."""
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    from dask.distributed import Client

    from pipeline.ensemble.cluster import local_cluster
    # started in a temporary folder: an rss6 before 0.3.1 (a baseline) forks its workers from a server
    # that imports rss6 from its working folder first (docs/performance.md section 32)
    with tempfile.TemporaryDirectory() as tmp, contextlib.chdir(tmp), local_cluster(2) as cluster, \
            Client(cluster) as client:
        client.run(lambda: __import__("pipeline.ensemble.run"))     # imports off the clock
        return [_on_cluster(client, cluster.scheduler_address, n, tmp, k) for k in range(3)]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", choices=("run", "phases", "parts", "floor", "cluster"))
    parser.add_argument("--rss6", default=str(Path(sys.executable).with_name("rss6")),
                        help="the rss6 executable to time (default: this interpreter's)")
    parser.add_argument("-n", type=int, default=1000)
    args = parser.parse_args(argv)
    if args.what == "phases":
        print(json.dumps(phases(args.n)))
    elif args.what == "floor":
        print(json.dumps(floor()))
    elif args.what == "cluster":
        print("\n".join(json.dumps(r) for r in on_cluster(args.n)))
    else:
        print(json.dumps(whole_run(args.rss6, args.n) if args.what == "run" else parts()))


if __name__ == "__main__":
    main()
