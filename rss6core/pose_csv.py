"""The pose CSV of a ``kind = "file"`` trajectory: reading and checking it, and carrying its samples in
the scene text.

Contract (docs/model.md): a header naming the columns t_s, x_m, y_m, z_m, n1_deg, n2_deg, n3_deg (any
order, no others), one row per sample, every cell a finite number, t_s starting at 0 s and strictly
increasing, at least 6 rows (a quintic spline).  The scene file's ``path`` is relative to the scene
file.  :func:`with_pose_samples` appends the samples to the scene's TOML text as the sub-table
[trajectory.samples] (columns, rows in the CSV's units, sha256 of the file), so the scene text alone
describes the motion: ensemble workers re-parse it wherever they run, and an ensemble file's
``scene_toml`` holds the CSV's content, not its path.
"""
from __future__ import annotations

import csv
import difflib
import hashlib
import io
import math
import tomllib
from pathlib import Path

import numpy as np

from .trajectory_kinds import SPLINE_DEGREE, SampledPoses, TrajectoryError, check_keys, increasing, sampled_poses

__all__ = ["COLUMNS", "read_pose_csv", "with_pose_samples", "file_trajectory"]

COLUMNS = ("t_s", "x_m", "y_m", "z_m", "n1_deg", "n2_deg", "n3_deg")
_KEYS = {"kind": "required", "path": "required", "samples": "optional"}
# units a header may name in place of the expected one (a wrong unit, not a misspelt column)
_UNITS = {"m", "mm", "cm", "um", "km", "in", "ft", "deg", "rad", "mrad", "s", "ms", "us", "min", "h"}


def _column_order(header: list[str], name: str) -> list[int]:
    """Index in ``header`` of each of COLUMNS; TrajectoryError naming a misspelt column, a column in
    another unit (one of _UNITS), a repeated or a missing column, and the file."""
    quantities = {c.split("_")[0]: c for c in COLUMNS}
    for cell in header:
        if cell in COLUMNS:
            if header.count(cell) > 1:
                raise TrajectoryError(f"{name}: column {cell} appears {header.count(cell)} times in the header")
            continue
        quantity, _, unit = cell.partition("_")
        if quantity in quantities and unit in _UNITS:
            expected = quantities[quantity]
            raise TrajectoryError(f"{name}: column {cell!r}: unit {unit!r} is not the expected one, the header "
                                  f"names {expected!r} ({expected.partition('_')[2]})")
        near = difflib.get_close_matches(cell, COLUMNS, n=1)
        raise TrajectoryError(f"{name}: unknown column {cell!r} in the header"
                              + (f" (did you mean {near[0]!r}?)" if near else "")
                              + f"; expected {','.join(COLUMNS)}")
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise TrajectoryError(f"{name}: column {missing[0]} missing from the header {','.join(header)!r}")
    return [header.index(c) for c in COLUMNS]


def _cell(text: str, name: str, row: int, column: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise TrajectoryError(f"{name} row {row} (line {row + 1}), column {column}: {text!r} is not a finite number")
    return value


def _check_samples(samples: np.ndarray, name: str) -> None:
    """At least SPLINE_DEGREE + 1 rows; t_s from 0 s, strictly increasing (the row named)."""
    if len(samples) < SPLINE_DEGREE + 1:
        raise TrajectoryError(f"{name}: {len(samples)} rows, a quintic spline needs at least {SPLINE_DEGREE + 1}")
    increasing(samples[:, 0], lambda i: f"{name} row {i + 1} (line {i + 2}), column t_s")


def read_pose_csv(path: Path) -> tuple[np.ndarray, str]:
    """Samples (N, 7) in the CSV's units, in COLUMNS order, and the file's sha256; TrajectoryError naming
    the file and the row and column of any mistake."""
    name = str(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise TrajectoryError(f"[trajectory] path: no such CSV file {name}") from None
    except OSError as exc:
        raise TrajectoryError(f"[trajectory] path: cannot read {name}: {exc}") from None
    try:
        lines = [row for row in csv.reader(io.StringIO(data.decode("utf-8-sig"))) if row]
    except (UnicodeDecodeError, csv.Error) as exc:
        raise TrajectoryError(f"{name}: not a UTF-8 CSV file: {exc}") from None
    if not lines:
        raise TrajectoryError(f"{name}: empty; expected the header {','.join(COLUMNS)}")
    header = [cell.strip() for cell in lines[0]]
    order = _column_order(header, name)
    rows = []
    for row, cells in enumerate(lines[1:], start=1):
        if len(cells) != len(header):
            raise TrajectoryError(f"{name} row {row} (line {row + 1}): {len(cells)} cells for {len(header)} columns")
        rows.append([_cell(cells[i].strip(), name, row, header[i]) for i in order])
    samples = np.array(rows, dtype=float).reshape(-1, len(COLUMNS))
    _check_samples(samples, name)
    return samples, hashlib.sha256(data).hexdigest()


def with_pose_samples(text: str, folder: Path) -> str:
    """The scene text with its pose CSV's samples appended as [trajectory.samples], when its
    [trajectory] is ``kind = "file"`` with a ``path`` (relative to ``folder``) and no samples yet;
    otherwise the text unchanged (the scene parser reports any other mistake)."""
    try:
        table = tomllib.loads(text).get("trajectory")
    except tomllib.TOMLDecodeError:
        return text
    if not (isinstance(table, dict) and table.get("kind") == "file" and "samples" not in table
            and isinstance(table.get("path"), str)):
        return text
    samples, digest = read_pose_csv(folder / table["path"])
    rows = ",\n".join("  [" + ", ".join(repr(float(v)) for v in row) + "]" for row in samples)
    columns = ", ".join(f'"{c}"' for c in COLUMNS)
    return (text.rstrip("\n") + f"\n\n# rss6: the samples of [trajectory] path {table['path']!r}, carried in the "
            f"scene text\n[trajectory.samples]\ncolumns = [{columns}]\nsha256 = \"{digest}\"\nrows = [\n{rows}\n]\n")


def file_trajectory(table: dict) -> SampledPoses:
    """A ``kind = "file"`` [trajectory] table whose samples the scene text carries (:func:`with_pose_samples`)."""
    check_keys(table, _KEYS, "file")
    if not isinstance(table["path"], str):
        raise TrajectoryError(f"[trajectory] path: expected a string, got {table['path']!r}")
    name = table["path"]
    samples = table.get("samples")
    if samples is None:
        raise TrajectoryError(f"[trajectory] path: the CSV {name} is read when a scene is loaded from its file; "
                              "this scene text carries no [trajectory.samples]")
    if not isinstance(samples, dict) or samples.get("columns") != list(COLUMNS):
        raise TrajectoryError(f"[trajectory.samples] columns: expected {list(COLUMNS)}")
    rows = samples.get("rows")
    if not (isinstance(rows, list) and all(isinstance(r, list) and len(r) == len(COLUMNS) for r in rows)):
        raise TrajectoryError(f"[trajectory.samples] rows: expected lists of {len(COLUMNS)} numbers")
    values = np.array([[_cell(repr(v), name, i + 1, c) for v, c in zip(r, COLUMNS)] for i, r in enumerate(rows)],
                      dtype=float).reshape(-1, len(COLUMNS))
    _check_samples(values, name)
    return sampled_poses(values[:, 0], values[:, 1:], str(samples.get("sha256", "")))
