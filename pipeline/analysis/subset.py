"""Subset simulation (Au and Beck 2001): small failure probabilities P(response(z) > threshold) for z
standard normal in d dimensions, with a few thousand evaluations of a vectorised response.

The failure event is reached through nested intermediate events {response > b_j}, each threshold
b_j the (1 - p0) sample quantile of the current level (the mean of the N p0-th and N p0 + 1-th
largest responses), so each conditional probability is about p0.  Level 0 is plain Monte Carlo;
level j >= 1 grows N p0 Markov chains of 1 / p0 states each from the level's seeds by adaptive
conditional sampling (Papaioannou et al. 2015, "MCMC algorithms for subset simulation", Prob. Eng.
Mech. 41): candidate v_i = rho_i z_i + sigma_i xi_i, sigma_i = min(1, lambda s_i) with s_i the seeds'
standard deviation of component i and rho_i = sqrt(1 - sigma_i^2), which leaves the standard normal
law invariant, so a candidate is accepted iff it is in the current intermediate event.  The scale
lambda starts at 0.6 at every level and is tuned after each step of all chains towards an
acceptance of 0.44 (log lambda += (a_i - 0.44) / sqrt(i), a_i the i-th step's acceptance).

P = p0^(m-1) * (share of the last level above the threshold).  Its CoV estimate (Au and Beck 2001,
eqs. 26-29): delta^2 = sum_j (1 - p_j) / (N p_j) (1 + gamma_j), gamma_0 = 0 (independent draws),
gamma_j = 2 sum_{k=1}^{Ns-1} (1 - k / Ns) rho_j(k) from the chains' indicator autocorrelation; the
levels are taken as uncorrelated.  Interval: log-normal from the CoV, ln P ~ N(ln p - s^2 / 2, s^2),
s^2 = ln(1 + delta^2); its coverage is measured in tests/test_subset.py.

All randomness comes from a fixed schedule: block c of level 0 and chain c of level j >= 1 draw from
SeedSequence([seed, j, c]) alone, and the response is evaluated on whole batches (level 0: all N
draws; a chain step: every chain's candidate), so the result does not depend on how a batch is split.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats as sps

from ..vocabulary import CONFIDENCE, ESTIMATE_ENDS
from .estimators import clopper_pearson

__all__ = ["SubsetSettings", "LevelRecord", "Evaluations", "SubsetResult", "check_estimate_end", "subset_simulation",
           "lognormal_interval", "chain_gamma", "MIN_N_INTERVAL"]

TARGET_ACCEPTANCE = 0.44   # Papaioannou et al. (2015), adaptive conditional sampling
INITIAL_SCALE = 0.6


@dataclass(frozen=True)
class SubsetSettings:
    """N draws per level, the level probability p0 (N p0 chains of 1 / p0 states), the seed, the
    interval's confidence and the most levels tried (P >= p0^max_levels)."""

    n_per_level: int = 1000
    p0: float = 0.1
    seed: int = 0
    confidence: float = CONFIDENCE
    max_levels: int = 16

    def __post_init__(self):
        if not 0 < self.p0 <= 0.5:
            raise ValueError(f"p0 {self.p0:g}: must lie in (0, 0.5]")
        chains = self.n_per_level * self.p0
        if abs(chains - round(chains)) > 1e-9 or round(chains) < 2 or self.n_per_level % round(chains):
            raise ValueError(f"N {self.n_per_level} and p0 {self.p0:g}: N p0 must be an integer of at "
                             "least 2 that divides N (e.g. N = 1000, p0 = 0.1)")
        if not 0 < self.confidence < 1:
            raise ValueError(f"confidence {self.confidence:g}: must lie in (0, 1)")

    @property
    def chains(self) -> int:
        return round(self.n_per_level * self.p0)

    @property
    def steps(self) -> int:
        """States per chain, the seed included."""
        return self.n_per_level // self.chains


@dataclass(frozen=True)
class LevelRecord:
    """One level: its threshold (the next intermediate one, or the target at the last level), the
    conditional probability of exceeding it, new evaluations, the chains' acceptance and scale
    (NaN at level 0), gamma and the level's CoV contribution."""

    threshold: float
    probability: float
    evaluations: int
    acceptance: float
    scale: float
    gamma: float
    cov: float


@dataclass(frozen=True)
class Evaluations:
    """Every evaluated point: its standard normal inputs z (E, d), level and response (E,)."""

    z: np.ndarray
    level: np.ndarray
    response: np.ndarray


def check_estimate_end(status: str) -> None:
    """ValueError unless ``status`` is one of the words an estimate ends with (vocabulary.ESTIMATE_ENDS)."""
    if status not in ESTIMATE_ENDS:
        raise ValueError(f"estimate status {status!r}: not one of {', '.join(ESTIMATE_ENDS)}")


@dataclass(frozen=True)
class SubsetResult:
    """P, its CoV estimate and log-normal interval at ``confidence``, per-level records and every
    evaluation; ``status``: 'converged', 'certain', 'impossible', 'stalled' or 'max_levels' (their meanings:
    pipeline.vocabulary.ESTIMATE_ENDS)."""

    pf: float
    cov: float
    cov_upper: float
    lower: float
    upper: float
    confidence: float
    levels: tuple[LevelRecord, ...]
    status: str
    message: str
    evaluations: Evaluations = field(repr=False)
    interval: str = ("log-normal from the CoV's upper bound (levels fully correlated): ln P ~ "
                     "N(ln p - s^2/2, s^2), s^2 = ln(1 + cov_upper^2)")

    def __post_init__(self):
        check_estimate_end(self.status)

    @property
    def n_evaluations(self) -> int:
        return int(self.evaluations.level.size)


def chain_gamma(indicator: np.ndarray) -> float:
    """Au and Beck (2001) eq. 27: gamma = 2 sum_{k=1}^{Ns-1} (1 - k/Ns) rho(k) of indicator chains
    (chains, Ns), the correlation rho(k) = R(k) / R(0) estimated over all chains."""
    chains, steps = indicator.shape
    x = indicator.astype(float)
    p = x.mean()
    r0 = p * (1 - p)
    if r0 <= 0:
        return 0.0
    lags = np.arange(1, steps)
    rk = np.array([np.mean(x[:, :steps - k] * x[:, k:]) - p * p for k in lags])
    return float(2 * np.sum((1 - lags / steps) * rk / r0))


def lognormal_interval(pf: float, cov: float, confidence: float) -> tuple[float, float]:
    """Two-sided interval of p from an estimate P of CoV ``cov``: ln P ~ N(ln p - s^2/2, s^2)."""
    if not (pf > 0 and np.isfinite(cov)):
        return float("nan"), float("nan")
    s = math.sqrt(math.log1p(cov * cov))
    z = sps.norm.ppf((1 + confidence) / 2)
    return pf * math.exp(s * s / 2 - z * s), pf * math.exp(s * s / 2 + z * s)


def _rng(settings: SubsetSettings, level: int, chain: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([settings.seed, level, chain]))


def _level_zero(response, dimension: int, settings: SubsetSettings):
    """(z (chains, steps, d), responses (chains, steps)) of N independent standard normal draws."""
    z = np.stack([_rng(settings, 0, c).standard_normal((settings.steps, dimension))
                  for c in range(settings.chains)])
    r = np.asarray(response(z.reshape(-1, dimension)), float).reshape(settings.chains, settings.steps)
    return z, r


def _grow_chains(response, seeds_z, seeds_r, threshold: float, level: int, settings: SubsetSettings):
    """Adaptive conditional sampling from the seeds (chains, d) in {response > threshold}: the
    states (chains, steps, d), their responses, the candidates (evaluated), the acceptance and the
    mean scale lambda (tuned after every step of all chains, module doc)."""
    chains, d = seeds_z.shape
    spread = seeds_z.std(axis=0, ddof=1)
    xi = np.stack([_rng(settings, level, c).standard_normal((settings.steps - 1, d)) for c in range(chains)])
    z, r = [seeds_z], [seeds_r]
    candidates, responses, accepted, scales = [], [], 0, []
    scale = INITIAL_SCALE
    for s in range(settings.steps - 1):
        sigma = np.minimum(1.0, scale * spread)
        cand = np.sqrt(1 - sigma ** 2) * z[-1] + sigma * xi[:, s]
        rc = np.asarray(response(cand), float)
        ok = rc > threshold
        accepted += int(ok.sum())
        candidates.append(cand)
        responses.append(rc)
        z.append(np.where(ok[:, None], cand, z[-1]))
        r.append(np.where(ok, rc, r[-1]))
        scales.append(scale)
        scale *= math.exp((ok.mean() - TARGET_ACCEPTANCE) / math.sqrt(s + 1))
    states = (np.stack(z, axis=1), np.stack(r, axis=1))
    acceptance = accepted / (chains * (settings.steps - 1))
    return states, (np.concatenate(candidates), np.concatenate(responses)), acceptance, float(np.mean(scales))


def _next_threshold(r: np.ndarray, chains: int) -> tuple[float, np.ndarray]:
    """The (1 - p0) sample quantile of a level's responses and the flat indices of its seeds."""
    order = np.argsort(r.ravel(), kind="stable")[::-1]
    flat = r.ravel()[order]
    return 0.5 * (flat[chains - 1] + flat[chains]), order[:chains]


def _finish(levels, pf, records, status, message, settings) -> SubsetResult:
    """The result: CoV from the levels' contributions (uncorrelated levels), its interval."""
    cov = math.sqrt(sum(rec.cov ** 2 for rec in levels)) if pf > 0 else float("nan")
    cov_upper = sum(rec.cov for rec in levels) if pf > 0 else float("nan")
    lower, upper = lognormal_interval(pf, cov_upper, settings.confidence)
    z, lev, resp = (np.concatenate(part) for part in zip(*records))
    result = SubsetResult(pf, cov, cov_upper, lower, upper, settings.confidence, tuple(levels), status, message,
                          Evaluations(z, lev, resp))
    if settings.n_per_level >= MIN_N_INTERVAL:
        return result
    return replace(result, lower=float("nan"), upper=float("nan"),
                   interval=f"below N = {MIN_N_INTERVAL} draws per level it would not reach its coverage "
                            "(docs/reliability.md)")


# draws per level from which the interval's stated coverage is measured (docs/reliability.md,
# `python benchmarks/subset_verification.py -n N`: at N = 100 one case covered 93.5 % of a 95 % interval)
MIN_N_INTERVAL = 300


def _level_record(r, threshold, level, evaluations, acceptance, scale) -> LevelRecord:
    """The record of a level whose states (chains, steps) have responses ``r`` above ``threshold``; its CoV
    takes gamma >= 0 (few chains can estimate gamma below -1, and no chain is less correlated than
    independent draws)."""
    hits = r > threshold
    p = float(hits.mean())
    gamma = 0.0 if level == 0 else chain_gamma(hits)
    cov = math.sqrt((1 - p) / (p * r.size) * (1 + max(gamma, 0.0))) if p > 0 else float("inf")
    return LevelRecord(float(threshold), p, evaluations, acceptance, scale, gamma, cov)


def _first_level_extreme(r, threshold, record0, records, settings):
    """A result when level 0 already decides (every draw fails, or a constant response below the
    threshold), else None."""
    n = r.size
    if np.all(r > threshold):
        return _plain_level_zero(_finish([record0], 1.0, records, "certain",
                                         f"all {n} level-0 draws exceed the threshold: P is 1 to within this sample",
                                         settings), n, n)
    if np.all(r == r.flat[0]):
        return _plain_level_zero(_finish([record0], 0.0, records, "impossible",
                                         f"the response is {r.flat[0]:g} at all {n} level-0 draws, below the "
                                         "threshold: P is 0 to within this sample (no subset level can start)",
                                         settings), 0, n)
    return None


def _plain_level_zero(result: SubsetResult, k: int, n: int) -> SubsetResult:
    """A result level 0 decided: its draws are plain Monte Carlo, so its interval is the exact binomial one of
    k of n (a CoV of 0 or none gives no log-normal interval: [1, 1] would claim certainty). Its CoV is
    undefined (NaN): the plug-in sqrt((1 - p) / (N p)) is 0 at p = 1, which no sample of N can claim."""
    lower, upper = clopper_pearson(k, n, result.confidence)
    return replace(result, lower=float(lower), upper=float(upper), cov=float("nan"), cov_upper=float("nan"),
                   interval=f"exact binomial (Clopper-Pearson) of {k} of {n} level-0 draws, plain Monte Carlo")


def subset_simulation(response, dimension: int, threshold: float = 0.0,
                      settings: SubsetSettings = SubsetSettings(), unit: tuple[str, float] = ("", 1.0)) -> SubsetResult:
    """P(response(z) > threshold), z ~ N(0, I_d); ``response`` maps an (m, d) array to (m,) responses
    and is called once per level-0 batch and once per chain step (module doc). ``unit``: the name and
    size (in the response's units) that messages give thresholds in."""
    nc, d = settings.chains, int(dimension)
    z, r = _level_zero(response, d, settings)
    records = [(z.reshape(-1, d), np.zeros(r.size, int), r.ravel())]
    levels, scale, pf = [], np.nan, 1.0
    early = _first_level_extreme(r, threshold, _level_record(r, threshold, 0, r.size, np.nan, np.nan),
                                 records, settings)
    if early is not None:
        return early
    acceptance, previous = np.nan, -np.inf
    for level in range(settings.max_levels):
        b, seeds = _next_threshold(r, nc)
        evaluations = r.size if level == 0 else (settings.steps - 1) * nc
        if b >= threshold:
            levels.append(_level_record(r, threshold, level, evaluations, acceptance, scale))
            return _finish(levels, pf * levels[-1].probability, records, "converged",
                           f"{level + 1} levels", settings)
        if not b > previous:
            return _finish(levels, float("nan"), records, "stalled",
                           f"level {level}: the threshold {b / unit[1]:g}{unit[0] and ' ' + unit[0]} does not rise; "
                           "the response may be flat or discontinuous here", settings)
        levels.append(_level_record(r, b, level, evaluations, acceptance, scale))
        pf, previous = pf * levels[-1].probability, b
        (z, r), (cz, cr), acceptance, scale = _grow_chains(response, z.reshape(-1, d)[seeds],
                                                           r.ravel()[seeds], b, level + 1, settings)
        records.append((cz, np.full(cr.size, level + 1), cr))
    return _finish(levels, float("nan"), records, "max_levels",
                   f"no convergence within {settings.max_levels} levels: P < {settings.p0 ** settings.max_levels:g}?",
                   settings)
