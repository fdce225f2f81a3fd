"""The measurements behind the mean's and the std's floors and the gate's mean bound at 95 % (docs/ensembles.md).

Run on demand: ``python benchmarks/floor_coverage.py [--trials T]`` (default 20 000 samples per cell; under a
minute).  It prints, per law:

- ``mean n=8 upper``: the share of samples of 8 whose one-sided 95 % upper bound of the mean (the gate's,
  pipeline.analysis.estimators.mean_bounds, computed as if n = 8 had one) lies below the true mean, i.e. a
  design exactly at a '<=' limit passed (5 % nominal), on the skewed laws;
- ``std own level``: the coverage of Bonett's interval at its own 95 % level (without the widening to 97 %,
  STD_WIDENING) at n = 200, 300, 400, on gamma(2) and the exponential law;
- ``mean n=20 upper``: at lognormal(0.5), n = 20, the share whose plain one-sided upper bound (the union
  interval at two-sided level 90 %) lies below the true mean, and the same with the gate's rule (the
  two-sided 95 % bound on the side the sample skewness points to).
"""
from __future__ import annotations

import argparse
from unittest import mock

import numpy as np
from scipy import stats as sps

import pipeline.analysis.estimators as estimators

SKEWED = {"exponential": sps.expon(), "gamma(2)": sps.gamma(2.0), "chi2(1)": sps.chi2(1)}
BONETT = {"gamma(2)": sps.gamma(2.0), "exponential": sps.expon()}
CONF = 0.95


def samples(law, n: int, trials: int, rng: np.random.Generator) -> np.ndarray:
    return law.rvs(size=(n, trials), random_state=rng)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20000)
    args = parser.parse_args()
    rng = np.random.default_rng(2026)
    with mock.patch.object(estimators, "moment_floor", lambda s, c: 1):     # every n gets its bounds here
        for name, law in SKEWED.items():
            upper = estimators.mean_bounds(samples(law, 8, args.trials, rng), CONF)[1]
            print(f"mean n=8 upper     {name:12} passed at the limit {np.mean(upper < law.mean()):.4f}")
        with mock.patch.object(estimators, "STD_WIDENING", 1.0):           # Bonett's at its own level
            for name, law in BONETT.items():
                for n in (200, 300, 400):
                    lower, upper = estimators.std_interval(samples(law, n, args.trials, rng), CONF)
                    covers = np.mean((lower <= law.std()) & (law.std() <= upper))
                    print(f"std own level      {name:12} n={n}  covers {covers:.4f}")
        law = sps.lognorm(0.5)
        x = samples(law, 20, args.trials, rng)
        plain = estimators.mean_interval(x, 2 * CONF - 1)[1]
        rule = estimators.mean_bounds(x, CONF)[1]
        print(f"mean n=20 upper    lognormal(0.5) missed: plain one-sided {np.mean(plain < law.mean()):.4f}, "
              f"gate's rule {np.mean(rule < law.mean()):.4f}")
    print(f"standard error at 5 %: {np.sqrt(0.05 * 0.95 / args.trials):.1e}")


if __name__ == "__main__":
    main()
