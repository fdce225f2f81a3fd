"""Coverage of the randomised-QMC intervals (``--sampler qmc``) per statistic and points per replicate.

Run on demand: ``python benchmarks/rqmc_coverage.py [--points 128 256 512 1024] [--reps N] [--replicates R]``
(default 2000 runs per size, R = 8; about 3 minutes, less at fewer replicates).  ``--until`` instead measures
the intervals where ``rss6 run --until`` stops (pipeline.analysis.until; 1000 runs per target, R = 8, about 10
minutes): checked at the rule's sample sizes, stopping at the first n where the relative half-width meets the
target, with the bounds at the label's 95 % (``plain``) and at the rule's widened level
:data:`pipeline.analysis.until.LEVEL` (``rss6``).

The output is benchmarks/sobol_coverage.py's maximum over time of |sum_i c_i(t) e_i| (24 uniform inputs in
4 groups), the clearance response's shape at the quasi-static level; its true statistics come from 4e6 plain
draws.  Each run draws R = 8 (``--replicates``) scrambled Sobol' replicates of m points and takes
:func:`pipeline.analysis.estimators.rqmc_intervals` at 95 %; the table gives the share of runs whose
interval covers each truth, also below the statistic's floor MIN_POINTS_RQMC (marked).  tests/test_sampler.py
measures the paper scene's own response at m = 128 (500 runs, slow).
"""
from __future__ import annotations

import argparse

import numpy as np
from scipy.stats import qmc

from pipeline.analysis.estimators import MIN_POINTS_RQMC, estimates, rqmc_intervals
from pipeline.analysis.until import LEVEL, checkpoints, parse_target
from pipeline.vocabulary import STATISTICS
from sobol_coverage import GROUPS, PER, response   # the same output as the Sobol' benchmark's

D, R = GROUPS * PER, 8


UNTIL_TARGETS = ("displacement:z@mean<=1%", "displacement:z@q95<=3%")
UNTIL_CAP = R * 4096


def until_coverage(text: str, truth: float, level: float, reps: int) -> tuple[float, int]:
    """Coverage and median stopping n of ``--until text`` runs whose bounds are taken at ``level``."""
    target = parse_target(text)
    i, points = STATISTICS.index(target.statistic), checkpoints([target], UNTIL_CAP, R)
    cover, stops = 0, []
    for run in range(reps):
        groups = np.stack([response(qmc.Sobol(D, scramble=True, seed=np.random.default_rng([run, k])).random(
            UNTIL_CAP // R)) for k in range(R)])
        for n in points:
            m = n // R
            lower, upper = rqmc_intervals(groups[:, :m, None], level)[i, :, 0]
            estimate = estimates(groups[:, :m].reshape(-1, 1))[0, i]          # of all R m points, as rss6's
            if (np.isfinite(upper) and (upper - lower) / 2 <= target.relative * abs(estimate)) or n == points[-1]:
                cover += lower <= truth <= upper
                stops.append(n)
                break
    return cover / reps, int(np.median(stops))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, nargs="+", default=[128, 256, 512, 1024])
    parser.add_argument("--reps", type=int, default=None, help="runs per cell (default 2000; --until 1000)")
    parser.add_argument("--replicates", type=int, default=R, help=f"scrambled replicates per run (default {R})")
    parser.add_argument("--until", action="store_true", help="coverage where rss6 run --until stops")
    args = parser.parse_args(argv)
    model, rng = response, np.random.default_rng(7)
    ys = np.concatenate([model(rng.random((500_000, D))) for _ in range(8)])
    truth = {"mean": ys.mean(), "std": ys.std(ddof=1),
             **{f"q{p:02d}": np.quantile(ys, p / 100) for p in (5, 50, 95, 99)}}
    if args.until:
        for text in UNTIL_TARGETS:
            for rule, level in (("plain", 0.95), ("rss6", LEVEL)):
                cover, n = until_coverage(text, truth[parse_target(text).statistic], level, args.reps or 1000)
                print(f"--until {text} ({rule}, bounds at {100 * level:g} %): coverage {cover:.3f}, median stop n {n}",
                      flush=True)
        return
    args.reps = args.reps or 2000
    floors = dict(MIN_POINTS_RQMC)
    MIN_POINTS_RQMC.update(dict.fromkeys(MIN_POINTS_RQMC, 1))   # measure below the floors too (marked *)
    print(f"points per replicate m (R = {args.replicates}), coverage of the 95 % interval over {args.reps} runs; "
          f"* below the statistic's floor ({', '.join(f'{s} {floors[s]}' for s in truth)}), where rss6 gives none")
    for m in args.points:
        hits = dict.fromkeys(truth, 0)
        for run in range(args.reps):
            groups = np.stack([model(qmc.Sobol(D, scramble=True, seed=np.random.default_rng([run, k, m])).random(m))
                               for k in range(args.replicates)])[:, :, None]
            iv = rqmc_intervals(groups, 0.95)
            for s in truth:
                i = STATISTICS.index(s)
                hits[s] += bool(np.isfinite(iv[i, 0, 0]) and iv[i, 0, 0] <= truth[s] <= iv[i, 1, 0])
        print(f"m = {m:5d}: " + ", ".join(f"{s} {hits[s] / args.reps:.3f}{'*' if m < floors[s] else ''}"
                                          for s in truth), flush=True)


if __name__ == "__main__":
    main()
