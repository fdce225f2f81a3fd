"""Benchmark: the wall time of whole `rss6 run` commands, this checkout's alone or against another, interleaved.

``python benchmarks/run_walls.py [--baseline DIR] [--rounds 3]`` runs, in each round, the baseline's
(if one is given) then this checkout's ``rss6 run`` of the README's main job (``paper -n 32 --model quasi-static``)
and of the paper level at N = 100 and 1000 (``--store summary``, two local workers), each in a fresh
process (this interpreter's ``rss6`` console script with ``PYTHONPATH`` at the checkout, so each
imports its own ``rss6core`` and ``pipeline``) writing a fresh file, and prints every wall time,
the medians and, with a baseline, their ratio (this / baseline). The whole run's fixed part (imports, cluster start,
level preparation, statistics) is in these figures, which is what docs/performance.md section 31
changes; the load average is printed beside each round.
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHECKOUT = Path(__file__).resolve().parent.parent
JOBS = {"main job (quasi-static, N = 32)": ["paper", "-n", "32", "--model", "quasi-static"],
        "paper level, N = 100": ["paper", "-n", "100", "--model", "paper"],
        "paper level, N = 1000": ["paper", "-n", "1000", "--model", "paper"]}


def _wall(checkout: Path, args: list[str], folder: Path) -> float:
    """Seconds of one ``rss6 run ARGS --store summary -o F`` with ``checkout``'s code, F fresh."""
    out = folder / "walls.nc"
    shutil.rmtree(folder / "walls.nc.parts", ignore_errors=True)
    out.unlink(missing_ok=True)
    rss6 = Path(sys.executable).with_name("rss6")
    env = dict(os.environ, PYTHONPATH=str(checkout))
    start = time.perf_counter()
    subprocess.run([str(rss6), "run", *args, "--store", "summary", "-o", str(out)], env=env, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=folder)
    return time.perf_counter() - start


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", type=Path, help="another checkout (e.g. a git worktree); "
                                                         "default: time this checkout alone")
    parser.add_argument("--rounds", type=int, default=3, help="rounds (default 3)")
    args = parser.parse_args(argv)
    checkouts = ([("baseline", args.baseline.resolve())] if args.baseline else []) + [("this", CHECKOUT)]
    walls = {(who, job): [] for who, _ in checkouts for job in JOBS}
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.rounds):
            print(f"round {k + 1}: load {os.getloadavg()[0]:.2f}", flush=True)
            for who, checkout in checkouts:
                for job, job_args in JOBS.items():
                    walls[who, job].append(_wall(checkout, job_args, Path(tmp)))
                    print(f"  {who:8s} {job:34s} {walls[who, job][-1]:6.2f} s", flush=True)
    _print_medians(walls, bool(args.baseline))
    return 0


def _print_medians(walls: dict, baseline: bool) -> None:
    """Each command's median wall time, and with a baseline the ratio this / baseline."""
    print(f"{'command':34s} " + (f"{'baseline median':>16s} " if baseline else "") + f"{'this median':>12s}"
          + (f" {'this / baseline':>16s}" if baseline else ""))
    for job in JOBS:
        this = statistics.median(walls["this", job])
        if baseline:
            base = statistics.median(walls["baseline", job])
            print(f"{job:34s} {base:14.2f} s {this:10.2f} s {this / base:15.2f}x")
        else:
            print(f"{job:34s} {this:10.2f} s")


if __name__ == "__main__":
    sys.exit(main())
