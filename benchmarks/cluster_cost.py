"""Benchmark: what rss6's local dask cluster itself costs in CPU, with its settings and with dask's.

Run on demand: ``python benchmarks/cluster_cost.py [--pairs P] [--json]``.
For each of P pairs, alternating which goes first, a cluster of 2 workers is started with rss6's
settings (``pipeline.ensemble.cluster.QUIET_CLUSTER``: no worker profiler, slower dashboard monitors) and one
with dask's defaults for those keys; each measures
- idle: the CPU seconds of the main process (scheduler, nannies, client) and of the workers over
  10 s without tasks;
- a run: ``run_ensemble`` of 1000 `paper` realisations of configs/paper.toml on 1 worker (so that
  the other core keeps the main process off the worker's), its wall time and the CPU seconds of
  the main process and the worker.
CPU is read from /proc, so the figures do not depend on what else the machine runs as much as
wall times do; the medians are printed.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

from paper_run import process_cpu as _cpu   # this folder is the script's first import path

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "paper.toml"
IDLE_S = 10.0


def _measure(quiet: bool, tmp: str) -> dict:
    """Idle CPU of a 2-worker cluster and a 1000-realisation run on a 1-worker cluster."""
    from dask.distributed import Client

    import pipeline.ensemble.cluster as cluster_module
    import pipeline.ensemble.run as run
    from rss6core import load_scene
    from rss6core.models import default_integrator, default_time_step
    settings = cluster_module.QUIET_CLUSTER
    cluster_module.QUIET_CLUSTER = settings if quiet else {}
    try:
        with cluster_module.local_cluster(2) as cluster, Client(cluster) as client:
            pids = list(client.run(os.getpid).values())
            time.sleep(2.0)                     # start-up settled
            main0, workers0 = _cpu(os.getpid()), [_cpu(p) for p in pids]
            time.sleep(IDLE_S)
            idle = {"main_cpu_s": _cpu(os.getpid()) - main0,
                    "workers_cpu_s": sum(_cpu(p) for p in pids) - sum(workers0)}
        scene = load_scene(CONFIG)
        spec = run.EnsembleSpec(scene.source_text, str(CONFIG), "paper", default_integrator(scene, "paper"),
                                default_time_step(scene, "paper"), scene.simulation.elements_per_link, 0)
        with cluster_module.local_cluster(1) as cluster, Client(cluster) as client:
            client.run(lambda: __import__("pipeline.ensemble.run"))
            pid = next(iter(client.run(os.getpid).values()))
            main0, worker0, start = _cpu(os.getpid()), _cpu(pid), time.perf_counter()
            run.run_ensemble(spec, 1000, Path(tempfile.mkdtemp(dir=tmp)) / "p.nc", client=client,
                             workers=2, progress=False)
            whole = {"wall_s": time.perf_counter() - start, "main_cpu_s": _cpu(os.getpid()) - main0,
                     "worker_cpu_s": _cpu(pid) - worker0}
    finally:
        cluster_module.QUIET_CLUSTER = settings
    return {"idle": idle, "run": whole}


def measure(pairs: int) -> dict:
    runs = {"rss6": [], "dask": []}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(pairs):
            for quiet in ((True, False), (False, True))[i % 2]:
                runs["rss6" if quiet else "dask"].append(_measure(quiet, tmp))
    out = {name: {part: {k: statistics.median(r[part][k] for r in rs) for k in rs[0][part]}
                  for part in ("idle", "run")} for name, rs in runs.items()}
    out["runs"] = runs   # every measurement, to show the spread
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=3, metavar="P")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    if args.pairs < 1:
        parser.error("--pairs must be at least 1")
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
    out = measure(args.pairs)
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    for name in ("rss6", "dask"):
        idle, whole = out[name]["idle"], out[name]["run"]
        print(f"{name} settings: idle 2-worker cluster, CPU per {IDLE_S:g} s: main {idle['main_cpu_s']:.2f} s, "
              f"workers {idle['workers_cpu_s']:.2f} s; paper 1000 on 1 worker: {whole['wall_s']:.2f} s wall, "
              f"CPU main {whole['main_cpu_s']:.2f} s, worker {whole['worker_cpu_s']:.2f} s")
        print("  each run: " + ", ".join(f"worker {m['run']['worker_cpu_s']:.2f} s / wall {m['run']['wall_s']:.2f} s"
                                          for m in out["runs"][name]))
    r, d = out["rss6"]["run"], out["dask"]["run"]
    print(f"rss6 / dask settings, medians of {args.pairs} pairs: "
          f"worker CPU {r['worker_cpu_s'] / d['worker_cpu_s']:.2f}, "
          f"main CPU {r['main_cpu_s'] / d['main_cpu_s']:.2f}, wall {r['wall_s'] / d['wall_s']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
