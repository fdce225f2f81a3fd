"""Coverage of ``rss6 sensitivity``'s bootstrap intervals on a maximum over time, with a reference truth.

Run on demand: ``python benchmarks/sobol_coverage.py [-n N] [--reps R]`` (default N = 64, 500 designs;
about 40 s, and a minute for the truth).  The output is a maximum over time of |sum_i c_i(t) e_i|, the
clearance response's shape at the quasi-static level: 24 uniform inputs e_i in [-1, 1] in 4 groups of
6 with group scales 1, 0.15, 0.8, 0.7 and phases drawn once, on 50 instants of a period.  The truth is
the indices at N = 2^16 (their own bootstrap half-widths <= 0.01); each of R designs of N base rows
(seeds 1000..) gets rss6's :func:`pipeline.studies.sensitivity.sobol_indices` (SALib's estimators, 500
resamples, 95 %), and the table gives per group the share of designs whose S1 and ST intervals cover
the truth, for rss6's widened z (SOBOL_WIDENING) and, as ``plain``, for the label's own z.
tests/test_sensitivity.py measures the closed-form case (one instant, a linear output).
"""
from __future__ import annotations

import argparse

import numpy as np

from pipeline.studies.sensitivity import SOBOL_WIDENING, Design, sobol_indices

GROUPS, PER = 4, 6
SCALES = (1.0, 0.15, 0.8, 0.7)


def design() -> Design:
    names = [f"u{i}" for i in range(GROUPS * PER)]
    groups = tuple(f"g{k}" for k in range(GROUPS))
    problem = {"num_vars": len(names), "names": names, "bounds": [[0.0, 1.0]] * len(names),
               "groups": [groups[i // PER] for i in range(len(names))]}
    return Design("families", groups, problem)


def response(u: np.ndarray) -> np.ndarray:
    """(rows,): the maximum over 50 instants of |sum_i c_i(t) e_i|, e = 2 u - 1 (also
    benchmarks/rqmc_coverage.py's output)."""
    rng = np.random.default_rng(5)
    t = np.linspace(0.0, 2.0 * np.pi, 50)
    phase = rng.uniform(0.0, 2.0 * np.pi, GROUPS * PER)
    coef = np.repeat(SCALES, PER)[:, None] * np.cos(t[None, :] + phase[:, None])
    return np.abs((2.0 * u - 1.0) @ coef).max(axis=1)


def indices(d: Design, n: int, seed: int, widening: float = SOBOL_WIDENING) -> np.ndarray:
    """(index S1/ST, bound, group) of one design of ``n`` base rows."""
    from SALib.sample import sobol
    u = sobol.sample(d.problem, n, calc_second_order=False, scramble=True, seed=seed)
    return sobol_indices(d, response(u)[:, None], 0.95, seed, widening=widening).values[..., 0]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=64)
    parser.add_argument("--reps", type=int, default=500)
    args = parser.parse_args(argv)
    d = design()
    truth = indices(d, 2 ** 16, 123)[:, 0]
    print("truth (N = 2^16): S1 " + " ".join(f"{v:.3f}" for v in truth[0]) + "; ST "
          + " ".join(f"{v:.3f}" for v in truth[1]))
    for rule, widening in (("rss6", SOBOL_WIDENING), ("plain", 1.0)):
        hits = np.zeros((2, GROUPS))
        for k in range(args.reps):
            got = indices(d, args.n, 1000 + k, widening)
            hits += (got[:, 1] <= truth) & (truth <= got[:, 2])
        for i, name in enumerate(("S1", "ST")):
            print(f"N = {args.n}, {args.reps} designs, {rule} z: {name} coverage per group "
                  + " ".join(f"{v:.3f}" for v in hits[i] / args.reps), flush=True)


if __name__ == "__main__":
    main()
