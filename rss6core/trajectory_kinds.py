"""The platform trajectory kinds of a scene's [trajectory] table, each with its exact derivatives.

- ``sinusoid`` (:class:`Sinusoid`, the default): eq. 35, pose_k = offset_k + amplitude_k sin(2 pi f t);
- ``points`` (:class:`ViaPoints`): poses at given times, rest (zero pose rate and acceleration) at the
  first and last point and at every point with a dwell, joined through the via points by quintic
  splines with zero first and second derivatives at both ends of each stretch (C4 inside a stretch,
  C2 across a rest point);
- ``file`` (:class:`SampledPoses`): sampled poses (a CSV, :mod:`.pose_csv`) interpolated by a quintic
  spline (C4: continuous acceleration and jerk; its acceleration error is O(h^4) on smooth samples).
Each kind holds ``duration`` (s) and gives pose, pose rate and pose acceleration (T, 6) at times t
(x, y, z in m, n1, n2, n3 in rad) from :meth:`derivatives`.  Mistakes raise :class:`TrajectoryError`
naming the key or row; the scene parser prefixes the file.
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import ClassVar

import numpy as np

from .frozen import frozen_array

__all__ = ["TRAJECTORY_KINDS", "TrajectoryError", "Sinusoid", "ViaPoints", "SampledPoses", "via_points",
           "sampled_poses", "check_keys"]

TRAJECTORY_KINDS = ("sinusoid", "points", "file")
SPLINE_DEGREE = 5   # quintic: C4 profiles, and (k - 1) / 2 = 2 end conditions (rate, acceleration) a side
_REST = [(1, np.zeros(6)), (2, np.zeros(6))]


class TrajectoryError(ValueError):
    """A [trajectory] table or pose CSV that does not describe a motion; the message names key or row."""


@dataclass(frozen=True)
class Sinusoid:
    """Eq. 35: pose_k(t) = offset_k + amplitude_k sin(2 pi f t), pose = (x, y, z, n1, n2, n3)."""
    frequency: float        # Hz
    offset: np.ndarray      # (6,) m and rad
    amplitude: np.ndarray   # (6,) m and rad
    duration: float         # s
    kind: ClassVar[str] = "sinusoid"
    duration_key: ClassVar[str] = "[trajectory] duration_s"
    label: ClassVar[str] = "eq. 35"

    def derivatives(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pose, pose rate and pose acceleration (T, 6) at times t (s), exact."""
        w = 2.0 * np.pi * self.frequency
        s, c = np.sin(w * t)[:, None], np.cos(w * t)[:, None]
        amp = self.amplitude[None, :]
        return self.offset[None, :] + amp * s, amp * w * c, -amp * w * w * s


@dataclass(frozen=True)
class ViaPoints:
    """Poses (N, 6) reached at times (N,) s, resting ``dwell`` (N,) s at each; rest at both ends."""
    times: np.ndarray       # (N,) s, arrival times, times[0] = 0
    poses: np.ndarray       # (N, 6) m and rad
    dwell: np.ndarray       # (N,) s
    duration: float         # s: times[-1] + dwell[-1], or shorter (a truncated horizon)
    kind: ClassVar[str] = "points"
    duration_key: ClassVar[str] = "[trajectory] times_s and dwell_s (their last time plus its dwell)"
    label: ClassVar[str] = "via points"

    @cached_property
    def _stretches(self) -> list[tuple[float, float, object]]:
        """(departure, arrival, quintic spline) per motion between consecutive rest points."""
        from scipy.interpolate import make_interp_spline   # here, not in every process's import
        rest = [0] + [i for i in range(1, len(self.times) - 1) if self.dwell[i] > 0] + [len(self.times) - 1]
        out = []
        for a, b in zip(rest[:-1], rest[1:]):
            knots = np.concatenate([[self.times[a] + self.dwell[a]], self.times[a + 1:b + 1]])
            spline = make_interp_spline(knots, self.poses[a:b + 1], k=SPLINE_DEGREE, bc_type=(_REST, _REST))
            out.append((knots[0], knots[-1], spline))
        return out

    def derivatives(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pose, pose rate and pose acceleration (T, 6) at times t (s): exactly at rest (the rest pose,
        zero rate and acceleration) outside the open stretches, the splines' exact derivatives inside."""
        resting = np.searchsorted(self.times, t, side="right") - 1   # the last point reached at t
        pose = self.poses[np.clip(resting, 0, None)].copy()
        rate, acc = np.zeros_like(pose), np.zeros_like(pose)
        for start, end, spline in self._stretches:
            inside = (t > start) & (t < end)
            if inside.any():
                ti = t[inside]
                pose[inside], rate[inside], acc[inside] = spline(ti), spline(ti, 1), spline(ti, 2)
        return pose, rate, acc


@dataclass(frozen=True)
class SampledPoses:
    """Poses (N, 6) sampled at times (N,) s from a CSV, interpolated by a quintic spline."""
    times: np.ndarray       # (N,) s, times[0] = 0
    poses: np.ndarray       # (N, 6) m and rad
    duration: float         # s: times[-1], or shorter (a truncated horizon)
    sha256: str = field(default="", compare=False)   # of the CSV file's bytes, provenance only
    kind: ClassVar[str] = "file"
    duration_key: ClassVar[str] = "[trajectory] path (the CSV's last t_s)"
    label: ClassVar[str] = "CSV samples"

    @cached_property
    def _spline(self):
        from scipy.interpolate import make_interp_spline
        return make_interp_spline(self.times, self.poses, k=SPLINE_DEGREE)

    def derivatives(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pose, pose rate and pose acceleration (T, 6) at times t (s), the spline's exact derivatives
        (its polynomial continuation beyond the samples, where a central difference pads the grid)."""
        s = self._spline
        return s(t), s(t, 1), s(t, 2)


def check_keys(table: dict, allowed: dict[str, str], kind: str) -> None:
    """Unknown keys of [trajectory] for ``kind`` (did-you-mean hint) and its required keys; ``allowed``
    maps each key to 'required' or 'optional'.  duration_s is refused with the reason."""
    for key in table:
        if key == "duration_s" and key not in allowed:
            raise TrajectoryError(f"[trajectory] duration_s: not allowed for kind = {kind!r} "
                                  "(the duration follows from the trajectory)")
        if key not in allowed:
            near = difflib.get_close_matches(key, list(allowed), n=1)
            raise TrajectoryError(f"unknown key [trajectory] {key}" + (f" (did you mean {near[0]!r}?)" if near else ""))
    for key, need in allowed.items():
        if need == "required" and key not in table:
            raise TrajectoryError(f"missing key [trajectory] {key} (kind = {kind!r})")


def _numbers(value, key: str, width: int | None = None) -> np.ndarray:
    """A list of finite numbers (width None) or of lists of ``width`` numbers, as floats."""
    def number(v, where):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise TrajectoryError(f"[trajectory] {key}{where}: expected a finite number, got {v!r}")
        return float(v)
    if not isinstance(value, list) or not value:
        raise TrajectoryError(f"[trajectory] {key}: expected a list, got {value!r}")
    if width is None:
        return np.array([number(v, f"[{i}]") for i, v in enumerate(value)])
    rows = []
    for i, row in enumerate(value):
        if not isinstance(row, list) or len(row) != width:
            raise TrajectoryError(f"[trajectory] {key}[{i}]: expected a list of {width} numbers, got {row!r}")
        rows.append([number(v, f"[{i}]") for v in row])
    return np.array(rows)


def increasing(times: np.ndarray, where) -> None:
    """Times (s) that start at 0 and strictly increase; ``where(i)`` names entry i in the message."""
    if times[0] != 0.0:
        raise TrajectoryError(f"{where(0)}: the first time must be 0 s, got {float(times[0])!r}")
    bad = np.flatnonzero(~(np.diff(times) > 0))
    if bad.size:
        i = int(bad[0]) + 1
        raise TrajectoryError(f"{where(i)}: time {float(times[i])!r} s does not increase "
                              f"(the previous is {float(times[i - 1])!r} s)")


def via_points(table: dict) -> ViaPoints:
    """A ``kind = "points"`` [trajectory] table: times_s (N,), positions_m (N x [x, y, z]), angles_deg
    (N x [n1, n2, n3]), optional dwell_s (N,) s at each point."""
    check_keys(table, {"kind": "required", "times_s": "required", "positions_m": "required",
                       "angles_deg": "required", "dwell_s": "optional"}, "points")
    times = _numbers(table["times_s"], "times_s")
    n = len(times)
    if n < 2:
        raise TrajectoryError(f"[trajectory] times_s: at least 2 points are needed, got {n}")
    positions, angles = _numbers(table["positions_m"], "positions_m", 3), _numbers(table["angles_deg"], "angles_deg", 3)
    dwell = _numbers(table["dwell_s"], "dwell_s") if "dwell_s" in table else np.zeros(n)
    for key, values in (("positions_m", positions), ("angles_deg", angles), ("dwell_s", dwell)):
        if len(values) != n:
            raise TrajectoryError(f"[trajectory] {key}: {len(values)} entries for {n} times_s")
    bad = np.flatnonzero(dwell < 0)
    if bad.size:
        raise TrajectoryError(f"[trajectory] dwell_s[{bad[0]}]: must be non-negative, got {float(dwell[bad[0]])!r}")
    increasing(times, lambda i: f"[trajectory] times_s[{i}]")
    late = np.flatnonzero(~(times[1:] > times[:-1] + dwell[:-1]))
    if late.size:
        i = int(late[0]) + 1
        raise TrajectoryError(f"[trajectory] times_s[{i}]: {float(times[i])!r} s is not after point {i - 1}'s "
                              f"dwell ends ({float(times[i - 1])!r} + {float(dwell[i - 1])!r} s)")
    poses = np.concatenate([positions, np.radians(angles)], axis=1)
    return ViaPoints(frozen_array(times), frozen_array(poses), frozen_array(dwell), float(times[-1] + dwell[-1]))


def sampled_poses(times: np.ndarray, poses_deg: np.ndarray, sha256: str = "") -> SampledPoses:
    """The file kind from checked samples: times (N,) s and poses (N, 6) in m and degrees."""
    poses = np.concatenate([poses_deg[:, :3], np.radians(poses_deg[:, 3:])], axis=1)
    return SampledPoses(frozen_array(times), frozen_array(poses), float(times[-1]), sha256)
