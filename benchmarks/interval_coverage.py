"""Coverage of the mean's and the std's two-sided intervals at levels other than 95 % (MEAN_FLOORS, STD_FLOORS).

Run on demand: ``python benchmarks/interval_coverage.py [--trials T]`` (default 20 000 per cell; about two
minutes).  For each level, law and n the table gives the share of T samples of n draws whose interval
(pipeline.analysis.estimators.mean_interval / std_interval, computed as if every n had one) covers the law's
true mean or standard deviation.  These measurements set the floors above 95 %: the mean's n from which
every law reaches the label, and no std interval where none does.
"""
from __future__ import annotations

import argparse
from unittest import mock

import numpy as np
from scipy import stats as sps

import pipeline.analysis.estimators as estimators

LAWS = {"exponential": sps.expon(), "gamma(2)": sps.gamma(2.0), "chi2(1)": sps.chi2(1), "Laplace": sps.laplace(),
        "Student t5": sps.t(5)}
CELLS = (("mean", 0.80, (16,)), ("mean", 0.90, (16, 64)), ("mean", 0.99, (16, 32, 64, 128)),
         ("mean", 0.999, (64, 128, 256)), ("std", 0.80, (300,)), ("std", 0.90, (300, 1000)),
         ("std", 0.99, (300, 1000)), ("mean", 0.95, (8,)))   # the last: below the 95 % floor (docs/ensembles.md)


def coverage(statistic: str, level: float, n: int, law, trials: int, rng: np.random.Generator) -> float:
    """Share of ``trials`` samples of ``n`` draws whose interval at ``level`` holds the law's true value
    (drawn 20 000 samples at a time)."""
    truth, hits = law.mean() if statistic == "mean" else law.std(), 0
    for size in np.diff(np.r_[0:trials:20000, trials]):
        x = law.rvs(size=(n, size), random_state=rng)
        with mock.patch.object(estimators, "moment_floor", lambda s, c: 1):   # every n gets its interval here
            lower, upper = (estimators.mean_interval if statistic == "mean" else estimators.std_interval)(x, level)
        hits += int(np.count_nonzero((lower <= truth) & (truth <= upper)))
    return hits / trials


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20000)
    parser.add_argument("--level", type=float, help="only the cells at this level (default: all)")
    args = parser.parse_args()
    rng = np.random.default_rng(2026)
    print(f"{'statistic':9} {'level':>6} {'n':>5}  " + "  ".join(f"{name:>11}" for name in LAWS)
          + "   standard error at the label")
    for statistic, level, sizes in CELLS:
        if args.level is not None and abs(level - args.level) > 1e-12:
            continue
        for n in sizes:
            shares = [coverage(statistic, level, n, law, args.trials, rng) for law in LAWS.values()]
            print(f"{statistic:9} {level:6g} {n:5d}  " + "  ".join(f"{share:11.4f}" for share in shares)
                  + f"   {np.sqrt(level * (1 - level) / args.trials):.1e}", flush=True)


if __name__ == "__main__":
    main()
