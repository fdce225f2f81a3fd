"""Checks that a readable netCDF file holds what rss6 wrote: dimensions, labels, units, values.

A tampered or foreign file that opens fine must not be summarised silently: each
check raises store.EnsembleFileError naming the file and the first problem.
"""
from __future__ import annotations

import numpy as np

from rss6core import FINISHED, STATUSES

from .store import (DIRECTIONS, MIXED_UNITS, QUANTITIES, WINDOWS, EnsembleFileError, _unit_table,
                    load_netcdf)

__all__ = ["check_ensemble", "check_run", "open_results"]

SUMMARIES = ("max_abs_error", "mean_abs_error")


def _labels(ds, path) -> None:
    for dim, expected in (("quantity", QUANTITIES), ("direction", DIRECTIONS), ("window", WINDOWS)):
        if dim not in ds.coords:
            raise EnsembleFileError(f"{path}: no '{dim}' coordinate")
        got = [str(v) for v in ds[dim].values]
        if got != list(expected):
            raise EnsembleFileError(f"{path}: '{dim}' labels are {', '.join(got)}; expected "
                                    f"{', '.join(expected)}")


def _units(ds, path) -> None:
    for name in SUMMARIES:
        got = ds[name].attrs.get("units")
        if got != MIXED_UNITS:
            raise EnsembleFileError(f"{path}: {name} has units {got!r}; rss6 writes {MIXED_UNITS!r}")
    if "unit" not in ds.coords:
        raise EnsembleFileError(f"{path}: no 'unit' coordinate (the SI unit of each element)")
    if set(ds["unit"].dims) != {"quantity", "direction"}:
        raise EnsembleFileError(f"{path}: 'unit' has dimensions ({', '.join(ds['unit'].dims)}); "
                                "expected quantity, direction")
    # the labels are checked (in QUANTITIES and DIRECTIONS order): compare the table at once
    got = ds["unit"].transpose("quantity", "direction").values.astype(str)
    want = _unit_table()   # the table rss6 writes
    for i, j in np.argwhere(got != want)[:1]:
        raise EnsembleFileError(f"{path}: unit of {QUANTITIES[i]} {DIRECTIONS[j]} is {str(got[i, j])!r}; "
                                f"expected {str(want[i, j])!r}")


def _dims(ds, path, expected: set) -> None:
    for name in SUMMARIES:
        if name not in ds:
            raise EnsembleFileError(f"{path}: no variable {name}")
        if "window" not in ds[name].dims and set(ds[name].dims) == expected - {"window"}:
            raise EnsembleFileError(f"{path}: {name} has no analysis windows (written by an rss6 "
                                    "before 'window' was added); rerun the command that wrote it "
                                    "with a new output, or after deleting this file")
        if set(ds[name].dims) != expected:
            raise EnsembleFileError(f"{path}: {name} has dimensions ({', '.join(ds[name].dims)}); "
                                    f"expected {', '.join(sorted(expected))}")


def _window_bounds(ds, path) -> tuple[float, float]:
    """settle_time_s and steady_after_s (s) from the file's attributes, checked."""
    out = []
    for key in ("settle_time_s", "steady_after_s"):
        try:
            value = float(ds.attrs[key])
        except (KeyError, TypeError, ValueError):
            raise EnsembleFileError(f"{path}: attribute {key} missing or not a number "
                                    f"(the analysis windows' bounds)") from None
        if not (np.isfinite(value) and value >= 0):
            raise EnsembleFileError(f"{path}: attribute {key} is {value!r}; expected a time >= 0 s")
        out.append(value)
    return out[0], out[1]


def _values(ds, path, finished: np.ndarray) -> None:
    """No negative or infinite value anywhere; finite values in every finished realisation and
    window (the startup window is empty, hence NaN, when steady_after_s <= settle_time_s)."""
    settle, steady_after = _window_bounds(ds, path)
    windows = [w for w in WINDOWS if w != "startup" or steady_after > settle]
    for name in SUMMARIES:
        x = ds[name].transpose("realization", ...).values
        with np.errstate(invalid="ignore"):
            if np.any(x < 0):
                raise EnsembleFileError(f"{path}: {name} has negative values (it is an |error|)")
        if np.any(np.isinf(x)):
            raise EnsembleFileError(f"{path}: {name} has infinite values")
        x = ds[name].sel(window=windows).transpose("realization", ...).values
        bad = ~np.isfinite(x[finished]).all(axis=tuple(range(1, x.ndim)))
        if bad.any():
            first = ds["realization"].values[finished][bad][0]
            raise EnsembleFileError(f"{path}: {name} is not finite in finished realisation {first}")


def check_ensemble(ds, path) -> None:
    """EnsembleFileError unless ``ds`` is a well-formed rss6 ensemble (docs/model.md section 7)."""
    _dims(ds, path, {"window", "quantity", "realization", "direction"})
    _labels(ds, path)
    _units(ds, path)
    index = ds["realization"].values
    uniq, counts = np.unique(index, return_counts=True)
    if (counts > 1).any():
        raise EnsembleFileError(f"{path}: realisation index {uniq[counts > 1][0]} appears "
                                f"{counts[counts > 1][0]} times")
    status = ds["status"]
    if status.dims != ("realization",):
        raise EnsembleFileError(f"{path}: status has dimensions ({', '.join(status.dims)}); "
                                "expected (realization)")
    unknown = set(map(str, status.values)) - set(STATUSES)
    if unknown:
        raise EnsembleFileError(f"{path}: unknown status {sorted(unknown)[0]!r}; expected "
                                f"{' or '.join(STATUSES)}")
    _values(ds, path, status.values == FINISHED)


def check_run(ds, path) -> None:
    """EnsembleFileError unless ``ds`` is a well-formed single-run file (``rss6 simulate -o``)."""
    _dims(ds, path, {"window", "quantity", "direction"})
    _labels(ds, path)
    _units(ds, path)
    status = ds.attrs.get("status")
    if status not in STATUSES:
        raise EnsembleFileError(f"{path}: status attribute {status!r}; expected "
                                f"{' or '.join(STATUSES)}")
    one = ds[list(SUMMARIES)].expand_dims(realization=[0], axis=1).assign_attrs(ds.attrs)
    _values(one, path, np.array([status == FINISHED]))


def open_results(path):
    """An ensemble file (``rss6 run``) or a single-run file (``rss6 simulate -o``), checked."""
    from .store import open_ensemble
    ds = load_netcdf(path)
    if "realization" not in ds.dims and "rss6_version" in ds.attrs and "error" in ds:
        check_run(ds, path)
        return ds
    return open_ensemble(path)
