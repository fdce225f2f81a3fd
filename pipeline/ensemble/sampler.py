"""How an ensemble's clearance draws are sampled: plain Monte Carlo or randomised quasi-Monte Carlo.

``mc`` (the default): realisation r draws from its own random stream
SeedSequence([seed, r]) (rss6core/clearance.py); the file carries no sampler
attributes, so mc files are what they were before samplers existed.

``qmc``: R independent scramblings (replicates) of a Sobol' sequence
(``scipy.stats.qmc.Sobol``, linear matrix scrambling plus digital shift),
replicate k scrambled from SeedSequence([seed, k, QMC_TAG]).  Realisation r is
point r // R of replicate r % R, mapped through the clearance laws' inverse CDFs
(:func:`rss6core.clearance.clearances_from_uniforms`); so the realisation set,
like mc's, does not depend on chunking or workers, and n = R m realisations are
the first m points of every replicate.  The R replicate estimates are independent
and unbiased (mean) or nearly so (quantiles, std), which gives the honest
interval of pipeline/analysis/estimators.py (Student t over the replicates).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from rss6core import SIZE_UNIFORMS

__all__ = ["SAMPLERS", "DEFAULT_REPLICATES", "QMCDesign", "design_of", "check_qmc"]

SAMPLERS = ("mc", "qmc")
DEFAULT_REPLICATES = 8
QMC_TAG = 5328195            # third SeedSequence word: scramblings never share mc's streams
BLOCK = 64                   # Sobol' points generated (and cached) together
MAX_DIMENSION = 21201        # scipy's Sobol' direction numbers


@dataclass(frozen=True)
class QMCDesign:
    """A randomised QMC design: ``replicates`` scramblings of Sobol' points, seeded by ``seed``."""
    seed: int
    replicates: int

    def point_of(self, realization: int) -> tuple[int, int]:
        """(replicate, point index within it) of a realisation."""
        return realization % self.replicates, realization // self.replicates

    def __call__(self, realization: int, dimension: int) -> np.ndarray:
        """The ``dimension`` uniforms of ``realization`` (rss6core's ``uniforms`` callback).

        The eccentricities take the Sobol' point's first coordinates, whose projections are the
        most even, and the sizes (often fixed, when they have no tolerance) its last ones: at
        n = 8 x 256 this doubled the variance reduction of the mean of a quasi-static maximum."""
        replicate, point = self.point_of(int(realization))
        return np.roll(_block(self.seed, replicate, dimension, point // BLOCK)[point % BLOCK],
                       SIZE_UNIFORMS)

    def attrs(self) -> dict:
        """File attributes: the sampler, R and the realisation -> (replicate, point) mapping."""
        import scipy
        return {"sampler": "qmc", "qmc_replicates": self.replicates,
                "qmc_mapping": f"realisation r is point r // {self.replicates} of replicate "
                               f"r % {self.replicates}; replicate k is scipy.stats.qmc.Sobol(d, "
                               f"scramble=True, rng=SeedSequence([seed, k, {QMC_TAG}])) "
                               f"(scipy {scipy.__version__}); a draw's d uniforms are the point's coordinates "
                               f"d-{SIZE_UNIFORMS}..d-1 (clearance sizes), then 0..d-{SIZE_UNIFORMS + 1}"}


@lru_cache(maxsize=16)
def _block(seed: int, replicate: int, dimension: int, block: int) -> np.ndarray:
    """Points block*BLOCK .. (block+1)*BLOCK-1 of a scrambled Sobol' sequence, (BLOCK, dimension)."""
    from scipy.stats import qmc
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(replicate), QMC_TAG]))
    engine = qmc.Sobol(dimension, scramble=True, rng=rng)
    if block:   # scipy refuses fast_forward(0)
        engine.fast_forward(block * BLOCK)
    return engine.random(BLOCK)


def design_of(attrs: dict) -> QMCDesign | None:
    """The QMC design a file's attributes record; None for a plain Monte Carlo file."""
    if str(attrs.get("sampler", "mc")) != "qmc":
        return None
    return QMCDesign(int(attrs["seed"]), int(attrs["qmc_replicates"]))


def check_qmc(n: int, replicates: int, dimension: int) -> None:
    """ValueError (one line, naming the option) for a QMC run that cannot be honest or built."""
    if replicates < 2:
        raise ValueError(f"--replicates must be 2 or more for an interval, got {replicates}")
    if n % replicates:
        raise ValueError(f"-n {n} with --sampler qmc must be a multiple of --replicates "
                         f"{replicates} (every replicate the same number of points)")
    if dimension > MAX_DIMENSION:
        raise ValueError(f"--sampler qmc: this level draws {dimension} uniforms per realisation "
                         f"(eccentricities redrawn every step), more than the {MAX_DIMENSION} "
                         "dimensions of scipy's Sobol' sequence; use --sampler mc")
