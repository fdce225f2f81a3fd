"""Verification table of subset simulation (pipeline.analysis.subset) on closed-form limit states.

Run on demand: ``python benchmarks/subset_verification.py [--reps R] [-n N]`` (default 200 runs, N = 1000,
a few seconds).
For linear limit states in 20 standard normal dimensions at P = 1e-3 and 1e-4 (P = Phi(-beta)), their
two-sided versions |a . z| > t (two failure regions, P = 2 Phi(-t)) and the outside of a sphere in 5
dimensions at P = 1e-4 (P = chi2_5.sf(c)), R runs with seeds 0..R-1 at
N draws per level, p0 = 0.1: mean relative bias, observed CoV of the estimates, mean reported CoV,
coverage of the 95 % interval (the log-normal one rss6 prints from N = MIN_N_INTERVAL on, computed here
at any N), mean evaluations, and the coverage an interval from the uncorrelated CoV would have had.
tests/test_subset.py asserts the same quantities.
"""
from __future__ import annotations

import argparse
import math

import numpy as np
from scipy import stats as sps

from pipeline.analysis.subset import SubsetSettings, lognormal_interval, subset_simulation


def cases() -> dict:
    """name -> (response, dimension, true P)."""
    b3, b4, c = sps.norm.isf(1e-3), sps.norm.isf(1e-4), sps.chi2.isf(1e-4, 5)
    t3, t4 = sps.norm.isf(0.5e-3), sps.norm.isf(0.5e-4)   # P(|Z| > t) = 2 P(Z > t)
    return {"linear 1e-3 (d = 20)": (lambda z: z.sum(axis=1) / math.sqrt(z.shape[1]) - b3, 20, 1e-3),
            "linear 1e-4 (d = 20)": (lambda z: z.sum(axis=1) / math.sqrt(z.shape[1]) - b4, 20, 1e-4),
            "sphere 1e-4 (d = 5)": (lambda z: (z ** 2).sum(axis=1) - c, 5, 1e-4),
            # two failure regions, |a . z| > b: the chains of one level may find one side only
            "two-sided 1e-3 (d = 20)": (lambda z: np.abs(z.sum(axis=1)) / math.sqrt(z.shape[1]) - t3, 20, 1e-3),
            "two-sided 1e-4 (d = 20)": (lambda z: np.abs(z.sum(axis=1)) / math.sqrt(z.shape[1]) - t4, 20, 1e-4)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--reps", type=int, default=200)
    p.add_argument("-n", type=int, default=1000, help="draws per level N (default 1000)")
    args = p.parse_args()
    reps, n = args.reps, args.n
    print(f"N = {n}, p0 = 0.1, {reps} runs per case (a run without an estimate counts as not covering)")
    print(f"{'case':<24s}{'bias':>8s}{'CoV obs':>9s}{'CoV rep':>9s}{'cover':>7s}{'evals':>7s}"
          "  cover (uncorrelated CoV)")
    for name, (response, d, truth) in cases().items():
        runs = [subset_simulation(response, d, 0.0, SubsetSettings(n, seed=s)) for s in range(reps)]
        pf = np.array([r.pf for r in runs if np.isfinite(r.pf)])
        # the interval rss6 prints from N = MIN_N_INTERVAL on, computed at every N (below it rss6 withholds it)
        cover = np.mean([lo <= truth <= up for lo, up in (lognormal_interval(r.pf, r.cov_upper, 0.95) for r in runs)])
        bare = np.mean([lo <= truth <= up for lo, up in (lognormal_interval(r.pf, r.cov, 0.95) for r in runs)])
        print(f"{name:<24s}{pf.mean() / truth - 1:>+8.3f}{pf.std(ddof=1) / truth:>9.3f}"
              f"{np.mean([r.cov for r in runs]):>9.3f}{cover:>7.3f}"
              f"{np.mean([r.n_evaluations for r in runs]):>7.0f}  {bare:.3f}")


if __name__ == "__main__":
    main()
