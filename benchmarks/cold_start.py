"""Benchmark: the first contact run on a fresh machine (an empty numba cache), this checkout against another.

Run on demand: ``python benchmarks/cold_start.py [--baseline DIR] [-n 16] [--workers 2] [--json]``.
For this checkout, and for ``--baseline DIR`` (another checkout, e.g. a ``git worktree`` of main at the
commit before a change) in the same run, one after the other: a fresh temporary ``NUMBA_CACHE_DIR``
(nothing compiled), then ``rss6 run paper -n N --model contact`` in a fresh process (``python -m
pipeline.cli`` with ``PYTHONPATH`` at the checkout, so each checkout imports its own ``rss6core`` and
``pipeline``), timed wall; then the same command again on the cache it filled (warm). The compile share is
(cold - warm) / cold: what the empty cache added, as a fraction of the cold run. Prints the command
line, the date, the machine's load, each checkout's commit, both runs' times, the ratio of the cold
runs (this / baseline), and whether the two checkouts' cold files hold the same data
(``compare_outputs.compare_netcdf``: every data variable at relative difference 0).
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
CHECKOUT = HERE.parent


def _git(checkout: Path, *args) -> str:
    proc = subprocess.run(["git", "-C", str(checkout), *args], capture_output=True, text=True)
    return proc.stdout.strip() if proc.returncode == 0 else "?"


def _commit(checkout: Path) -> str:
    """The checkout's commit, with ``+changes`` where its tracked files differ from it."""
    dirty = _git(checkout, "status", "--porcelain", "--untracked-files=no")
    return _git(checkout, "rev-parse", "--short", "HEAD") + ("+changes" if dirty else "")


def _run(checkout: Path, cache: Path, args: list[str], out: Path) -> dict:
    """One ``rss6 run`` of ``checkout`` in a fresh process on numba cache ``cache``: wall s, load, notes."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(checkout))
    env.pop("NUMBA_DISABLE_JIT", None)
    load = os.getloadavg()[0]
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pipeline.cli", "run", *args, "-o", str(out)], env=env,
                          cwd=out.parent, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"cold_start: rss6 run of {checkout} failed ({proc.returncode}):\n{proc.stderr}")
    return {"wall_s": wall, "load_before": load, "compile_note": "compiling" in proc.stderr}


def measure(checkout: Path, args: list[str], folder: Path) -> dict:
    """Cold run (empty cache), then warm run (the cache it filled) of ``checkout``; the compile share."""
    imported = subprocess.run([sys.executable, "-c", "import rss6core, pipeline; print(rss6core.__file__)"],
                              env=dict(os.environ, PYTHONPATH=str(checkout)), cwd=folder, capture_output=True,
                              text=True)   # in the run's folder, as the runs: the current folder comes first
    cache = folder / "numba_cache"
    cache.mkdir()
    cold = _run(checkout, cache, args, folder / "cold.nc")
    warm = _run(checkout, cache, args, folder / "warm.nc")
    return {"checkout": str(checkout), "commit": _commit(checkout), "imports": imported.stdout.strip(),
            "cold": cold, "warm": warm, "compile_share": (cold["wall_s"] - warm["wall_s"]) / cold["wall_s"],
            "file": str(folder / "cold.nc")}


def same_data(a: str, b: str) -> list[str]:
    """compare_outputs' differences of two ensemble files (empty: the same data and attributes)."""
    sys.path.insert(0, str(HERE))
    from compare_outputs import compare_netcdf
    return compare_netcdf(Path(a), Path(b))


def _line(name: str, m: dict) -> str:
    code = Path(m["imports"]).parent.parent   # the checkout the runs imported rss6core from
    return (f"{name:9s} {m['commit']} ({code}): "
            f"cold {m['cold']['wall_s']:6.1f} s (load {m['cold']['load_before']:.1f}), "
            f"warm {m['warm']['wall_s']:5.1f} s (load {m['warm']['load_before']:.1f}), compile share "
            f"{100 * m['compile_share']:.0f} %")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", type=Path, help="another checkout to measure in the same run")
    parser.add_argument("-n", type=int, default=16, help="realisations (default 16)")
    parser.add_argument("--workers", type=int, default=2, help="local workers (default 2)")
    parser.add_argument("--config", default="paper", help="scene (default paper)")
    parser.add_argument("--baseline-first", action="store_true", help="measure the baseline first")
    parser.add_argument("--json", action="store_true", help="print the measurements as JSON too")
    opts = parser.parse_args(argv)
    args = [opts.config, "-n", str(opts.n), "--model", "contact", "--workers", str(opts.workers)]
    print(f"$ python {' '.join(sys.argv)}")
    print(f"date {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}; each: rss6 run {' '.join(args)} -o F.nc, fresh NUMBA_CACHE_DIR")
    result = {}
    with tempfile.TemporaryDirectory(prefix="cold_start_") as tmp:
        checkouts = {"this": CHECKOUT} | ({"baseline": opts.baseline.resolve()} if opts.baseline else {})
        for name in sorted(checkouts, key=lambda k: (k != "baseline") == opts.baseline_first):
            checkout = checkouts[name]
            folder = Path(tmp) / name
            folder.mkdir()
            result[name] = measure(checkout, args, folder)
            print(_line(name, result[name]), flush=True)
        if opts.baseline:
            ratio = result["this"]["cold"]["wall_s"] / result["baseline"]["cold"]["wall_s"]
            diffs = same_data(result["this"]["file"], result["baseline"]["file"])
            result |= {"cold_ratio": ratio, "file_differences": diffs}
            print(f"cold this / baseline: {ratio:.2f}x; the cold runs' files: "
                  + ("the same data and attributes" if not diffs else "; ".join(diffs)))
    if opts.json:
        print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
