"""Checksums of a file's values: sha256 per variable, canonical (independent of blocks, workers and
machine), written with every file and verified by every reader."""
from __future__ import annotations

import hashlib
import json

import dask
import numpy as np
import xarray as xr

from .schema import ALTERED, CHECKSUM, EnsembleFileError

__all__ = ["file_checksums", "attribute_checksums", "verify_checksums", "CHECKSUMS_SINCE", "ATTRIBUTES"]


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


# the entry of CHECKSUM that holds {attribute: sha256} of the global attributes (a netCDF name has
# no "/", so no variable is called so); files of rss6 0.3.0 written before it have no such entry
ATTRIBUTES = "/attributes"
# global attributes the attribute checksums leave out: ``history`` (CF tools append to it; it
# names commands, not values), ``coordinates`` (xarray's encoding, which it takes away on reading)
_UNCHECKED = frozenset({"history", "coordinates", CHECKSUM})
# the entry of CHECKSUM that holds {variable: {attribute: sha256}} of every variable's attributes (units,
# long_name, cell_methods, ...); files written before the entry was added (2026-11-29) have none
VARIABLE_ATTRIBUTES = "/variable_attributes"
# variable attributes that are the encoding's, not the values' meaning: xarray moves them into a
# variable's encoding on reading (or writes them itself), so they are left out on both sides
_ENCODING_ATTRS = frozenset({"_FillValue", "missing_value", "coordinates", "scale_factor", "add_offset",
                             "_Encoding", "_Unsigned", "dtype", "calendar"})


def attribute_checksums(attrs: dict, unchecked: frozenset = _UNCHECKED) -> dict:
    """{attribute: sha256 of its value} of a file's global (or a variable's) attributes as netCDF4 reads
    them (type and value: 7 as int64 and 7.0 differ), but those of ``unchecked``."""
    out = {}
    for name, value in attrs.items():
        if name not in unchecked:
            digest = _Checksum(np.asarray(value))
            digest.update(value)
            out[str(name)] = digest.hexdigest()
    return out


def file_checksums(ds: xr.Dataset) -> dict:
    """{variable: sha256} of a Dataset as read from a file before :func:`cf_decode` (the digests
    :class:`_InOrderWriter` records), with its global attributes' under ATTRIBUTES and its variables'
    attributes' under VARIABLE_ATTRIBUTES; dask-backed
    variables are read block by block."""
    out = {ATTRIBUTES: attribute_checksums(ds.attrs), VARIABLE_ATTRIBUTES: variable_attribute_checksums(ds.variables)}
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
ATTRIBUTE_CHECKSUMS_SINCE = (0, 3, 1)   # ... and the first whose CHECKSUM holds the ATTRIBUTES entry


def _writes_checksums(version, since: tuple = CHECKSUMS_SINCE) -> bool:
    """Whether rss6 ``version`` (a file's ``rss6_version``) is ``since`` or later: a file of such a
    version without what it writes was altered; one of an earlier rss6 (or of no rss6) is read as
    that version wrote it (without checksums: with a note)."""
    try:
        return tuple(int(p) for p in str(version).split(".")[:len(since)]) >= since
    except ValueError:
        return False


def verify_checksums(ds: xr.Dataset, path) -> bool:
    """EnsembleFileError naming the file and the first variable whose values differ from the
    checksum written with the file (changed since), or that was added or removed, then the first
    such global attribute; False when the file has no checksum (written by an earlier rss6 or by
    another program), True when it holds. A file without the attributes' entry has its variables
    checked alone if an rss6 before ATTRIBUTE_CHECKSUMS_SINCE wrote it, and is refused otherwise."""
    text = ds.attrs.get(CHECKSUM)
    if text is None:
        if _writes_checksums(ds.attrs.get("rss6_version")):
            raise EnsembleFileError(f"{path}: attribute {CHECKSUM} is missing, although rss6 "
                                    f"{ds.attrs['rss6_version']} writes it: {ALTERED}")
        return False
    try:
        recorded = json.loads(str(text))
        assert isinstance(recorded, dict)
        attributes = recorded.pop(ATTRIBUTES, None)
        assert attributes is None or isinstance(attributes, dict)
    except (ValueError, AssertionError):
        raise EnsembleFileError(f"{path}: attribute {CHECKSUM} is not the JSON rss6 writes: {ALTERED}") from None
    variables = recorded.pop(VARIABLE_ATTRIBUTES, None)
    got = file_checksums(ds)
    got_attributes, got_variables = got.pop(ATTRIBUTES), got.pop(VARIABLE_ATTRIBUTES)
    for name in sorted(set(recorded) | set(got)):
        if recorded.get(name) != got.get(name):
            what = (f"has no checksum in attribute {CHECKSUM}: it was added after rss6 wrote the file"
                    if name not in recorded else
                    f"has a checksum in attribute {CHECKSUM} but is missing from the file" if name not in got
                    else f"has values that no longer match its checksum in attribute {CHECKSUM}")
            raise EnsembleFileError(f"{path}: variable {name} {what}: {ALTERED}")
    if isinstance(variables, dict):
        _verify_variable_attributes(variables, got_variables, ds, path)
    elif variables is not None:
        raise EnsembleFileError(f"{path}: attribute {CHECKSUM} is not the JSON rss6 writes: {ALTERED}")
    if attributes is not None:
        _verify_attributes(attributes, got_attributes, ds.attrs, path)
    elif _writes_checksums(ds.attrs.get("rss6_version"), ATTRIBUTE_CHECKSUMS_SINCE):
        raise EnsembleFileError(f"{path}: attribute {CHECKSUM} lacks its {ATTRIBUTES} entry, although rss6 "
                                f"{ds.attrs['rss6_version']} writes it: {ALTERED}")
    return True


def variable_attribute_checksums(variables) -> dict:
    """{variable: :func:`attribute_checksums` of its attributes, but the encoding's} of ``variables``
    ({name: object with ``attrs``}, or a netCDF4 file's variables)."""
    return {str(name): attribute_checksums(_attrs_of(var), _ENCODING_ATTRS) for name, var in variables.items()}


def _attrs_of(var) -> dict:
    """A variable's attributes, of an xarray Variable or of a netCDF4 one."""
    return dict(var.attrs) if hasattr(var, "attrs") else {k: var.getncattr(k) for k in var.ncattrs()}


def _verify_variable_attributes(recorded: dict, got: dict, ds: xr.Dataset, path) -> None:
    """EnsembleFileError naming the first variable attribute changed, removed or added since rss6 wrote
    the file (``recorded``: its digests then, ``got``: now); a variable added or removed is the values'
    check's."""
    for variable in sorted(set(recorded) & set(got)):
        was, now = recorded[variable], got[variable]
        for name in sorted(set(was) | set(now)):
            if was.get(name) != now.get(name):
                what = ("was removed" if name not in now else "was added" if name not in was
                        else f"is {ds[variable].attrs[name]!r}, not the value whose checksum {CHECKSUM} holds")
                raise EnsembleFileError(f"{path}: attribute {name} of variable {variable} {what}: {ALTERED}")


def _verify_attributes(recorded: dict, got: dict, attrs: dict, path) -> None:
    """EnsembleFileError naming the first global attribute changed, removed or added since rss6
    wrote the file (``recorded``: its digests then, ``got``: now, of ``attrs``)."""
    for name in sorted(set(recorded) | set(got)):
        if recorded.get(name) != got.get(name):
            value = attrs.get(name)
            shown = repr(value.item() if isinstance(value, np.generic) else value)
            shown = (shown if len(shown) <= 40 else shown[:36] + " ...") + (
                f" ({value.dtype})" if isinstance(value, np.generic) else "")
            what = (f"missing, although {CHECKSUM} records it" if name not in got
                    else f"was added after rss6 wrote the file ({CHECKSUM} does not record it)"
                    if name not in recorded else f"is {shown}, not the value whose checksum {CHECKSUM} holds")
            raise EnsembleFileError(f"{path}: attribute {name} {what}: {ALTERED}")
