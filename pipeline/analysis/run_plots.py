"""A single run's figures (``rss6 plot`` of a ``rss6 simulate -o`` file): its signed error histories."""
from __future__ import annotations

from pathlib import Path

from ..vocabulary import DIRECTIONS, QUANTITIES
from .envelopes import finer_maxima, mark_stored_maxima, output_grid, stored_maxima
from .plot_common import family_units, figure_legend, figure_title, mark_steady, panel_grid, plain_ticks, save_figures
from .stats import ensemble_stats

__all__ = ["run_figures", "plot_run"]


def _history(ds, q: str, sds):
    """One run's signed error history per direction, sampled on the output grid, with the stored
    maxima marked where they exceed what the samples show."""
    err = ds["error"].sel(quantity=q).transpose("time", "direction").values       # (T, 6)
    t = ds["time"].values
    stored = stored_maxima(ds, sds, q)
    finer = finer_maxima(ds, t, err, stored)
    units = family_units(q, err, *stored.values())
    fig, axes = panel_grid(figure_title(f"{q} error history (actual minus ideal rigid motion)", ds))
    for k, (ax, d) in enumerate(zip(axes, DIRECTIONS)):
        f, unit = units[d]
        ax.plot(t, err[:, k] * f, color="C0", lw=1.0, label=f"error, sampled on the {output_grid(t)}", gid="history")
        mark_stored_maxima(ax, finer, k, f, signed=True)
        mark_steady(ax, ds)
        ax.set(xlabel="time [s]", ylabel=f"{d} error [{unit}]", title=d)
        ax.grid(alpha=0.3)
        plain_ticks(ax)
    figure_legend(fig, axes)
    return fig


def run_figures(ds):
    """{file name: Figure} of a single run (``rss6 simulate -o``): its error histories."""
    if "error" not in ds:
        raise ValueError("no error histories in the file")
    sds = ensemble_stats(ds, window=None)
    return {f"history_{q}.png": _history(ds, q, sds) for q in QUANTITIES}


def plot_run(ds, out_dir) -> list[Path]:
    """Write a single run's error-history figures to ``out_dir``."""
    return save_figures(run_figures(ds), out_dir)
