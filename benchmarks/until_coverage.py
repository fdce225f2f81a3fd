"""Coverage of the 95 % intervals at the n where ``rss6 run --until`` stops (pipeline.analysis.until).

Run on demand: ``python benchmarks/until_coverage.py [--reps R] [--cap N]`` (default 4000 runs per cell,
cap 2000; about a minute).  Each run draws N values from a known law, checks rss6's interval of the
statistic at :func:`pipeline.analysis.until.checkpoints`' sample sizes and stops at the first where its
relative half-width (upper - lower) / 2 / |estimate| meets the target (or at the cap), as ``--until``
does; the table gives the share of runs whose interval at the stop covers the true value, the share with
the true value above the upper bound, and the median stopping n.  A fixed-n run's interval covers at
least 95 % (tests/test_stats.py); choosing n by the interval's own width costs some of that.
"""
from __future__ import annotations

import argparse

import numpy as np
from scipy import stats as sps

from pipeline.analysis.estimators import mean_interval, quantile_estimates, quantile_interval
from pipeline.analysis.until import checkpoints, parse_target

LAWS = {"gamma(2)": sps.gamma(2.0), "exponential": sps.expon(), "lognormal(0.5)": sps.lognorm(0.5)}
TARGETS = ("displacement:z@q95<=20%", "displacement:z@q95<=10%", "displacement:z@mean<=30%",
           "displacement:z@mean<=10%")


def _interval(x: np.ndarray, statistic: str):
    """(estimate, lower, upper) of ``statistic`` ('mean' or 'q95') along axis 0."""
    if statistic == "mean":
        lower, upper = mean_interval(x, 0.95)
        return x.mean(axis=0), lower, upper
    lower, upper = quantile_interval(np.sort(x, axis=0), 0.95, 0.95)
    return quantile_estimates(x, 0.95, axis=0), lower, upper


def stopped_coverage(law, text: str, reps: int, cap: int, seed: int) -> dict:
    """Coverage, share above the upper bound and median n of ``--until text`` runs on ``law``."""
    target = parse_target(text)
    truth = law.mean() if target.statistic == "mean" else law.ppf(0.95)
    x = law.rvs(size=(cap, reps), random_state=np.random.default_rng(seed))
    done, cover, above, stop = np.zeros(reps, bool), np.zeros(reps, bool), np.zeros(reps, bool), np.full(reps, cap)
    for n in checkpoints([target], cap):
        est, lower, upper = _interval(x[:n], target.statistic)
        met = ((upper - lower) / 2 <= target.relative * np.abs(est)) | (n == cap)
        new = met & ~done
        cover[new] = (lower[new] <= truth) & (truth <= upper[new])
        above[new] = truth > upper[new]
        stop[new] = n
        done |= met
    return {"coverage": cover.mean(), "above": above.mean(), "median_n": int(np.median(stop))}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=4000)
    parser.add_argument("--cap", type=int, default=2000)
    args = parser.parse_args(argv)
    print(f"{'--until target':28s} {'law':15s} {'coverage':>9s} {'above upper':>12s} {'median stop n':>14s}")
    for i, text in enumerate(TARGETS):
        for j, (name, law) in enumerate(LAWS.items()):
            r = stopped_coverage(law, text, args.reps, args.cap, seed=100 * i + j)
            print(f"{text:28s} {name:15s} {r['coverage']:9.3f} {r['above']:12.3f} {r['median_n']:14d}", flush=True)


if __name__ == "__main__":
    main()
