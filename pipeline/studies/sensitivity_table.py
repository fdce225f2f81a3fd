"""The tables ``rss6 sensitivity`` prints from a sensitivity file (:func:`pipeline.studies.sensitivity.sensitivity`):
the families' total indices with the largest family, the joints of largest index, and the notes on what the
numbers can and cannot say (coverage of the label, bounds clipped to [0, 1], estimates outside it, families of fixed
sizes, a drawn start's impacts, outputs whose spread the level does not resolve)."""
from __future__ import annotations

import numpy as np
import xarray as xr

from ..analysis.resolution import resolutions
from ..analysis.stats import level_notes
from ..files.schema import JOINTS
from .sensitivity import BOUNDS, JOINT_FAMILIES, UNMEASURED, coverage_caveat, measured

__all__ = ["format_sensitivity", "format_joints", "unresolved_outputs"]

NOISE = "- (noise: spread below resolution)"   # the 'largest' column of an output the level does not resolve


def _dominant(cell) -> str:
    """The group of largest total index; with the runner-up named when their intervals overlap."""
    est, lo, hi = (cell.sel(bound=b).values for b in BOUNDS)
    if not np.isfinite(est).any():
        return "-"
    order = np.argsort(-np.nan_to_num(est, nan=-np.inf))
    names = [str(g) for g in cell["group"].values]
    top, second = order[0], order[1]
    return names[top] + ("" if lo[top] > hi[second] else f" (overlaps {names[second]})")


def unresolved_outputs(ds: xr.Dataset, statistic: str = "max_abs_error") -> xr.DataArray | None:
    """(quantity, direction) True where the outputs' spread over the evaluated rows is within the level's resolution
    (the file's ``{statistic}_spread`` and ``_resolution``): the indices there rank numerical noise; None for a file
    without them."""
    if f"{statistic}_spread" not in ds:
        return None
    return ds[f"{statistic}_spread"] <= ds[f"{statistic}_resolution"]


def format_sensitivity(ds: xr.Dataset, statistic: str = "max_abs_error") -> str:
    """A table of the family indices of ``statistic``: per quantity and direction, each family's
    total index with its interval, and the family of largest total index (with the runner-up when
    their intervals overlap; none where the outputs' spread is below the level's resolution); below it,
    the notes (:func:`_notes`)."""
    da = ds[f"{statistic}_sobol"].sel(group=[g for g, d in zip(ds["group"].values, ds["group_design"].values)
                                             if d == "families"])
    confidence = float(ds.attrs["confidence"])
    head = "".join(f"{g:>24s}" for g in da["group"].values)
    window = ds[f"{statistic}_sobol"].attrs.get("analysis_window", "whole run")
    fixed = " (eccentricity inside a fixed size: see 'inputs' below)" if _fixed_size_families(ds) else ""
    by = "joint family" + fixed + (" and uncertain input" if set(da["group"].values) - set(JOINT_FAMILIES) else "")
    lines = [f"total Sobol' indices ST of the per-realisation {statistic} by {by}, "
             f"{ds.attrs['model']} level, {window}, N = {ds.attrs['n_base_samples']}, "
             f"[{100 * confidence:g} % bootstrap interval, {coverage_caveat(confidence)}]",
             f"{'quantity':<13s}{'dir':<4s}{head}  largest"]
    noise = unresolved_outputs(ds, statistic)
    for q in ds["quantity"].values:
        for d in ds["direction"].values:
            cell = da.sel(index="ST", quantity=q, direction=d)
            text = "".join(f"{e:8.3f} [{lo:6.3f},{hi:6.3f}]" for e, lo, hi in
                           zip(*(cell.sel(bound=b).values for b in BOUNDS)))
            unresolved = noise is not None and bool(noise.sel(quantity=q, direction=d))
            lines.append(f"{q:<13s}{d:<4s}{text}  {NOISE if unresolved else _dominant(cell)}")
    return "\n".join(lines + _notes(ds, da, statistic))


def _notes(ds: xr.Dataset, da: xr.DataArray, statistic: str) -> list[str]:
    """The notes below the family table: inputs of fixed-size families, estimates outside [0, 1], the clipped
    bounds, the label's coverage, the level's (a drawn start's impacts) and the unresolved outputs."""
    confidence = float(ds.attrs["confidence"])
    coverage = [] if measured(confidence) else [
        f"note: {100 * confidence:g} % intervals: {UNMEASURED} (python benchmarks/sobol_coverage.py: the widened "
        "bootstrap covered >= 96 % of a 95 % label on a maximum over time); at this label the coverage is not known"]
    bounds = da.sel(index="ST", bound=["lower", "upper"])
    clipped = [] if not ((bounds == 0) | (bounds == 1)).any() else [
        "note: interval bounds are clipped to [0, 1], where every Sobol' index lies (the bootstrap's normal "
        "interval estimate -+ z sd can cross them; clipping keeps its coverage); the estimates are not"]
    windows = {str(ds.attrs.get("window", "whole"))}
    level = [f"note: {t}" for t in level_notes(ds.attrs, {str(q) for q in ds["quantity"].values}, windows)]
    return (_fixed_size_note(ds) + _outside_note(da.sel(index="ST", bound="estimate"), ds.attrs["n_base_samples"])
            + clipped + coverage + level + _noise_note(ds, statistic))


def _noise_note(ds: xr.Dataset, statistic: str) -> list[str]:
    """Where the outputs' spread is within the level's resolution (:func:`unresolved_outputs`): which rows, what the
    level resolves there, and that their indices rank noise, so no largest family is named."""
    noise = unresolved_outputs(ds, statistic)
    if noise is None or not noise.any():
        return []
    rows = [(str(q), str(d)) for q in noise["quantity"].values for d in noise["direction"].values
            if bool(noise.sel(quantity=q, direction=d))]
    sources = dict.fromkeys(resolutions(ds, q)[d].source.split(", x ")[0] for q, d in rows)   # gains: in the file
    named = ", ".join(f"{q} {d}" for q, d in rows[:6]) + (", ..." if len(rows) > 6 else "")
    return [f"note: {len(rows)} rows ({named}): the {statistic} differs over the evaluated rows by less than the "
            f"{ds.attrs['model']} level resolves ({'; '.join(sources)}; the plots' test), so their indices rank "
            f"numerical noise, not the joints: no largest family is named there"]


def _fixed_size_families(ds: xr.Dataset) -> list[str]:
    """The joint families whose group holds no size input: the scene fixes their clearance sizes."""
    return [str(g) for g, d, inputs in zip(ds["group"].values, ds["group_design"].values, ds["group_inputs"].values)
            if d == "families" and g in JOINT_FAMILIES and "_size" not in str(inputs)]


def _fixed_size_note(ds: xr.Dataset) -> list[str]:
    """What the groups of fixed-size families draw: the eccentricities inside each clearance, not its size, so their
    indices say nothing of what tightening gains, and where that question is answered."""
    fixed = _fixed_size_families(ds)
    if not fixed:
        return []
    return [f"inputs: {', '.join(fixed)} (and their joints with --per-joint): this scene fixes their clearance "
            "sizes, so the inputs are the drawn eccentricities inside each clearance (the joint's state within its "
            "play), not the sizes; a small index does not mean that tightening that play gains nothing. Which size "
            "to tighten: a scene that draws the sizes ([tolerance.*] bands as paper_tolerance, size_tolerance, "
            "[uncertain.*] inputs) or rss6 allocate"]


def format_joints(ds: xr.Dataset, statistic: str = "max_abs_error", top: int = 3) -> str:
    """With the joint design (--per-joint): per quantity and direction the ``top`` joints of largest
    total index with their intervals, largest first, and whether the first two intervals overlap
    (:func:`_dominant`), or that the outputs' spread is below the level's resolution; empty without it."""
    joints = [g for g in JOINTS if g in ds["group"].values]
    if not joints:
        return ""
    da = ds[f"{statistic}_sobol"].sel(group=joints, index="ST")
    noise = unresolved_outputs(ds, statistic)
    lines = [f"the {top} joints of largest total index ST of the per-realisation {statistic}, largest "
             f"first (of {len(joints)}; all in the file)", f"{'quantity':<13s}{'dir':<4s}ST [interval]"]
    for q in ds["quantity"].values:
        for d in ds["direction"].values:
            cell = da.sel(quantity=q, direction=d)
            est = cell.sel(bound="estimate").values
            order = np.argsort(-np.nan_to_num(est, nan=-np.inf))[:top]
            text = ", ".join(f"{joints[i]} {est[i]:.3f} [{float(cell.sel(bound='lower')[i]):.3f},"
                             f"{float(cell.sel(bound='upper')[i]):.3f}]" for i in order)
            overlap = "  (the first two overlap)" if "overlaps" in _dominant(cell) else ""
            if noise is not None and bool(noise.sel(quantity=q, direction=d)):
                overlap = "  (noise: spread below resolution, see the family table's note)"
            lines.append(f"{q:<13s}{d:<4s}{text}{overlap}")
    return "\n".join(lines)


def _outside_note(st: xr.DataArray, n: int) -> list[str]:
    """A note line when total-index estimates fall outside [0, 1], where no index lies: the
    estimator's sampling noise at this N, which the intervals show."""
    outside = (st < 0) | (st > 1)
    if not outside.any():
        return []
    worst = abs(st - st.clip(0, 1)).where(outside).argmax(...)
    cell = st.isel(worst)
    return [f"note: {int(outside.sum())} ST estimates lie outside [0, 1] (e.g. {float(cell):.3f}, "
            f"{cell['group'].item()} on {cell['quantity'].item()} {cell['direction'].item()}): sampling "
            f"noise of the estimator at N = {n}, not an index outside [0, 1]; a larger -n narrows it"]
