"""The workspace error map file (``rss6 map``, docs/model.md section 7): per pose of a two-axis grid and
per direction the quasi-static level's worst-case |pose error| and the q95 and max over drawn
realisations, a reachable mask, and the trajectory's path over the grid, as CF-1.10 netCDF."""
from __future__ import annotations

import numpy as np
import xarray as xr

from rss6core import __version__

from ..vocabulary import DIRECTIONS, FAMILIES

__all__ = ["POSE_AXES", "MAP_FIELDS", "axis_name", "error_map_dataset"]

# the pose's six axes: (long name, SI unit); angles are eq. 1's n1, n2, n3
POSE_AXES = {"x": ("platform position x", "m"), "y": ("platform position y", "m"),
             "z": ("platform position z", "m"), "n1": ("platform angle n1 (about X, eq. 1)", "rad"),
             "n2": ("platform angle n2 (about Y, eq. 1)", "rad"), "n3": ("platform angle n3 (about Z, eq. 1)", "rad")}
# the map's fields, each per direction family (m for translations, rad for rotations)
MAP_FIELDS = {
    "worst_case": "largest |platform pose error| any clearance state within the joints' clearance sets "
                  "causes (quasi-static level, closed form)",
    "q95": "0.95-quantile of |platform pose error| over the drawn realisations (quasi-static level)",
    "q95_lower": "lower end of the q95's two-sided distribution-free confidence interval (global attribute "
                 "confidence; NaN below its minimum number of draws)",
    "q95_upper": "upper end of the q95's two-sided distribution-free confidence interval (global attribute "
                 "confidence; NaN below its minimum number of draws)",
    "max_sampled": "largest |platform pose error| of the drawn realisations (quasi-static level)",
}
_FAMILY_UNITS = {"translation": "m", "rotation": "rad"}


def axis_name(axis: str) -> str:
    """The file's name of a pose axis (x .. n3): platform_x .. platform_n3."""
    return f"platform_{axis}"


def _pose_coordinate(axis: str, values) -> tuple:
    name, unit = POSE_AXES[axis]
    return (() if np.ndim(values) == 0 else (axis_name(axis),)), values, {"long_name": name, "units": unit}


def _fields(fields: dict, dims: tuple) -> dict:
    """{field}_{family} (family, *dims) from each field's (*dims, direction) array, SI."""
    out = {}
    for field, values in fields.items():
        for family, members in FAMILIES.items():
            part = values[..., [DIRECTIONS.index(d) for d in members]]
            out[f"{field}_{family}"] = ((family, *dims), np.moveaxis(part, -1, 0),
                                        {"long_name": f"{MAP_FIELDS[field]}: {family}",
                                         "units": _FAMILY_UNITS[family]})
    return out


def _quality(reachable, transmission, condition, dims: tuple) -> dict:
    return {
        "reachable": (dims, reachable.astype(np.int8),
                      {"long_name": "pose reachable: inverse kinematics exists, no leg at its crank-rod "
                                    "singularity, closure well conditioned (check_workspace's thresholds)",
                       "flag_values": np.array([0, 1], np.int8), "flag_meanings": "unreachable reachable"}),
        "transmission": (dims, transmission,
                         {"long_name": "smallest leg transmission |n_i . dc_i/dalpha_i| / (L_ac L_cb)",
                          "units": "1"}),
        "condition": (dims, condition, {"long_name": "condition number of the linearised closure G",
                                        "units": "1"}),
    }


def _path(axes: tuple, path_t, path_pose) -> tuple[dict, dict]:
    """The trajectory's path on the map's two axes (variables) over its time (coordinate)."""
    data = {f"path_{axis_name(a)}": (("path_time",), path_pose[:, list(POSE_AXES).index(a)],
                                     {"long_name": f"trajectory: {POSE_AXES[a][0]}", "units": POSE_AXES[a][1]})
            for a in axes}
    return data, {"path_time": ("path_time", path_t, {"long_name": "time along the scene's trajectory",
                                                      "units": "s"})}


def error_map_dataset(scene, grid: dict, fixed: dict, fields: dict, quality: dict, path: tuple,
                      attrs: dict) -> xr.Dataset:
    """The map as a Dataset: ``grid`` {axis: values (SI)} of its two axes (the second along the rows),
    ``fixed`` {axis: value} of the other four, ``fields`` {field of MAP_FIELDS: (rows, columns, direction)},
    ``quality`` reachable, transmission, condition (rows, columns), ``path`` (times s, poses (T, 6)),
    ``attrs`` the run's own attributes (seed, draws, sizes, history)."""
    (a, va), (b, vb) = grid.items()
    dims = (axis_name(b), axis_name(a))
    path_data, path_coords = _path((a, b), *path)
    coords = {axis_name(k): _pose_coordinate(k, v) for k, v in (*grid.items(), *fixed.items())}
    coords |= {family: (family, list(members), {"long_name": f"platform pose {family} direction"})
               for family, members in FAMILIES.items()} | path_coords
    data = _fields(fields, dims) | _quality(quality["reachable"], quality["transmission"],
                                            quality["condition"], dims) | path_data
    return xr.Dataset(data, coords=coords, attrs={
        "Conventions": "CF-1.10", "title": f"rss6 workspace error map: quasi-static level, scene {scene.name!r}",
        "source": f"rss6 {__version__}", "rss6_version": __version__, "scene_name": scene.name,
        "scene_toml": scene.source_text, **attrs})
