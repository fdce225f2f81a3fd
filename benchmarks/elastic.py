"""Benchmark: one `elastic` run of configs/paper.toml (2 s at 1 ms), and its mesh study.

Run on demand: ``python benchmarks/elastic.py [--repeat N] [--json]``.  Prints the
median wall time of N runs pinned to one BLAS thread, the ratio to the 1 s target,
and, for 1, 2, 4, 8 elements per link, the time, the platform error peaks and the 12 lowest
natural frequencies at t = 0, each with its largest relative change against 8 elements (the mesh
convergence that sets the default; docs/guide.md "Mesh convergence").
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[var] = "1"  # before numpy is imported: one core

import numpy as np  # noqa: E402

from rss6core import load_scene  # noqa: E402
from rss6core.models import natural_frequencies, simulate  # noqa: E402

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "paper.toml"


def _timed(scene, elements):
    start = time.perf_counter()
    result = simulate(scene, "elastic", elements=elements)
    return time.perf_counter() - start, result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    scene = load_scene(CONFIG)
    _timed(scene, 4)  # warm-up: imports, caches
    times = [_timed(scene, 4)[0] for _ in range(args.repeat)]
    mesh = {}
    for n in (1, 2, 4, 8):
        wall = statistics.median(_timed(scene, n)[0] for _ in range(3))
        mesh[n] = (wall, np.abs(_timed(scene, n)[1].displacement).max(0), natural_frequencies(scene, n)[:12])
    ref, ref_f = mesh[8][1], mesh[8][2]
    out = {
        "elastic_paper_median_s": statistics.median(times),
        "elastic_paper_min_s": min(times),
        "ratio_to_1s_target": statistics.median(times) / 1.0,
        "repeats": args.repeat,
        "mesh": {str(n): {"median_s": w, "max_abs_displacement": dict(zip(
            ("x_m", "y_m", "z_m", "rx_rad", "ry_rad", "rz_rad"), p.tolist())),
            "max_rel_change_vs_8": float(np.abs(p / ref - 1).max()),
            "lowest_12_hz": (f / (2 * np.pi)).tolist(),
            "frequency_max_rel_change_vs_8": float(np.abs(f / ref_f - 1).max())} for n, (w, p, f) in mesh.items()},
        "machine": f"{os.cpu_count()} cores, {sys.platform}, numpy {np.__version__}",
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"elastic, configs/paper.toml, 2001 steps: median {out['elastic_paper_median_s']:.3f} s "
          f"over {args.repeat} runs (min {out['elastic_paper_min_s']:.3f} s); "
          f"{out['ratio_to_1s_target']:.2f} x the 1 s target")
    print(f"{'elements':>8s} {'median s':>9s} {'max|x| mm':>10s} {'max|y| mm':>10s} "
          f"{'max|z| mm':>10s} {'change vs 8':>12s} {'lowest Hz':>10s} {'12 lowest f, change vs 8':>25s}")
    for n, row in out["mesh"].items():
        p = row["max_abs_displacement"]
        print(f"{n:>8s} {row['median_s']:9.3f} {p['x_m'] * 1e3:10.6f} {p['y_m'] * 1e3:10.6f} "
              f"{p['z_m'] * 1e3:10.6f} {row['max_rel_change_vs_8']:12.2e} {row['lowest_12_hz'][0]:10.2f} "
              f"{100 * row['frequency_max_rel_change_vs_8']:23.3f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
