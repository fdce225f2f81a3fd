"""The netCDF schema of rss6's files: SI and display units, the provenance and identity attributes
every file carries, and the CF-1.10 encoding (mixed-unit variables split per unit, labels as strings).

The direction dimension mixes translations (x, y, z in m) and rotations
(rx, ry, rz in rad), so in memory a variable's ``units`` attribute names both and
the coordinate ``unit`` (quantity, direction) gives each element's unit exactly;
in a file each such variable is split into one variable per unit (see the CF
mapping below).
"""
from __future__ import annotations

import dask
import numpy as np
import xarray as xr

from rss6core import __version__, model_level

from ..vocabulary import DIRECTIONS, FAMILIES, QUANTITIES, UserError

__all__ = ["UNITS", "MIXED_UNITS", "display_unit", "SETTINGS", "settings_attrs", "PROVENANCE", "ENSEMBLE_ATTRS",
           "IDENTITY", "ensemble_identity", "identity", "command_line", "derived_history", "JOINTS",
           "EnsembleFileError", "CHECKSUM", "ALTERED", "cf_encode", "cf_decode", "labelled", "unit_json"]

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

# the level's settings as global attributes: keyword of the functions here -> attribute name
SETTINGS = {"model": "model", "integrator": "integrator", "dt": "time_step_s", "elements": "elements_per_link"}
# the global attributes :func:`_provenance` gives every file (contact-level files also contact_start)
PROVENANCE = ("Conventions", "title", "source", "rss6_version", "scene_name", "scene_toml", *SETTINGS.values(),
              "settle_time_s", "steady_after_s")
ENSEMBLE_ATTRS = ("seed", "store", "n_realizations", "n_failed")   # and PROVENANCE: finish_ensemble
# the attributes that fix an ensemble's values (:func:`ensemble_identity`); the last two absent
# (None) in mc files
IDENTITY = ("scene_toml", *SETTINGS.values(), "seed", "store", "sampler", "qmc_replicates")


def settings_attrs(**settings) -> dict:
    """The level's settings (keywords model, integrator, dt in s, elements) as the attributes of SETTINGS."""
    return {attr: settings[key] for key, attr in SETTINGS.items()}


def ensemble_identity(scene_toml: str, *, seed: int, store: str, sampler: dict, **settings) -> dict:
    """An ensemble's IDENTITY as its files write it: the scene text, the level's settings
    (:func:`settings_attrs`), seed, store and the QMC design's attributes (none for Monte Carlo)."""
    return {"scene_toml": scene_toml, **settings_attrs(**settings), "seed": seed, "store": store, **sampler}


def identity(attrs: dict) -> dict:
    """The attributes that must match for two pieces to belong to the same ensemble (numbers as
    Python scalars; a file without a sampler is plain Monte Carlo)."""
    out = {k: attrs.get(k) for k in IDENTITY}
    out = {k: v.item() if isinstance(v, np.generic) else v for k, v in out.items()}
    return out | {"sampler": out["sampler"] or "mc"}


def _provenance(scene, title: str, *, model: str, integrator: str, dt: float,
                elements: int, history: str | None = None) -> dict:
    """Global attributes every rss6 file carries: conventions, what made it (``history``: the
    command, without the machine-dependent options, so the same command gives the same file;
    by default the title), version, scene text, settings."""
    return {"Conventions": "CF-1.10", "title": title, "history": history or f"rss6: {title}",
            "source": f"rss6 {__version__}",
            "rss6_version": __version__, "scene_name": scene.name, "scene_toml": scene.source_text,
            **settings_attrs(model=model, integrator=integrator, dt=dt, elements=elements),
            "settle_time_s": scene.simulation.settle_time,
            "steady_after_s": scene.simulation.steady_after,
            **({"contact_start": scene.simulation.contact_start} if model_level(model).contact_start else {})}


def command_line(command: str, scene, *, model: str, integrator: str, dt: float, elements: int,
                 options: str = "") -> str:
    """A history line: the rss6 command and the options that fix its results (the scene by name;
    its text is the file's scene_toml), e.g. 'rss6 run smoke --model contact ... -n 16'; the integrator
    and mesh only for a level with elastic links (a rigid-link level refuses them)."""
    level = model_level(model)
    start = f" --start {scene.simulation.contact_start}" if level.contact_start else ""
    links = f" --integrator {integrator} --dt {dt} --elements {elements}" if level.elastic_links else f" --dt {dt}"
    return f"rss6 {command} {scene.name} --model {model}{links}{start}" + (f" {options}" if options else "")


def derived_history(source: xr.Dataset, line: str) -> str:
    """The history of a file made from ``source``: its history, then ``line`` (CF: each command that
    derives a file appends itself)."""
    previous = str(source.attrs.get("history", "")).strip()
    return f"{previous}\n{line}" if previous else line


def unit_json() -> dict:
    """{quantity: {direction: SI unit}}: what a JSON output says its bare SI numbers are in."""
    return {q: {d: str(u) for d, u in zip(DIRECTIONS, row)} for q, row in zip(QUANTITIES, _unit_table())}


def _unit_table() -> np.ndarray:
    return np.array([[UNITS[q][0]] * 3 + [UNITS[q][1]] * 3 for q in QUANTITIES])


JOINTS = tuple(f"{j}{i}" for j in "ACB" for i in range(1, 7))   # the clearance joints, A_i C_i B_i


class EnsembleFileError(UserError):
    """A file that is not a complete rss6 ensemble, or one from a different run."""


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
# what a reader says of a file whose values or attributes changed after rss6 wrote it
ALTERED = "the file was altered after rss6 wrote it; rerun the command that wrote it, or restore the file"
CHECKSUM = "rss6_sha256"      # global attribute: {variable: sha256 of its values, "/attributes": {...}} as JSON


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
    along dimension ``translation``), ... ``max_abs_error_acceleration_rotation`` (rad s-2).
    The parts are taken by position from the variables (no label lookups: a chunk's write is in the
    main process, beside the workers)."""
    mixed = [name for name in ds.data_vars if _splittable(ds, name)]
    if not mixed:
        return ds
    directions = [str(d) for d in ds["direction"].values]
    families = {f: [d for d in directions if d in members] for f, members in FAMILIES.items()}
    data = {}
    for name, var in ds.data_vars.items():
        data.update(_unit_parts(name, var, families, directions) if name in mixed else {name: var.variable})
    coords = {f: (f, members, {"long_name": f"platform pose {family_name}"})
              for f, members, family_name in (("translation", families["translation"], "translation direction"),
                                              ("rotation", families["rotation"], "rotation axis"))
              if members}
    return xr.Dataset(data, coords={**ds.coords, **coords}, attrs=ds.attrs)


def _unit_parts(name: str, var: xr.DataArray, families: dict, directions: list) -> dict:
    """:func:`_split_units`'s parts of one mixed-unit variable, {part name: Variable}."""
    attrs = {k: v for k, v in var.attrs.items() if k not in ("units", "long_name")}
    long_name = var.attrs.get("long_name", name)
    parts = {}
    for qi, q in enumerate(map(str, var["quantity"].values)):
        for i, (family, members) in enumerate(families.items()):
            if members:
                part = var.variable.isel(quantity=qi, direction=[directions.index(d) for d in members])
                parts[f"{name}_{q}_{family}"] = xr.Variable(
                    tuple(family if d == "direction" else d for d in part.dims), part.data,
                    {"long_name": f"{long_name}: {q}, {family}", "units": UNITS[q][i], **attrs,
                     "rss6_long_name": long_name, _PART_OF: name, _PART_DIMS: " ".join(var.dims),
                     _PART_QUANTITY: q})
    return parts


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


def _check_part_units(ds: xr.Dataset, part: str, quantity: str, got, want: str) -> None:
    """A split variable's units are those rss6 wrote: a reader that trusts them (a CF tool) would
    otherwise read the values in another unit; rss6's own numbers do not depend on them."""
    if got != want:
        raise EnsembleFileError(f"{ds.encoding.get('source', 'the file')}: variable {part} has units {got!r}, "
                                f"but rss6 writes {want!r} for its {_PART_QUANTITY} {quantity!r}: {ALTERED}")


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
        _check_part_units(ds, part, q, var.attrs.get("units"), UNITS[q][list(FAMILIES).index(family)])
        by_quantity.setdefault(q, []).append(var.transpose(*[family if d == "direction" else d
                                                             for d in inner]).data)
        labels.setdefault(q, []).extend(str(v) for v in ds[family].values)
    lib = np
    if any(dask.is_dask_collection(x) for xs in by_quantity.values() for x in xs):
        import dask.array as lib   # histories read lazily (imported here, where needed: its import is slow)
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

