"""Opening the files rss6 wrote for use: an ensemble or a single run, read and then checked
(:mod:`.check`), so that nothing reads a tampered or foreign file silently."""
from __future__ import annotations

import xarray as xr

from .check import check_ensemble, check_run
from .reading import load_netcdf, note_unverified
from .schema import EnsembleFileError

__all__ = ["open_ensemble", "checked_ensemble", "open_results"]


def open_ensemble(path, lazy: bool = False, verify: bool = True, summary_block: int | None = None) -> xr.Dataset:
    """Open an ensemble file into memory (``lazy``: its histories, and the summaries of a file of more
    than ``summary_block`` (default SUMMARY_BLOCK) realisations, stay on disk; ``verify``: its checksums checked, see
    :func:`load_netcdf`); EnsembleFileError names the file and the problem."""
    return checked_ensemble(load_netcdf(path, lazy, verify, summary_block), path)


def checked_ensemble(ds: xr.Dataset, path) -> xr.Dataset:
    """``ds`` (read from ``path``) if it is a well-formed rss6 ensemble, else EnsembleFileError."""
    missing = [k for k in ("max_abs_error", "mean_abs_error", "status") if k not in ds]
    if missing or "rss6_version" not in ds.attrs or "realization" not in ds.dims:
        other = _other_kind(ds) if missing else None   # a tampered ensemble keeps the message below
        if other:
            raise EnsembleFileError(f"{path}: not an rss6 ensemble file (rss6 run -o) but {other}")
        raise EnsembleFileError(f"{path}: not an rss6 ensemble file (missing "
                                f"{', '.join(missing) or 'rss6 attributes'})")
    check_ensemble(ds, path)
    return ds


def _other_kind(ds) -> str | None:
    """What another rss6 command's file holds (its title, with the command its history names when the
    title does not say), else None."""
    ours = "rss6_version" in ds.attrs or str(ds.attrs.get("source", "")).startswith("rss6")
    title = str(ds.attrs.get("title", ""))
    if not ours or not title:
        return None
    history = str(ds.attrs.get("history", "")).split()
    made = f" ({' '.join(history[:2])})" if not title.startswith("rss6") and history[:1] == ["rss6"] else ""
    return f"{title!r}{made}"


def open_results(path):
    """An ensemble file (``rss6 run``) or a single-run file (``rss6 simulate -o``), checked (a file
    without checksums with a note on stderr)."""
    ds = load_netcdf(path)
    if "realization" not in ds.dims and "rss6_version" in ds.attrs and "error" in ds:
        check_run(ds, path)
    else:
        ds = checked_ensemble(ds, path)
    note_unverified(ds, path)
    return ds
