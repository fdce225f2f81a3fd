"""Largest relative difference between the numbers of two ensemble files (e.g. before and after a
refactoring): python benchmarks/compare_ensembles.py A.nc B.nc

Per numeric variable: max |a - b| / max(|a|, |b|) over the entries where they differ (both NaN
counts as equal; NaN against a number as 1); prints each variable's figure and the overall one.
The files are compared as rss6 reads them (pipeline.labelled), so a file with the error variables
split by unit (rss6 after issue 36) compares with one that holds them whole.
"""
import sys

import numpy as np
import xarray as xr


def relative_differences(a: xr.Dataset, b: xr.Dataset) -> dict:
    """{variable: largest relative difference} over the numeric variables both files hold."""
    out = {}
    for name in sorted(set(a.variables) & set(b.variables)):
        x, y = a[name].values, b[name].values
        if x.dtype.kind not in "fiu" or y.dtype.kind not in "fiu":
            out[name] = 0.0 if np.array_equal(x, y) else 1.0
            continue
        x, y = x.astype(float), y.astype(float)
        both_nan = np.isnan(x) & np.isnan(y)
        scale = np.maximum(np.abs(x), np.abs(y))
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.where(x == y, 0.0, np.abs(x - y) / scale)
        rel = np.where(both_nan, 0.0, np.where(np.isnan(rel), 1.0, rel))
        out[name] = float(rel.max()) if rel.size else 0.0
    return out


def main(argv):
    from pipeline import labelled
    if len(argv) != 2 or argv[0].startswith("-"):
        raise SystemExit(__doc__)
    with xr.open_dataset(argv[0]) as a, xr.open_dataset(argv[1]) as b:
        diffs = relative_differences(labelled(a), labelled(b))
        only = sorted(set(a.variables) ^ set(b.variables))
    for name, d in diffs.items():
        print(f"{name:40s} {d:.3e}")
    worst = max(diffs, key=diffs.get)
    print(f"maximum relative difference {diffs[worst]:.3e} ({worst}); variables in one file only: {only or 'none'}")


if __name__ == "__main__":
    main(sys.argv[1:])
