"""What a run or an ensemble holds before it is a file: the analysis windows and their max and mean
of |error|, a single run's Dataset, an ensemble's slice of realisations, and the finished ensemble
with its provenance."""
from __future__ import annotations

import warnings

import numpy as np
import xarray as xr

from ..vocabulary import DIRECTIONS, FINISHED, QUANTITIES, WINDOWS
from .schema import JOINTS, MIXED_UNITS, _provenance, _unit_table, command_line

__all__ = ["window_masks", "window_reductions", "error_summaries", "window_summaries", "window_label",
           "check_window", "run_dataset", "chunk_dataset", "input_variables", "INPUT_COORDS", "finish_ensemble"]


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
    (window, quantity, direction) each; NaN where a window holds no finite value.  Both reduce along
    the time axis of a transposed contiguous copy (quantity, direction, time): exact for the maxima
    in any order, numpy's pairwise sums for the means, and several times faster than across the history's
    rows (docs/performance.md sections 29 and 34)."""
    by_time = np.ascontiguousarray(np.abs(err).transpose(0, 2, 1))
    windows = [_samples(mask) for mask in masks]
    if np.isfinite(by_time).all() and all(np.any(mask) for mask in masks):
        return (np.stack([by_time[..., window].max(axis=-1) for window in windows]),
                np.stack([by_time[..., window].mean(axis=-1) for window in windows]))
    peaks, means = [], []
    for window in windows:
        e = by_time[..., window]
        finite = np.isfinite(e).any(axis=-1)
        with np.errstate(invalid="ignore", all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)        # empty or all-NaN windows
            peaks.append(np.where(finite, np.max(np.where(np.isfinite(e), e, -np.inf), axis=-1,
                                                 initial=-np.inf), np.nan))
            means.append(np.nanmean(e, axis=-1) if e.shape[-1] else np.full(finite.shape, np.nan))
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


def window_label(window: str, steady_after: float, settle: float = 0.0) -> str:
    """How a window reads in tables and figures, e.g. 'steady (t >= 0.5 s)': the times it covers, s,
    with the scene's settle_time_s ``settle`` left out of every window."""
    if empty_window(window, settle, steady_after):
        return f"startup (empty: steady_after_s {steady_after:g} s <= settle_time_s {settle:g} s)"
    after = f" (t >= {settle:g} s)" if settle > 0 else ""
    since = f"{settle:g} s <= " if settle > 0 else ""
    return {"whole": f"whole run{after}", "startup": f"startup ({since}t < {steady_after:g} s)",
            "steady": f"steady (t >= {max(steady_after, settle):g} s)"}[window]


def file_window_bounds(attrs) -> tuple[float, float]:
    """A file's (or a summary's) settle_time_s and steady_after_s (s); 0 and NaN where it lacks them."""
    return float(attrs.get("settle_time_s", 0.0)), float(attrs.get("steady_after_s", np.nan))


def file_window_label(window: str, attrs) -> str:
    """:func:`window_label` of a file's (or a summary's) ``steady_after_s`` and ``settle_time_s``."""
    settle, steady_after = file_window_bounds(attrs)
    return window_label(window, steady_after, settle)


def empty_window(window: str, settle: float, steady_after: float) -> str | None:
    """Why analysis ``window`` holds no output sample, or None. The one empty window rss6 allows is the
    startup of a scene whose steady_after_s <= settle_time_s (s): the scene's checks keep every other
    window filled (rss6core.scene: steady_after_s < the duration, a start-up window holds a sample)."""
    if window == "startup" and steady_after <= settle:
        return (f"the startup window is empty (steady_after_s {steady_after:g} s <= settle_time_s {settle:g} s): "
                "choose the steady or whole window")
    return None


def check_window(scene, window: str) -> None:
    """ValueError (naming --window) unless ``window`` is one of WINDOWS and holds output samples of
    ``scene`` (:func:`empty_window`; an ensemble's statistics over an empty window would all be NaN)."""
    if window not in WINDOWS:
        raise ValueError(f"--window {window}: choose one of {', '.join(WINDOWS)}")
    empty = empty_window(window, scene.simulation.settle_time, scene.simulation.steady_after)
    if empty:
        raise ValueError(f"--window {window}: {empty}")


_WINDOW_ATTRS = {"long_name": "analysis window: whole run, startup t < steady_after_s, "
                              "steady t >= steady_after_s (global attributes, s; each from settle_time_s on)"}


def run_dataset(scene, result, *, model: str, integrator: str, dt: float, elements: int,
                seed: int | None = None, realization: int | None = None) -> xr.Dataset:
    """One simulation as a self-describing Dataset: error histories, summaries, provenance (with
    the ``seed`` and ``realization`` of its clearance draw when given)."""
    drawn = {k: v for k, v in (("seed", seed), ("realization", realization)) if v is not None}
    options = " ".join(f"--{k} {v}" for k, v in drawn.items())
    err = _history(result)
    summary_attrs = {"units": MIXED_UNITS, "cell_methods": "time: maximum"}
    peak, mean = window_summaries(result, scene.simulation.settle_time, scene.simulation.steady_after)
    extra, input_coords = {}, {}
    if result.contact_force_peak is not None:
        extra["max_contact_force"] = (("joint",), result.contact_force_peak, _CONTACT_ATTRS)
    if result.inputs is not None:   # a scene with [uncertain.*] tables: the run's drawn inputs
        (_, values, attrs), input_coords = input_variables([result.inputs])
        extra["uncertain_input"] = (("input",), values[0], attrs)
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
            **({"joint": ("joint", list(JOINTS))} if "max_contact_force" in extra else {}),
            **input_coords,
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
        })


def chunk_dataset(results: list, draws: list, realizations: list[int], store: str,
                  settle: float = 0.0, steady_after: float = 0.0, inputs: list | None = None) -> xr.Dataset:
    """Realisations ``realizations`` (their results and the draws the file records) as one slice of
    the ensemble file (docs/model.md section 7), built at once rather than concatenated from one
    Dataset per realisation; the summaries leave out t < ``settle`` (s) and are split into WINDOWS
    at ``steady_after`` (s). A realisation without contact forces among others that have them
    (a failed one) gets NaN there. ``inputs``: each realisation's uncertain inputs (InputDraw) of a
    scene with [uncertain.*] tables, stored as ``uncertain_input`` (:func:`input_variables`)."""
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
    if inputs:
        variable, input_coords = input_variables(inputs)
        data["uncertain_input"] = variable
        coords.update(input_coords)
    if store == "full":
        data["error"] = (("realization", "quantity", "time", "direction"),
                         np.stack([_history(r) for r in results]),
                         {"long_name": "platform pose error, actual minus ideal rigid pose",
                          "units": MIXED_UNITS})
        coords["time"] = ("time", results[0].t, {"units": "s", "standard_name": "time", "axis": "T"})
    return xr.Dataset(data, coords=coords)


INPUT_COORDS = ("input_parameter", "input_units", "input_law")   # per drawn input, beside its label


def input_variables(inputs: list) -> tuple[tuple, dict]:
    """The realisations' drawn uncertain inputs (InputDraw each) as the variable ``uncertain_input``
    (realization, input): SI deviations from the nominal (lognormal: factors); per input its label,
    the scene key it draws, its units and its law as coordinates along ``input``."""
    table = inputs[0].inputs
    values = np.stack([d.values for d in inputs])
    variable = (("realization", "input"), values,
                {"long_name": "drawn uncertain input: deviation from the nominal value in SI units, "
                              "or the factor on it for a lognormal law",
                 "comment": "units per input: coordinate input_units; law: input_law ([uncertain.*] tables, "
                            "docs/model.md section 4b)"})
    coords = {"input": ("input", list(table.labels()), {"long_name": "uncertain input, per draw"}),
              "input_parameter": ("input", list(table.columns(lambda i: i.parameter)),
                                  {"long_name": "the scene key (table.key) the input draws"}),
              "input_units": ("input", list(table.columns(lambda i: i.draw_units)),
                              {"long_name": "units of the input's draws"}),
              "input_law": ("input", list(table.columns(lambda i: i.law_text())),
                            {"long_name": "law of the input's draws, parameters in the key's TOML unit"})}
    return variable, coords


def finish_ensemble(parts: list[xr.Dataset], scene, *, model: str, integrator: str, dt: float,
                    elements: int, seed: int, store: str, sampler: dict | None = None) -> xr.Dataset:
    """Concatenate realisations (sorted) and add coordinates and provenance (``sampler``: the
    attributes of a QMC design, pipeline/ensemble/sampler.py; none for plain Monte Carlo)."""
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

