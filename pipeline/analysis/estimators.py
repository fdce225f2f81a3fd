"""Point and interval estimators on plain numpy arrays, each interval holding its stated confidence.

Axis 0 is the realisations; the statistics Dataset of a file (:mod:`pipeline.analysis.stats`) is
built from these.

How each interval is chosen (coverage measured by simulation in
tests/test_stats.py, 2000 trials per cell, n = 8, 16, 32, 100, 200, 300, 1000, on a
normal, a gamma(2) (skewness 1.4), an exponential (skewness 2) and a Laplace (excess
kurtosis 3) law; rss6's own quasi-static ensembles have skewness about 1-2 and excess
kurtosis about 1):

- Quantiles: distribution-free.  With B ~ Binomial(n, p), the order statistics
  X_(l) <= X_(u) bracket the p-quantile with probability P(l <= B <= u - 1) for
  any continuous law.  Of the rank pairs reaching the confidence the shortest
  (u - l) is taken, then the one whose two tail probabilities are closest.  If
  even (1, n) falls short, no interval exists: the bounds are NaN and
  ``min_n_for_quantile`` gives the n needed (59 for q95, 299 for q99 at 95 %).
- Mean: the union of the Student-t interval and Hall's (1992) skewness-
  corrected t interval.  Student t under-covers on skewed data (gamma(2), n = 8:
  92 %), Hall's correction under-covers on symmetric heavy tails (Laplace,
  n = 16: 92.5 %) where the sample skewness is noise; the union holds on both
  (>= 94 % measured).  Withheld below n = MIN_N_MEAN = 16: at n = 8 it covers 93.0 %
  on chi2(1) (20 000 trials) and its one-sided upper bound misses the mean of an exponential law in
  6.2 % (20 000 trials; 5 % nominal); from 16 on >= 94.7 % on laws of skewness up to
  2.8 (chi2(1)), 92.2 % on lognormal(1) (skewness 6.2).
- Std: Bonett's (2006) kurtosis-adjusted interval, computed at the level
  1 - 0.6 (1 - confidence) (97 % for a 95 % label).  The chi-square interval
  assumes normal data and covers 81 % for gamma(2) at n = 32, 72 % for the
  exponential law.  Bonett's interval at its own level stays below its label on
  skewed and heavy-tailed laws (20 000 trials at 95 %: gamma(2) 93.5 %, 93.8 %,
  94.3 % and exponential 92.9 %, 93.6 %, 93.8 % at n = 200, 300, 400; gamma(2),
  n = 32: 91 %); at the widened level it covers >= 94.7 % on gamma(2), Laplace,
  exponential and Student t5 from n = MIN_N_STD = 300 (t5: 94.1 % at n = 200), so
  below that it is withheld.
- Max: no interval.  The sample maximum estimates no population parameter an
  interval could cover: the next realisation exceeds it with probability
  1/(n + 1) whatever the law.  A bootstrap of the maximum brackets only the
  largest value seen, so it is not offered.

No bootstrap runs: none of the intervals above needs one.

A sample size chosen by the intervals' own widths (``rss6 run --until``) costs them coverage:
at the stop a q95 interval at 95 % covered 92.3-93.4 % and its one-sided upper bound missed in up
to 6.3 % (benchmarks/until_coverage.py).  There the quantiles' bounds (RQMC: every statistic's)
are computed at the level 1 - UNTIL_WIDENING (1 - confidence) (:func:`stopped_level`), which
reaches the label at the stop (docs/ensembles.md, "Run until known").

One-sided bounds (``ensemble_stats(..., one_sided=True)``; the requirement gate,
pipeline/analysis/gate.py, decides on them): ``lower`` and ``upper`` are each a bound at the
confidence on its own side (not together an interval at it); error rates of the
gate's decisions measured in tests/test_gate.py.

- Quantiles: exact binomial order statistics, distribution-free: X_(r) with the
  largest r such that P(B >= r) >= confidence bounds the p-quantile from below,
  X_(s) with the smallest s such that P(B <= s - 1) >= confidence from above
  (``one_sided_ranks``).  The lower bound of q95 exists from n = 1 (if all n
  realisations exceed a limit L, q95 <= L had probability at most 0.05^n), the
  upper one from n = 59.
- Mean: the union interval above at two-sided level 2 confidence - 1, except on
  the side the sample skewness points to (the upper bound for right-skewed data),
  where it is the bound of the two-sided interval at the confidence: there
  Hall's correction removes only part of the skew at small n (lognormal(0.5),
  n = 20, 2000 samples: the plain one-sided upper bound misses the mean in
  7.0 %, against 5 % nominal; with this rule in 4.5 %).
- Std: the two-sided (widened) Bonett interval's bounds (one-sided at level 2 confidence - 1
  they miss 11 % on lognormal(0.5) at n = 200); from n = MIN_N_STD as above.
- Randomised QMC: Student t over the replicates, one-sided (two-sided level
  2 confidence - 1), for every statistic; none if a realisation failed.

Randomised quasi-Monte Carlo files (``sampler = "qmc"``, pipeline/ensemble/sampler.py)
are not iid samples, so none of the intervals above holds for them.  There the
R independent scramblings give R independent estimates of each statistic
(replicate k: its first m = n // R points); the interval is Student t with
R - 1 degrees of freedom about their average (``rqmc_intervals``).  It is
given for the mean, std and quantiles once every replicate has at least
MIN_POINTS_RQMC[statistic] points (a replicate's quantile or std estimate is
biased by O(1/m); coverage measured in tests/test_sampler.py and, per m, by
benchmarks/rqmc_coverage.py: on a maximum over time the q99 interval covered
90.7, 92.2, 93.9 and 94.3 % at m = 128, 256, 512, 1024 (2000 runs each), hence
its floor of 1024; q95 93.8-94.0 % at 128-256, 94.9 % at 512, hence its floor of
512; with 2 and 4 replicates every statistic covered 94.1-95.6 % and 93.7-95.9 % from its
floor, ``--replicates``; at other R it is unmeasured, which ``replicates_note`` says), never for the
maximum, and not at all if a realisation failed (a replicate with holes is no
longer a scrambled net).  Point estimates stay those of all n realisations.  The statistics
files raise bounds below 0 to 0 (``clipped_at_zero``: every summary is of |error|, and the
t factor over R = 2 replicates, 12.7, reaches below 0 on a spread-out statistic).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import stats as sps

from ..vocabulary import CONFIDENCE, QUANTILES, STATISTICS

__all__ = ["BOUNDS", "MIN_N_MEAN", "MIN_N_STD", "STD_WIDENING", "UNTIL_WIDENING", "MIN_POINTS_RQMC", "MAX_NOTE",
           "QUANTILE_DECISION_CAP", "MEAN_FLOORS", "STD_FLOORS", "LOWEST_MEASURED", "highest_level", "short_of_label",
           "moment_floor",
           "clopper_pearson", "one_sided_cp",
           "quantile_ranks", "min_n_for_quantile", "quantile_estimates", "quantile_interval", "BoundRanks",
           "one_sided_ranks", "quantile_bounds", "quantile_decision_n", "mean_interval", "mean_bounds",
           "running_mean_interval", "std_interval", "estimates", "one_sided_bounds", "stopped_level", "bound_level",
           "estimates_and_bounds", "replicate_groups", "rqmc_intervals", "interval_floor", "no_interval_at",
           "clipped_at_zero", "MEASURED_REPLICATES", "replicates_note"]

BOUNDS = ("estimate", "lower", "upper")
MIN_N_MEAN = 16     # smallest n whose coverage reaches the label on the measured laws (module doc)
MIN_N_STD = 300     # widened Bonett: >= 94.7 % measured on the laws of the module doc from here
# above 95 % the mean needs more n and the std reaches no label (docs/ensembles.md, benchmarks/interval_coverage.py):
# (highest two-sided level, smallest n) in order; beyond the last level, no interval at any n
MEAN_FLOORS = ((CONFIDENCE, MIN_N_MEAN), (0.99, 64), (0.999, 128))
STD_FLOORS = ((CONFIDENCE, MIN_N_STD),)
LOWEST_MEASURED = 0.8   # the lowest two-sided level at which those floors' coverage was measured
STD_WIDENING = 0.6  # Bonett's interval is computed at the level 1 - STD_WIDENING (1 - confidence)
UNTIL_WIDENING = 0.5  # n chosen by the intervals' widths: bounds at 1 - UNTIL_WIDENING (1 - confidence)
MIN_POINTS_RQMC = {"mean": 16, "std": 32, "q05": 128, "q50": 16, "q95": 512, "q99": 1024}
MEASURED_REPLICATES = (2, 4, 8)   # the R at which benchmarks/rqmc_coverage.py measured those floors' coverage
MAX_NOTE = ("no interval: the sample maximum estimates no population parameter; the next "
            "realisation exceeds it with probability 1/(n + 1)")
_RTOL = 1e-12       # binomial coverage computed in floating point
QUANTILE_DECISION_CAP = 10 ** 6   # largest n quantile_decision_n looks at
EXACT_DECISION_SCAN = 5000        # its first block of n' (then doubling)


# --- quantiles ----------------------------------------------------------------


@lru_cache(maxsize=4096)


def quantile_ranks(n: int, p: float, confidence: float) -> tuple[int, int] | None:
    """1-based ranks (l, u) of the shortest, then most symmetric, order-statistic interval whose
    binomial coverage P(l <= B <= u - 1), B ~ Bin(n, p), reaches ``confidence``; None if none does."""
    if n < 2:
        return None
    cdf = sps.binom.cdf(np.arange(n + 1), n, p)            # cdf[k] = P(B <= k)
    below = np.concatenate([[0.0], cdf[:-1]])               # below[l] = P(B <= l - 1) = P(B < l)
    best = None
    for lo in range(1, n):
        # smallest u with cdf[u - 1] >= confidence + below[lo]
        u = int(np.searchsorted(cdf, below[lo] + confidence - _RTOL, side="left")) + 1
        if u > n:
            break
        u = max(u, lo + 1)
        key = (u - lo, abs(below[lo] - (1.0 - cdf[u - 1])))
        if best is None or key < best[0]:
            best = (key, (lo, u))
    return None if best is None else best[1]


def min_n_for_quantile(p: float, confidence: float) -> int:
    """Smallest n for which a two-sided order-statistic interval of the p-quantile reaches
    ``confidence``: the first n with 1 - p^n - (1 - p)^n >= confidence (the ranks 1 and n)."""
    n = 2
    while 1.0 - p ** n - (1.0 - p) ** n < confidence - _RTOL:
        n += 1
    return n


def quantile_estimates(x: np.ndarray, probs, axis: int = 0) -> np.ndarray:
    """Quantile estimates (numpy's linear interpolation) along ``axis``, NaN values left out;
    the one quantile estimator of rss6 (statistics tables, studies, figures)."""
    with warnings.catch_warnings():                         # all-NaN slices give NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanquantile(np.asarray(x, float), probs, axis=axis)


def quantile_interval(sorted_x: np.ndarray, p: float, confidence: float) -> np.ndarray:
    """(lower, upper) along axis 0 of samples sorted along axis 0; NaN if no interval exists."""
    ranks = quantile_ranks(sorted_x.shape[0], p, confidence)
    if ranks is None:
        return np.full((2,) + sorted_x.shape[1:], np.nan)
    return np.stack([sorted_x[ranks[0] - 1], sorted_x[ranks[1] - 1]])


@dataclass(frozen=True)


class BoundRanks:
    """1-based ranks of the order statistics that bound a quantile from one side each (None: no
    rank reaches the confidence at this n)."""

    lower: int | None
    upper: int | None


@lru_cache(maxsize=4096)


def one_sided_ranks(n: int, p: float, confidence: float) -> BoundRanks:
    """Ranks of the one-sided bounds of the p-quantile of a continuous law: ``lower`` the largest r
    with P(X_(r) <= xi_p) = P(B >= r) >= confidence, ``upper`` the smallest s with
    P(X_(s) >= xi_p) = P(B <= s - 1) >= confidence, B ~ Bin(n, p)."""
    ranks = np.arange(1, n + 1)
    lower = np.flatnonzero(sps.binom.sf(ranks - 1, n, p) >= confidence - _RTOL)
    upper = np.flatnonzero(sps.binom.cdf(ranks - 1, n, p) >= confidence - _RTOL)
    return BoundRanks(int(ranks[lower[-1]]) if lower.size else None,
                      int(ranks[upper[0]]) if upper.size else None)


def quantile_bounds(sorted_x: np.ndarray, p: float, confidence: float) -> np.ndarray:
    """One-sided (lower, upper) bounds of the p-quantile along axis 0 of samples sorted along axis 0,
    each at ``confidence``; NaN where no order statistic reaches it."""
    ranks = one_sided_ranks(sorted_x.shape[0], p, confidence)
    nan = np.full(sorted_x.shape[1:], np.nan)
    return np.stack([nan if r is None else sorted_x[r - 1] for r in (ranks.lower, ranks.upper)])


def quantile_decision_n(n: int, violating: int, allowed: float, confidence: float) -> int | None:
    """The smallest n' > n at which the one-sided binomial bound decides (either way) whether the
    share of violating draws exceeds ``allowed`` (1 - p for an upper limit on the p-quantile, p for a
    lower one), if a share ``violating / n`` of n' draws violate (k' rounded): every n' is tried (the
    binomial tails jitter, so a grid can step over the first), in blocks that double from
    EXACT_DECISION_SCAN; None when no n' within EXACT_DECISION_SCAN below QUANTILE_DECISION_CAP decides
    (looked at first).  Fail: P(Bin(n', allowed) >= k') <= 1 - confidence; pass: P(Bin(n', allowed) <= k')
    <= 1 - confidence (the ranks of :func:`one_sided_ranks` as counts)."""
    def first(m: np.ndarray) -> int | None:
        k = np.rint(violating / n * m)
        fail = (k >= 1) & (sps.binom.sf(k - 1, m, allowed) <= 1 - confidence + _RTOL)
        hit = np.flatnonzero(fail | (sps.binom.cdf(k, m, allowed) <= 1 - confidence + _RTOL))
        return int(m[hit[0]]) if hit.size else None

    near_cap = np.arange(max(n + 1, QUANTILE_DECISION_CAP - EXACT_DECISION_SCAN), QUANTILE_DECISION_CAP + 1)
    if first(near_cap) is None:
        return None   # the bounds narrow as n grows: what no n near the cap decides, no smaller n does
    start, block = n + 1, EXACT_DECISION_SCAN
    while start <= QUANTILE_DECISION_CAP:
        stop = min(start + block, QUANTILE_DECISION_CAP + 1)
        found = first(np.arange(start, stop))
        if found is not None:
            return found
        start, block = stop, 2 * block
    return None


# --- mean and std -----------------------------------------------------------------


def highest_level(statistic: str) -> float:
    """The highest two-sided level at which the mean's or std's interval was seen to reach its label."""
    return {"mean": MEAN_FLOORS, "std": STD_FLOORS}[statistic][-1][0]


def short_of_label(statistic: str) -> str:
    """Why the mean or std has no interval at any n beyond its highest measured level."""
    return f"its coverage falls short of the label above {100 * highest_level(statistic):g} % (docs/ensembles.md)"


def moment_floor(statistic: str, confidence: float) -> int | None:
    """Smallest n from which the mean's or std's two-sided interval at ``confidence`` reaches its label on the
    measured laws (MEAN_FLOORS, STD_FLOORS); None where no n was seen to (the std above 95 %)."""
    floors = {"mean": MEAN_FLOORS, "std": STD_FLOORS}[statistic]
    return next((n for level, n in floors if confidence <= level + 1e-12), None)


def _mean_interval_from_moments(n, mean, std, skew, confidence, floor: int | None):
    """Union of the Student-t and Hall's skewness-corrected intervals (see module doc); NaN below ``floor``
    (None: at every n)."""
    n, mean, std, skew = np.broadcast_arrays(*(np.asarray(v, float) for v in (n, mean, std, skew)))
    tq = sps.t.ppf(0.5 + confidence / 2, np.maximum(n - 1, 1))
    se = std / np.sqrt(n)
    a = skew / (3 * np.sqrt(n))
    b = skew / (6 * np.sqrt(n))
    with np.errstate(all="ignore"):
        def inverse(v):   # inverse of Hall's g(T) = ((1 + aT)^3 - 1) / (3a) + b
            return np.where(np.abs(a) > 1e-12, (np.cbrt(1 + 3 * a * (v - b)) - 1) / a, v - b)
        hall = np.stack([mean - inverse(tq) * se, mean - inverse(-tq) * se])
    t = np.stack([mean - tq * se, mean + tq * se])
    hall = np.where(np.isfinite(hall), hall, t)             # zero spread: skewness undefined
    out = np.stack([np.minimum(t[0], hall[0]), np.maximum(t[1], hall[1])])
    return np.where((n >= floor) if floor is not None else False, out, np.nan)


def _moments(x: np.ndarray):
    """n, mean, std (ddof=1) and the skewness g1 (biased) along axis 0 of finite data."""
    n = x.shape[0]
    mean = x.mean(axis=0)
    d = x - mean
    m2 = (d ** 2).mean(axis=0)
    with np.errstate(all="ignore"):
        skew = np.where(m2 > 0, (d ** 3).mean(axis=0) / m2 ** 1.5, 0.0)
        std = np.sqrt(m2 * n / (n - 1)) if n > 1 else np.full_like(mean, np.nan)
    return n, mean, std, skew


def mean_interval(x: np.ndarray, confidence: float, own_floor: int | None = None) -> np.ndarray:
    """(lower, upper) for the mean along axis 0 of finite data; NaN below its floor at ``confidence``
    (moment_floor), or below ``own_floor`` where the caller's estimator sets its own (multi-fidelity's
    widened level, whose coverage it measured itself)."""
    n, mean, std, skew = _moments(np.asarray(x, float))
    floor = moment_floor("mean", confidence) if own_floor is None else own_floor
    return _mean_interval_from_moments(n, mean, std, skew, confidence, floor)


def mean_bounds(x: np.ndarray, confidence: float) -> np.ndarray:
    """One-sided (lower, upper) bounds of the mean along axis 0 of finite data, each at
    ``confidence`` (module doc: the bound on the side of the sample skewness is the two-sided
    interval's); NaN below its floor (moment_floor)."""
    skew = _moments(np.asarray(x, float))[3]
    one, two = mean_interval(x, 2 * confidence - 1), mean_interval(x, confidence)
    return np.stack([np.where(skew < 0, two[0], one[0]), np.where(skew > 0, two[1], one[1])])


def running_mean_interval(x: np.ndarray, confidence: float):
    """Running mean of a 1-D sample and its interval after 1, 2, ..., N values (for convergence
    figures): the same interval as :func:`mean_interval`, from cumulative moments."""
    x = np.asarray(x, float)
    n = np.arange(1, len(x) + 1)
    c = x - x.mean()                                         # shift for round-off
    s1, s2, s3 = (np.cumsum(c ** k) for k in (1, 2, 3))
    m = s1 / n
    m2 = np.maximum(s2 / n - m ** 2, 0.0)
    m3 = s3 / n - 3 * m * s2 / n + 2 * m ** 3
    with np.errstate(all="ignore"):
        skew = np.where(m2 > 0, m3 / m2 ** 1.5, 0.0)
        std = np.sqrt(m2 * n / np.maximum(n - 1, 1))
    mean = m + x.mean()
    return mean, _mean_interval_from_moments(n, mean, std, skew, confidence, moment_floor("mean", confidence))


def std_interval(x: np.ndarray, confidence: float) -> np.ndarray:
    """Bonett's (2006) interval for the standard deviation along axis 0 of finite data, at the widened
    level 1 - STD_WIDENING (1 - confidence) (module doc); NaN below its floor (moment_floor)."""
    x = np.asarray(x, float)
    n = x.shape[0]
    floor = moment_floor("std", confidence)
    if floor is None or n < max(floor, 5):
        return np.full((2,) + x.shape[1:], np.nan)
    z = sps.norm.ppf(1 - STD_WIDENING * (1 - confidence) / 2)
    trimmed = sps.trim_mean(x, 1 / (2 * np.sqrt(n - 4)), axis=0)
    ss = ((x - x.mean(axis=0)) ** 2).sum(axis=0)
    c = n / (n - z)
    with np.errstate(all="ignore"):
        kurt = n * ((x - trimmed) ** 4).sum(axis=0) / ss ** 2
        se = c * np.sqrt(np.maximum(kurt - (n - 3) / n, 0.0) / (n - 1))
        var = ss / (n - 1)
        out = np.sqrt(np.stack([c * var * np.exp(-z * se), c * var * np.exp(z * se)]))
    return np.where(ss > 0, out, 0.0)


# --- point estimates -------------------------------------------------------------


def estimates(x: np.ndarray, names=STATISTICS) -> np.ndarray:
    """Point estimates ``names`` (of STATISTICS) along axis 0, NaN values left out; stacked on a
    new last axis.  The one implementation the tables, the studies and the figures use."""
    x = np.asarray(x, float)
    out = []
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        for name in names:
            if name == "mean":
                out.append(np.nanmean(x, axis=0))
            elif name == "std":
                out.append(np.nanstd(x, axis=0, ddof=1))
            elif name == "max":
                out.append(np.nanmax(x, axis=0))
            else:
                out.append(quantile_estimates(x, QUANTILES[name], axis=0))
    return np.stack(out, axis=-1)


def _intervals(x: np.ndarray, confidence: float, stopped_by_width: bool = False) -> np.ndarray:
    """(statistic, 2, cells) lower and upper bounds for finite data x (n, cells), each at its
    :func:`bound_level`."""
    sx = np.sort(x, axis=0)
    rows = [mean_interval(x, confidence), std_interval(x, confidence)]
    rows += [quantile_interval(sx, p, bound_level(k, confidence, stopped_by_width)) for k, p in QUANTILES.items()]
    rows.append(np.full((2,) + x.shape[1:], np.nan))        # max: see module doc
    return np.stack(rows)


def one_sided_bounds(x: np.ndarray, confidence: float, stopped_by_width: bool = False) -> np.ndarray:
    """(statistic, 2, cells) one-sided lower and upper bounds, each at its :func:`bound_level` for
    ``confidence``, for finite data x (n, cells) (module doc); the bounds the requirement gate decides on."""
    sx = np.sort(x, axis=0)
    rows = [mean_bounds(x, confidence), std_interval(x, confidence)]
    rows += [quantile_bounds(sx, p, bound_level(k, confidence, stopped_by_width)) for k, p in QUANTILES.items()]
    rows.append(np.full((2,) + x.shape[1:], np.nan))
    return np.stack(rows)


def stopped_level(confidence: float, stopped_by_width: bool) -> float:
    """The level bounds are computed at for a ``confidence`` label: widened where the sample size was
    chosen by the intervals' own widths (``rss6 run --until``; module doc), else the label's."""
    return 1.0 - UNTIL_WIDENING * (1.0 - confidence) if stopped_by_width else confidence


def bound_level(statistic: str, confidence: float, stopped_by_width: bool, rqmc: bool = False) -> float:
    """The level ``statistic``'s bounds are computed at for a ``confidence`` label: where n was chosen by
    the intervals' widths, widened (:func:`stopped_level`) for the quantiles, and with ``rqmc`` for every
    statistic (all their widths come from the replicates); else the label's. The one statement of the
    rule that the tables, the statistics files and the requirement gate apply."""
    return stopped_level(confidence, stopped_by_width and (rqmc or statistic in QUANTILES))


def estimates_and_bounds(x: np.ndarray, confidence: float, one_sided: bool = False,
                         stopped_by_width: bool = False) -> np.ndarray:
    """(statistic, bound, cells) for finite data x (n, cells); all NaN when n = 0.  ``stopped_by_width``:
    n was chosen by the intervals' own widths (the quantiles' bounds widened, :func:`stopped_level`)."""
    if x.shape[0] == 0:
        return np.full((len(STATISTICS), len(BOUNDS), x.shape[1]), np.nan)
    est = np.moveaxis(estimates(x), -1, 0)                   # (statistic, cells)
    bounds = (one_sided_bounds if one_sided else _intervals)(x, confidence, stopped_by_width)
    return np.concatenate([est[:, None], bounds], axis=1)


# --- randomised quasi-Monte Carlo ----------------------------------------------------


def replicate_groups(x: np.ndarray, realizations, replicates: int) -> np.ndarray:
    """(R, m, cells) of data x (n, cells) whose row j is realisation ``realizations[j]``: replicate
    k holds points 0..m-1 of scrambling k (realisation k + R i), m = n // R; rows beyond are left out."""
    order = np.argsort(np.asarray(realizations))
    m = len(order) // replicates
    first = x[order[:replicates * m]]                        # realisations 0 .. R m - 1
    return first.reshape(m, replicates, *x.shape[1:]).swapaxes(0, 1)


def rqmc_intervals(groups: np.ndarray, confidence: float) -> np.ndarray:
    """(statistic, 2, cells): Student t over the R replicate estimates of each statistic of
    STATISTICS; NaN where a replicate has fewer than MIN_POINTS_RQMC points, and for the max."""
    R, m = groups.shape[:2]
    per = np.moveaxis(estimates(np.swapaxes(groups, 0, 1)), -1, 0)   # (statistic, R, cells)
    # sectioning: centred on the estimate of all R m points, whose O(1/m) bias a replicate
    # quantile's would carry R times over; the spread of the replicates gives the width
    centre = np.moveaxis(estimates(groups.reshape(R * m, *groups.shape[2:])), -1, 0)
    spread = per.std(axis=1, ddof=1) if R > 1 else np.nan * per[:, 0]
    half = sps.t.ppf(0.5 + confidence / 2, max(R - 1, 1)) * spread / np.sqrt(R)
    out = np.stack([centre - half, centre + half], axis=1)
    enough = np.array([R >= 2 and m >= MIN_POINTS_RQMC.get(s, np.inf) for s in STATISTICS])
    return np.where(enough[:, None, None], out, np.nan)


def clipped_at_zero(bounds: np.ndarray) -> np.ndarray:
    """Bounds of statistics of a non-negative quantity (every rss6 summary is a max or mean of |error|) with
    those below 0 raised to 0; NaN stays NaN.

    The true mean, std or quantile of such a quantity is >= 0, so an interval [l, u] covers it exactly when
    [max(l, 0), max(u, 0)] does, and a one-sided lower bound l holds exactly when max(l, 0) does: clipping
    keeps every interval's and bound's coverage and removes only values no such law can take.  Student t
    over few replicates (R = 2: t = 12.7) or a small skewed sample's mean interval reach below 0 otherwise."""
    return np.maximum(bounds, 0.0)


def replicates_note(replicates: int) -> str | None:
    """Where a QMC file's replicate count R is not one whose intervals' coverage was measured
    (MEASURED_REPLICATES), a note saying so; None where it is."""
    if replicates in MEASURED_REPLICATES:
        return None
    counts = ", ".join(map(str, MEASURED_REPLICATES[:-1])) + f" and {MEASURED_REPLICATES[-1]}"
    return (f"RQMC coverage measured with {counts} replicates (docs/ensembles.md); at R = {replicates} the t "
            "interval's coverage is unmeasured")


def interval_floor(statistic: str, confidence: float, replicates: int | None = None) -> int | None:
    """Smallest n with an interval of ``statistic`` (mc: iid intervals; with ``replicates``: RQMC); None
    where none is given at any n (:func:`moment_floor`)."""
    if replicates is not None:
        return replicates * MIN_POINTS_RQMC[statistic]
    if statistic in QUANTILES:
        return min_n_for_quantile(QUANTILES[statistic], confidence)
    return moment_floor(statistic, confidence)


def no_interval_at(statistic: str, confidence: float, n: int, replicates: int | None = None) -> str | None:
    """Why a request capped at ``n`` realisations can get no interval of ``statistic`` (e.g. "q99 has
    no 95 % interval below n = 299 (-n 100); raise -n"), or None when it can."""
    floor = interval_floor(statistic, confidence, replicates)
    if floor is None:
        top = highest_level(statistic)
        return (f"{statistic} has no {100 * confidence:g} % interval at any n: {short_of_label(statistic)}; "
                f"use --confidence {top:g} or below")
    if n >= floor:
        return None
    return f"{statistic} has no {100 * confidence:g} % interval below n = {floor} (-n {n}); raise -n"


def clopper_pearson(k, n, confidence: float = CONFIDENCE) -> tuple:
    """Two-sided exact (Clopper-Pearson) interval of a binomial proportion from k of n: each bound a
    one-sided bound at (1 + confidence) / 2; 0 and 1 at k = 0 and k = n."""
    return one_sided_cp(k, n, (1 + confidence) / 2)


def one_sided_cp(k, n, confidence: float = CONFIDENCE) -> tuple:
    """One-sided exact bounds (lower, upper) of a binomial proportion, each at ``confidence``:
    lower = Beta(1 - c; k, n - k + 1), upper = Beta(c; k + 1, n - k) (Clopper and Pearson 1934)."""
    k, n = np.asarray(k, float), np.asarray(n, float)
    with np.errstate(invalid="ignore"):
        lower = np.where(k > 0, sps.beta.ppf(1 - confidence, k, n - k + 1), 0.0)
        upper = np.where(k < n, sps.beta.ppf(confidence, k + 1, n - k), 1.0)
    return lower, upper
