"""Statistics of an ensemble file as one xarray Dataset; every interval holds its stated confidence.

``ensemble_stats(ds)`` summarises, over the finished realisations only, each
realisation's max |error| and mean |error| per quantity and direction: point
estimates (``estimate``) of the mean, the standard deviation (ddof=1), the
quantiles q05/q50/q95/q99 (numpy's default, linear interpolation) and the
sample maximum, and two-sided confidence intervals (``lower``, ``upper``; NaN
where withheld).  Values are SI, in the source file's units.

The intervals, their coverage and the one-sided bounds the requirement gate decides on:
:mod:`pipeline.analysis.estimators`.  ``to_json`` and ``format_stats`` are the Dataset as strict
JSON and as the printed table of ``rss6 stats``.
"""
from __future__ import annotations

import numpy as np
import xarray as xr

from ..files.records import empty_window, file_window_bounds
from ..files.schema import SETTINGS
from ..vocabulary import CONFIDENCE, FINISHED, QUANTILES, STATISTICS, STEP_WORDS, SUMMARIES, counted, step_measured
from .estimators import (BOUNDS, LOWEST_MEASURED, MAX_NOTE, MIN_POINTS_RQMC, STD_WIDENING, UNTIL_WIDENING,
                         bound_level, estimates_and_bounds, interval_floor, min_n_for_quantile, moment_floor,
                         short_of_label, stopped_level, replicate_groups, rqmc_intervals, clipped_at_zero,
                         replicates_note)

__all__ = ["SOURCE_ATTRS", "windows_of", "in_window", "finished_values", "ensemble_stats", "json_number",
           "to_json", "format_stats", "table_notes", "left_out_note", "level_notes", "below_floor", "one_run_repeated"]


def windows_of(ds: xr.Dataset) -> list[str]:
    """The analysis windows of an ensemble, run or statistics Dataset (none without a window dimension)."""
    return [str(w) for w in ds["window"].values] if "window" in ds.dims else []


def check_window_samples(ds: xr.Dataset, window: str) -> None:
    """ValueError if ``window`` of a file holds no sample (:func:`.records.empty_window`): every statistic
    there would be NaN, and a probability or verdict a claim about nothing."""
    empty = empty_window(window, *file_window_bounds(ds.attrs))
    if empty:
        raise ValueError(empty)


def in_window(ds: xr.Dataset, window: str = "whole") -> xr.Dataset:
    """``ds`` with the summaries of analysis window ``window`` (whole, startup, steady), the window
    dimension dropped; a Dataset without windows is returned as it is.  ValueError names an unknown
    window."""
    if "window" not in ds.dims:
        return ds
    if window not in windows_of(ds):
        raise ValueError(f"unknown window {window!r}; choose one of {', '.join(windows_of(ds))}")
    return ds.sel(window=window, drop=True)


def _as_ensemble(ds: xr.Dataset) -> xr.Dataset:
    """A single-run file (``rss6 simulate -o``) as a one-realisation ensemble."""
    if "realization" in ds.dims:
        return ds
    out = ds[list(SUMMARIES)].expand_dims(realization=[0], axis=1)
    return out.assign(status=("realization", [ds.attrs.get("status", FINISHED)]))


def finished_values(ds: xr.Dataset, variable: str, window: str = "whole") -> xr.DataArray:
    """``variable`` of the finished realisations of an ensemble (or single-run) Dataset in analysis
    window ``window`` (realization, quantity, direction); SI."""
    ens = _as_ensemble(in_window(ds, window))
    return ens[variable].isel(realization=np.flatnonzero(ens["status"].values == FINISHED))


def _source(ds: xr.Dataset) -> str:
    """The name of the file ``ds`` was read from (never its folder), or 'an in-memory Dataset'."""
    from pathlib import Path
    source = ds.encoding.get("source")
    return Path(str(source)).name if source else "an in-memory Dataset"


# what a statistics file keeps of its source's provenance (rss6_version as source_rss6_version)
SOURCE_ATTRS = ("scene_name", *SETTINGS.values(), "contact_start", "seed", "realization")


def _provenance(ds: xr.Dataset, confidence: float) -> dict:
    """Title, history (the source's, then this command's line), source, and the source ensemble's
    scene, level, settings, seed, rss6 version and file name."""
    from rss6core import __version__

    from ..files.schema import derived_history
    name, a = _source(ds), ds.attrs
    what = f": {a['model']} level, scene {a.get('scene_name', '')!r}" if "model" in a else ""
    return {"title": f"rss6 statistics of {name}{what}",
            "history": derived_history(ds, f"rss6 stats {name} --confidence {confidence:g} "
                                           "(finished realisations only)"),
            "source": f"rss6 {__version__}", "rss6_version": __version__, "source_file": name,
            **({"source_rss6_version": a["rss6_version"]} if "rss6_version" in a else {}),
            **{k: a[k] for k in SOURCE_ATTRS if k in a}}


def ensemble_stats(ds: xr.Dataset, confidence: float = CONFIDENCE, window: str | None = "whole",
                   one_sided: bool = False, stopped_by_width: bool | None = None) -> xr.Dataset:
    """Statistics (statistic, bound, quantity, direction) of ``max_abs_error`` and
    ``mean_abs_error`` over the finished realisations of an ensemble (or single-run) Dataset, in
    analysis window ``window``; ``window=None``: every window of the file, along a leading window
    dimension (a file without windows gives none).  ``one_sided``: ``lower`` and ``upper`` are
    one-sided bounds, each at ``confidence`` (:mod:`pipeline.analysis.estimators`), not a
    two-sided interval.  ``stopped_by_width``: n was chosen by the intervals' own widths, so the
    quantiles' bounds are widened (default: whether the file was written by ``rss6 run --until``)."""
    if stopped_by_width is None:
        stopped_by_width = "until_rule" in ds.attrs
    repeated = one_run_repeated(ds)   # once per file, not per window: it may parse the scene
    if window is None and "window" in ds.dims:
        parts = [_window_stats(in_window(ds, w), confidence, one_sided, stopped_by_width, repeated)
                 .expand_dims(window=[w]) for w in windows_of(ds)]
        out = xr.concat(parts, dim="window", combine_attrs="override")
        return out.assign_coords(unit=parts[0]["unit"]) if "unit" in parts[0].coords else out
    return _window_stats(in_window(ds, window or "whole"), confidence, one_sided, stopped_by_width, repeated)


def _window_stats(ds: xr.Dataset, confidence: float, one_sided: bool = False,
                  stopped_by_width: bool = False, repeated: bool = False) -> xr.Dataset:
    """:func:`ensemble_stats` of a Dataset without a window dimension (``repeated``: :func:`one_run_repeated`)."""
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")
    if one_sided and not confidence > 0.5:
        raise ValueError(f"one-sided bounds need a confidence above 0.5, got {confidence!r}")
    from ..ensemble.sampler import design_of
    ens, design = _as_ensemble(ds), design_of(ds.attrs)
    finished = np.asarray(ens["status"].values == FINISHED)
    data = {}
    for name in SUMMARIES:
        var = ens[name].transpose("realization", "quantity", "direction")
        per_quantity = [_column_stats(var.isel(quantity=q).values[finished], ens["realization"].values, finished,
                                      design, confidence, one_sided, stopped_by_width)
                        for q in range(var.sizes["quantity"])]
        attrs = {"long_name": f"statistics over finished realisations of {name}",
                 "units": var.attrs.get("units", "")}
        data[name] = (("statistic", "bound", "quantity", "direction"), np.stack(per_quantity, axis=2), attrs)
    n = int(finished.sum())
    attrs = _attrs(ds, n, int((~finished).sum()), confidence, stopped_by_width, repeated)
    if design is not None:
        attrs |= _rqmc_attrs(design.replicates, confidence, stopped_by_width)
    if one_sided:
        attrs["bounds"] = ("one-sided: 'lower' and 'upper' are each a bound at the confidence on its "
                           "own side (pipeline.analysis.estimators, one-sided bounds)")
    coords = {"statistic": list(STATISTICS), "bound": list(BOUNDS),
              "quantity": ens["quantity"].values, "direction": ens["direction"].values}
    if "unit" in ds.coords:
        coords["unit"] = (("quantity", "direction"), ds["unit"].values, ds["unit"].attrs)
    return xr.Dataset(data, coords=coords, attrs=attrs)


def _column_stats(x: np.ndarray, realizations, finished: np.ndarray, design, confidence: float,
                  one_sided: bool, stopped_by_width: bool) -> np.ndarray:
    """(statistic, bound, cells) of the finished data x (n, cells). Every cell is independent of the
    others, so an ensemble's statistics are taken one quantity at a time: a 1,000,000-realisation
    file's values are then read 48 MB at a time, not all at once (docs/performance.md section 26)."""
    flat = estimates_and_bounds(x, confidence, one_sided, stopped_by_width)
    if design is not None:                          # not iid: see pipeline.analysis.estimators
        level = bound_level("mean", confidence, stopped_by_width, rqmc=True)
        flat[:, 1:] = _rqmc_bounds(x, realizations, finished, design.replicates,
                                   2 * level - 1 if one_sided else level)
    flat[:, 1:] = clipped_at_zero(flat[:, 1:])      # statistics of |error| are >= 0
    return flat


def _rqmc_bounds(x: np.ndarray, realizations, finished: np.ndarray, replicates: int,
                 confidence: float) -> np.ndarray:
    """(statistic, 2, cells) RQMC bounds of finished data x (n, cells); all NaN if any failed."""
    if not finished.all():
        return np.full((len(STATISTICS), 2, x.shape[1]), np.nan)
    return rqmc_intervals(replicate_groups(x, realizations, replicates), confidence)


def _widened(confidence: float, stopped_by_width: bool) -> str:
    """What an interval's text adds where its level is widened (:func:`.estimators.stopped_level`)."""
    if not stopped_by_width:
        return ""
    return f" at the level {stopped_level(confidence, True):g} (the run chose n by its widths: interval_after_until)"


def _rqmc_attrs(replicates: int, confidence: float, stopped_by_width: bool) -> dict:
    """The attributes that say which intervals a QMC file's statistics carry (pipeline.analysis.estimators)."""
    floors = ", ".join(f"{k} {interval_floor(k, confidence, replicates)}" for k in MIN_POINTS_RQMC)
    text = (f"randomised QMC: Student t ({replicates - 1} degrees of freedom) over the "
            f"{replicates} replicate estimates{_widened(confidence, stopped_by_width)}, centred on the estimate of "
            f"all complete replicate rounds; NaN below n = {floors}, or if a realisation failed")
    return {"sampler": "qmc", "qmc_replicates": replicates,
            **{f"interval_{k}": text for k in ("mean", "std", "quantiles")},
            **{f"min_n_{k}": interval_floor(k, confidence, replicates) for k in QUANTILES}}


def below_floor(statistic: str, confidence: float) -> str:
    """Where the mean's or std's interval is NaN: 'n < 16', or every n above 95 % for the std."""
    floor = moment_floor(statistic, confidence)
    return f"n < {floor}" if floor is not None else f"every n at this confidence ({short_of_label(statistic)})"


def _attrs(ds, n: int, failed: int, confidence: float, stopped_by_width: bool, repeated: bool) -> dict:
    needed = {k: min_n_for_quantile(p, bound_level(k, confidence, stopped_by_width)) for k, p in QUANTILES.items()}
    steady = {k: ds.attrs[k] for k in ("steady_after_s", "settle_time_s") if k in ds.attrs}
    return {**_provenance(ds, confidence), **steady, "n_finished": n, "n_failed": failed,
            **({"one_run_repeated": ONE_RUN} if n > 1 and repeated else {}),
            "confidence": confidence,
            "interval_mean": f"union of Student t and Hall (1992) skewness-corrected t; NaN for "
                             f"{below_floor('mean', confidence)}",
            "interval_std": f"Bonett (2006) at the level 1 - {STD_WIDENING:g} (1 - confidence); NaN for "
                            f"{below_floor('std', confidence)}",
            "interval_quantiles": "distribution-free order statistics, exact binomial coverage"
                                  f"{_widened(confidence, stopped_by_width)}; NaN for n < "
                                  + ", ".join(f"{v} ({k})" for k, v in needed.items()),
            "interval_max": MAX_NOTE,
            **{f"min_n_{k}": v for k, v in needed.items()},
            **({"interval_after_until": until_note(str(ds.attrs.get("sampler", "mc")))} if stopped_by_width else {})}


# the coverages where --until stops that docs/ensembles.md ("Run until known") gives, per sampler, their one copy in
# code: whose bounds are widened, their coverage at the label's 95 %, at the widened level, and the benchmark
STOP_COVERAGE = {
    "mc": ("its quantiles'", "q95 92.3-93.4 %, q50 94.2-95.1 %",
           "q95 96.1-96.6 %, q50 97.0-98.0 %; the mean's interval is not widened and covers 94.5-95.8 %",
           "python benchmarks/until_coverage.py"),
    "qmc": ("every statistic's", "mean 94.3 %, q95 91.4 %",
            "mean 96.7 %, q95 95.4 % (8 replicates; every width comes from the replicates' spread)",
            "python benchmarks/rqmc_coverage.py --until"),
}


def until_note(sampler: str = "mc") -> str:
    """What the statistics of a --until run say about their widened bounds (``interval_after_until``): what
    was widened for the file's ``sampler`` ('mc' or 'qmc') and that sampler's measured coverages."""
    widened, plain, at_level, command = STOP_COVERAGE[sampler]
    flag = " --sampler qmc" if sampler == "qmc" else ""
    return (f"this run chose n by its own intervals' widths (rss6 run --until{flag}), which costs them coverage "
            f"(95 % bounds at the stop covered {plain}), so {widened} bounds are taken at the level "
            f"1 - {UNTIL_WIDENING:g} (1 - confidence) ({100 * stopped_level(CONFIDENCE, True):g} % for 95 %), "
            f"covering {at_level} at the stop ({command}; docs/ensembles.md)")


def json_number(v):
    """A float for strict JSON: None where it is NaN or infinite."""
    v = float(v)
    return v if np.isfinite(v) else None


def json_record(record) -> dict:
    """A dataclass instance as a strict-JSON dict: its NaN and infinite floats None (:func:`json_number`)."""
    from dataclasses import asdict
    return {k: (json_number(v) if isinstance(v, float) else v) for k, v in asdict(record).items()}


def to_json(sds: xr.Dataset) -> dict:
    """Strict-JSON view of :func:`ensemble_stats` (None for a missing number), SI units:
    {variable: {quantity: {direction: {statistic: {bound: value}}}}} plus the attributes; statistics
    with a window dimension give the whole run's (else the first window's) there, that window's name
    under ``window``, and every window's under ``by_window`` = {window: {variable: ...}}."""
    if "window" in sds.dims:
        top = "whole" if "whole" in windows_of(sds) else windows_of(sds)[0]
        out = to_json(in_window(sds, top)) | {"window": top}
        out["by_window"] = {w: {name: _json_table(in_window(sds, w)[name]) for name in SUMMARIES}
                            for w in windows_of(sds)}
        return out
    out = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in sds.attrs.items()}
    out["units"] = {name: sds[name].attrs.get("units", "") for name in SUMMARIES}
    if "unit" in sds.coords:
        out["unit"] = {str(q): {str(d): str(sds["unit"].sel(quantity=q, direction=d).item())
                                for d in sds.direction.values} for q in sds.quantity.values}
    for name in SUMMARIES:
        out[name] = _json_table(sds[name])
    return out


def _json_table(var: xr.DataArray) -> dict:
    return {str(q): {str(d): {s: {b: json_number(var.sel(statistic=s, bound=b, quantity=q, direction=d))
                                  for b in BOUNDS} for s in STATISTICS}
                     for d in var.direction.values} for q in var.quantity.values}


def table_cell(value: float, factor: float = 1.0, width: int = 11) -> str:
    """A number of a printed table in display units (``value`` SI times ``factor``), a dash where it is missing."""
    return f"{value * factor:{width}.4g}" if np.isfinite(value) else f"{'-':>{width}s}"


def left_out_note(failed: int, total: int) -> str:
    """What the statistics of an ensemble with ``failed`` of ``total`` realisations failed leave out, and why
    that matters (rss6 stats' note, and rss6 report's under a table with such a run)."""
    return (f"{failed} of {total} realisations failed and are in no statistic or bound: each describes the "
            "robots that finished, whose errors the failed draws (often the largest) may exceed")


def table_notes(sds: xr.Dataset) -> list[str]:
    """Why bounds are dashes (the n each interval needs, the maximum's note), which realisations the
    statistics leave out (the failed ones) and which intervals measure numerical noise (the attribute
    within_resolution: pipeline.analysis.resolution.resolution_attrs)."""
    n, conf = sds.attrs["n_finished"], 100 * sds.attrs["confidence"]
    replicates = sds.attrs.get("qmc_replicates")
    replicates = None if replicates is None else int(replicates)
    stopped = "interval_after_until" in sds.attrs   # --until chose n: the quantiles' bounds are widened
    need = {k: interval_floor(k, bound_level(k, sds.attrs["confidence"], stopped, replicates is not None), replicates)
            for k in ("mean", "std", *QUANTILES)}
    notes = [f"{k}: no {conf:g} % interval below n = {v} (n = {n} here)" if v is not None else
             f"{k}: no {conf:g} % interval at any n: {short_of_label(k)}" for k, v in need.items()
             if v is None or n < v]
    if replicates is not None:
        unmeasured = replicates_note(replicates)
        notes.insert(0, f"randomised QMC, {replicates} replicates: intervals are Student t over "
                        "the replicates (none if a realisation failed)" + (f"; {unmeasured}" if unmeasured else ""))
    until = [f"--until: {sds.attrs['interval_after_until']}"] if "interval_after_until" in sds.attrs else []
    other = [f"confidence {conf:g} %: the quantiles' intervals are exact at any level, but the mean's and std's "
             f"coverage was measured from {100 * LOWEST_MEASURED:g} % up (docs/ensembles.md)"] \
        if replicates is None and sds.attrs["confidence"] < LOWEST_MEASURED - 1e-12 else []
    failed = int(sds.attrs.get("n_failed", 0))
    left_out = [left_out_note(failed, n + failed) + "; --require counts them against a pass"] if failed else []
    windows = set(windows_of(sds)) or {"whole"}
    noise = [t for t in str(sds.attrs.get("within_resolution", "")).split("\n") if t]   # resolution_attrs
    return (left_out + _identical_note(sds) + noise + notes + [f"max: {MAX_NOTE}"] + until + other
            + level_notes(sds.attrs, {str(q) for q in sds["quantity"].values}, windows))


ONE_RUN = "the level draws no clearances and the scene no [uncertain.*] inputs: every realisation is the same run"


def one_run_repeated(ds) -> bool:
    """Whether every realisation of the ensemble (or single-run) Dataset ``ds`` is the same run: its level draws
    no clearances, its scene no [uncertain.*] inputs, and none failed (each statistic is then that run's value,
    known exactly: the gate's exact rule and the tables' note)."""
    from rss6core import model_level, parse_scene
    model, text = ds.attrs.get("model"), ds.attrs.get("scene_toml")
    if model is None or text is None or model_level(str(model)).draws_clearances:
        return False
    if "status" in ds and (ds["status"].values.astype(str) != FINISHED).any():
        return False
    return not parse_scene(str(text), "file").uncertain.inputs


def _identical_note(sds: xr.Dataset) -> list[str]:
    """Where the statistics are of one run repeated (:func:`one_run_repeated`, the attribute one_run_repeated)."""
    if "one_run_repeated" not in sds.attrs:
        return []
    return [f"all {sds.attrs['n_finished']} realisations are one run: {sds.attrs['model']} level and scene "
            "without [uncertain.*] inputs draw nothing, so each statistic is that run's value (rss6 simulate gives "
            "it; no bound is needed)"]


def level_notes(attrs, shown: set, windows: set) -> list[str]:
    """Which numbers of a table (its quantities ``shown``, its analysis ``windows``) of a file with
    attributes ``attrs`` do not measure the robot in operation, by the file's level: the paper level's
    velocities and accelerations (they measure the step), and the contact level's start-up maxima after
    a drawn start (the start's impacts)."""
    from rss6core import MODELS, model_level
    model = str(attrs.get("model", ""))
    if model not in MODELS:
        return []
    level, notes = model_level(model), []
    if step_measured(model, shown):
        notes.append(f"{model} level: its velocity and acceleration errors {STEP_WORDS} (the contact level "
                     "measures them)")
    starts = not empty_window("startup", *file_window_bounds(attrs))   # the start is in the whole run
    if level.contact_start and attrs.get("contact_start") == "drawn" and starts and windows & {"whole", "startup"}:
        notes.append(f"{model} level, drawn start: the joints start off their contact equilibrium, and the impacts "
                     "that follow are in the whole run's and the startup's maxima (velocity and acceleration above "
                     "all); the steady window measures the robot in operation, as does a run with --start equilibrium")
    return notes


def format_stats(sds: xr.Dataset) -> str:
    """A table of :func:`ensemble_stats` in the paper's display units (mm, mm/s, mm/s^2; rad,
    rad/s, rad/s^2): per quantity, direction and variable the estimates, then the lower and upper
    confidence bounds ('-' where none is given, with the reason below the table); one table per
    analysis window, labelled, when the statistics have several."""
    from ..files.records import file_window_label
    if "window" not in sds.dims:
        return "\n".join(_table_lines(sds) + ["notes:"] + [f"  {t}" for t in table_notes(sds)])
    lines = []
    for i, w in enumerate(windows_of(sds)):
        body = _table_lines(in_window(sds, w))
        lines += ([] if i else body[:1]) + [f"window: {file_window_label(w, sds.attrs)}"]
        lines += body[1:]
    return "\n".join(lines + ["notes:"] + [f"  {t}" for t in table_notes(sds)])


def _table_lines(sds: xr.Dataset) -> list[str]:
    """The lines of one window's table (the first one says what the rows are)."""
    from ..files.schema import display_unit
    a = sds.attrs
    lines = [f"{counted(int(a['n_finished']), 'finished realisation')} ({a['n_failed']} failed); 'max' rows: "
             "per-realisation max |error|, 'mean' rows: per-realisation mean |error|; 'lower' and "
             f"'upper': two-sided {100 * a['confidence']:g} % confidence bounds",
             f"{'quantity':<13s}{'dir':<4s}{'of':<5s}{'unit':<8s}{'':<9s}"
             + "".join(f"{c:>11s}" for c in STATISTICS)]
    for q in sds.quantity.values:
        for d in sds.direction.values:
            f, unit = display_unit(str(q), str(d))
            for name in SUMMARIES:
                v = sds[name].sel(quantity=q, direction=d)
                for b in BOUNDS:
                    head = f"{q:<13s}{d:<4s}{name.split('_')[0]:<5s}{unit:<8s}" if b == "estimate" \
                        else " " * 30
                    lines.append(head + f"{b:<9s}" + "".join(
                        table_cell(float(v.sel(statistic=s, bound=b)), f) for s in STATISTICS))
    return lines
