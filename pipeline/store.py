"""netCDF files (CF-1.10, via xarray) for single runs; SI units in every ``units`` attribute.

The direction dimension mixes translations (x, y, z in m) and rotations
(rx, ry, rz in rad), so a variable's ``units`` attribute names both and the
coordinate ``unit`` (quantity, direction) gives each element's unit exactly.
"""
from __future__ import annotations

import numpy as np
import xarray as xr

from rss6core import __version__

__all__ = ["DIRECTIONS", "QUANTITIES", "UNITS", "run_dataset", "write_netcdf"]

DIRECTIONS = ("x", "y", "z", "rx", "ry", "rz")
QUANTITIES = ("displacement", "velocity", "acceleration")
UNITS = {"displacement": ("m", "rad"), "velocity": ("m s-1", "rad s-1"),
         "acceleration": ("m s-2", "rad s-2")}


def _unit_table() -> np.ndarray:
    return np.array([[UNITS[q][0]] * 3 + [UNITS[q][1]] * 3 for q in QUANTITIES])


def _history(result) -> np.ndarray:
    return np.stack([result.displacement, result.velocity, result.acceleration])


def run_dataset(scene, result, *, model: str, integrator: str, dt: float, elements: int,
                wall_time: float) -> xr.Dataset:
    """One simulation as a self-describing Dataset: error histories, summaries, provenance."""
    err = _history(result)
    mixed = "m or rad, per direction (see coordinate 'unit'); time derivatives thereof"
    finite = np.isfinite(err)
    summary_attrs = {"units": mixed, "cell_methods": "time: maximum"}
    return xr.Dataset(
        data_vars={
            "error": (("quantity", "time", "direction"), err,
                      {"long_name": "platform pose error, actual minus ideal rigid pose",
                       "units": mixed}),
            "max_abs_error": (("quantity", "direction"),
                              np.where(finite.any(1), np.nanmax(np.abs(err), axis=1), np.nan),
                              {"long_name": "maximum over time of |error|", **summary_attrs}),
            "mean_abs_error": (("quantity", "direction"), np.nanmean(np.abs(err), axis=1),
                               {"long_name": "mean over time of |error|", "units": mixed,
                                "cell_methods": "time: mean"}),
        },
        coords={
            "time": ("time", result.t, {"units": "s", "long_name": "time", "axis": "T",
                                        "standard_name": "time"}),
            "direction": ("direction", list(DIRECTIONS),
                          {"long_name": "platform pose direction in the base frame"}),
            "quantity": ("quantity", list(QUANTITIES)),
            "unit": (("quantity", "direction"), _unit_table(),
                     {"long_name": "SI unit of each element"}),
        },
        attrs={
            "Conventions": "CF-1.10",
            "title": f"rss6 {model} simulation of scene {scene.name!r}",
            "source": f"rss6 {__version__}",
            "rss6_version": __version__,
            "scene_name": scene.name,
            "scene_toml": scene.source_text,
            "model": model,
            "integrator": integrator,
            "time_step_s": dt,
            "elements_per_link": elements,
            "status": result.status,
            "status_message": result.message,
            "steps": result.steps,
            "wall_time_s": wall_time,
        })


def write_netcdf(ds: xr.Dataset, path) -> None:
    """Write ``ds`` as netCDF4 to ``path`` via a temporary file, so a crash leaves no half file."""
    import os
    tmp = f"{path}.part"
    ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4")
    os.replace(tmp, path)
