"""Bias and coverage of ``rss6 reliability --method mc --cov C``: the estimate where the CoV rule stops.

Run on demand: ``python benchmarks/cov_stopping.py [--trials T]`` (default 20 000 runs per cell; seconds).
Each run adds blocks of MC_BLOCK Bernoulli(p) draws, as pipeline.studies.reliability does, and stops after the
first block at which sqrt((1 - P) / (n P)) <= C, or at the default budget; the table gives the mean of the
stopped estimate over p (1 = unbiased), the share of runs that met the target, and the share whose two-sided
95 % Clopper-Pearson interval at the stop covers p.
"""
from __future__ import annotations

import argparse

import numpy as np

from pipeline.analysis.estimators import clopper_pearson
from pipeline.studies.reliability import DEFAULT_BUDGET, MC_BLOCK, _mc_cov

BUDGET = DEFAULT_BUDGET["mc"]


def stopped_runs(p: float, cov: float, trials: int, rng: np.random.Generator):
    """(k, n, met) at the stop of each of ``trials`` runs."""
    blocks = BUDGET // MC_BLOCK
    k = np.cumsum(rng.binomial(MC_BLOCK, p, size=(trials, blocks)), axis=1)
    n = MC_BLOCK * np.arange(1, blocks + 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        met = np.vectorize(_mc_cov)(k, n) <= cov
    stop = np.where(met.any(axis=1), met.argmax(axis=1), blocks - 1)
    rows = np.arange(trials)
    return k[rows, stop], n[stop], met[rows, stop]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20000)
    args = parser.parse_args()
    rng = np.random.default_rng(2026)
    print(f"{'p':>8} {'C':>5}  {'mean P / p':>10} {'target met':>10} {'CP 95 % covers':>14} {'median n':>9}")
    for p in (1e-2, 1e-3, 1e-4):
        for cov in (0.1, 0.3, 0.5):
            k, n, met = stopped_runs(p, cov, args.trials, rng)
            lower, upper = clopper_pearson(k, n, 0.95)
            print(f"{p:8g} {cov:5g}  {np.mean(k / n) / p:10.3f} {met.mean():10.3f} "
                  f"{np.mean((lower <= p) & (p <= upper)):14.3f} {np.median(n):9.0f}", flush=True)


if __name__ == "__main__":
    main()
