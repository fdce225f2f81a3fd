"""The spread (SI) below which a level's per-realisation values are numerical noise, per quantity.

A histogram of values within it would show noise: the ensemble figures draw a note instead; ``rss6 stats``
says that such values' intervals measure numerical noise (:func:`resolution_attrs`), and the requirement
gate leaves a limit within the level's accuracy of its estimate undecided (pipeline.analysis.gate)."""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from rss6core import TOL_DISPLACEMENT, TOL_VELOCITY, closure_matrix, models_with, parse_scene, rigid_motion

from ..vocabulary import DIRECTIONS, SUMMARIES
from .plot_common import FAMILY_DIRECTIONS, si_text

__all__ = ["ROUND_OFF", "ROUND_OFF_FLOOR", "CONTACT_ACCURACY", "Resolution", "resolutions", "closure_gain",
           "within_resolution", "resolution_attrs"]

# A level's resolution: the spread below which per-realisation values are numerical noise.
ROUND_OFF = 1e-9        # relative: rss6's errors computed two mathematically equal ways (regrouped
#                         sums, batches against single runs, compiled against cached kernels) differ
#                         by 3e-12 relative at most (docs/performance.md); 1e-9 leaves 300x margin
ROUND_OFF_FLOOR = 1e-15  # SI: errors are differences of poses, rates and accelerations of order 0.1-10
#                          SI, whose double-precision round-off is about 1e-16 of that
# relative: the contact level's accuracy with its adaptive step (paper scenes: 0.2 ms -> 12.5 us,
# 1e-8 m) against a converged reference, largest over the velocity and the acceleration statistics
# (docs/guide.md, "Speed and accuracy": rss6 tradeoff configs/paper.toml -n 4).  The steady-window
# maxima of `rss6 run paper -n 16 --model contact` spread by 0.008-0.77 % (velocity) and 0.3-0.74 %
# (acceleration) over realisations whose displacements agree to 14 nm: within twice these.
CONTACT_ACCURACY = {"velocity": 0.0075, "acceleration": 0.036}


@dataclass(frozen=True)


class Resolution:
    """The spread (SI) below which one quantity's and direction's per-realisation values are not
    resolved by the level's numerics: max(absolute, relative x |value|); ``source`` says whence."""
    absolute: float
    relative: float
    source: str

    def limit(self, value: float) -> float:
        return max(self.absolute, self.relative * abs(value))

    @property
    def round_off(self) -> bool:
        """Whether this is round-off only: no numerical error beyond double precision's (ROUND_OFF)."""
        return self.relative <= ROUND_OFF and self.absolute <= ROUND_OFF_FLOOR

    def error(self, value: float) -> float:
        """The numerical error of one value, or of a statistic of values, near ``value`` against the
        converged model: half the resolution, the spread of two values each off by it the other way."""
        return self.limit(value) / 2


def within_resolution(values, resolution: Resolution) -> bool:
    """Whether the finite ``values`` (SI, one quantity and direction) spread by no more than the level
    resolves (False if there are none): any histogram or interval of them shows numerical noise."""
    x = np.asarray(values, dtype=float)
    x = x[np.isfinite(x)]
    return bool(x.size) and bool(np.ptp(x) <= resolution.limit(np.max(x)))


def resolutions(ds, quantity: str) -> dict[str, Resolution]:
    """{direction: Resolution} of a file's level for ``quantity``: round-off (ROUND_OFF) at every
    level but those whose joints are contact pairs, the contact level (:func:`_contact_resolutions`); {} for
    such a level's Dataset without its scene (none rss6 writes), whose resolution is then unknown."""
    if ds.attrs.get("model") not in models_with("contact_joints"):
        return dict.fromkeys(DIRECTIONS, Resolution(ROUND_OFF_FLOOR, ROUND_OFF, "round-off"))
    if "scene_toml" not in ds.attrs:
        return {}
    return _contact_resolutions(parse_scene(ds.attrs["scene_toml"]), quantity)


def closure_gain(scene) -> np.ndarray:
    """(direction,) the largest platform pose error (m/m, rad/m) that leg closures each off by 1 m
    can give, over the scene's trajectory: the row sums of |G^-1| of the linearised leg closure G
    (rss6core.quasi_static.closure_matrix, docs/model.md section 3)."""
    G, _ = closure_matrix(rigid_motion(scene, scene.times))
    return np.abs(np.linalg.inv(G)).sum(axis=-1).max(axis=0)


def _contact_resolutions(scene, quantity: str) -> dict[str, Resolution]:
    """The contact level's step bounds every joint's relative displacement error per step by eps
    (contact_tolerance_m; Newton's TOL_DISPLACEMENT where the step is fixed): carried to the platform
    through the legs' closure (:func:`closure_gain`), and doubled as two realisations each off by
    that can differ by twice it.  Velocity and acceleration with the adaptive step: twice its
    documented relative accuracy (CONTACT_ACCURACY); with a fixed step, Newton's TOL_VELOCITY
    carried likewise, and round-off for the acceleration."""
    sim = scene.simulation
    adaptive = sim.contact_refinements > 0 and sim.contact_tolerance > 0
    if adaptive and quantity != "displacement":
        a = CONTACT_ACCURACY[quantity]
        return dict.fromkeys(DIRECTIONS, Resolution(ROUND_OFF_FLOOR, 2 * a, f"twice the level's {100 * a:g} % "
                                                                       f"accuracy in {quantity}"))
    if quantity == "acceleration":
        return dict.fromkeys(DIRECTIONS, Resolution(ROUND_OFF_FLOOR, ROUND_OFF, "round-off"))
    eps, base = (TOL_DISPLACEMENT, "m") if quantity == "displacement" else (TOL_VELOCITY, "m/s")
    what = f"Newton's {si_text(eps, base)} tolerance"
    if adaptive:
        eps, what = sim.contact_tolerance, f"{si_text(sim.contact_tolerance, 'm')} contact tolerance"
    gains = dict(zip(DIRECTIONS, closure_gain(scene)))
    return {d: Resolution(2 * g * eps, ROUND_OFF, f"twice the {what} through the legs' closure, "
                                                  f"x {g:.2g}" + ("" if d in FAMILY_DIRECTIONS[0] else " rad/m"))
            for d, g in gains.items()}


def resolution_attrs(sds, ds) -> dict:
    """{"within_resolution": lines} for the statistics ``sds`` of ensemble ``ds`` (after any selection of
    windows, quantities and directions): per window and quantity, the cells whose finished realisations
    spread within the level's resolution (:func:`within_resolution`), whose intervals measure numerical noise,
    not the robot; {} where none does, for fewer than two realisations and for one run repeated."""
    from ..files.records import file_window_label
    from .stats import finished_values, windows_of
    if int(sds.attrs.get("n_finished", 0)) < 2 or "one_run_repeated" in sds.attrs:
        return {}
    directions, lines = [str(d) for d in sds["direction"].values], []
    for w in windows_of(sds) or ["whole"]:
        for q in (str(q) for q in sds["quantity"].values):
            res, cells = resolutions(ds, q), {}
            for name in SUMMARIES:
                values = finished_values(ds, name, w).sel(quantity=q)
                cells[name.split("_")[0]] = [d for d in directions
                                             if d in res and within_resolution(values.sel(direction=d), res[d])]
            if any(cells.values()):
                lines.append(_noise_line(file_window_label(w, sds.attrs), q, cells, res))
    return {"within_resolution": "\n".join(lines)} if lines else {}


def _noise_line(window: str, quantity: str, cells: dict, res: dict) -> str:
    """The note of one window's and quantity's cells ({'max'/'mean': directions}) within resolution ``res``."""
    which = "; ".join(f"{name} |error| in {', '.join(dirs)}" for name, dirs in cells.items() if dirs)
    return (f"{window}, {quantity} ({which}): the realisations spread less than the level resolves "
            f"({_sources(res, [d for d in DIRECTIONS if any(d in dirs for dirs in cells.values())])}): "
            "those intervals measure numerical noise, not the robot")


def _sources(res: dict, directions: list) -> str:
    """Whence the resolutions of ``directions``: one text where they share it, else their common start once
    and each direction's rest ('..., x 2.1 (x), 1.4 (y, z)')."""
    by_source = {}
    for d in directions:
        by_source.setdefault(res[d].source, []).append(d)
    if len(by_source) == 1:
        return next(iter(by_source))
    start = os.path.commonprefix(list(by_source))
    start = start[:start.rfind(" ") + 1]
    return start + ", ".join(f"{s[len(start):]} ({', '.join(dirs)})" for s, dirs in by_source.items())
