"""Coverage of the 95 % intervals at the n where ``rss6 run --until`` stops (pipeline.analysis.until).

Run on demand: ``python benchmarks/until_coverage.py [--reps R] [--cap N]`` (default 4000 runs per cell,
cap 2000; about two minutes).  Each run draws N values from a known law, checks rss6's interval of the
statistic at :func:`pipeline.analysis.until.checkpoints`' sample sizes and stops at the first where its
relative half-width (upper - lower) / 2 / |estimate| meets the target (or at the cap), as ``--until``
does; the table gives the share of runs whose interval at the stop covers the true value, the share with
the true value above the upper bound, the share above the one-sided upper bound the requirement gate
decides on (5 % nominal), and the median stopping n.  Both for the rule as it is (the quantiles' bounds at
:data:`pipeline.analysis.until.LEVEL`, 97.5 %) and, as ``plain``, for the quantiles' bounds at the label's
95 %: a fixed-n run's interval covers at least 95 % (tests/test_stats.py), but choosing n by the interval's
own width costs it some of that.
"""
from __future__ import annotations

import argparse

import numpy as np
from scipy import stats as sps

from pipeline.analysis.estimators import (mean_bounds, mean_interval, quantile_bounds, quantile_estimates,
                                          quantile_interval)
from pipeline.analysis.until import LEVEL, checkpoints, parse_target

LAWS = {"gamma(2)": sps.gamma(2.0), "exponential": sps.expon(), "lognormal(0.5)": sps.lognorm(0.5)}
TARGETS = ("displacement:z@q95<=20%", "displacement:z@q95<=10%", "displacement:z@q50<=5%",
           "displacement:z@mean<=30%", "displacement:z@mean<=10%")
P = {"q95": 0.95, "q50": 0.5}


def _interval(x: np.ndarray, statistic: str, level: float):
    """(estimate, lower, upper, one-sided upper) of ``statistic`` ('mean', 'q50' or 'q95') along axis 0;
    a quantile's bounds at ``level``, the mean's at 95 %."""
    if statistic == "mean":
        lower, upper = mean_interval(x, 0.95)
        return x.mean(axis=0), lower, upper, mean_bounds(x, 0.95)[1]
    sx, p = np.sort(x, axis=0), P[statistic]
    lower, upper = quantile_interval(sx, p, level)
    return quantile_estimates(x, p, axis=0), lower, upper, quantile_bounds(sx, p, level)[1]


def stopped_coverage(law, text: str, reps: int, cap: int, seed: int, level: float = LEVEL) -> dict:
    """Coverage, shares above the upper bound and the one-sided one, and median n of ``--until text``
    runs on ``law`` with a quantile's bounds at ``level``."""
    target = parse_target(text)
    truth = law.mean() if target.statistic == "mean" else law.ppf(P[target.statistic])
    x = law.rvs(size=(cap, reps), random_state=np.random.default_rng(seed))
    done, stop = np.zeros(reps, bool), np.full(reps, cap)
    cover, above, above_one = np.zeros(reps, bool), np.zeros(reps, bool), np.zeros(reps, bool)
    for n in checkpoints([target], cap):
        est, lower, upper, one = _interval(x[:n], target.statistic, level)
        met = ((upper - lower) / 2 <= target.relative * np.abs(est)) | (n == cap)
        new = met & ~done
        cover[new] = (lower[new] <= truth) & (truth <= upper[new])
        above[new], above_one[new] = truth > upper[new], truth > one[new]
        stop[new] = n
        done |= met
    return {"coverage": cover.mean(), "above": above.mean(), "above_one": above_one.mean(),
            "median_n": int(np.median(stop))}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=4000)
    parser.add_argument("--cap", type=int, default=2000)
    args = parser.parse_args(argv)
    print(f"{'--until target':26s} {'law':15s} {'rule':6s} {'coverage':>9s} {'above upper':>12s} "
          f"{'above 1-sided':>14s} {'median stop n':>14s}")
    for i, text in enumerate(TARGETS):
        for j, (name, law) in enumerate(LAWS.items()):
            rules = {"rss6": LEVEL} | ({"plain": 0.95} if "@mean" not in text else {})
            for rule, level in rules.items():
                r = stopped_coverage(law, text, args.reps, args.cap, seed=100 * i + j, level=level)
                print(f"{text:26s} {name:15s} {rule:6s} {r['coverage']:9.3f} {r['above']:12.3f} "
                      f"{r['above_one']:14.3f} {r['median_n']:14d}", flush=True)


if __name__ == "__main__":
    main()
