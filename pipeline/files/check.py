"""Checks that a readable netCDF file holds what rss6 wrote: dimensions, labels, units, values,
and global attributes consistent with the data, rss6's vocabularies and the recorded scene.

A tampered or foreign file that opens fine must not be summarised silently: each
check raises schema.EnsembleFileError naming the file and the first problem.
"""
from __future__ import annotations

import functools
import math

import numpy as np
import xarray as xr

from rss6core import INTEGRATORS, MODELS, STATUSES, SceneError, model_level, models_with, parse_scene, time_grid

from ..vocabulary import DIRECTIONS, FINISHED, QUANTITIES, STORES, SUMMARIES, WINDOWS
from .reading import SUMMARY_BLOCK
from .records import INPUT_COORDS, empty_window
from .schema import ENSEMBLE_ATTRS, MIXED_UNITS, PROVENANCE, EnsembleFileError, _unit_table

__all__ = ["check_ensemble", "check_run"]

FORCE_LEVELS = models_with("contact_forces")   # the levels that write max_contact_force


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
    windows = [w for w in WINDOWS if not empty_window(w, settle, steady_after)]
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


# relative slack of the bounds below: the reductions' round-off is below 1e-12 of the values (a
# mean of n <= 1e5 samples), a changed value is off by far more
SLACK = 1e-9


def _invariants(ds, path) -> None:
    """Bounds the summaries obey by construction (records.window_reductions): a window's maximum is
    at most the whole run's, which is the larger of the startup and steady maxima; a mean is at
    most its window's maximum; the whole run's mean lies between the startup and steady means
    (their weighted average). NaN (no value) bounds nothing."""
    peak, mean = ds["max_abs_error"], ds["mean_abs_error"]
    parts = ["startup", "steady"]
    for w in parts:
        _refuse_above(path, "max_abs_error", peak.sel(window=w), peak.sel(window="whole"),
                      f"the {w} maximum", "the whole-run maximum")
    _refuse_above(path, "max_abs_error", peak.sel(window="whole"),
                  peak.sel(window=parts).max("window", skipna=False),
                  "the whole-run maximum", "the larger of the startup and steady maxima")
    _refuse_above(path, "mean_abs_error", mean, peak, "the mean", "the maximum over the same window")
    whole, split = mean.sel(window="whole"), mean.sel(window=parts)
    _refuse_above(path, "mean_abs_error", whole, split.max("window"), "the whole-run mean",
                  "the larger of the startup and steady means")
    _refuse_above(path, "mean_abs_error", split.min("window"), whole,
                  "the smaller of the startup and steady means", "the whole-run mean")


def _refuse_above(path, name: str, value, bound, what: str, than: str) -> None:
    """EnsembleFileError naming the file, ``name`` and the first element where ``value`` exceeds
    ``bound`` (DataArrays, broadcast by dimension name) beyond SLACK."""
    value, bound = xr.broadcast(value, bound)
    with np.errstate(invalid="ignore"):
        above = value.values > bound.values + SLACK * np.abs(bound.values)
    if not above.any():
        return
    at = tuple(np.argwhere(above)[0])
    where = ", ".join(f"{'realisation' if d == 'realization' else d} {value[d].values[i]}"
                      for d, i in zip(value.dims, at) if d in value.coords)
    raise EnsembleFileError(f"{path}: {name}: {what} ({value.values[at]:.6g}) is above {than} "
                            f"({bound.values[at]:.6g}) at {where}, which cannot happen: the file "
                            "was altered; rerun the command that wrote it")


def _plain(value):
    """An attribute as a Python value (netCDF gives numpy scalars and arrays), to compare and print."""
    return value.tolist() if isinstance(value, (np.generic, np.ndarray)) else value


def _required(ds, path, names, kind: str) -> None:
    """Every global attribute of ``names`` present (``kind``: the files rss6 writes them in)."""
    missing = [k for k in names if k not in ds.attrs]
    if missing:
        raise EnsembleFileError(f"{path}: attribute {missing[0]} missing (rss6 writes it in every {kind})")


def _integer(ds, path, key: str, least: int) -> int:
    """Attribute ``key``, which rss6 writes as an integer, checked to be one >= ``least``."""
    value = _plain(ds.attrs[key])
    if isinstance(value, bool) or not isinstance(value, int) or value < least:
        raise EnsembleFileError(f"{path}: attribute {key} is {value!r}; expected an integer >= {least}")
    return value


def _choice(ds, path, key: str, allowed: tuple) -> str:
    """Attribute ``key`` checked to be a word of rss6's vocabulary ``allowed``."""
    value = _plain(ds.attrs[key])
    if not isinstance(value, str) or value not in allowed:
        raise EnsembleFileError(f"{path}: attribute {key} is {value!r}; expected one of {', '.join(allowed)}")
    return value


def _settings(ds, path) -> str:
    """Model, integrator, time step (s), mesh and version as rss6 writes them; returns the model."""
    model = _choice(ds, path, "model", MODELS)
    _choice(ds, path, "integrator", INTEGRATORS)
    dt = _plain(ds.attrs["time_step_s"])
    if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not (math.isfinite(dt) and dt > 0):
        raise EnsembleFileError(f"{path}: attribute time_step_s is {dt!r}; expected a time > 0 s")
    _integer(ds, path, "elements_per_link", 1)
    version = _plain(ds.attrs["rss6_version"])
    if not isinstance(version, str) or not version.strip():
        raise EnsembleFileError(f"{path}: attribute rss6_version is {version!r}; expected a version")
    return model


def _level(ds, path, model: str, finished: np.ndarray) -> None:
    """The model agrees with the data: the paper and contact levels, and only they, write contact
    forces, for every finished realisation."""
    has = "max_contact_force" in ds
    if has and model not in FORCE_LEVELS:
        raise EnsembleFileError(f"{path}: attribute model is {model!r}, but the file holds max_contact_force, "
                                f"which only the {' and '.join(FORCE_LEVELS)} levels write")
    if not has and model in FORCE_LEVELS and finished.any():
        raise EnsembleFileError(f"{path}: attribute model is {model!r}, but the file has no max_contact_force, "
                                "which that level writes for every finished realisation")


@functools.lru_cache(maxsize=8)
def _scene_of(text: str):
    """The scene a file's scene_toml describes, or the parser's complaint in one line; cached, as
    every part of an ensemble carries the same text (parsed once, not once per part)."""
    try:
        return parse_scene(text, "scene_toml")
    except SceneError as exc:
        return " ".join(str(exc).removeprefix("scene_toml: ").split())


def _scene(ds, path, model: str) -> None:
    """scene_toml is a scene rss6 reads, and the name, window bounds (s), time step and contact
    start recorded beside it agree with it."""
    text = ds.attrs["scene_toml"]
    scene = _scene_of(text) if isinstance(text, str) else f"a {type(text).__name__}, not TOML text"
    if isinstance(scene, str):
        raise EnsembleFileError(f"{path}: attribute scene_toml is not a scene rss6 reads: {scene}")
    if _plain(ds.attrs["scene_name"]) != scene.name:
        raise EnsembleFileError(f"{path}: attribute scene_name is {_plain(ds.attrs['scene_name'])!r}, but "
                                f"scene_toml is scene {scene.name!r}")
    sim = scene.simulation
    for key, value, want in zip(("settle_time_s", "steady_after_s"), _window_bounds(ds, path),
                                (sim.settle_time, sim.steady_after)):
        if not math.isclose(value, want, rel_tol=1e-12, abs_tol=1e-15):
            raise EnsembleFileError(f"{path}: attribute {key} is {value:g} s, but scene_toml says {want:g} s")
    dt, duration = float(ds.attrs["time_step_s"]), scene.trajectory.duration
    try:
        time_grid(duration, dt)
    except ValueError:
        raise EnsembleFileError(f"{path}: attribute time_step_s ({dt:g} s) does not divide the scene's "
                                f"duration ({duration:g} s)") from None
    _contact_start(ds, path, model, sim.contact_start)


def _contact_start(ds, path, model: str, scene_start: str) -> None:
    """contact_start: in every contact-level file and only there, equal to the scene's."""
    start = _plain(ds.attrs.get("contact_start"))
    if not model_level(model).contact_start:
        if start is not None:
            raise EnsembleFileError(f"{path}: attribute contact_start in a {model}-level file (only the "
                                    "contact level writes it)")
    elif start is None:
        raise EnsembleFileError(f"{path}: attribute contact_start missing (rss6 writes it in every "
                                "contact-level file)")
    elif start != scene_start:
        raise EnsembleFileError(f"{path}: attribute contact_start is {start!r}, but scene_toml says "
                                f"{scene_start!r}")


def _attributes(ds, path, finished: np.ndarray) -> None:
    """The provenance every rss6 file carries (schema._provenance): present, in rss6's vocabularies,
    and agreeing with the scene text it records and with the data."""
    _required(ds, path, PROVENANCE, "file")
    model = _settings(ds, path)
    _level(ds, path, model, finished)
    _scene(ds, path, model)


def _sampler(ds, path) -> None:
    """Plain Monte Carlo (no sampler attribute), or sampler 'qmc' with its replicates and mapping."""
    sampler = _plain(ds.attrs.get("sampler"))
    if sampler is None:
        stray = [k for k in ("qmc_replicates", "qmc_mapping") if k in ds.attrs]
        if stray:
            raise EnsembleFileError(f"{path}: attribute {stray[0]} without sampler 'qmc'")
        return
    if sampler != "qmc":
        raise EnsembleFileError(f"{path}: attribute sampler is {sampler!r}; expected 'qmc' (a plain "
                                "Monte Carlo file has none)")
    _required(ds, path, ("qmc_replicates", "qmc_mapping"), "QMC ensemble file")
    _integer(ds, path, "qmc_replicates", 2)


def _ensemble_attributes(ds, path, status: np.ndarray) -> None:
    """seed, store, sampler and the counts n_realizations and n_failed, against the data."""
    _required(ds, path, ENSEMBLE_ATTRS, "ensemble file")
    _integer(ds, path, "seed", 0)
    store = _choice(ds, path, "store", STORES)
    if (store == "full") != ("error" in ds):
        raise EnsembleFileError(f"{path}: attribute store is {store!r}, but the file "
                                f"{'has no' if store == 'full' else 'holds'} histories (error)")
    _sampler(ds, path)
    counts = (("n_realizations", ds.sizes["realization"], "realisations"),
              ("n_failed", int((status != FINISHED).sum()), "failed realisations (status)"))
    for key, held, what in counts:
        value = _integer(ds, path, key, 0)
        if value != held:
            raise EnsembleFileError(f"{path}: attribute {key} is {value}, but the file holds {held} {what}")


def _uncertain_inputs(ds, path) -> None:
    """uncertain_input: present exactly when scene_toml has [uncertain.*] tables, with their labels,
    keys, units and laws along ``input``, and every draw inside its law's range."""
    inputs = _scene_of(ds.attrs["scene_toml"]).uncertain
    if not inputs:
        if "uncertain_input" in ds:
            raise EnsembleFileError(f"{path}: the file holds uncertain_input, but scene_toml has no "
                                    "[uncertain.*] table")
        return
    if "uncertain_input" not in ds or ds["uncertain_input"].dims != ("realization", "input"):
        raise EnsembleFileError(f"{path}: no variable uncertain_input (realization, input), which rss6 writes "
                                "for a scene with [uncertain.*] tables")
    want = {"input": inputs.labels(), "input_parameter": inputs.columns(lambda i: i.parameter),
            "input_units": inputs.columns(lambda i: i.draw_units), "input_law": inputs.columns(lambda i: i.law_text())}
    for name in ("input",) + INPUT_COORDS:
        got = tuple(str(v) for v in ds[name].values) if name in ds.coords else None
        if got != want[name]:
            raise EnsembleFileError(f"{path}: coordinate {name} is {got}; scene_toml's [uncertain.*] tables give "
                                    f"{want[name]}")
    x = ds["uncertain_input"].values
    low, high = (np.concatenate([i.draws(np.full(i.count, u)) for i in inputs.inputs]) for u in (0.0, 1.0))
    with np.errstate(invalid="ignore"):
        bad = ~((x >= low - SLACK * np.abs(low)) & (x <= high + SLACK * np.abs(high)))
    if bad.any():
        r, k = np.argwhere(bad)[0]
        raise EnsembleFileError(f"{path}: uncertain_input {want['input'][k]} of realisation "
                                f"{ds['realization'].values[r]} is {x[r, k]!r}, outside its law's range "
                                f"[{low[k]!r}, {high[k]!r}]")


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
    _attributes(ds, path, status.values == FINISHED)
    _ensemble_attributes(ds, path, status.values)
    _uncertain_inputs(ds, path)
    finished = status.values == FINISHED
    for start in range(0, ds.sizes["realization"], SUMMARY_BLOCK):   # a large file's summaries are on disk
        rows = slice(start, start + SUMMARY_BLOCK)
        part = ds.isel(realization=rows)
        _values(part, path, finished[rows])
        _invariants(part, path)


def check_run(ds, path) -> None:
    """EnsembleFileError unless ``ds`` is a well-formed single-run file (``rss6 simulate -o``)."""
    _dims(ds, path, {"window", "quantity", "direction"})
    _labels(ds, path)
    _units(ds, path)
    status = ds.attrs.get("status")
    if status not in STATUSES:
        raise EnsembleFileError(f"{path}: status attribute {status!r}; expected "
                                f"{' or '.join(STATUSES)}")
    _attributes(ds, path, np.array([status == FINISHED]))
    one = ds[list(SUMMARIES)].expand_dims(realization=[0], axis=1).assign_attrs(ds.attrs)
    _values(one, path, np.array([status == FINISHED]))
    _invariants(ds, path)
