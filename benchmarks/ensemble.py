"""Benchmark: ensemble throughput of the `paper` and `contact` levels on configs/paper.toml.

Run on demand: ``python benchmarks/ensemble.py [--quick] [--json] [--profile] [--repeat R]``.
Measures, in one run and on this machine:
- seconds per realisation one at a time (a batch of one) and batched (one
  batch of many), and their ratio;
- realisations per second through ``run_ensemble`` on a local dask cluster of
  1 and 2 single-threaded workers (cluster start-up and worker imports not
  counted; the median of ``--repeat`` runs each), and the parallel efficiency
  (throughput of 2 / twice that of 1); after each pair of runs, the same ratio for two
  processes of a fixed single-threaded BLAS load, what the machine itself gives
  compute-bound work on two cores at that time; and, from dask's task stream,
  how busy the workers were kept (task seconds / workers x wall) and how much
  longer the same tasks took with 2 workers than with 1, and how much longer a
  worker's first task took than its others (the level's preparation);
- peak resident memory of a whole ``rss6 run`` (main process and its workers,
  sampled every 0.05 s) for N = 100 and N = 1000 with ``--store summary``
  (`paper` level), and that run's wall time;
- the wall time of a whole ``rss6 run -n 1000 --model contact --store summary`` on
  2 workers (start-up and fine-grid precompute included), and the four issue-20
  targets on one line: contact 1000 <= 120 s, paper 1000 <= 10 s, batched >= 10x,
  2 workers >= 1.8x one; then, for configs/paper.toml, the targets the run misses, judged on the
  unrounded values (a 1.798x prints as 1.80x on that line).
``--models paper`` (or ``contact``) measures one level only (the memory runs and the contact 1000
run belong to the paper and the contact level respectively). ``--baseline DIR`` measures another
checkout (e.g. a ``git worktree`` of the commit before a change) in the same run, right after this
one: this script again in a fresh process with ``PYTHONPATH`` at DIR (so it, its dask workers and its
``rss6 run`` subprocesses import DIR's ``rss6core`` and ``pipeline``), then prints each figure of both
checkouts side by side with the ratio, and issue 42's steady-cost targets: contact steps (batched
seconds per realisation) >= 1.7x, paper (2-worker throughput) >= 1.6x, contact 1000 <= 45 s wall,
paper 1000 <= 4 s wall.
``--quick`` uses configs/smoke.toml (0.2 s) and small counts, and finishes in
under a minute once the contact steps are compiled (the first run on a machine compiles for
about a minute); ``--profile`` adds the top entries of a profile of each batched run.
"""
from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pstats
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[var] = "1"  # before numpy is imported: one core per process

import numpy as np  # noqa: E402

from rss6core import load_scene  # noqa: E402
from pipeline.ensemble.run import default_chunk  # noqa: E402
from rss6core.models import default_integrator, default_time_step, simulate_batch  # noqa: E402

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
# counts per model: loop (one at a time), batched (one batch), workers (per throughput run). The
# batch is the one `rss6 run -n 1000` makes on 2 workers (default_chunk: 250 for paper, 125 for
# contact; a baseline checkout uses its own); paper's throughput is that of the 1000-realisation
# ensemble its time target names (4 chunks of 250): a run's fixed costs (the first task's start,
# the final merge) are then amortised as in real runs; contact's is that of two tasks of the same
# 125 (one per worker with 2), as its 1000 run computes them (that run on 1 worker would take
# about 3 minutes per repeat)
BATCH = default_chunk(1000, 2, "paper"), default_chunk(1000, 2, "contact")
FULL = {"config": "paper.toml", "paper": (10, BATCH[0], 1000), "contact": (2, BATCH[1], 2 * BATCH[1]),
        "memory": (100, 1000), "reference": 6000, "contact_run": 1000}
QUICK = {"config": "smoke.toml", "paper": (3, 50, 100), "contact": (1, 6, 4), "memory": (100, 1000),
         "reference": 1500, "contact_run": 8}


def _per_realization(scene, model, counts):
    """Median seconds per realisation one at a time, and seconds per realisation of one batch."""
    n_loop, n_batch, _ = counts
    simulate_batch(scene, model, realizations=[0])            # warm-up: imports, caches
    loop = []
    for r in range(n_loop):
        start = time.perf_counter()
        simulate_batch(scene, model, realizations=[r])
        loop.append(time.perf_counter() - start)
    start = time.perf_counter()
    simulate_batch(scene, model, realizations=range(n_batch))
    return statistics.median(loop), (time.perf_counter() - start) / n_batch


def _missed_targets(out) -> list[str]:
    """Issue 20's targets that this run misses, each with its unrounded value (a printed 1.80x can
    be 1.798x)."""
    (_, contact_wall), = out["contact_run_wall_s"].items()
    paper_wall = out["run_wall_s"][max(out["run_wall_s"], key=int)]
    checks = [("contact 1000 wall", contact_wall, 120.0, " s", False),
              ("paper 1000 wall", paper_wall, 10.0, " s", False)]
    checks += [(f"{m} batched / one at a time", x, 10.0, "x", True) for m, x in out["batched_speedup"].items()]
    checks += [(f"{m} 2 workers / 1", 2 * x, 1.8, "x", True) for m, x in out["parallel_efficiency"].items()]
    return [f"{name} {value:.4g}{unit} {'<' if at_least else '>'} {limit:g}{unit}"
            for name, value, limit, unit, at_least in checks
            if (value < limit if at_least else value > limit)]


def _profile(scene, model, n, top=8):
    prof = cProfile.Profile()
    prof.runcall(simulate_batch, scene, model, realizations=range(n))
    out = io.StringIO()
    pstats.Stats(prof, stream=out).sort_stats("tottime").print_stats(top)
    lines = [ln for ln in out.getvalue().splitlines() if ln.strip()]
    start = next(i for i, ln in enumerate(lines) if ln.lstrip().startswith("ncalls"))
    return lines[start:start + top + 1]


def _throughput(scene, config, model, n, workers, tmp):
    """Realisations per second of run_ensemble on a local cluster of ``workers`` workers, in the
    chunks ``rss6 run -n N --model MODEL`` makes for two workers (the same batches for 1 and 2), and the
    seconds its tasks computed (dask's task stream): how busy the pipeline kept the workers."""
    from dask.distributed import Client, get_task_stream

    from pipeline.ensemble.cluster import local_cluster
    from pipeline.ensemble.run import EnsembleSpec, run_ensemble
    spec = EnsembleSpec(scene.source_text, str(config), model, default_integrator(scene, model),
                        default_time_step(scene, model), scene.simulation.elements_per_link, 0)
    with local_cluster(workers) as cluster, Client(cluster) as client:
        client.run(lambda: __import__("pipeline.ensemble.run"))     # imports off the clock (solver, xarray)
        fresh = Path(tempfile.mkdtemp(dir=tmp)) / f"{model}-{workers}.nc"   # nothing stored to resume
        with get_task_stream(client) as stream:
            start = time.perf_counter()
            run_ensemble(spec, n, fresh, scheduler=cluster.scheduler_address,
                         chunk=default_chunk(n, 2, model), progress=False)
            elapsed = time.perf_counter() - start
        tasks = [(task["worker"], s["start"], s["stop"] - s["start"]) for task in stream.data
                 for s in task["startstops"] if s["action"] == "compute"]
        task_s = sum(t[2] for t in tasks)
        return n / elapsed, task_s, task_s / (workers * elapsed), _first_task_extra(tasks)


def _first_task_extra(tasks: list) -> float:
    """Seconds each worker's first task took beyond the median of its others (the level's
    preparation and anything else done once per worker), the median over the workers."""
    extra = []
    for worker in {t[0] for t in tasks}:
        own = [t[2] for t in sorted(t for t in tasks if t[0] == worker)]
        if len(own) > 1:
            extra.append(own[0] - statistics.median(own[1:]))
    return statistics.median(extra) if extra else float("nan")


# a fixed single-threaded compute load (products of 256 x 256 matrices, 0.6 ms each here); prints
# its own seconds, start-up excluded
_REFERENCE = ("import sys, time\nimport numpy as np\na = np.random.default_rng(0).random((256, 256))\n"
              "a @ a\nstart = time.perf_counter()\nfor _ in range(int(sys.argv[1])):\n    a @ a\n"
              "print(time.perf_counter() - start)")


def _machine_ratio(products: int) -> float:
    """Throughput of two single-threaded BLAS processes at once over that of one alone: what the
    machine gives compute-bound work on two cores at the time: a reference for the 2 / 1 worker ratio,
    which it bounds but for the machine's drift between the measurements."""
    def run(k):
        procs = [subprocess.Popen([sys.executable, "-c", _REFERENCE, str(products)], stdout=subprocess.PIPE,
                                  text=True)
                 for _ in range(k)]
        return max(float(p.communicate()[0]) for p in procs)   # two are done when the slower is
    alone = run(1)
    return 2.0 * alone / run(2)


def _pairs(scene, config, model, n, repeat, products, tmp) -> list[dict]:
    """``repeat`` throughput runs with 1 and 2 workers, alternating and in turn first so that a
    drifting load hits both, each pair followed by the machine's own ratio (:func:`_machine_ratio`)."""
    runs = []
    for i in range(repeat):
        pair = {str(w): _throughput(scene, config, model, n, w, tmp) for w in ((1, 2), (2, 1))[i % 2]}
        runs.append({"1": pair["1"][0], "2": pair["2"][0], "machine": _machine_ratio(products),
                     "task_s": {w: m[1] for w, m in pair.items()},
                     "busy": {w: m[2] for w, m in pair.items()},
                     "first_task_extra_s": {w: m[3] for w, m in pair.items()}})
    return runs


def _tree_rss(pid: int) -> int:
    """Resident bytes of a process and all its descendants (Linux /proc)."""
    children = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
        except (OSError, IndexError, ValueError):
            continue
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        todo.extend(children.get(p, []))
        try:
            for line in Path(f"/proc/{p}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1]) * 1024
        except OSError:
            continue
    return total


def _peak_rss(config, n, tmp, model="paper"):
    """Peak resident MiB and wall seconds of ``rss6 run CONFIG -n N --model MODEL --store summary``
    on 2 workers."""
    cmd = [sys.executable, "-m", "pipeline.cli", "run", str(config), "-n", str(n), "--model", model,
           "--store", "summary", "--workers", "2", "-o", str(Path(tmp) / f"{model}-{n}.nc")]
    peak, start = 0, time.perf_counter()
    # cwd: ``-m`` puts the working directory first on sys.path, before PYTHONPATH: run from a checkout's
    # root, a baseline's run would import this checkout's pipeline
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=tmp)
    stop = threading.Event()

    def sample():
        nonlocal peak
        while not stop.is_set():
            peak = max(peak, _tree_rss(proc.pid))
            stop.wait(0.05)

    sampler = threading.Thread(target=sample)
    sampler.start()
    _, err = proc.communicate()
    stop.set()
    sampler.join()
    if proc.returncode:
        raise RuntimeError(f"{' '.join(cmd)} failed: {err.strip()}")
    return peak / 2 ** 20, time.perf_counter() - start


def measure(quick: bool, profile: bool, repeat: int = 1, models=("paper", "contact")) -> dict:
    plan = QUICK if quick else FULL
    config = CONFIGS / plan["config"]
    scene = load_scene(config)
    out = {"config": f"configs/{plan['config']}", "per_realization_s": {}, "batched_speedup": {},
           "realizations_per_s": {}, "parallel_efficiency": {}, "peak_rss_MiB": {}, "run_wall_s": {},
           "runs": {}, "machine_ratio": {}, "workers_busy": {}, "task_time_ratio": {},
           "first_task_extra_s": {}, "profile": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for model in models:
            loop, batched = _per_realization(scene, model, plan[model])
            out["per_realization_s"][model] = {"loop": loop, "batched": batched}
            out["batched_speedup"][model] = loop / batched
            rates = _pairs(scene, config, model, plan[model][2], repeat, plan["reference"], tmp)
            rate = {w: statistics.median(r[w] for r in rates) for w in ("1", "2")}
            out["realizations_per_s"][model] = rate
            out["runs"][model] = rates            # each repeat's pair, to show the machine's spread
            out["parallel_efficiency"][model] = rate["2"] / (2 * rate["1"])
            out["machine_ratio"][model] = statistics.median(r["machine"] for r in rates)
            out["workers_busy"][model] = {w: statistics.median(r["busy"][w] for r in rates)
                                          for w in ("1", "2")}
            out["task_time_ratio"][model] = statistics.median(r["task_s"]["2"] / r["task_s"]["1"]
                                                              for r in rates)
            out["first_task_extra_s"][model] = {w: statistics.median(r["first_task_extra_s"][w] for r in rates)
                                                for w in ("1", "2")}
            if profile:
                out["profile"][model] = _profile(scene, model, plan[model][1])
        for n in plan["memory"] if "paper" in models else ():
            peak, wall = _peak_rss(config, n, tmp)
            out["peak_rss_MiB"][str(n)] = peak
            out["run_wall_s"][str(n)] = wall
        if "contact" in models:
            out["contact_run_wall_s"] = {str(plan["contact_run"]): _peak_rss(config, plan["contact_run"], tmp,
                                                                             "contact")[1]}
    if "paper" in models:
        lo, hi = (str(n) for n in plan["memory"])
        out["memory_growth"] = out["peak_rss_MiB"][hi] / out["peak_rss_MiB"][lo] - 1.0
    out["projected_1000_s_2_workers"] = {m: 1000 / r["2"] for m, r in out["realizations_per_s"].items()}
    out["machine"] = f"{os.cpu_count()} cores, {sys.platform}, numpy {np.__version__}"
    if not profile:
        del out["profile"]
    return out


def _print(out: dict) -> None:
    """One checkout's figures, as the benchmark has always printed them."""
    print(f"{out['config']} ({out['machine']})")
    print(f"{'model':8s} {'loop s/real':>12s} {'batched s/real':>15s} {'speedup':>8s} "
          f"{'1 worker real/s':>16s} {'2 workers real/s':>17s} {'efficiency':>10s} {'1000 with 2 (s)':>16s}")
    for m in out["per_realization_s"]:
        p, r = out["per_realization_s"][m], out["realizations_per_s"][m]
        print(f"{m:8s} {p['loop']:12.4f} {p['batched']:15.4f} {out['batched_speedup'][m]:8.1f} "
              f"{r['1']:16.3f} {r['2']:17.3f} {out['parallel_efficiency'][m]:10.2f} "
              f"{out['projected_1000_s_2_workers'][m]:16.1f}")
        print(f"{'':8s} each repeat's 2 / 1 worker ratio: "
              + ", ".join(f"{r['2'] / r['1']:.2f}" for r in out["runs"][m])
              + "; two BLAS processes / one, right after each: "
              + ", ".join(f"{r['machine']:.2f}" for r in out["runs"][m]))
        busy = out["workers_busy"][m]
        print(f"{'':8s} workers busy (task seconds / workers x wall): {busy['1']:.3f} with 1, "
              f"{busy['2']:.3f} with 2; the same tasks took {out['task_time_ratio'][m]:.2f}x as long with 2")
        first = out["first_task_extra_s"][m]
        print(f"{'':8s} a worker's first task took {first['1']:.2f} s (1 worker), {first['2']:.2f} s "
              "(2 workers) longer than its others (the level's preparation, once per worker)")
    if out["peak_rss_MiB"]:
        print("rss6 run --model paper --store summary: " + ", ".join(
            f"N = {n}: peak {out['peak_rss_MiB'][n]:.0f} MiB, {out['run_wall_s'][n]:.1f} s"
            for n in out["peak_rss_MiB"]) + f"; growth {100 * out['memory_growth']:.1f} %")
    if "contact_run_wall_s" not in out or not out["run_wall_s"]:
        return                                   # one level measured: issue 20's line needs both
    (n_contact, contact_wall), = out["contact_run_wall_s"].items()
    hi = max(out["run_wall_s"], key=int)
    print(f"targets (issue 20): contact {n_contact} wall {contact_wall:.1f} s (<= 120 s for 1000); "
          f"paper {hi} wall {out['run_wall_s'][hi]:.1f} s (<= 10 s); batched / one at a time "
          + ", ".join(f"{m} {out['batched_speedup'][m]:.1f}x" for m in out["batched_speedup"])
          + " (>= 10x); 2 workers / 1 " + ", ".join(f"{m} {2 * out['parallel_efficiency'][m]:.2f}x"
                                                    for m in out["parallel_efficiency"]) + " (>= 1.8x)")
    if out["config"].endswith("paper.toml"):     # the targets name the paper scene's full counts
        missed = _missed_targets(out)
        print("targets missed: " + "; ".join(missed) if missed else "every target holds (unrounded)")


def _commit(checkout: Path) -> str:
    """The checkout's commit, with ``+changes`` where its tracked files differ from it."""
    def git(*args):
        proc = subprocess.run(["git", "-C", str(checkout), *args], capture_output=True, text=True)
        return proc.stdout.strip() if proc.returncode == 0 else "?"
    dirty = git("status", "--porcelain", "--untracked-files=no")
    return git("rev-parse", "--short", "HEAD") + ("+changes" if dirty else "")


def _baseline(checkout: Path, argv: list[str]) -> dict:
    """This benchmark's figures for another checkout: this script in a fresh process whose
    ``rss6core`` and ``pipeline`` (and those of its workers and subprocesses) are the checkout's.

    It runs in the checkout's folder: the workers' fork server of an rss6 before 0.3.1 imports
    rss6 from its working folder first (docs/performance.md section 32), so that started in this
    checkout's folder the baseline's workers computed with this checkout's code."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    proc = subprocess.run([sys.executable, __file__, *argv, "--json"], env=env, capture_output=True, text=True,
                          cwd=checkout)
    if proc.returncode != 0:
        raise SystemExit(f"ensemble.py for the baseline {checkout} failed ({proc.returncode}):\n{proc.stderr}")
    return json.loads(proc.stdout)


def _side_by_side(this: dict, base: dict) -> list[tuple]:
    """(figure, this, baseline, baseline / this or this / baseline: the speed-up, > 1 faster) of the
    figures both checkouts measured."""
    rows = []
    for m in this["per_realization_s"]:
        for kind in ("loop", "batched"):
            a, b = this["per_realization_s"][m][kind], base["per_realization_s"][m][kind]
            rows.append((f"{m} {kind} s per realisation", a, b, b / a))
        for w in ("1", "2"):
            a, b = this["realizations_per_s"][m][w], base["realizations_per_s"][m][w]
            rows.append((f"{m} realisations per s, {w} worker{'s' if w == '2' else ''}", a, b, a / b))
    for key, label in (("run_wall_s", "rss6 run paper --store summary, N = {} wall s"),
                       ("contact_run_wall_s", "rss6 run contact --store summary, N = {} wall s")):
        for n, a in this.get(key, {}).items():
            rows.append((label.format(n), a, base[key][n], base[key][n] / a))
    return rows


def _issue42(this: dict, rows: list[tuple]) -> str:
    """Issue 42's steady-cost targets on this run's figures, each with its unrounded value."""
    ratio = {name: r for name, _, _, r in rows}
    checks = []
    if "contact" in this["per_realization_s"]:
        checks.append(("contact steps (batched s per realisation) speed-up",
                       ratio["contact batched s per realisation"], 1.7, "x", True))
    if "paper" in this["per_realization_s"]:
        checks.append(("paper speed-up (2 workers' realisations per s)",
                       ratio["paper realisations per s, 2 workers"], 1.6, "x", True))
    walls = [("contact 1000 wall", this.get("contact_run_wall_s", {}).get("1000"), 45.0),
             ("paper 1000 wall", this.get("run_wall_s", {}).get("1000"), 4.0)]
    checks += [(name, value, limit, " s", False) for name, value, limit in walls if value is not None]
    return "; ".join(f"{name} {value:.4g}{unit} ({'>=' if at_least else '<='} {limit:g}{unit}: "
                     f"{'holds' if (value >= limit if at_least else value <= limit) else 'MISSED'})"
                     for name, value, limit, unit, at_least in checks)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="configs/smoke.toml, small counts (< 1 min)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument("--profile", action="store_true", help="add each batched run's top profile entries")
    parser.add_argument("--repeat", type=int, default=1, metavar="R",
                        help="throughput runs per worker count; their median is reported")
    parser.add_argument("--models", default="paper,contact", help="levels to measure, comma-separated")
    parser.add_argument("--baseline", type=Path, help="another checkout to measure in the same run, after this one")
    args = parser.parse_args(argv)
    models = tuple(m for m in ("paper", "contact") if m in args.models.split(","))
    if args.repeat < 1:
        parser.error("--repeat must be at least 1")
    if not models or set(args.models.split(",")) - {"paper", "contact"}:
        parser.error(f"--models {args.models}: choose paper, contact or both")
    load = os.getloadavg()[0]
    out = measure(args.quick, args.profile, args.repeat, models)
    out["load_before"] = load
    if args.baseline:
        forwarded = [*(["--quick"] if args.quick else []), "--repeat", str(args.repeat), "--models", ",".join(models)]
        base = _baseline(args.baseline.resolve(), forwarded)
        out = {"this": out, "baseline": base, "commits": {"this": _commit(Path(__file__).resolve().parent.parent),
                                                          "baseline": _commit(args.baseline)}}
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    if not args.baseline:
        _print(out)
    else:
        _report_pair(out, args)
    for m, lines in (out if not args.baseline else out["this"]).get("profile", {}).items():
        print(f"\nprofile of one batched {m} run (top entries by own time):")
        print("\n".join(lines))
    return 0


def _report_pair(out: dict, args) -> None:
    """Both checkouts' figures, then side by side with the speed-ups and issue 42's targets."""
    this, base = out["this"], out["baseline"]
    print(f"date {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; load before this "
          f"{this['load_before']:.1f}, before the baseline {base['load_before']:.1f}")
    print(f"--- this: {out['commits']['this']}")
    _print(this)
    print(f"--- baseline: {out['commits']['baseline']} ({args.baseline})")
    _print(base)
    rows = _side_by_side(this, base)
    print(f"\n{'figure':55s} {'this':>10s} {'baseline':>10s} {'speed-up':>9s}")
    for name, a, b, r in rows:
        print(f"{name:55s} {a:10.4g} {b:10.4g} {r:8.2f}x")
    if this["config"].endswith("paper.toml"):
        print("targets (issue 42, steady cost): " + _issue42(this, rows))


if __name__ == "__main__":
    sys.exit(main())
