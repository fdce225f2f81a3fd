"""The figures of ``rss6 report`` (pipeline.studies.report): the ideal rigid motion of a scene and, per
quantity, the platform error of its levels like the paper's figs. 11-16."""
from __future__ import annotations

import textwrap
from dataclasses import dataclass

import numpy as np

from rss6core import rigid_motion

from ..analysis.envelopes import draw_envelope, envelope_marks, steady_samples
from ..analysis.plot_common import family_units, legend_entries, plain_ticks, plt, realisation_count
from ..analysis.stats import ensemble_stats
from ..vocabulary import DIRECTIONS, FINISHED
from .report_text import clearance_mm

LEVELS = ("paper", "contact")

def rigid_figure(scene, t):
    """The ideal rigid platform motion (pose, rate, acceleration per direction) of a scene."""
    pm = rigid_motion(scene, t).platform
    fig, axes = plt.subplots(3, 6, figsize=(18, 8), constrained_layout=True, sharex=True)
    fig.suptitle(f"scene {scene.name}: ideal rigid platform motion ({scene.trajectory.label}), the reference of "
                 f"every error; {len(t)} instants over {t[-1] - t[0]:.3g} s")
    labels = ("x", "y", "z", "n1", "n2", "n3")
    for row, (q, values) in enumerate((("displacement", pm.pose), ("velocity", pm.pose_rate),
                                       ("acceleration", pm.pose_acc))):
        units = family_units(q, values)
        for k in range(6):
            f, unit = units[DIRECTIONS[k]]
            ax = axes[row, k]
            ax.plot(t, values[:, k] * f, color="0.3", lw=1.2)
            ax.set(title=f"{labels[k]} {q}", ylabel=f"[{unit}]")
            ax.grid(alpha=0.3)
            plain_ticks(ax)
            if row == 2:
                ax.set_xlabel("time [s]")
    return fig


@dataclass(frozen=True)
class _LevelErrors:
    """One level's ensemble in an error figure: its file, the finished realisations' errors
    (R, T, direction) SI, and its stored maxima and those above the sampled envelope (envelope_marks)."""
    ds: object
    err: np.ndarray
    stored: dict
    finer: dict

    @classmethod
    def of(cls, ds, quantity: str) -> "_LevelErrors":
        err = ds["error"].sel(quantity=quantity).transpose("realization", "time", "direction")
        err = err.values[ds["status"].values.astype(str) == FINISHED]
        return cls(ds, err, *envelope_marks(ds, ensemble_stats(ds, window=None), quantity, err))

    def rows(self) -> list[str]:
        """The figure rows of this level: one realisation, the envelope, and the steady window's
        envelope on axes of its own where the file has a steady window."""
        return ["signed", "envelope"] + (["steady"] if steady_samples(self.ds).any() else [])


def error_figure(scene, quantity: str, runs: dict):
    """Like the paper's figs. 11-16: the platform error (actual minus rigid) of the elastic level
    (ideal joints) and, per clearance level, one realisation (signed), the envelope of |error| over
    the ensemble and that envelope over the steady window alone (which start-up impacts would
    flatten), per direction, with the file's stored maxima where they exceed the envelope's samples
    (the contact level's come from every internal step); one unit per direction family.  ``runs``:
    the scene's opened files by role."""
    elastic = runs["elastic"]
    el = elastic["error"].sel(quantity=quantity).transpose("time", "direction").values
    levels = {level: _LevelErrors.of(runs[level], quantity) for level in LEVELS}
    units = family_units(quantity, el, *(a for lv in levels.values() for a in (lv.err, *lv.stored.values())))
    rows = [(level, row) for level, lv in levels.items() for row in lv.rows()]
    fig, axes = plt.subplots(len(rows), 6, figsize=(19, 2.6 * len(rows) + 0.8), constrained_layout=True)
    inputs = " + manufacturing inputs" if scene.uncertain else ""
    fig.suptitle(f"scene {scene.name} ({clearance_mm(scene)} mm clearances{inputs}): platform {quantity} "
                 "error, actual minus ideal rigid motion; levels " + ", ".join(LEVELS))
    for r, (level, row) in enumerate(rows):
        lv = levels[level]
        for k, (ax, d) in enumerate(zip(axes[r], DIRECTIONS)):
            if row == "signed":
                _signed_panel(ax, lv, elastic, el, k, units[d], level)
            else:
                _envelope_panel(ax, lv, k, units[d], level, row == "steady")
            if r and row != "steady":
                ax.sharex(axes[0, k])
            if row == "signed":
                ax.tick_params(labelbottom=False)   # the envelope below shares its time axis
            else:
                ax.set_xlabel("time [s]")
            ax.grid(alpha=0.3)
            plain_ticks(ax)
        if row != "steady":
            _row_legend(axes[r], wrap=row == "envelope")
    return fig


def _signed_panel(ax, lv: _LevelErrors, elastic, el, k: int, unit: tuple, level: str) -> None:
    """Realisation 0 of a level and the elastic level's error in direction ``k``, signed."""
    f, name = unit
    ax.plot(lv.ds["time"].values, lv.err[0, :, k] * f, color="C3", lw=0.8, label=f"{level}: realisation 0")
    nominal = ", nominal inputs" if "uncertain_input" in lv.ds and "uncertain_input" not in elastic else ""
    ax.plot(elastic["time"].values, el[:, k] * f, color="k", lw=1.0, label=f"elastic, ideal joints{nominal}")
    ax.set(title=f"{level}: {DIRECTIONS[k]} error", ylabel=f"[{name}]")


def _envelope_panel(ax, lv: _LevelErrors, k: int, unit: tuple, level: str, steady: bool) -> None:
    """A level's envelope of |error| in direction ``k`` over the whole run or the steady window."""
    f, name = unit
    draw_envelope(ax, lv.ds, lv.err[..., k], lv.finer, k, f, steady=steady)
    when = f"t >= {float(lv.ds.attrs['steady_after_s']):g} s" if steady else realisation_count(lv.ds, len(lv.err))
    ax.set(title=f"{level}: |{DIRECTIONS[k]} error|, {when}", ylabel=f"[{name}]")


def _row_legend(axes, wrap: bool) -> None:
    """One legend in a row's first panel with every label of the row (wrapped for envelopes)."""
    labelled = legend_entries(axes)
    labels = [textwrap.fill(x, 28) for x in labelled] if wrap else list(labelled)
    axes[0].legend(labelled.values(), labels, fontsize=7, loc="best")
