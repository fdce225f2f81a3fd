"""Coverage of ``rss6 multifidelity``'s 95 % interval on skewed margins (pipeline.studies.multifidelity).

Run on demand: ``python benchmarks/multifidelity_coverage.py [--reps R]`` (default 4000 pairs of ensembles
per cell; about two minutes).  Pairs (Y, X) with a Gaussian copula of correlation rho and a common
margin (exponential, skewness 2; lognormal(0.75), 2.9; chi2(1), 2.8; and, for contrast, normal and
gamma(2), 1.4); N high and M low realisations, the first N of the low ones paired;
:func:`control_variate_mean` at 95 %.  The table gives the share of runs whose interval covers the
margin's mean, and the shares missing it low (upper bound below) and high.  tests/test_multifidelity.py
measures normal, gamma(2) and Laplace margins with 10 000 repetitions per cell.
"""
from __future__ import annotations

import argparse

import numpy as np
from scipy import stats as sps

from pipeline.studies.multifidelity import control_variate_mean

MARGINS = {"exponential": sps.expon(), "lognormal(0.75)": sps.lognorm(0.75), "chi2(1)": sps.chi2(1),
           "normal": sps.norm(1.0, 0.2), "gamma(2)": sps.gamma(2.0)}


def coverage(law, n: int, m: int, rho: float, reps: int, rng) -> tuple[float, float, float]:
    """(covered, upper below the mean, lower above it) over ``reps`` pairs of ensembles."""
    z = rng.standard_normal((m, reps, 2)) @ np.linalg.cholesky([[1.0, rho], [rho, 1.0]]).T
    u = sps.norm.cdf(z)
    res = control_variate_mean(law.ppf(u[:n, :, 0]), law.ppf(u[:, :, 1]), 0.95)
    mu = law.mean()
    return (float(np.mean((res.lower <= mu) & (mu <= res.upper))), float(np.mean(res.upper < mu)),
            float(np.mean(res.lower > mu)))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=4000)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(3)
    print(f"{'N':>4s} {'M/N':>4s} {'rho':>5s} {'margin':16s} {'coverage':>9s} {'miss low':>9s} {'miss high':>10s}")
    for n in (32, 64):
        for ratio in (4, 32):
            for rho in (0.5, 0.8, 0.95):
                for name, law in MARGINS.items():
                    c, low, high = coverage(law, n, n * ratio, rho, args.reps, rng)
                    print(f"{n:4d} {ratio:4d} {rho:5.2f} {name:16s} {c:9.3f} {low:9.3f} {high:10.3f}", flush=True)


if __name__ == "__main__":
    main()
