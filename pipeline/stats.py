"""Statistics of an ensemble file: functions of a Dataset, the same on a file written yesterday.

For each quantity and direction, across the finished realisations, of both the
per-realisation max |error| and mean |error|: mean, std, standard error,
quantiles 0.05/0.5/0.95/0.99 (numpy's default, linear interpolation) and the
maximum, each with a 95 % confidence interval:
- mean: Student t;  std: chi-square;  sem: the std interval over sqrt(n);
- quantiles: distribution-free, from order statistics (binomial ranks);
- maximum: percentile bootstrap (2000 resamples from a fixed seed), which can
  only bracket the largest value seen, not the population maximum.
"""
from __future__ import annotations

import numpy as np
from scipy import stats as sps

from .store import display_unit

__all__ = ["QUANTILES", "summarize", "ensemble_stats", "format_stats"]

QUANTILES = {"q05": 0.05, "q50": 0.5, "q95": 0.95, "q99": 0.99}
LEVEL = 0.95


def _quantile_ci(sorted_x: np.ndarray, p: float) -> list[float]:
    n = len(sorted_x)
    lo = int(sps.binom.ppf((1 - LEVEL) / 2, n, p))          # 0-based ranks
    hi = int(sps.binom.ppf(1 - (1 - LEVEL) / 2, n, p))
    return [float(sorted_x[max(lo - 1, 0)]), float(sorted_x[min(hi, n - 1)])]


def summarize(x: np.ndarray, bootstrap_seed: int = 0) -> dict:
    """Summary statistics of one sample with 95 % confidence intervals (see module doc)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    n = len(x)
    if n == 0:
        nan = float("nan")
        return {k: nan for k in ("mean", "std", "sem", *QUANTILES, "max")} | {"n": 0, "ci95": {}}
    mean = float(np.mean(x))
    std = float(np.std(x, ddof=1)) if n > 1 else float("nan")
    sem = std / np.sqrt(n) if n > 1 else float("nan")
    out = {"n": n, "mean": mean, "std": std, "sem": sem}
    out.update({k: float(np.quantile(x, p)) for k, p in QUANTILES.items()})
    out["max"] = float(np.max(x))
    ci = {}
    if n > 1:
        t = sps.t.ppf(0.5 + LEVEL / 2, n - 1)
        ci["mean"] = [mean - t * sem, mean + t * sem]
        chi_lo, chi_hi = sps.chi2.ppf([0.5 + LEVEL / 2, 0.5 - LEVEL / 2], n - 1)
        ci["std"] = [std * np.sqrt((n - 1) / chi_lo), std * np.sqrt((n - 1) / chi_hi)]
        ci["sem"] = [v / np.sqrt(n) for v in ci["std"]]
    else:
        ci.update({k: [float("nan")] * 2 for k in ("mean", "std", "sem")})
    sx = np.sort(x)
    ci.update({k: _quantile_ci(sx, p) for k, p in QUANTILES.items()})
    rng = np.random.default_rng(bootstrap_seed)
    boot = x[rng.integers(0, n, size=(2000, n))].max(axis=1)
    ci["max"] = [float(v) for v in np.quantile(boot, [(1 - LEVEL) / 2, 0.5 + LEVEL / 2])]
    out["ci95"] = {k: [float(a), float(b)] for k, (a, b) in ci.items()}
    return out


def ensemble_stats(ds, quantity: str | None = None, direction: str | None = None) -> dict:
    """``{"n_realizations": N, "stats": {quantity: {direction: {"max": .., "mean": ..}}}}``, SI."""
    finished = ds["status"].values == "finished"
    quantities = [quantity] if quantity else [str(q) for q in ds.quantity.values]
    directions = [direction] if direction else [str(d) for d in ds.direction.values]
    for name, given, allowed in (("quantity", quantity, ds.quantity.values),
                                 ("direction", direction, ds.direction.values)):
        if given and given not in allowed:
            raise ValueError(f"unknown {name} {given!r}; choose one of {', '.join(map(str, allowed))}")
    out = {}
    for q in quantities:
        out[q] = {}
        for d in directions:
            out[q][d] = {stat: summarize(ds[f"{stat}_abs_error"].sel(quantity=q, direction=d)
                                         .values[finished]) for stat in ("max", "mean")}
    return {"n_realizations": int(finished.sum()), "n_failed": int((~finished).sum()), "stats": out}


def format_stats(result: dict) -> str:
    """A table in the paper's display units (mm, mm/s, mm/s^2 and rad, rad/s, rad/s^2)."""
    cols = ("mean", "std", "q05", "q50", "q95", "q99", "max")
    lines = [f"{result['n_realizations']} finished realisations ({result['n_failed']} failed); "
             "'max' rows: per-realisation max |error|, 'mean' rows: per-realisation mean |error|; "
             "[lo, hi] = 95 % confidence interval of the mean",
             f"{'quantity':<13s}{'dir':<4s}{'of':<5s}{'unit':<8s}" + "".join(f"{c:>11s}" for c in cols)
             + f"{'mean 95% CI':>25s}"]
    for q, by_dir in result["stats"].items():
        for d, by_stat in by_dir.items():
            f, unit = display_unit(q, d)
            for stat, s in by_stat.items():
                ci = s["ci95"].get("mean", [float("nan")] * 2)
                lines.append(f"{q:<13s}{d:<4s}{stat:<5s}{unit:<8s}"
                             + "".join(f"{s[c] * f:11.4g}" for c in cols)
                             + f"   [{ci[0] * f:.4g}, {ci[1] * f:.4g}]")
    return "\n".join(lines)
