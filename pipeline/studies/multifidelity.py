"""Multi-fidelity means: a cheap level on many realisations as a control variate for a dear level.

Realisation r of a seeded ensemble draws from the stream (seed, r) only, so the
first N realisations of a low-level ensemble of M >= N are the same clearance
draws as the N of a high-level ensemble.  With Y the high level's and X the low
level's per-realisation statistic (e.g. max |error| in x), the two-model
multi-fidelity Monte Carlo estimator (Peherstorfer, Willcox, Gunzburger 2016;
the classic control variate with the low mean estimated from M samples) is

    mu = mean_N(Y) + alpha * (mean_M(X) - mean_N(X)),  alpha = cov_N(Y, X) / var_N(X),

unbiased up to the O(1/N) bias of the estimated alpha (measured: within the
sampling noise over 20 000 repetitions, tests/test_multifidelity.py).  Its variance
is var(Y)/N * (1 - (1 - N/M) rho^2): the variance reduction 1/(1 - (1 - N/M) rho^2)
over plain Monte Carlo on the same N, which tends to 1/(1 - rho^2) for M >> N;
N times it is the equivalent plain-MC sample size.

Interval: with Z = Y - alpha X on the N pairs, the standard error
se = sqrt(var(Z)/N + alpha^2 var_M(X)/M) (var(Z) with N - 2 degrees of freedom, alpha
being fitted).  Student t with N - 2 degrees of freedom on se covered >= 93.6 % on normal,
gamma(2) and Laplace margins from N = MIN_N_MF = 32 (91.5 % for gamma(2) at N = 8-16, so
below 32 the interval is withheld), but only 88.5-94.9 % on margins of skewness 2-2.9
(exponential, lognormal(0.75), chi2(1)) at N = 32-64, mostly missing below the mean
(benchmarks/multifidelity_coverage.py, 4000 repetitions per cell).  So the interval is the
union of that t interval and the plain mean's interval (Student t and Hall's skewness
correction, :func:`pipeline.analysis.estimators.mean_interval`) of the residuals Z around the
estimate, its half-widths scaled by se / (sd(Z) / sqrt(N)), both at the level
1 - MF_WIDENING (1 - confidence): 95.5-98.3 % on those margins and 97.7-98.8 % on normal and
gamma(2) ones at N = 32-64, M/N = 4 and 32, rho = 0.5-0.95 (the same benchmark);
tests/test_multifidelity.py repeats N = 32 and 64 with 10 000
repetitions per cell and a real pair of quasi-static ensembles.  The widening costs the
interval about z_L / z_c = 1.19 in width against a plain-MC interval at the label, so the
sizes and costs for a given width (:func:`_costs`) carry that factor squared (:func:`width_cost`,
1.41 at 95 %).
The reported variance reduction
(:func:`estimated_variance_reduction`) corrects the sample correlation's upward bias and
the factor (N - 2)/(N - 3) the fitted alpha costs; its median over repetitions is within
3 % of the measured reduction at N = 32 (tests).

Only the mean: a quantile or exceedance probability would take the indicator
1{Y > t} as the statistic, whose correlation with 1{X > t'} is much weaker than
that of the maxima themselves (0.47 for rho = 0.8 at the 95 % level of a normal pair,
a variance reduction of 1.28), and a Wald-type interval for a probability near 0.05 at
N = 64 under-covers (Brown, Cai, DasGupta 2001), so none is offered.

Cost: with c the cost of a high realisation over a low one, the cost-optimal M/N is
sqrt(c rho^2 / (1 - rho^2)) and the cost over plain MC for the same interval width is
(sqrt(1 - rho^2) + sqrt(rho^2 / c))^2 (Peherstorfer et al. 2016); above about 1 the
cheap level does not pay.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr
from scipy import stats as sps

from rss6core import FINISHED, models_with

from ..analysis.estimators import BOUNDS, LOWEST_MEASURED, mean_interval, moment_floor, short_of_label
from ..analysis.stats import below_floor, in_window, json_number, table_cell
from ..files.outputs import REQUEST_ATTR  # noqa: F401  (re-exported: the attribute of the request a file answers)
from ..files.records import file_window_label
from ..vocabulary import CONFIDENCE, SUMMARIES, UNMEASURED_LEVEL, at_measured_level

__all__ = ["MIN_N_MF", "MF_WIDENING", "mf_floor", "interval_notes", "result_notes", "width_cost", "ESTIMATORS",
           "ControlVariateMean", "control_variate_mean",
           "variance_reduction", "estimated_variance_reduction", "adjusted_correlation",
           "optimal_low_ratio", "cost_ratio", "paired_values", "multifidelity_dataset",
           "format_multifidelity", "to_json", "level_paths"]

HISTORY = "rss6 multifidelity"   # how the last line of a multi-fidelity file's history begins
MIN_N_MF = 32   # smallest N whose interval coverage was measured on all laws (module doc)
MF_WIDENING = 0.4   # the interval is taken at the level 1 - MF_WIDENING (1 - confidence) (module doc)
SKEWED_COVERAGE = ("the union of Student t and the residuals' skewness-corrected interval, at 1 - 0.4 (1 - "
                   "confidence): a 95 % interval covered 95.5-98.3 % on margins of skewness 2-2.9 at "
                   "N = 32-64 (python benchmarks/multifidelity_coverage.py)")
ESTIMATORS = ("multifidelity", "high_only")


def mf_floor(confidence: float) -> int | None:
    """Smallest N with a multi-fidelity interval at ``confidence``: MIN_N_MF (measured at 95 %), and at least the
    plain mean's floor at that level (pipeline.analysis.estimators.moment_floor: 64 at 99 %), as the high-only
    column's; None where the plain mean has none at any n."""
    floor = moment_floor("mean", confidence)
    return None if floor is None else max(MIN_N_MF, floor)


def interval_notes(confidence: float, n_high: int) -> list[str]:
    """What the intervals at ``confidence`` rest on, for the table's notes, the JSON and the file: the MF
    bounds' coverage measured at 95 % only, the high-only mean's measured from LOWEST_MEASURED up (rss6 stats'
    note), and why the high-only column (the plain mean, as rss6 stats gives it) is a dash."""
    conf, notes = f"{100 * confidence:g} %", []
    if not at_measured_level(confidence):
        floor = mf_floor(confidence)
        given = (f"at this label they are given from N = {floor} (the larger of {MIN_N_MF} and the plain mean's "
                 "floor)" if floor is not None else "none at any N, as the plain mean's")
        notes.append(f"MF bounds at {conf}: {UNMEASURED_LEVEL} (python benchmarks/multifidelity_coverage"
                     f".py); {given}")
    if confidence < LOWEST_MEASURED - 1e-12:
        notes.append(f"confidence {conf}: the high-only mean's coverage was measured from "
                     f"{100 * LOWEST_MEASURED:g} % up (docs/ensembles.md), as rss6 stats says")
    plain = moment_floor("mean", confidence)
    if plain is None:
        notes.append(f"high only: no {conf} interval at any n: {short_of_label('mean')} (rss6 stats' mean)")
    elif n_high < plain:
        notes.append(f"high only: no {conf} interval below n = {plain} (n = {n_high} here), as rss6 stats' mean")
    return notes


@dataclass(frozen=True)
class ControlVariateMean:
    """The multi-fidelity mean per cell (arrays over the trailing axes of the data)."""
    estimate: np.ndarray
    lower: np.ndarray            # NaN below mf_floor(confidence)
    upper: np.ndarray
    correlation: np.ndarray      # sample correlation of Y and X on the N pairs
    coefficient: np.ndarray      # alpha, the fitted control-variate coefficient
    variance_reduction: np.ndarray
    equivalent_n: np.ndarray     # plain-MC sample size of the same variance
    n_high: int
    n_low: int


def variance_reduction(rho, n_high: int, n_low: int):
    """Var(plain MC on n_high) / Var(multi-fidelity): 1 / (1 - (1 - n_high/n_low) rho^2)."""
    rho = np.asarray(rho, float)
    with np.errstate(divide="ignore"):
        return 1.0 / (1.0 - (1.0 - n_high / n_low) * rho ** 2)


def estimated_variance_reduction(r, n_high: int, n_low: int):
    """The variance reduction estimated from the sample correlation ``r`` of n_high pairs: the
    closed form at the adjusted rho^2 = 1 - (1 - r^2)(N - 1)/(N - 2), times the (N - 3)/(N - 2)
    the fitted coefficient costs (about unbiased in the median; the plug-in r^2 overstates it)."""
    return (n_high - 3) / (n_high - 2) * variance_reduction(adjusted_correlation(r, n_high),
                                                            n_high, n_low)


def adjusted_correlation(r, n: int):
    """sqrt of the adjusted rho^2 = max(0, 1 - (1 - r^2)(n - 1)/(n - 2)) of n pairs: the plug-in
    r^2 overstates rho^2 by about (1 - rho^2)/n."""
    return np.sqrt(np.maximum(1 - (1 - np.asarray(r, float) ** 2) * (n - 1) / (n - 2), 0.0))


def optimal_low_ratio(rho, cost_high_over_low: float):
    """The cost-optimal M/N, sqrt(c rho^2 / (1 - rho^2)) for a cost ratio c (at least 1)."""
    rho2 = np.minimum(np.asarray(rho, float) ** 2, 1 - 1e-12)
    return np.maximum(np.sqrt(cost_high_over_low * rho2 / (1 - rho2)), 1.0)


def cost_ratio(rho, cost_high_over_low: float, low_ratio=None):
    """Cost of the multi-fidelity estimator over plain MC for the same variance,
    (1 - (1 - 1/r) rho^2) (1 + r / c), at M/N = r (default: the optimal r)."""
    r = optimal_low_ratio(rho, cost_high_over_low) if low_ratio is None else np.asarray(low_ratio)
    rho2 = np.asarray(rho, float) ** 2
    return (1 - (1 - 1 / r) * rho2) * (1 + r / cost_high_over_low)


def _interval(estimate, resid, se, level: float):
    """(lower, upper) at ``level``: the union of Student t (N - 2 degrees of freedom) on the standard
    error ``se`` and the residuals' mean interval (Student t and Hall) around ``estimate``, its
    half-widths scaled from the residuals' own standard error to ``se`` (module doc)."""
    n = resid.shape[0]
    half = sps.t.ppf(0.5 + level / 2, n - 2) * se
    with np.errstate(all="ignore"):
        scale = np.where(se > 0, se / (resid.std(axis=0, ddof=1) / np.sqrt(n)), 0.0)
        low, high = mean_interval(resid, level, own_floor=MIN_N_MF)   # around the residuals' mean, 0
    return (estimate - np.maximum(half, np.nan_to_num(-low * scale)),
            estimate + np.maximum(half, np.nan_to_num(high * scale)))


def width_cost(confidence: float) -> float:
    """(z_L / z_c)^2: the sample-size factor the widened level L = 1 - MF_WIDENING (1 - c) costs the
    interval against a plain-MC one at the label c, for the same width (normal quantiles)."""
    return float((sps.norm.ppf(1 - MF_WIDENING * (1 - confidence) / 2) / sps.norm.ppf(0.5 + confidence / 2)) ** 2)


def control_variate_mean(y: np.ndarray, x: np.ndarray, confidence: float = CONFIDENCE) -> ControlVariateMean:
    """The multi-fidelity mean of ``y`` (N, ...) with the control variate ``x`` (M, ...), M >= N,
    whose first N rows are the same draws as ``y``'s; all values finite."""
    y, x = np.asarray(y, float), np.asarray(x, float)
    n, m = y.shape[0], x.shape[0]
    if n < 3 or m < n:
        raise ValueError(f"need at least 3 finished high realisations and at least as many low ones "
                         f"(got {n} and {m})")
    xp = x[:n]
    dy, dx = y - y.mean(axis=0), xp - xp.mean(axis=0)
    sxx, syy, sxy = (dx * dx).sum(axis=0), (dy * dy).sum(axis=0), (dx * dy).sum(axis=0)
    with np.errstate(all="ignore"):
        alpha = np.where(sxx > 0, sxy / sxx, 0.0)
        rho = np.where((sxx > 0) & (syy > 0), sxy / np.sqrt(sxx * syy), 0.0)
    estimate = y.mean(axis=0) + alpha * (x.mean(axis=0) - xp.mean(axis=0))
    resid = dy - alpha * dx
    se = np.sqrt((resid ** 2).sum(axis=0) / (n - 2) / n + alpha ** 2 * x.var(axis=0, ddof=1) / m)
    lower, upper = _interval(estimate, resid, se, 1.0 - MF_WIDENING * (1.0 - confidence))
    floor = mf_floor(confidence)
    given = floor is not None and n >= floor
    lower, upper = np.where(given, lower, np.nan), np.where(given, upper, np.nan)
    vr = estimated_variance_reduction(rho, n, m)
    return ControlVariateMean(estimate, lower, upper, rho, alpha, vr, n * vr, n, m)


# --- two ensemble files ------------------------------------------------------

def _finished(ds: xr.Dataset) -> np.ndarray:
    return np.asarray(ds["status"].values.astype(str) == FINISHED)


def paired_values(high: xr.Dataset, low: xr.Dataset, name: str, window: str = "whole"
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(Y, X) of variable ``name`` in analysis window ``window`` as (realisation, quantity,
    direction): Y over the realisations finished at both levels among the high file's, X over every
    finished low realisation with those pairs first (the control variate's layout)."""
    high, low = in_window(high, window), in_window(low, window)
    ids_h = high["realization"].values
    ok_h = dict(zip(ids_h.tolist(), _finished(high)))
    ok_l = dict(zip(low["realization"].values.tolist(), _finished(low)))
    pairs = [r for r in ids_h.tolist() if ok_h[r] and ok_l.get(r, False)]
    rest = [r for r, ok in ok_l.items() if ok and r not in ok_h]   # draws the high level lacks
    order = ("realization", "quantity", "direction")
    y = high[name].transpose(*order).sel(realization=pairs).values
    x = low[name].transpose(*order).sel(realization=pairs + rest).values
    return y, x


def _check_pairing(high: xr.Dataset, low: xr.Dataset, high_path, low_path) -> None:
    """The pairs must be the same draws: same seed and scene, equal recorded draws (sizes, and
    eccentricities unless a level redraws them every step, as the paper level does, and records
    its first step's)."""
    from ..files.schema import EnsembleFileError
    for key in ("seed", "scene_toml"):
        if str(high.attrs.get(key)) != str(low.attrs.get(key)):
            raise EnsembleFileError(f"{low_path}: a different {key} than {high_path}; the "
                                    "realisations are not the same draws")
    common = np.intersect1d(high["realization"].values, low["realization"].values)
    redrawn = models_with("redraws_every_step")
    per_step = high.attrs.get("model") in redrawn or low.attrs.get("model") in redrawn
    for name in ("clearance_size", "axial_clearance_size") + (() if per_step else ("eccentricity",)):
        if not np.array_equal(high[name].sel(realization=common).values,
                              low[name].sel(realization=common).values, equal_nan=True):
            raise EnsembleFileError(f"{low_path}: its recorded {name} differs from {high_path}'s "
                                    "for the same realisations; the files are not a pair")


def _estimates(high: xr.Dataset, low: xr.Dataset, name: str, confidence: float) -> dict:
    """The data variables of one summary ``name`` (both estimators and the diagnostics)."""
    y, x = paired_values(high, low, name)
    cv = control_variate_mean(y, x, confidence)
    plain = np.concatenate([[y.mean(axis=0)], mean_interval(y, confidence)])
    mf = np.stack([cv.estimate, cv.lower, cv.upper])
    cells = ("quantity", "direction")
    src = high[name].attrs
    one = {"units": "1"}
    return {
        f"{name}_mean": (("estimator", "bound") + cells, np.stack([mf, plain]),
                         {"long_name": f"mean over realisations of {name} of the high level",
                          "units": src.get("units", "")}),
        f"{name}_correlation": (cells, cv.correlation,
                                {**one, "long_name": f"correlation of {name} between the levels "
                                                     "on the paired realisations"}),
        f"{name}_coefficient": (cells, cv.coefficient,
                                {**one, "long_name": "fitted control-variate coefficient alpha"}),
        f"{name}_variance_reduction": (cells, cv.variance_reduction,
                                       {**one, "long_name": "estimated variance of plain MC on the "
                                                            "high realisations over the multi-"
                                                            "fidelity variance"}),
        f"{name}_equivalent_n": (cells, cv.equivalent_n,
                                 {**one, "long_name": "plain Monte Carlo sample size of the same "
                                                      "variance"}),
    }


def multifidelity_dataset(high: xr.Dataset, low: xr.Dataset, confidence: float = CONFIDENCE,
                          sources=("high", "low"), cost_high_over_low: float | None = None,
                          width: float | None = None, window: str = "whole") -> xr.Dataset:
    """Multi-fidelity and high-only means of every per-realisation summary (SI units, the source
    files' layout), with correlation, variance reduction and equivalent plain-MC size per cell.
    With a cost ratio (one high realisation over one low one) also the cost-optimal M/N and the
    cost relative to plain MC for the same interval width; with a relative half-width ``width``
    too, the realisations each method needs to reach it; all in analysis window ``window``."""
    where = {"window": window, "analysis_window": file_window_label(window, high.attrs)}
    high, low = in_window(high, window), in_window(low, window)
    _check_pairing(high, low, *sources)
    data = {}
    for name in SUMMARIES:
        data |= _estimates(high, low, name, confidence)
    n_pairs = int(np.sum(_finished(high) & np.isin(high["realization"].values,
                                                    low["realization"].values[_finished(low)])))
    ds = xr.Dataset(data, coords={"estimator": list(ESTIMATORS), "bound": list(BOUNDS),
                                  "quantity": high["quantity"].values,
                                  "direction": high["direction"].values,
                                  "unit": high["unit"]})
    if cost_high_over_low is not None:
        for name in SUMMARIES:
            ds = ds.assign(_costs(ds, paired_values(high, low, name)[0], name, cost_high_over_low,
                                  width, confidence))
    return ds.assign_attrs(_attrs(high, low, confidence, sources, n_pairs, cost_high_over_low,
                                  width) | where)


def _costs(ds: xr.Dataset, y: np.ndarray, name: str, cost: float, width, confidence) -> dict:
    """The cost variables of summary ``name``: optimal M/N, cost over plain MC, and with a relative
    half-width the sample sizes reaching it (normal approximation, standard deviation of y), all
    at the adjusted correlation, the multi-fidelity ones with its widened interval's factor
    (:func:`width_cost`)."""
    cells, one = ("quantity", "direction"), {"units": "1"}
    rho = adjusted_correlation(ds[f"{name}_correlation"].values, y.shape[0])
    ratio, widened = optimal_low_ratio(rho, cost), width_cost(confidence)
    out = {f"{name}_optimal_low_ratio": (cells, ratio, {**one, "long_name": "cost-optimal ratio of "
                                                        "low to high realisations"}),
           f"{name}_cost_ratio": (cells, widened * cost_ratio(rho, cost), {**one, "long_name": "multi-fidelity "
                                  "cost over plain MC cost for the same interval width, at the "
                                  "optimal ratio"})}
    if width is None:
        return out
    mean = np.abs(ds[f"{name}_mean"].sel(estimator="multifidelity", bound="estimate").values)
    z = sps.norm.ppf(0.5 + confidence / 2)
    plain = np.maximum(np.ceil((z * y.std(axis=0, ddof=1) / (width * mean)) ** 2),
                       moment_floor("mean", confidence) or np.nan)
    high = np.maximum(np.ceil(plain * widened * (1 - (1 - 1 / ratio) * rho ** 2)),   # none below its floor
                      mf_floor(confidence) or np.nan)
    return out | {
        f"{name}_plain_n_for_width": (cells, plain, {**one, "long_name": "plain MC high "
                                      "realisations for the relative half-width"}),
        f"{name}_high_n_for_width": (cells, high, {**one, "long_name": "multi-fidelity high "
                                     "realisations for the relative half-width"}),
        f"{name}_low_n_for_width": (cells, np.maximum(np.ceil(ratio * high), high), {**one, "long_name":
                                    "multi-fidelity low realisations for the relative half-width"})}


def _name(path) -> str:
    """A source file by its name alone (a folder path says where it was, not what it is)."""
    from pathlib import Path
    return Path(str(path)).name


def _history(high, low, sources) -> str:
    """The two ensembles' histories, then this command's line (last, starting with HISTORY)."""
    from ..files.schema import derived_history
    line = f"{HISTORY} of {_name(sources[0])} and {_name(sources[1])}"
    return derived_history(high, derived_history(low, line))


def _attrs(high, low, confidence, sources, n_pairs: int, cost, width) -> dict:
    from rss6core import __version__
    a = high.attrs
    return {"Conventions": "CF-1.10", "source": f"rss6 {__version__}", "rss6_version": __version__,
            "title": f"rss6 multi-fidelity means: {a['model']} level with {low.attrs['model']} "
                     f"as control variate, scene {a.get('scene_name', '')!r}",
            "history": _history(high, low, sources),
            "scene_name": a.get("scene_name", ""), "scene_toml": a["scene_toml"], "seed": a["seed"],
            "high_model": a["model"], "low_model": low.attrs["model"],
            "high_file": _name(sources[0]), "low_file": _name(sources[1]),
            "n_high": n_pairs, "n_low": int(_finished(low).sum()),
            "n_high_failed": int((~_finished(high)).sum()), "n_low_failed": int((~_finished(low)).sum()),
            "confidence": confidence,
            "estimator": "two-model multi-fidelity Monte Carlo (control variate, optimal fitted "
                         "coefficient, low mean from all low realisations)",
            "interval_multifidelity": f"{SKEWED_COVERAGE}; NaN for "
                                      + (f"N < {mf_floor(confidence)}" if mf_floor(confidence) else "every N"),
            "interval_high_only": "pipeline.analysis.estimators mean interval; NaN for "
                                  f"{below_floor('mean', confidence)}",
            "min_n_multifidelity": mf_floor(confidence) or 0,   # 0: none at any N
            "interval_coverage": "; ".join(interval_notes(confidence, n_pairs))
            or "measured at 95 % (interval_multifidelity, interval_high_only)",
            "statistics_offered": "mean only (quantiles and exceedance probabilities: see "
                                  "pipeline/multifidelity.py)",
            **({"cost_high_over_low": cost} if cost is not None else {}),
            **({"relative_half_width": width} if width is not None and cost is not None else {})}


# --- output ------------------------------------------------------------------------

def to_json(mds: xr.Dataset) -> dict:
    """Strict-JSON view (None for a missing number), SI units:
    {variable: {quantity: {direction: {field: value}}}} plus the attributes."""
    out = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in mds.attrs.items()
           if k != "scene_toml"}
    fields = [f for f in ("correlation", "coefficient", "variance_reduction", "equivalent_n",
                          "optimal_low_ratio", "cost_ratio", "plain_n_for_width", "high_n_for_width",
                          "low_n_for_width") if f"max_abs_error_{f}" in mds]
    for name in SUMMARIES:
        out[name] = {str(q): {str(d): {
            **{f"{e}_{b}": json_number(mds[f"{name}_mean"].sel(estimator=e, bound=b, quantity=q,
                                                          direction=d))
               for e in ESTIMATORS for b in BOUNDS},
            **{f: json_number(mds[f"{name}_{f}"].sel(quantity=q, direction=d)) for f in fields}}
            for d in mds.direction.values} for q in mds.quantity.values}
    from ..files.schema import unit_json
    out["unit"] = unit_json()
    return out


_WIDTH_COLUMNS = {"plain_n_for_width": "n MC", "high_n_for_width": "N MF", "low_n_for_width": "M MF"}


def _extra_columns(mds: xr.Dataset, name: str) -> dict:
    """The optional columns present in ``mds``: {variable suffix: header}."""
    return {k: v for k, v in {"cost_ratio": "cost MF/MC", **_WIDTH_COLUMNS}.items()
            if f"{name}_{k}" in mds}


def _row(mds: xr.Dataset, name: str, q, d) -> str:
    from ..files.schema import display_unit
    f, unit = display_unit(str(q), str(d))
    m = mds[f"{name}_mean"].sel(quantity=q, direction=d)

    def at(field):
        return float(mds[f"{name}_{field}"].sel(quantity=q, direction=d))
    cells = "".join(table_cell(float(m.sel(estimator=e, bound=b)), f, 10) for e in ESTIMATORS for b in BOUNDS)
    extra = "".join(table_cell(at(k)) for k in _extra_columns(mds, name))
    return (f"{q:<13s}{d:<4s}{unit:<8s}{cells}{at('correlation'):7.2f}"
            f"{at('variance_reduction'):7.2f}{at('equivalent_n'):8.0f}{extra}")


def format_multifidelity(mds: xr.Dataset, name: str = "max_abs_error") -> str:
    """A table of the means of ``name`` in display units (mm, mm/s, mm/s^2; rad, rad/s, rad/s^2):
    multi-fidelity and high-only estimate and bounds, correlation, variance reduction, equivalent
    plain-MC n, and the cost columns when known."""
    a = mds.attrs
    extra = _extra_columns(mds, name)
    lines = [f"mean of per-realisation {name}, window {a.get('analysis_window', 'whole run')}: "
             f"{a['high_model']} level on N = {a['n_high']} with {a['low_model']} on M = {a['n_low']} "
             f"as control variate; two-sided {100 * a['confidence']:g} % bounds",
             f"{'quantity':<13s}{'dir':<4s}{'unit':<8s}{'MF':>10s}{'lower':>10s}{'upper':>10s}"
             f"{'high only':>10s}{'lower':>10s}{'upper':>10s}{'rho':>7s}{'VR':>7s}{'n_eq':>8s}"
             + "".join(f"{h:>11s}" for h in extra.values())]
    lines += [_row(mds, name, q, d) for q in mds.quantity.values for d in mds.direction.values]
    notes = ["rho: correlation between the levels; VR: variance reduction over plain MC on the same N; "
             "n_eq: plain-MC sample size of the same variance"]
    if "cost_ratio" in extra:
        notes.append(f"cost MF/MC: multi-fidelity over plain-MC cost for the same interval width at "
                     f"the optimal M/N (one {a['high_model']} realisation costs "
                     f"{a['cost_high_over_low']:g} {a['low_model']} ones); above 1 it does not pay")
    if "plain_n_for_width" in extra:
        notes.append(f"n MC, N MF, M MF: realisations for a half-width of "
                     f"{100 * a['relative_half_width']:g} % of the mean (normal approximation)")
    floor = mf_floor(a["confidence"])
    if floor is None or a["n_high"] < floor:
        notes.append(f"MF: no {100 * a['confidence']:g} % interval "
                     + (f"below N = {floor}" if floor else "at any N") + f" (N = {a['n_high']} here); rho, VR, n_eq "
                     f"and every size and cost column are point estimates from these {a['n_high']} pairs, "
                     "without an interval")
    notes.append(f"MF bounds: {SKEWED_COVERAGE}")
    notes += result_notes(mds, name)
    return "\n".join(lines + ["notes:"] + [f"  {t}" for t in notes])


def result_notes(mds: xr.Dataset, name: str = "max_abs_error") -> list[str]:
    """The notes on a file's intervals (:func:`interval_notes`) and where its control variate costs precision
    (:func:`_costly_note`): the table's, and its JSON's and file's table_notes."""
    return interval_notes(float(mds.attrs["confidence"]), int(mds.attrs["n_high"])) + _costly_note(mds, name)


def _costly_note(mds: xr.Dataset, name: str) -> list[str]:
    """Rows whose VR is below 1: the control variate adds variance there (|rho| too small to pay for the
    fitted coefficient), so the high-only mean is the better estimate (docs/ensembles.md: it gains nothing)."""
    vr = mds[f"{name}_variance_reduction"]
    rows = [f"{q} {d}" for q in vr["quantity"].values for d in vr["direction"].values
            if float(vr.sel(quantity=q, direction=d)) < 1]
    if not rows:
        return []
    named = "all" if len(rows) == vr.size else ", ".join(rows[:6]) + (", ..." if len(rows) > 6 else "")
    return [f"VR < 1 in {len(rows)} rows ({named}): the control variate costs precision there (|rho| small), "
            "the high-only mean is the better estimate there; where it gains nothing, use plain rss6 run"]


def check_multifidelity_output(path, request: dict, create_dirs: bool = False):
    """The output F.nc checked before any work: a file there must be an earlier multi-fidelity file of
    the same ``request`` (:func:`pipeline.files.outputs.answered_request`: a rerun resumes the two ensembles
    and rewrites it); any other file, or one answering another request, is refused, not overwritten."""
    from ..files.outputs import answered_request, check_output_path
    answered_request(path, "multifidelity", request, create_dirs, "multi-fidelity")
    return check_output_path(path)




def level_paths(output) -> tuple:
    """The two ordinary ensemble files beside the multi-fidelity file F.nc: F.high.nc, F.low.nc."""
    from pathlib import Path
    output = Path(output)
    stem = output.name[:-3] if output.name.endswith(".nc") else output.name
    return output.with_name(f"{stem}.high.nc"), output.with_name(f"{stem}.low.nc")
