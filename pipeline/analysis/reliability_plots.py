"""A reliability run's figure (``rss6 reliability --plot``): the thresholds of its levels against the
event's limit, and the shift of its inputs among the failing evaluations (pipeline.analysis.failure_domain)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .plot_common import figure_unit, plt, save_figure

__all__ = ["plot_reliability"]


def _thresholds_panel(ax, thresholds, event) -> None:
    """Each level's threshold (the last one the limit) in display units, the limit dashed."""
    factor, unit = figure_unit(event.quantity, event.directions[0], np.asarray(thresholds))
    levels = np.arange(len(thresholds))
    ax.plot(levels, np.asarray(thresholds) * factor, "o-", label="threshold of the level")
    ax.axhline(event.limit * factor, color="C3", ls="--", label=f"limit {event.text}")
    ax.set(xlabel="subset level [1]", ylabel=f"max |{event.quantity} error| {event.direction_words} [{unit}]",
           title="intermediate thresholds")
    ax.set_xticks(levels)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def _shift_panel(ax, fd, shown: int) -> None:
    """The inputs of largest |mean z| among the failing evaluations: mean (bar) and std (marker)."""
    order = np.argsort(-np.abs(fd.mean))[:shown][::-1]
    y = np.arange(len(order))
    ax.barh(y, fd.mean[order], color="C0", label="mean of z (shift) [1]")
    ax.plot(fd.std[order], y, "k|", ms=10, label="std of z [1] (1: as its law)")
    ax.axvline(0.0, color="k", lw=0.6)
    ax.axvline(1.0, color="0.5", lw=0.6, ls=":")
    ax.set_yticks(y, [fd.labels[i] for i in order], fontsize=7)
    ax.set(xlabel="standard normal input z [1]",
           title=f"inputs among the {fd.failing} failing evaluations of level {fd.level}")
    ax.grid(alpha=0.3, axis="x")
    ax.legend(fontsize=8, loc="lower right")


def plot_reliability(est, event, fd, path, title: str, shown: int = 20) -> Path:
    """Write the two panels (thresholds per level, inputs' shift) as a PNG to ``path``."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 6), constrained_layout=True,
                                      gridspec_kw={"width_ratios": [1, 1.3]})
    fig.suptitle(title)
    _thresholds_panel(left, est.thresholds, event)
    if fd is None:
        right.text(0.5, 0.5, "no evaluation exceeded the limit", ha="center", va="center")
        right.set_axis_off()
    else:
        _shift_panel(right, fd, shown)
    return save_figure(fig, Path(path))
