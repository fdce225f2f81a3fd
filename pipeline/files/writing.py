"""Writing a file: CF-encoded netCDF4 through a temporary file, streamed block by block with its
checksums, after a check of the free space, and never cut by Ctrl-C."""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import threading

import dask
import numpy as np
import xarray as xr

from .checksums import (ATTRIBUTES, VARIABLE_ATTRIBUTES, _Checksum, _rows, attribute_checksums,
                        variable_attribute_checksums)
from .schema import CHECKSUM, EnsembleFileError, cf_encode

__all__ = ["sigint_deferred", "write_netcdf", "netcdf_size", "check_free_space"]


@contextlib.contextmanager
def sigint_deferred():
    """Ctrl-C during the block takes effect when it ends: a file write is never cut inside the
    netCDF library or xarray's file lock (an interrupt landing there left the lock held and hung
    the run). Python runs signal handlers in the main thread only, so elsewhere this does nothing.

    Yields the list the held signals are appended to: a long block may look at it at a safe point
    and stop early (raising KeyboardInterrupt itself).
    """
    received = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield received
    finally:
        signal.signal(signal.SIGINT, previous)
    if received:
        if callable(previous) and previous is not signal.default_int_handler:
            previous(signal.SIGINT, None)   # an enclosing block's recorder, or the caller's handler
        elif previous is not signal.SIG_IGN:
            raise KeyboardInterrupt


def write_netcdf(ds: xr.Dataset, path) -> None:
    """Write ``ds`` as CF-1.10 netCDF4 to ``path`` via a temporary file, so a crash leaves no half file.

    The in-memory schema is mapped to CF here (:func:`cf_encode`) and back in :func:`load_netcdf`.
    Variables held as dask arrays (an ensemble merged from its parts) are streamed block by block:
    the write holds one block in memory, and the file is byte for byte the one an in-memory
    Dataset gives (every variable is written when it is defined, in the Dataset's order).
    """
    tmp = f"{path}.part"
    encoded, encoding = cf_encode(ds)
    needed = netcdf_size(ds) + metadata_size(encoded)
    check_free_space(path, needed)
    with sigint_deferred() as interrupted:
        try:
            # The data are in memory or in local files. While a dask.distributed client is open,
            # xarray would otherwise guard the file with a distributed lock: a scheduler round
            # trip per variable, which slowed every chunk's write severalfold (docs/performance.md).
            with dask.config.set(scheduler="synchronous"):
                _stream_to_netcdf(encoded, tmp, encoding, interrupted)
        except BaseException as exc:
            if os.path.exists(tmp):
                os.remove(tmp)
            if isinstance(exc, (OSError, RuntimeError)):  # a full disk shows as "NetCDF: HDF error"
                check_free_space(path, needed)
            raise
        os.replace(tmp, path)


class _InOrderWriter:
    """xarray's array writer, writing each variable as soon as it is defined; a dask-backed one
    block by block (strings at once: they are small and their heap layout then matches), stopping
    between blocks once ``interrupted`` (a list) is not empty. It takes each variable's checksum
    (:class:`_Checksum`) from the values as they are written."""
    lock = None

    def __init__(self, interrupted: list):
        self.interrupted = interrupted
        self.digests = {}

    def add(self, source, target, region=None) -> None:
        if region is not None:
            raise ValueError("region writes are not used by rss6")
        digest = _Checksum(source)
        if not dask.is_dask_collection(source):
            target[...] = source
            digest.update(np.asarray(source))
        elif source.dtype.kind in "OUS":
            values = source.compute()
            target[...] = values
            digest.update(values)
        else:
            source = _rows(source)
            edges = np.cumsum((0,) + tuple(source.chunks[0])) if source.ndim else [0, 1]
            for i in range(source.numblocks[0] if source.ndim else 1):
                if self.interrupted:
                    raise KeyboardInterrupt
                values = source.blocks[i].compute() if source.ndim else source.compute()
                target[slice(edges[i], edges[i + 1]) if source.ndim else ...] = values
                digest.update(values)
        self.digests[target.variable_name] = digest.hexdigest()


def _stream_to_netcdf(ds: xr.Dataset, path, encoding: dict, interrupted: list) -> None:
    """``ds.to_netcdf(path)`` (netCDF4, NETCDF4 format) with :class:`_InOrderWriter`, and the
    values' checksums (global attribute CHECKSUM) written last, with those of the global attributes
    as the file holds them."""
    from xarray.backends import NetCDF4DataStore
    store = NetCDF4DataStore.open(path, mode="w", format="NETCDF4")
    try:
        writer = _InOrderWriter(interrupted)
        ds.dump_to_store(store, writer=writer, encoding=encoding)
        writer.digests[ATTRIBUTES] = attribute_checksums({k: store.ds.getncattr(k) for k in store.ds.ncattrs()})
        writer.digests[VARIABLE_ATTRIBUTES] = variable_attribute_checksums(store.ds.variables)
        store.ds.setncattr(CHECKSUM, json.dumps(writer.digests, sort_keys=True))
    finally:
        store.close()


def netcdf_size(ds: xr.Dataset) -> int:
    """Bytes the values of ``ds`` take in a netCDF4 file (without its metadata, about 4 kB per
    variable, ~100 kB for an ensemble): the numbers, and per string its UTF-8 bytes padded to 8
    plus 32 bytes of HDF5 overhead."""
    total = 0
    for var in ds.variables.values():
        if var.dtype.kind in "OUS":
            total += sum(32 + -(-len(str(s).encode()) // 8) * 8 for s in np.ravel(var.values))
        else:
            total += var.nbytes
    return total


def metadata_size(encoded: xr.Dataset) -> int:
    """Bytes a netCDF4 file of the CF-encoded ``encoded`` takes beyond its values, bounded from above: 4 KiB of
    HDF5 headers per variable, twice the attributes' text, 16 KiB for the file (``tests/test_merge.py`` checks
    that it bounds a merged ensemble's file); a fixed 1 MiB had refused a 94 kB file on a nearly full disk."""
    text = sum(len(str(v).encode()) for v in encoded.attrs.values())
    text += sum(len(str(v).encode()) for var in encoded.variables.values() for v in var.attrs.values())
    return 4096 * len(encoded.variables) + 2 * text + 16384


def check_free_space(path, needed: int) -> None:
    """EnsembleFileError naming the folder when it has less than ``needed`` bytes free."""
    folder = os.path.dirname(os.path.abspath(path))
    free = shutil.disk_usage(folder).free
    if free < needed:
        raise EnsembleFileError(f"{path}: not enough disk space in {folder}: {_amounts(needed, free)}; "
                                "free some space and rerun (nothing of this file was written; a run's finished "
                                "parts are kept)")


def _amounts(needed: int, free: int) -> str:
    """'about X MiB needed, Y MiB free', in bytes where the MiB would print the same."""
    mib = [f"{b / 2 ** 20:.1f} MiB" for b in (needed, free)]
    shown = mib if mib[0] != mib[1] else [f"{b:,} bytes" for b in (needed, free)]
    return f"about {shown[0]} needed, {shown[1]} free"

