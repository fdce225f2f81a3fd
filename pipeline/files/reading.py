"""Reading a file rss6 wrote: into memory or with its histories left on disk, its checksums verified
and its CF encoding undone; a file without checksums is noted."""
from __future__ import annotations

import os
import sys

import xarray as xr

from .checksums import verify_checksums
from .outputs import unfinished
from .schema import _ELAPSED, _PART_DIMS, _PART_OF, _PART_QUANTITY, ALTERED, CHECKSUM, EnsembleFileError, cf_decode

__all__ = ["HISTORY_BLOCK", "SUMMARY_BLOCK", "load_netcdf", "note_unverified"]

HISTORY_BLOCK = 64   # realisations per block of a history read lazily (a merge holds one block)
# a file read lazily with more realisations than this keeps its per-realisation summaries on disk
# too, in blocks of this many (24 MB of max_abs_error each), so that the memory of reading a
# 1,000,000-realisation file stays bounded (docs/performance.md section 26); smaller files are
# read into memory, which is 3x faster than through dask
SUMMARY_BLOCK = 2 ** 16


NETCDF_MAGIC = (b"CDF\x01", b"CDF\x02", b"CDF\x05", b"\x89HDF\r\n\x1a\n")   # classic, 64-bit, CDF5, netCDF-4


def _unreadable(path) -> str:
    """Why a file netCDF could not open is no rss6 file: not netCDF at all (a scene or text file given for
    a netCDF one?), or a netCDF file cut short or damaged."""
    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError:
        head = b""
    if head and not head.startswith(NETCDF_MAGIC):
        text = head.isascii() and all(c >= 9 for c in head)
        return "not a netCDF file" + (" but text (a scene file? this option takes a .nc file)" if text else "")
    return "not a readable netCDF file (truncated or corrupt?)"


def load_netcdf(path, lazy: bool = False, verify: bool = True, summary_block: int | None = None) -> xr.Dataset:
    """Any netCDF file fully into memory; EnsembleFileError names the file if it is missing (or not
    written yet by a run, :func:`unfinished`) or unreadable.

    ``lazy``: the variables over time (histories) stay on disk as dask arrays of HISTORY_BLOCK
    realisations, read block by block when used, and so do all variables along ``realization``
    (in blocks of SUMMARY_BLOCK) when the file holds more than ``summary_block`` (default
    SUMMARY_BLOCK) realisations;
    the file stays open while the Dataset is used.
    ``verify``: the values are checked against the checksums written with the file
    (:func:`verify_checksums`; read once more, block by block, when ``lazy``); a file without them
    is marked ``encoding["rss6_unverified"]`` (see :func:`note_unverified`).
    """
    if not os.path.exists(path):
        raise EnsembleFileError(f"{path}: {unfinished(path) or 'no such file'}")
    if os.path.isdir(path):
        raise EnsembleFileError(f"{path}: is a folder; give an rss6 netCDF file")
    closer = None   # a lazy Dataset's file stays open: Dataset.close() (and a view's) closes it
    try:
        if lazy:
            # opened without dask: only the histories become dask arrays (loading each small
            # variable through dask was slower than reading it; docs/performance.md section 26)
            ds = xr.open_dataset(path, engine="netcdf4", decode_times=False)
            closer = ds.close
            ds = ds.assign(_on_disk(ds, SUMMARY_BLOCK if summary_block is None else summary_block))
            for var in ds.variables.values():
                if _ELAPSED not in var.dims and var.chunks is None:
                    var.load()
        else:
            with xr.open_dataset(path, engine="netcdf4", decode_times=False) as opened:
                ds = opened.load()
    except Exception as exc:  # netCDF4/HDF5 raise OSError, RuntimeError, ValueError...
        if closer is not None:
            closer()
        raise EnsembleFileError(f"{path}: {_unreadable(path)}: {exc}") from None
    try:
        out = _decoded(ds, path, verify)
    except BaseException:
        if closer is not None:
            closer()
        raise
    if closer is not None:
        out.set_close(closer)   # xarray's assign and rss6's decoding drop it
    return out


def _decoded(ds: xr.Dataset, path, verify: bool) -> xr.Dataset:
    """The Dataset as rss6 holds it (:func:`.schema.cf_decode`), its checksums checked if ``verify``
    (:func:`load_netcdf`); EnsembleFileError where its values or attributes were altered."""
    verified = verify and verify_checksums(ds, path)
    try:
        out = _forget_string_widths(cf_decode(ds))
    except EnsembleFileError:
        raise
    except Exception as exc:  # split variables whose own attributes no longer join them
        if verified:          # rss6 wrote the values: their variables' attributes were edited since
            raise EnsembleFileError(f"{path}: the split variables' attributes ({_PART_OF}, {_PART_DIMS}, "
                                    f"{_PART_QUANTITY}) no longer join them ({exc}): {ALTERED}") from None
        raise EnsembleFileError(f"{path}: not a file rss6 reads: {type(exc).__name__}: {exc}") from None
    if verify and not verified:
        out.encoding["rss6_unverified"] = True
    return out


def _on_disk(ds: xr.Dataset, summary_block: int) -> dict:
    """The variables :func:`load_netcdf` leaves on disk as dask arrays: the histories, and every
    numeric variable along ``realization`` of a file with more than ``summary_block`` realisations
    (its strings, status and messages, are read: rss6 looks at them all at once)."""
    large = ds.sizes.get("realization", 0) > summary_block
    return {name: var.chunk({"realization": HISTORY_BLOCK if _ELAPSED in var.dims else SUMMARY_BLOCK})
            for name, var in ds.data_vars.items()
            if "realization" in var.dims and (_ELAPSED in var.dims or (large and var.dtype.kind not in "OUS"))}


def note_unverified(ds: xr.Dataset, path, stream=None) -> None:
    """One line on stderr when ``ds`` was read from a file without checksums: it is accepted (an
    earlier rss6's results stay usable; its values pass every consistency check), but a change
    to its values could not be seen."""
    if ds.encoding.get("rss6_unverified"):
        print(f"rss6: note: {path}: no checksum of its values ({CHECKSUM}; written by an earlier "
              "rss6 or by another program): checked for consistency only", file=stream or sys.stderr)


def _forget_string_widths(ds: xr.Dataset) -> xr.Dataset:
    """Drop the read width of string variables (encoding ``dtype`` '<U6'): a Dataset concatenated
    from pieces keeps the first piece's encoding, which would cut longer strings on writing
    ('finished' stored as 'finish' after a piece holding only 'failed')."""
    for var in ds.variables.values():
        if var.dtype.kind in "OUS":
            var.encoding.pop("dtype", None)
    return ds

