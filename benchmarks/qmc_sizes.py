"""Does ``--sampler qmc`` pay on the paper scene? The sample size each sampler needs for an interval half-width.

Run on demand: ``python benchmarks/qmc_sizes.py [-n N] [--seeds S ...] [--workers W]`` (default N = 4096,
seeds 0-3, 2 workers; about 5 minutes).  For each seed and sampler (mc, and qmc with 8 replicates) it runs
``rss6 run configs/paper.toml --model quasi-static -n N`` and takes each statistic's 95 % interval of the
per-realisation displacement maxima (``rss6 stats``' intervals); the relative half-width h(N) of the worst
direction gives the n that reaches a target half-width t as N (h / t)^2 (both samplers' widths fall as
1/sqrt(n) at fixed replicates).  The table gives the median of that n over the seeds, per sampler, for
the targets docs/ensembles.md quotes.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from pipeline.analysis.stats import ensemble_stats
from pipeline.files.opening import open_ensemble

SCENE = Path(__file__).resolve().parents[1] / "configs" / "paper.toml"
TARGETS = {"mean": 0.02, "q50": 0.03, "q95": 0.03}   # relative half-widths


def worst_half_width(path: Path, statistic: str) -> float:
    """The largest relative half-width over the six directions of the displacement maxima's ``statistic``."""
    sds = ensemble_stats(open_ensemble(path))["max_abs_error"].sel(quantity="displacement", statistic=statistic)
    est, lo, hi = (sds.sel(bound=b).values for b in ("estimate", "lower", "upper"))
    return float(np.max((hi - lo) / 2 / np.abs(est)))


def run(folder: Path, n: int, seed: int, sampler: str, workers: int) -> Path:
    """One ensemble file of the paper scene's quasi-static level."""
    out = folder / f"{sampler}-{seed}.nc"
    subprocess.run([sys.executable, "-m", "pipeline.cli", "run", str(SCENE), "--model", "quasi-static", "-n", str(n),
                    "--seed", str(seed), "--sampler", sampler, "--workers", str(workers), "--store", "summary",
                    "-o", str(out)], check=True, capture_output=True)
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=4096)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    needed = {(s, k): [] for s in ("mc", "qmc") for k in TARGETS}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            for sampler in ("mc", "qmc"):
                path = run(Path(tmp), args.n, seed, sampler, args.workers)
                for statistic, target in TARGETS.items():
                    h = worst_half_width(path, statistic)
                    needed[sampler, statistic].append(args.n * (h / target) ** 2)
                    print(f"seed {seed} {sampler:3s} {statistic}: half-width {100 * h:.2f} % at n = {args.n}",
                          flush=True)
    print(f"median n to reach the half-width in the worst direction ({len(args.seeds)} seeds, n = {args.n} each):")
    for statistic, target in TARGETS.items():
        mc, qmc = (float(np.median(needed[s, statistic])) for s in ("mc", "qmc"))   # nan: no interval at this n
        print(f"  {statistic} +-{100 * target:g} %: mc {mc:.0f}, qmc {qmc:.0f} (qmc / mc {qmc / mc:.2f})")


if __name__ == "__main__":
    main()
