"""Checksums of a file's values: sha256 per variable, canonical (independent of blocks, workers and
machine), written with every file and verified by every reader."""
from __future__ import annotations

import hashlib
import json

import dask
import numpy as np
import xarray as xr

from .schema import CHECKSUM, EnsembleFileError

__all__ = ["file_checksums", "verify_checksums", "CHECKSUMS_SINCE"]


def _rows(array):
    """A dask array cut along its first axis only, so its blocks in order are its values in C order."""
    return array.rechunk({i: -1 for i in range(1, array.ndim)}) if array.ndim > 1 else array


class _Checksum:
    """sha256 of a variable's values in C order, canonical: little-endian numbers with every NaN
    the same NaN, strings as UTF-8 each ended by a NUL; headed by the type and shape. So the
    digest does not depend on how the values were cut into blocks, on the worker count or on the
    machine, only on the values."""

    def __init__(self, array):
        kind = "str" if array.dtype.kind in "OUS" else np.dtype(array.dtype).newbyteorder("<").str
        self._sha = hashlib.sha256(f"{kind} {tuple(array.shape)}\n".encode())

    def update(self, values) -> None:
        values = np.asarray(values)
        if values.dtype.kind in "OUS":
            self._sha.update(b"".join((v.decode() if isinstance(v, bytes) else str(v)).encode() + b"\0"
                                      for v in values.ravel()))
            return
        if values.dtype.kind in "fc":
            values = np.where(np.isnan(values), np.nan, values)
        self._sha.update(np.ascontiguousarray(values, values.dtype.newbyteorder("<")).tobytes())

    def hexdigest(self) -> str:
        return self._sha.hexdigest()


def file_checksums(ds: xr.Dataset) -> dict:
    """{variable: sha256} of a Dataset as read from a file before :func:`cf_decode` (the digests
    :class:`_InOrderWriter` records); dask-backed variables are read block by block."""
    out = {}
    for name, var in ds.variables.items():
        digest = _Checksum(var)
        if dask.is_dask_collection(var.data) and var.ndim:
            data = _rows(var.data)
            for i in range(data.numblocks[0]):
                digest.update(data.blocks[i].compute())
        else:
            digest.update(var.values)
        out[str(name)] = digest.hexdigest()
    return out


CHECKSUMS_SINCE = (0, 3)   # the first rss6 version whose files carry CHECKSUM


def _writes_checksums(version) -> bool:
    """Whether rss6 ``version`` (a file's ``rss6_version``) writes checksums: a file of such a
    version without them was altered; one of an earlier rss6 (or of no rss6) is read with a note."""
    try:
        return tuple(int(p) for p in str(version).split(".")[:2]) >= CHECKSUMS_SINCE
    except ValueError:
        return False


def verify_checksums(ds: xr.Dataset, path) -> bool:
    """EnsembleFileError naming the file and the first variable whose values differ from the
    checksum written with the file (changed since), or that was added or removed; False when the
    file has no checksum (written by an earlier rss6 or by another program), True when it holds."""
    text = ds.attrs.get(CHECKSUM)
    if text is None:
        if _writes_checksums(ds.attrs.get("rss6_version")):
            raise EnsembleFileError(f"{path}: attribute {CHECKSUM} is missing, although rss6 "
                                    f"{ds.attrs['rss6_version']} writes it: the file was altered after rss6 "
                                    "wrote it; rerun the command that wrote it, or restore the file")
        return False
    try:
        recorded = json.loads(str(text))
        assert isinstance(recorded, dict)
    except (ValueError, AssertionError):
        raise EnsembleFileError(f"{path}: attribute {CHECKSUM} is not the JSON rss6 writes; the file "
                                "was edited after rss6 wrote it: rerun the command that wrote it") from None
    got = file_checksums(ds)
    for name in sorted(set(recorded) | set(got)):
        if recorded.get(name) != got.get(name):
            what = ("was added to" if name not in recorded else "was removed from" if name not in got
                    else "has values that no longer match its checksum in")
            raise EnsembleFileError(f"{path}: variable {name} {what} attribute {CHECKSUM}: the file was "
                                    "altered after rss6 wrote it; rerun the command that wrote it, "
                                    "or restore the file")
    return True

