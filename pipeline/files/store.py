"""netCDF files (CF-1.10, via xarray) for single runs; SI units in every ``units`` attribute.

The direction dimension mixes translations (x, y, z in m) and rotations
(rx, ry, rz in rad), so in memory a variable's ``units`` attribute names both and
the coordinate ``unit`` (quantity, direction) gives each element's unit exactly;
in a file each such variable is split into one variable per unit (see the CF
mapping below). Every file records checksums of its values, which every reader
verifies.
"""
from __future__ import annotations

import contextlib
import hashlib
import signal
import threading
import warnings

import dask
import numpy as np
import xarray as xr

from rss6core import __version__

from ..vocabulary import DIRECTIONS, FAMILIES, FINISHED, QUANTITIES, STORES, UserError, WINDOWS

__all__ = ["DIRECTIONS", "QUANTITIES", "UNITS", "WINDOWS", "PROVENANCE", "ENSEMBLE_ATTRS", "STORES", "display_unit",
           "error_summaries", "window_summaries", "window_masks", "window_reductions", "window_label",
           "run_dataset", "chunk_dataset", "write_netcdf", "cf_encode", "cf_decode", "check_free_space",
           "netcdf_size", "labelled", "load_netcdf", "open_ensemble", "checked_ensemble",
           "verify_checksums", "file_checksums", "note_unverified", "CHECKSUM", "FAMILIES"]

UNITS = {"displacement": ("m", "rad"), "velocity": ("m s-1", "rad s-1"),
         "acceleration": ("m s-2", "rad s-2")}
_DISPLAY = {"displacement": ("mm", "rad"), "velocity": ("mm/s", "rad/s"),
            "acceleration": ("mm/s^2", "rad/s^2")}


def display_unit(quantity: str, direction: str) -> tuple[float, str]:
    """Factor from SI and unit of the paper's display units (mm, mm/s, mm/s^2; rad, rad/s, rad/s^2)."""
    if direction in ("x", "y", "z"):
        return 1e3, _DISPLAY[quantity][0]
    return 1.0, _DISPLAY[quantity][1]


MIXED_UNITS = "m or rad, per direction (see coordinate 'unit'); time derivatives thereof"

# the global attributes :func:`_provenance` gives every file (contact-level files also contact_start)
PROVENANCE = ("Conventions", "title", "source", "rss6_version", "scene_name", "scene_toml", "model",
              "integrator", "time_step_s", "elements_per_link", "settle_time_s", "steady_after_s")


def _provenance(scene, title: str, *, model: str, integrator: str, dt: float,
                elements: int, history: str | None = None) -> dict:
    """Global attributes every rss6 file carries: conventions, what made it (``history``: the
    command, without the machine-dependent options, so the same command gives the same file;
    by default the title), version, scene text, settings."""
    return {"Conventions": "CF-1.10", "title": title, "history": history or f"rss6: {title}",
            "source": f"rss6 {__version__}",
            "rss6_version": __version__, "scene_name": scene.name, "scene_toml": scene.source_text,
            "model": model, "integrator": integrator, "time_step_s": dt,
            "elements_per_link": elements, "settle_time_s": scene.simulation.settle_time,
            "steady_after_s": scene.simulation.steady_after,
            **({"contact_start": scene.simulation.contact_start} if model == "contact" else {})}


def command_line(command: str, scene, *, model: str, integrator: str, dt: float, elements: int,
                 options: str = "") -> str:
    """A history line: the rss6 command and the options that fix its results (the scene by name;
    its text is the file's scene_toml), e.g. 'rss6 run smoke --model contact ... -n 16'."""
    start = f" --start {scene.simulation.contact_start}" if model == "contact" else ""
    return (f"rss6 {command} {scene.name} --model {model} --integrator {integrator} --dt {dt} "
            f"--elements {elements}{start}" + (f" {options}" if options else ""))


def derived_history(source: xr.Dataset, line: str) -> str:
    """The history of a file made from ``source``: its history, then ``line`` (CF: each command that
    derives a file appends itself)."""
    previous = str(source.attrs.get("history", "")).strip()
    return f"{previous}\n{line}" if previous else line


def _unit_table() -> np.ndarray:
    return np.array([[UNITS[q][0]] * 3 + [UNITS[q][1]] * 3 for q in QUANTITIES])


_CONTACT_ATTRS = {"long_name": "maximum over time of the contact force magnitude per joint",
                  "units": "N"}


def _history(result) -> np.ndarray:
    return np.stack([result.displacement, result.velocity, result.acceleration])


def window_masks(t, settle: float, steady_after: float) -> np.ndarray:
    """(window, T) which samples t (s) each of WINDOWS holds: whole t >= settle, startup
    settle <= t < steady_after, steady t >= max(settle, steady_after)."""
    t = np.asarray(t)
    kept = t >= settle - 1e-12
    steady = t >= steady_after - 1e-12
    return np.stack([kept, kept & ~steady, kept & steady])


def window_reductions(err: np.ndarray, masks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Max and mean of |err| (quantity, time, direction) over each window's samples (window, time):
    (window, quantity, direction) each; NaN where a window holds no finite value."""
    peaks, means, magnitude = [], [], np.abs(err)
    for mask in masks:
        e = magnitude[:, _samples(mask)]
        finite = np.isfinite(e).any(axis=1)
        with np.errstate(invalid="ignore", all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)        # empty or all-NaN windows
            peaks.append(np.where(finite, np.max(np.where(np.isfinite(e), e, -np.inf), axis=1,
                                                 initial=-np.inf), np.nan))
            means.append(np.nanmean(e, axis=1) if e.shape[1] else np.full(finite.shape, np.nan))
    return np.stack(peaks), np.stack(means)


def _samples(mask: np.ndarray):
    """The samples a window's mask holds: a slice where they are consecutive (every window of
    :func:`window_masks` is), so they are read in place rather than copied; else the mask."""
    where = np.flatnonzero(mask)
    if where.size and where[-1] - where[0] + 1 == where.size:
        return slice(int(where[0]), int(where[-1]) + 1)
    return mask


def error_summaries(result, settle: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Max and mean over t >= ``settle`` (s) of |error| (quantity, direction): the whole window of
    :func:`window_summaries`."""
    peak, mean = window_summaries(result, settle, settle)
    return peak[0], mean[0]


def window_summaries(result, settle: float = 0.0, steady_after: float = 0.0
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Max and mean of |error| per window of WINDOWS (t >= ``settle`` s, split at ``steady_after`` s):
    (window, quantity, direction) each, NaN where nothing finite was computed.  The contact level's
    maxima come from every internal step (its peak_abs_error per startup and steady window)."""
    masks = window_masks(result.t, settle, steady_after)
    peak, mean = window_reductions(_history(result), masks)
    if result.peak_abs_error is not None:  # taken over every internal step, finer than the output
        finer = np.asarray(result.peak_abs_error)                  # (startup, steady)
        finer = np.concatenate([finer.max(axis=0)[None], finer])
        peak = np.where(np.isfinite(peak), finer, np.nan)
    return peak, mean


def window_label(window: str, steady_after: float) -> str:
    """How a window reads in tables and figures, e.g. 'steady (t >= 0.5 s)'."""
    return {"whole": "whole run", "startup": f"startup (t < {steady_after:g} s)",
            "steady": f"steady (t >= {steady_after:g} s)"}[window]


def check_window(scene, window: str) -> None:
    """ValueError (naming --window) unless ``window`` is one of WINDOWS and holds output samples of
    ``scene`` (an ensemble's statistics over an empty window would all be NaN)."""
    if window not in WINDOWS:
        raise ValueError(f"--window {window}: choose one of {', '.join(WINDOWS)}")
    sim = scene.simulation
    if not window_masks(scene.times, sim.settle_time, sim.steady_after)[WINDOWS.index(window)].any():
        raise ValueError(f"--window {window}: the scene's {window_label(window, sim.steady_after)} "
                         f"window holds no sample after settle_time_s = {sim.settle_time:g} s")


_WINDOW_ATTRS = {"long_name": "analysis window: whole run, startup t < steady_after_s, "
                              "steady t >= steady_after_s (global attribute, s)"}


def run_dataset(scene, result, *, model: str, integrator: str, dt: float, elements: int,
                wall_time: float, seed: int | None = None, realization: int | None = None) -> xr.Dataset:
    """One simulation as a self-describing Dataset: error histories, summaries, provenance (with
    the ``seed`` and ``realization`` of its clearance draw when given)."""
    drawn = {k: v for k, v in (("seed", seed), ("realization", realization)) if v is not None}
    options = " ".join(f"--{k} {v}" for k, v in drawn.items())
    err = _history(result)
    summary_attrs = {"units": MIXED_UNITS, "cell_methods": "time: maximum"}
    peak, mean = window_summaries(result, scene.simulation.settle_time, scene.simulation.steady_after)
    extra = {}
    if result.contact_force_peak is not None:
        extra["max_contact_force"] = (("joint",), result.contact_force_peak, _CONTACT_ATTRS)
    return xr.Dataset(
        data_vars={
            "error": (("quantity", "time", "direction"), err,
                      {"long_name": "platform pose error, actual minus ideal rigid pose",
                       "units": MIXED_UNITS}),
            "max_abs_error": (("window", "quantity", "direction"), peak,
                              {"long_name": "maximum over time of |error|", **summary_attrs}),
            "mean_abs_error": (("window", "quantity", "direction"), mean,
                               {"long_name": "mean over time of |error|", "units": MIXED_UNITS,
                                "cell_methods": "time: mean"}),
            **extra,
        },
        coords={
            "time": ("time", result.t, {"units": "s", "long_name": "time", "axis": "T",
                                        "standard_name": "time"}),
            **({"joint": ("joint", list(JOINTS))} if extra else {}),
            "window": ("window", list(WINDOWS), _WINDOW_ATTRS),
            "direction": ("direction", list(DIRECTIONS),
                          {"long_name": "platform pose direction in the base frame"}),
            "quantity": ("quantity", list(QUANTITIES)),
            "unit": (("quantity", "direction"), _unit_table(),
                     {"long_name": "SI unit of each element"}),
        },
        attrs={
            **_provenance(scene, f"rss6 {model} simulation of scene {scene.name!r}", model=model,
                          integrator=integrator, dt=dt, elements=elements,
                          history=command_line("simulate", scene, model=model, integrator=integrator,
                                               dt=dt, elements=elements, options=options)),
            **drawn,
            "status": result.status,
            "status_message": result.message,
            "steps": result.steps,
            "wall_time_s": wall_time,
        })


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
    import os
    tmp = f"{path}.part"
    encoded, encoding = cf_encode(ds)
    needed = netcdf_size(ds)
    check_free_space(path, needed)
    with sigint_deferred() as interrupted:
        try:
            # The data are in memory or in local files. While a dask.distributed client is open,
            # xarray would otherwise guard the file with a distributed lock: a scheduler round
            # trip per variable, which made each chunk's write 8x slower.
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


def _stream_to_netcdf(ds: xr.Dataset, path, encoding: dict, interrupted: list) -> None:
    """``ds.to_netcdf(path)`` (netCDF4, NETCDF4 format) with :class:`_InOrderWriter`, and the
    values' checksums (global attribute CHECKSUM) written last."""
    import json

    from xarray.backends import NetCDF4DataStore
    store = NetCDF4DataStore.open(path, mode="w", format="NETCDF4")
    try:
        writer = _InOrderWriter(interrupted)
        ds.dump_to_store(store, writer=writer, encoding=encoding)
        store.ds.setncattr(CHECKSUM, json.dumps(writer.digests, sort_keys=True))
    finally:
        store.close()


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
    import json
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


def check_free_space(path, needed: int) -> None:
    """EnsembleFileError naming the folder when it has less than ``needed`` bytes (plus 1 MiB) free."""
    import os
    import shutil
    folder = os.path.dirname(os.path.abspath(path))
    free = shutil.disk_usage(folder).free
    if free < needed + 2 ** 20:
        raise EnsembleFileError(f"{path}: not enough disk space in {folder}: about "
                                f"{(needed + 2 ** 20) / 2 ** 20:.1f} MiB needed, "
                                f"{free / 2 ** 20:.1f} MiB free; free some space and rerun "
                                "(finished parts are kept)")


# --- CF mapping --------------------------------------------------------------
# CF wants UDUNITS units, one per variable; labels as auxiliary string variables (CF coordinate
# variables are numeric), cell_methods naming dimensions the variable has, no axis "E" and no fill
# value on coordinates. The error variables mix units over (quantity, direction), so each is
# stored split into one variable per quantity and direction family (translation x, y, z in m,
# m s-1, m s-2; rotation rx, ry, rz in rad, rad s-1, rad s-2), each with its CF ``units``, and
# joined again when the file is read. What CF cannot say is kept under an ``rss6_`` attribute and
# restored when the file is read.

_LABEL = "_label"
_ELAPSED = "elapsed_time"   # the file's name of ``time``: CF keeps "time" for calendar times
_MOVED = ("units", "cell_methods", "axis", "standard_name", "long_name")
_PART_OF = "rss6_part_of"     # a split variable: the variable it is part of, its dims, its quantity
_PART_DIMS = "rss6_dims"
_PART_QUANTITY = "rss6_quantity"
CHECKSUM = "rss6_sha256"      # global attribute: {variable: sha256 of its values} as JSON


def _cf_attrs(name: str, var: xr.DataArray) -> dict:
    """A variable's attributes with the non-CF ones moved under ``rss6_``."""
    attrs = dict(var.attrs)
    names = set(var.dims)
    moved = {}
    if attrs.get("units") == MIXED_UNITS:
        moved["units"] = attrs.pop("units")  # per-element SI units: the auxiliary 'unit' variable
    if "cell_methods" in attrs and attrs["cell_methods"].split(":")[0].strip() not in names:
        moved["cell_methods"] = attrs.pop("cell_methods")  # over time, which the file does not hold
    if attrs.get("axis") == "E":
        moved["axis"] = attrs.pop("axis")
    if name == _ELAPSED:  # time since the start of the motion, not a CF calendar time
        moved.update({k: attrs.pop(k) for k in ("standard_name", "axis", "long_name") if k in attrs})
        attrs["long_name"] = "time since the start of the motion"
    return {**attrs, **{f"rss6_{k}": v for k, v in moved.items()}}


def _splittable(ds: xr.Dataset, name) -> bool:
    """A variable of mixed units over (quantity, direction) with rss6's labels there."""
    var = ds[name]
    return (var.attrs.get("units") == MIXED_UNITS and {"quantity", "direction"} <= set(var.dims)
            and set(map(str, ds["quantity"].values)) <= set(QUANTITIES)
            and set(map(str, ds["direction"].values)) <= set(DIRECTIONS))


def _split_units(ds: xr.Dataset) -> xr.Dataset:
    """Each mixed-unit variable as one variable per quantity and direction family, in its place:
    ``max_abs_error`` -> ``max_abs_error_displacement_translation`` (units m, direction x, y, z
    along dimension ``translation``), ... ``max_abs_error_acceleration_rotation`` (rad s-2)."""
    mixed = [name for name in ds.data_vars if _splittable(ds, name)]
    if not mixed:
        return ds
    directions = [str(d) for d in ds["direction"].values]
    families = {f: [d for d in directions if d in members] for f, members in FAMILIES.items()}
    data = {}
    for name, var in ds.data_vars.items():
        if name not in mixed:
            data[name] = var
            continue
        attrs = {k: v for k, v in var.attrs.items() if k not in ("units", "long_name")}
        for q in map(str, ds["quantity"].values):
            for i, (family, members) in enumerate(families.items()):
                if members:
                    part = var.sel(quantity=q, direction=members, drop=True).rename(direction=family)
                    data[f"{name}_{q}_{family}"] = part.assign_attrs(
                        long_name=f"{var.attrs.get('long_name', name)}: {q}, {family}",
                        units=UNITS[q][i], **attrs, rss6_long_name=var.attrs.get("long_name", name),
                        **{_PART_OF: name, _PART_DIMS: " ".join(var.dims), _PART_QUANTITY: q})
    coords = {f: (f, members, {"long_name": f"platform pose {family_name}"})
              for f, members, family_name in (("translation", families["translation"], "translation direction"),
                                              ("rotation", families["rotation"], "rotation axis"))
              if members}
    return xr.Dataset(data, coords={**ds.coords, **coords}, attrs=ds.attrs)


def _join_units(ds: xr.Dataset) -> xr.Dataset:
    """Undo :func:`_split_units` (labels already index coordinates): each split variable's parts
    joined over (quantity, direction) in the file's label order, in the place of its first part."""
    parts = {}
    for name, var in ds.data_vars.items():
        if _PART_OF in var.attrs:
            parts.setdefault(str(var.attrs[_PART_OF]), []).append(name)
    if not parts:
        return ds
    data, joined = {}, {}
    for name, var in ds.data_vars.items():
        whole = str(var.attrs.get(_PART_OF, ""))
        if not whole:
            data[name] = var
        elif whole not in joined:
            joined[whole] = data[whole] = _joined(ds, whole, parts[whole])
    families = [f for f in FAMILIES if f in ds.coords]
    out = xr.Dataset(data, coords=ds.coords, attrs=ds.attrs).drop_vars(families)
    out.encoding = dict(ds.encoding)   # the file it was read from (``source``)
    return out


def _joined(ds: xr.Dataset, name: str, names: list) -> xr.Variable:
    """Variable ``name`` from its parts ``names`` (see :func:`_split_units`), its quantities and
    directions in the order of the Dataset's labels; stacked as arrays (dask ones stay lazy)."""
    first = ds[names[0]]
    dims = str(first.attrs[_PART_DIMS]).split()
    inner = [d for d in dims if d != "quantity"]         # a part's dims, with its family as direction
    by_quantity, labels = {}, {}
    for part in names:
        var = ds[part].variable
        family = next(f for f in FAMILIES if f in var.dims)
        q = str(var.attrs[_PART_QUANTITY])
        by_quantity.setdefault(q, []).append(var.transpose(*[family if d == "direction" else d
                                                             for d in inner]).data)
        labels.setdefault(q, []).extend(str(v) for v in ds[family].values)
    lib = np
    if any(dask.is_dask_collection(x) for xs in by_quantity.values() for x in xs):
        import dask.array as lib   # histories read lazily (imported here: it takes 0.1 s)
    axis = inner.index("direction")
    data = lib.stack([lib.concatenate(xs, axis=axis) for xs in by_quantity.values()],
                     axis=dims.index("quantity"))
    quantities, directions = list(by_quantity), next(iter(labels.values()))
    want_q, want_d = ([str(v) for v in ds[d].values] for d in ("quantity", "direction"))
    if quantities != want_q:
        data = lib.take(data, [quantities.index(q) for q in want_q], axis=dims.index("quantity"))
    if directions != want_d:
        data = lib.take(data, [directions.index(d) for d in want_d], axis=dims.index("direction"))
    attrs = {k: v for k, v in first.attrs.items()
             if k not in ("units", "long_name", _PART_OF, _PART_DIMS, _PART_QUANTITY)}
    attrs = {"long_name": attrs.pop("rss6_long_name", name), "units": MIXED_UNITS, **attrs}
    return xr.Variable(dims, data, attrs)


def cf_encode(ds: xr.Dataset) -> tuple[xr.Dataset, dict]:
    """Any Dataset rss6 writes, as CF-1.10 allows it, and the netCDF encoding to write it with."""
    out = ds.rename({"time": _ELAPSED}) if "time" in ds.variables else ds.copy()
    out = _split_units(out)
    labelled = sorted(d for d in out.dims if d in out.coords and out[d].dtype.kind in "OUS")
    if labelled:   # one drop and one assignment: each costs xarray an alignment (ms)
        out = out.drop_vars(labelled).assign_coords(
            {dim + _LABEL: ((dim,), out[dim].values.astype(str).astype(object),
                            {"long_name": out[dim].attrs.get("long_name", dim)})
             for dim in labelled})
    for name, var in out.variables.items():
        var.attrs = _cf_attrs(name, out[name])
        var.encoding.pop("coordinates", None)   # a file read earlier: xarray lists them afresh
    out.attrs = {"Conventions": "CF-1.10", "source": f"rss6 {__version__}",
                 **{k: v for k, v in out.attrs.items() if k != CHECKSUM}}
    encoding = {name: {"_FillValue": None} for name in out.coords
                if out[name].dtype.kind == "f"}
    return out, encoding


def cf_decode(ds: xr.Dataset) -> xr.Dataset:
    """Undo :func:`cf_encode`: string labels back as coordinates, split variables joined,
    ``rss6_`` attributes restored (the checksum attribute dropped: it describes the file)."""
    labels = {str(name)[:-len(_LABEL)]: ds[name] for name in ds.variables
              if str(name).endswith(_LABEL) and ds[name].dims == (str(name)[:-len(_LABEL)],)}
    if labels:   # one drop and one assignment: each costs xarray an alignment (ms)
        ds = ds.drop_vars([dim + _LABEL for dim in labels]).assign_coords(
            {dim: (dim, label.values.astype(str).astype(object),
                   {k: v for k, v in label.attrs.items() if k != "long_name" or v != dim})
             for dim, label in labels.items()})
    ds = _join_units(ds)
    if _ELAPSED in ds.variables:
        ds = ds.rename({_ELAPSED: "time"})
        ds["time"].attrs.pop("long_name", None)
    for name in ds.variables:
        attrs = ds[name].attrs
        if any(k.startswith("rss6_") and k[5:] in _MOVED for k in attrs):
            ds[name].attrs = {**{k: v for k, v in attrs.items()
                                 if not (k.startswith("rss6_") and k[5:] in _MOVED)},
                              **{k[5:]: v for k, v in attrs.items()
                                 if k.startswith("rss6_") and k[5:] in _MOVED}}
    ds.attrs = {k: v for k, v in ds.attrs.items() if k != CHECKSUM}
    return ds


def labelled(ds: xr.Dataset) -> xr.Dataset:
    """A Dataset opened with plain xarray (``xr.open_dataset(f)``) as rss6 holds it in memory: label
    coordinates (``.sel(quantity="displacement", direction="x", statistic="q95")``), the error
    variables joined over (quantity, direction) again, ``elapsed_time`` as ``time``. ``ds`` itself
    is left as it is."""
    return cf_decode(ds.copy())


# --- ensembles -------------------------------------------------------------

JOINTS = tuple(f"{j}{i}" for j in "ACB" for i in range(1, 7))
ENSEMBLE_ATTRS = ("seed", "store", "n_realizations", "n_failed")   # and PROVENANCE: finish_ensemble
IDENTITY = ("scene_toml", "model", "integrator", "time_step_s", "elements_per_link", "seed", "store",
            "sampler", "qmc_replicates")   # the last two absent (None) in mc files


class EnsembleFileError(UserError):
    """A file that is not a complete rss6 ensemble, or one from a different run."""


def chunk_dataset(results: list, draws: list, realizations: list[int], store: str,
                  settle: float = 0.0, steady_after: float = 0.0) -> xr.Dataset:
    """Realisations ``realizations`` (their results and the draws the file records) as one slice of
    the ensemble file (docs/model.md section 7), built at once rather than concatenated from one
    Dataset per realisation; the summaries leave out t < ``settle`` (s) and are split into WINDOWS
    at ``steady_after`` (s). A realisation without contact forces among others that have them
    (a failed one) gets NaN there."""
    summaries = [window_summaries(result, settle, steady_after) for result in results]
    peak = np.stack([p for p, _ in summaries], axis=2)          # (window, quantity, realization, dir)
    mean = np.stack([m for _, m in summaries], axis=2)
    size = np.stack([np.concatenate([d.radial_size, d.size_C, d.size_B]) for d in draws])
    axial = np.stack([np.concatenate([d.axial_size, np.full(12, np.nan)]) for d in draws])
    ecc = np.stack([np.concatenate([d.e_A, d.e_C, d.e_B]) for d in draws])
    data = {
        "max_abs_error": (("window", "quantity", "realization", "direction"), peak,
                          {"long_name": "per-realisation maximum over time of |platform pose error|",
                           "units": MIXED_UNITS, "cell_methods": "time: maximum"}),
        "mean_abs_error": (("window", "quantity", "realization", "direction"), mean,
                           {"long_name": "per-realisation mean over time of |platform pose error|",
                            "units": MIXED_UNITS, "cell_methods": "time: mean"}),
        "clearance_size": (("realization", "joint"), size,
                           {"long_name": "drawn clearance size (radial for A_i, spherical for C_i, B_i)",
                            "units": "m"}),
        "axial_clearance_size": (("realization", "joint"), axial,
                                 {"long_name": "drawn axial clearance size of the revolute A_i",
                                  "units": "m"}),
        "eccentricity": (("realization", "joint", "component"), ecc,
                         {"long_name": "drawn eccentricity, distal minus proximal joint element, base frame",
                          "units": "m"}),
        "status": (("realization",), np.array([r.status for r in results], dtype=object),
                   {"long_name": "solver status (finished or failed)"}),
        "status_message": (("realization",), np.array([r.message for r in results], dtype=object),
                           {"long_name": "solver message"}),
        "steps": (("realization",), np.array([r.steps for r in results], dtype=np.int64),
                  {"long_name": "time steps completed", "units": "1"}),
    }
    if any(r.contact_force_peak is not None for r in results):
        data["max_contact_force"] = (("realization", "joint"), np.stack(
            [np.full(18, np.nan) if r.contact_force_peak is None else r.contact_force_peak
             for r in results]), _CONTACT_ATTRS)
    coords = {"realization": ("realization", np.asarray(realizations, dtype=np.int64),
                              {"long_name": "realisation index", "axis": "E"})}
    if store == "full":
        data["error"] = (("realization", "quantity", "time", "direction"),
                         np.stack([_history(r) for r in results]),
                         {"long_name": "platform pose error, actual minus ideal rigid pose",
                          "units": MIXED_UNITS})
        coords["time"] = ("time", results[0].t, {"units": "s", "standard_name": "time", "axis": "T"})
    return xr.Dataset(data, coords=coords)


def finish_ensemble(parts: list[xr.Dataset], scene, *, model: str, integrator: str, dt: float,
                    elements: int, seed: int, store: str, sampler: dict | None = None) -> xr.Dataset:
    """Concatenate realisations (sorted) and add coordinates and provenance (``sampler``: the
    attributes of a QMC design, pipeline/sampler.py; none for plain Monte Carlo)."""
    ds = xr.concat(parts, dim="realization", data_vars="minimal", coords="minimal",
                   compat="override", join="override") if len(parts) > 1 else parts[0]
    if not (np.diff(ds["realization"].values) > 0).all():   # (lazy histories: no reindexing)
        ds = ds.sortby("realization")
    ds = ds.assign_coords(
        direction=("direction", list(DIRECTIONS), {"long_name": "platform pose direction, base frame"}),
        quantity=("quantity", list(QUANTITIES)),
        joint=("joint", list(JOINTS), {"long_name": "clearance joint"}),
        component=("component", ["x", "y", "z"], {"long_name": "base-frame vector component"}),
        unit=(("quantity", "direction"), _unit_table(), {"long_name": "SI unit of each element"}),
        window=("window", list(WINDOWS), _WINDOW_ATTRS))
    sampler = sampler or {}
    history = command_line("run", scene, model=model, integrator=integrator, dt=dt, elements=elements,
                           options=_run_options(ds["realization"].values, seed, store, sampler))
    ds.attrs = {
        **_provenance(scene, f"rss6 ensemble: {model} level, scene {scene.name!r}", model=model,
                      integrator=integrator, dt=dt, elements=elements, history=history),
        "seed": seed,
        "store": store,
        "n_realizations": int(ds.sizes["realization"]),
        "n_failed": int((ds["status"].values != FINISHED).sum()),
        **sampler,
    }
    return ds


def _run_options(realizations: np.ndarray, seed: int, store: str, sampler: dict) -> str:
    """The options of ``rss6 run`` that fix an ensemble's values; realisations 0..n-1 as ``-n n``,
    another set (a part of a run) by its range."""
    qmc = f" --sampler qmc --replicates {sampler['qmc_replicates']}" if sampler else ""
    r = [int(v) for v in realizations]
    size = f"-n {len(r)}" if r == list(range(len(r))) else f"(realisations {r[0]}-{r[-1]})"
    return f"--seed {seed} --store {store}{qmc} {size}"


def identity(attrs: dict) -> dict:
    """The attributes that must match for two pieces to belong to the same ensemble (numbers as
    Python scalars; a file without a sampler is plain Monte Carlo)."""
    out = {k: attrs.get(k) for k in IDENTITY}
    out = {k: v.item() if isinstance(v, np.generic) else v for k, v in out.items()}
    return out | {"sampler": out["sampler"] or "mc"}


HISTORY_BLOCK = 64   # realisations per block of a history read lazily (a merge holds one block)


def load_netcdf(path, lazy: bool = False, verify: bool = True) -> xr.Dataset:
    """Any netCDF file fully into memory; EnsembleFileError names the file if it is missing or unreadable.

    ``lazy``: the variables over time (histories) stay on disk as dask arrays of HISTORY_BLOCK
    realisations, read block by block when used; the file stays open while the Dataset is used.
    ``verify``: the values are checked against the checksums written with the file
    (:func:`verify_checksums`; read once more, block by block, when ``lazy``); a file without them
    is marked ``encoding["rss6_unverified"]`` (see :func:`note_unverified`).
    """
    import os
    if not os.path.exists(path):
        raise EnsembleFileError(f"{path}: no such file")
    try:
        if lazy:
            # opened without dask: only the histories become dask arrays (loading each small
            # variable through dask took 3x as long as reading it)
            ds = xr.open_dataset(path, engine="netcdf4", decode_times=False)
            histories = {name: var.chunk({"realization": HISTORY_BLOCK})
                         for name, var in ds.data_vars.items() if {_ELAPSED, "realization"} <= set(var.dims)}
            for var in ds.variables.values():
                if _ELAPSED not in var.dims:
                    var.load()
            ds = ds.assign(histories)
        else:
            with xr.open_dataset(path, engine="netcdf4", decode_times=False) as opened:
                ds = opened.load()
    except Exception as exc:  # netCDF4/HDF5 raise OSError, RuntimeError, ValueError...
        raise EnsembleFileError(f"{path}: not a readable netCDF file "
                                f"(truncated or corrupt?): {exc}") from None
    verified = verify and verify_checksums(ds, path)
    try:
        out = _forget_string_widths(cf_decode(ds))
    except Exception as exc:  # a foreign file whose variables look like rss6's split ones
        raise EnsembleFileError(f"{path}: not a file rss6 reads: {type(exc).__name__}: {exc}") from None
    if verify and not verified:
        out.encoding["rss6_unverified"] = True
    return out


def note_unverified(ds: xr.Dataset, path, stream=None) -> None:
    """One line on stderr when ``ds`` was read from a file without checksums: it is accepted (an
    earlier rss6's results stay usable; its values pass every consistency check), but a change
    to its values could not be seen."""
    import sys
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


def open_ensemble(path, lazy: bool = False, verify: bool = True) -> xr.Dataset:
    """Open an ensemble file into memory (``lazy``: its histories stay on disk; ``verify``: its
    checksums checked, see :func:`load_netcdf`); EnsembleFileError names the file and the problem."""
    return checked_ensemble(load_netcdf(path, lazy, verify), path)


def checked_ensemble(ds: xr.Dataset, path) -> xr.Dataset:
    """``ds`` (read from ``path``) if it is a well-formed rss6 ensemble, else EnsembleFileError."""
    missing = [k for k in ("max_abs_error", "mean_abs_error", "status") if k not in ds]
    if missing or "rss6_version" not in ds.attrs or "realization" not in ds.dims:
        raise EnsembleFileError(f"{path}: not an rss6 ensemble file (missing "
                                f"{', '.join(missing) or 'rss6 attributes'})")
    from .check import check_ensemble   # filecheck imports this module
    check_ensemble(ds, path)
    return ds
