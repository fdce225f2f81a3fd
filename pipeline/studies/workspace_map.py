"""The workspace error map (``rss6 map``): over a grid of static poses, per direction, the quasi-static
level's worst-case |pose error| over every clearance state (closed form, rss6core.workspace_map) and
the q95 and max over the scene's drawn realisations, as a Dataset (pipeline/files/error_map.py).

The default grid spans the trajectory's two position axes of largest range (padded by PAD of the range,
at least MIN_PAD), the third position and the orientation at the trajectory's mean pose."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr

from rss6core import (drawn_eccentricities, models_with, rigid_motion, sampled_errors, static_closure,
                      worst_case_error, worst_case_sizes)

from ..analysis.estimators import quantile_estimates, quantile_interval
from ..files.error_map import POSE_AXES, error_map_dataset
from ..vocabulary import CONFIDENCE, DIRECTIONS, QUANTILES, family_of

__all__ = ["MAP_MODELS", "GridAxis", "DEFAULT_COUNT", "DEFAULT_DRAWS", "PAD", "MIN_PAD", "USER_UNITS",
           "default_grid", "workspace_map", "map_table", "write_map"]

MAP_MODELS = models_with("linear_in_clearances")   # the levels whose worst case has a closed form
DEFAULT_COUNT = 21          # grid points per axis
DEFAULT_DRAWS = 1000        # realisations for the q95 and max
MAX_DRAWS = 100_000         # at most: a block then holds 64 x N x 6 errors, 0.3 GB
PAD = 0.1                   # the default grid reaches this fraction of the range beyond the trajectory
MIN_PAD = {"m": 5e-3, "rad": np.radians(2.0)}   # and at least this far (m, rad)
USER_UNITS = {"m": (1.0, "m"), "rad": (180.0 / np.pi, "deg")}   # --grid's units: metres and degrees
_BLOCK = 64                 # poses per block of sampled errors (64 x N x 6 numbers in memory)


@dataclass(frozen=True)
class GridAxis:
    """One axis of the map: a pose axis (x, y, z, n1, n2, n3) from ``low`` to ``high`` (m or rad)."""
    axis: str
    low: float
    high: float
    count: int

    @property
    def values(self) -> np.ndarray:
        return np.linspace(self.low, self.high, self.count)

    def option(self) -> str:
        """As --grid writes it (m, deg)."""
        factor = USER_UNITS[POSE_AXES[self.axis][1]][0]
        return f"{self.axis}:{self.low * factor:.6g}:{self.high * factor:.6g}:{self.count}"


def _trajectory(scene) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and poses (T, 6) of the scene's trajectory, whatever its kind."""
    platform = rigid_motion(scene).platform
    return platform.t, platform.pose


def default_grid(scene, count: int = DEFAULT_COUNT) -> tuple[GridAxis, GridAxis]:
    """The trajectory's two position axes of largest range, padded, ``count`` points each, in axis order."""
    pose = _trajectory(scene)[1]
    low, high = pose[:, :3].min(axis=0), pose[:, :3].max(axis=0)
    widest = sorted(np.argsort(-(high - low), kind="stable")[:2])
    axes = []
    for k in widest:
        pad = max(PAD * (high[k] - low[k]), MIN_PAD["m"])
        axes.append(GridAxis(list(POSE_AXES)[k], float(low[k] - pad), float(high[k] + pad), count))
    return tuple(axes)


def _grid_poses(axes, fixed: np.ndarray) -> np.ndarray:
    """(rows x columns, 6) poses: the first axis along the columns, the second along the rows."""
    columns, rows = np.meshgrid(axes[0].values, axes[1].values)
    poses = np.tile(fixed, (columns.size, 1))
    names = list(POSE_AXES)
    poses[:, names.index(axes[0].axis)], poses[:, names.index(axes[1].axis)] = columns.ravel(), rows.ravel()
    return poses


def _sampled_statistics(closure, drawn) -> dict:
    """Over the draws of |d|, (P, 6) each: the q95, its two-sided CONFIDENCE interval (distribution-free,
    NaN below its minimum n) and the max; block by block of poses, NaN where unreachable."""
    count = len(closure.reachable)
    out = {k: np.full((count, 6), np.nan) for k in ("q95", "q95_lower", "q95_upper", "max_sampled")}
    for start in range(0, count, _BLOCK):
        part = slice(start, start + _BLOCK)
        err = sampled_errors(closure.poses(part), drawn)
        out["q95"][part] = quantile_estimates(err, QUANTILES["q95"], axis=1)
        out["q95_lower"][part], out["q95_upper"][part] = quantile_interval(
            np.sort(np.moveaxis(err, 1, 0), axis=0), QUANTILES["q95"], CONFIDENCE)
        out["max_sampled"][part] = np.max(err, axis=1)
    return out


def workspace_map(scene, axes=None, draws: int = DEFAULT_DRAWS, seed: int = 0,
                  model: str = MAP_MODELS[0]) -> xr.Dataset:
    """The map over the grid ``axes`` (two GridAxis; default :func:`default_grid`) at the trajectory's
    mean pose otherwise, with ``draws`` realisations of the run seeded ``seed``."""
    axes = axes or default_grid(scene)
    t, path = _trajectory(scene)
    fixed = path.mean(axis=0)
    closure = static_closure(scene.geometry, _grid_poses(axes, fixed))
    sizes = worst_case_sizes(scene)
    worst = worst_case_error(closure, scene.geometry.w, sizes)
    fields = {"worst_case": worst, **_sampled_statistics(closure, drawn_eccentricities(scene, draws, seed))}
    shape = (axes[1].count, axes[0].count)
    fields = {k: v.reshape(*shape, 6) for k, v in fields.items()}
    quality = {k: getattr(closure, k).reshape(shape) for k in ("reachable", "transmission", "condition")}
    names = list(POSE_AXES)
    others = {a: float(fixed[names.index(a)]) for a in names if a not in (axes[0].axis, axes[1].axis)}
    return error_map_dataset(scene, {ax.axis: ax.values for ax in axes}, others, fields, quality, (t, path),
                             _attributes(scene, axes, sizes, draws, seed, model))


def _attributes(scene, axes, sizes, draws: int, seed: int, model: str) -> dict:
    """The run's own global attributes: model, seed, draws, the sizes the worst case takes, history."""
    banded = ", ".join(sizes.from_band)
    grid = " ".join(f"--grid {ax.option()}" for ax in axes)
    return {
        "model": model, "seed": seed, "n_draws": draws, "confidence": CONFIDENCE,
        "grid": ", ".join(ax.option() for ax in axes) + " (AXIS:LO:HI:N; x, y, z in m, n1, n2, n3 in deg)",
        "clearance_sizes": (f"upper end of the size band for {banded}, nominal for the others" if banded
                            else "nominal [clearance] sizes"),
        **{f"worst_case_size_{family}_m": getattr(sizes, family)
           for family in ("revolute_radial", "revolute_axial", "spherical_C", "spherical_B")},
        "eccentricities": "drawn by the scene's [sampling] laws (realisations 0 .. n_draws-1 of the seed)",
        "history": f"rss6 map {scene.name} --model {model} {grid} -n {draws} --seed {seed}",
    }


def _where(ds: xr.Dataset, values: np.ndarray) -> str:
    """The grid pose of the largest finite value, in mm or deg."""
    rows, columns = np.unravel_index(np.nanargmax(values), values.shape)
    from ..analysis.map_plots import axis_display
    b, a = ds["reachable"].dims
    out = []
    for dim, k in ((a, columns), (b, rows)):
        factor, unit = axis_display(ds, dim)
        out.append(f"{dim.removeprefix('platform_')} = {round(float(ds[dim][k]) * factor, 6) + 0.0:.4g} {unit}")
    return ", ".join(out)


def map_table(ds: xr.Dataset) -> str:
    """Per direction the worst case and the q95 over the reachable grid (mm, mrad): range and where largest."""
    reachable = ds["reachable"].values.astype(bool)
    lines = [f"reachable: {int(reachable.sum())} of {reachable.size} poses",
             f"{'dir':4}{'unit':6}{'worst min':>11}{'worst max':>11}  {'where largest':30}"
             f"{'q95 min':>10}{'q95 max':>10}  where largest"]
    for d in DIRECTIONS:
        family = family_of(d)
        factor, unit = 1e3, ("mm" if family == "translation" else "mrad")
        worst = ds[f"worst_case_{family}"].sel({family: d}).values
        q95 = ds[f"q95_{family}"].sel({family: d}).values
        if not reachable.any():
            lines.append(f"{d:4}{unit:6}  (no reachable pose)")
            continue
        lines.append(f"{d:4}{unit:6}{np.nanmin(worst) * factor:11.4g}{np.nanmax(worst) * factor:11.4g}  "
                     f"{_where(ds, worst):30}{np.nanmin(q95) * factor:10.4g}{np.nanmax(q95) * factor:10.4g}  "
                     f"{_where(ds, q95)}")
    from ..analysis.map_plots import q95_caveat
    caveat = q95_caveat(ds)
    if caveat or not reachable.any():
        return "\n".join(lines + ([caveat] if caveat else []))
    lines.append(f"q95's largest pose per direction with its {100 * float(ds.attrs['confidence']):g} % interval, "
                 "and the poses whose interval reaches that interval's lower end:")
    return "\n".join(lines + [_q95_location(ds, d) for d in DIRECTIONS])


def _q95_location(ds: xr.Dataset, d: str) -> str:
    """Where the q95 of direction ``d`` is largest, with its interval, and whether that is resolved: other
    poses whose interval reaches its lower end could hold the largest q95 as well (the location is noise)."""
    family = family_of(d)
    factor, unit = 1e3, ("mm" if family == "translation" else "mrad")
    q95, lower, upper = (ds[f"{k}_{family}"].sel({family: d}).values for k in ("q95", "q95_lower", "q95_upper"))
    top = np.unravel_index(np.nanargmax(q95), q95.shape)
    reach = upper >= lower[top]    # NaN (unreachable) compares False
    head = (f"  {d}: {q95[top] * factor:.4g} {unit} [{lower[top] * factor:.4g}, {upper[top] * factor:.4g}] at "
            f"{_where(ds, q95)}; ")
    if reach.sum() <= 1:
        return head + "no other pose's interval reaches it: located at this n"
    return head + (f"{int(reach.sum()) - 1} other poses' intervals reach it (spanning {_span(ds, reach)}): where it is "
                   f"largest is not resolved at n = {int(ds.attrs['n_draws'])}")


def _span(ds: xr.Dataset, mask: np.ndarray) -> str:
    """The range of each grid axis over the poses of ``mask`` (rows, columns), in mm or deg."""
    from ..analysis.map_plots import axis_display
    b, a = ds["reachable"].dims
    out = []
    for dim, axis in ((a, 0), (b, 1)):
        factor, unit = axis_display(ds, dim)
        values = ds[dim].values[mask.any(axis=axis)] * factor
        out.append(f"{dim.removeprefix('platform_')} {values.min() + 0.0:.4g} to {values.max() + 0.0:.4g} {unit}")
    return ", ".join(out)


def write_map(ds: xr.Dataset, outdir) -> list:
    """DIR/workspace_map.nc and the heat maps DIR/workspace_map_<direction>.png; the paths written."""
    from pathlib import Path

    from ..analysis.map_plots import map_figures
    from ..analysis.plot_common import save_figures
    from ..files.writing import write_netcdf
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    write_netcdf(ds, out / "workspace_map.nc")
    return [out / "workspace_map.nc", *save_figures(map_figures(ds), out)]
