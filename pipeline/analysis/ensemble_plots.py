"""An ensemble's figures (``rss6 plot``): |error| envelopes, histograms of maxima, convergence.

The histograms are of the per-realisation maxima per analysis window, the convergence that of
their running mean."""
from __future__ import annotations

import textwrap
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np

from ..files.records import file_window_label
from ..vocabulary import CONFIDENCE, DIRECTIONS, FINISHED, QUANTITIES
from .envelopes import draw_envelope, envelope_marks, marked_windows, steady_samples
from .estimators import estimates, moment_floor, running_mean_interval
from .plot_common import (FAMILY_DIRECTIONS, SI_UNITS, family_units, figure_legend, figure_title, panel_grid,
                          plain_ticks, plt, save_figures, si_text)
from .resolution import Resolution, resolutions, within_resolution
from .stats import ensemble_stats, in_window

__all__ = ["ensemble_figures", "plot_ensemble", "BARS_TOP"]


def _envelope(ds, q: str, finished, sds):
    """|q error| envelopes per direction over the whole run and, where the file has a steady
    window, over that window alone on axes of its own (a block of panels per view)."""
    err = ds["error"].sel(quantity=q).transpose("realization", "time", "direction").values[finished]
    stored, finer = envelope_marks(ds, sds, q, err)
    units = family_units(q, err, *stored.values())
    views = ["whole"] + (["steady"] if steady_samples(ds).any() else [])
    fig, axes = plt.subplots(2 * len(views), 3, figsize=(13, 1 + 5.5 * len(views)), constrained_layout=True)
    fig.suptitle(figure_title(f"|{q} error| envelope over realisations", ds, err.shape[0]))
    for i, view in enumerate(views):
        for k, (ax, d) in enumerate(zip(axes.ravel()[6 * i:6 * i + 6], DIRECTIONS)):
            f, unit = units[d]
            draw_envelope(ax, ds, err[..., k], finer, k, f, steady=view == "steady")
            ax.set(xlabel="time [s]", ylabel=f"|{d} error| [{unit}]",
                   title=d if view == "whole" else f"{d}, {file_window_label('steady', ds.attrs)}")
            ax.grid(alpha=0.3)
            plain_ticks(ax)
    figure_legend(fig, axes.ravel())
    return fig


def _peaks(ds, q: str, finished, window: str = "whole") -> np.ndarray:
    return in_window(ds, window)["max_abs_error"].sel(quantity=q).transpose(
        "realization", "direction").values[finished]


def _histograms(ds, q: str, finished, sds):
    """Histograms of the per-realisation maxima, a 2 x 3 block of directions per analysis window
    (startup above steady; the whole run's where the file has no windows), each panel on its own
    x range (the contact level's startup maxima exceed the steady ones a hundredfold) in one unit
    per direction family; a panel whose spread the level's numerics do not resolve says so."""
    peaks = {w: _peaks(ds, q, finished, w) for w in marked_windows(ds)}      # (R, 6) each
    peaks = {w: p for w, p in peaks.items() if np.isfinite(p).any()} or {"whole": _peaks(ds, q, finished)}
    units, res = family_units(q, *peaks.values()), resolutions(ds, q)
    fig, axes = plt.subplots(2 * len(peaks), 3, figsize=(13, 1 + 5.5 * len(peaks)), constrained_layout=True)
    fig.suptitle(figure_title(f"per-realisation max |{q} error| per analysis window", ds, int(finished.sum())))
    for i, (w, peak) in enumerate(peaks.items()):
        for k, (ax, d) in enumerate(zip(axes.ravel()[6 * i:6 * i + 6], DIRECTIONS)):
            panel = _Panel(q, d, w, i, units[d], res[d], file_window_label(w, ds.attrs))
            _histogram_panel(ax, peak[:, k], in_window(sds, w)["max_abs_error"].sel(
                statistic="q95", quantity=q, direction=d), panel)
    fig.supxlabel(_histogram_key(ds, sds), fontsize=9)
    return fig


@dataclass(frozen=True)


class _Panel:
    """What one histogram panel shows: quantity, direction and window, its colour index, display
    unit (factor from SI, name), the level's resolution there and the window's label."""
    quantity: str
    direction: str
    window: str
    colour: int
    unit: tuple[float, str]
    resolution: Resolution
    label: str


BARS_TOP = 0.6   # axes fraction the tallest bar reaches: the q95 interval bar and legend sit above


def _histogram_panel(ax, peak, q95, panel: _Panel) -> None:
    """One window's and direction's histogram of maxima ``peak`` (R,) SI, with its mean and the q95
    cell of pipeline.analysis.stats; where their spread is within the level's resolution, a note instead."""
    (f, unit), d, w, i = panel.unit, panel.direction, panel.window, panel.colour
    ax.set(xlabel=f"max |{d} error| [{unit}]", ylabel="realisations", title=f"{d}, {panel.label}")
    x = peak[np.isfinite(peak)]
    if not x.size:
        return
    if within_resolution(x, panel.resolution):
        _unresolved_note(ax, x, panel)
        return
    x = x * f
    mean = estimates(x, ("mean",))[0]
    counts, _, _ = ax.hist(x, bins=min(30, max(5, x.size // 4)), color=f"C{i}", alpha=0.5,
                           label=f"{w}, mean {mean:.3g} {unit}")
    ax.axvline(mean, color=f"C{i}", lw=1.2, gid=f"mean {w}")
    _mark_q95(ax, q95, panel.unit, i, w)
    ax.set_ylim(0, max(counts.max(), 1) / BARS_TOP)
    ax.legend(fontsize=7, loc="upper left")
    ax.grid(alpha=0.3)
    plain_ticks(ax)
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(5))
    ax.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))   # counts


def _unresolved_note(ax, x, panel: _Panel) -> None:
    """In place of a histogram of maxima ``x`` (R,) SI whose spread is within the level's
    resolution (a histogram of numerical noise): how many agree to what, and their median, its
    last digit of the resolution's order."""
    (f, unit), res = panel.unit, panel.resolution
    limit, base = res.limit(np.max(x)), SI_UNITS[panel.quantity][panel.direction not in FAMILY_DIRECTIONS[0]]
    decimals = max(0, int(-np.floor(np.log10(limit * f))))
    value = f"{np.median(x) * f:.{decimals}f} {unit}"
    text = [f"all {x.size} realisations agree within {si_text(limit, base)}", f"({res.source}):", value,
            f"spread {si_text(np.ptp(x), base)}, below what the level resolves: no histogram"]
    if x.size == 1:
        text = ["one realisation:", value]
    ax.text(0.5, 0.5, "\n".join(textwrap.fill(line, 46) for line in text), transform=ax.transAxes,
            ha="center", va="center", fontsize=9, gid="within resolution")
    ax.set(xticks=[], yticks=[], ylabel="")


def _mark_q95(ax, cell, shown: tuple, i: int, window: str) -> None:
    """A dashed line at the q95 estimate of ``cell`` (bound: estimate, lower, upper; SI, shown as
    ``shown`` = (factor, unit)) and, only where pipeline.analysis.stats gives one, its interval as a
    capped bar above the bars."""
    f, unit = shown
    est, lo, hi = (float(cell.sel(bound=b)) * f for b in ("estimate", "lower", "upper"))
    text = f"{window}, q95 est. {est:.3g} {unit}"
    if np.isfinite(lo) and np.isfinite(hi):
        ax.plot([lo, hi], [BARS_TOP + 0.07] * 2, color=f"C{i}", lw=1.5, marker="|", ms=7,
                transform=ax.get_xaxis_transform(), gid=f"q95 interval {window}")
        text += f" [{lo:.3g}, {hi:.3g}] {unit}"
    ax.axvline(est, color=f"C{i}", lw=1.2, ls="--", label=text, gid=f"q95 {window}")


def _histogram_key(ds, sds) -> str:
    """The line under the histograms: the windows' time spans and what the marks are."""
    conf = f"{100 * float(sds.attrs['confidence']):g} %"
    marks = (f"solid: mean; dashed: q95 estimate; bar: its {conf} interval, where rss6 stats gives one "
             f"(from n = {int(sds.attrs['min_n_q95'])})")
    if "steady_after_s" not in ds.attrs:
        return marks
    return f"{file_window_label('startup', ds.attrs)}; {file_window_label('steady', ds.attrs)}; {marks}"


def _convergence(ds, q: str, finished, confidence: float = CONFIDENCE):
    peak = _peaks(ds, q, finished)
    n = np.arange(1, peak.shape[0] + 1)
    iid = str(ds.attrs.get("sampler", "mc")) == "mc"   # a QMC prefix has no running iid interval
    units = family_units(q, peak)
    floor = moment_floor("mean", confidence)
    fig, axes = panel_grid(figure_title(f"running mean of max |{q} error| (whole run) with its "
                                   f"{100 * confidence:g} % interval (given from n = {floor})"
                                   if iid else f"running mean of max |{q} error| (whole run, randomised "
                                   "QMC: intervals from the replicates, rss6 stats)",
                                   ds, peak.shape[0]))
    for k, (ax, d) in enumerate(zip(axes, DIRECTIONS)):
        f, unit = units[d]
        mean, (lo, hi) = running_mean_interval(peak[:, k] * f, confidence)
        has = np.isfinite(lo) & np.isfinite(hi) & iid
        _interval(ax, n[has], mean[has], lo[has], hi[has], f"{100 * confidence:g} % interval")
        ax.plot(n, mean, lw=1.2, marker="." if n.size <= 30 else None, label="running mean")
        ax.set(xlabel="realisations n", ylabel=f"mean max |{d} error| [{unit}]", title=d)
        ax.set_xlim(0.5, n[-1] + 0.5)
        ax.set_ylim(*_convergence_range(mean, lo[has], hi[has]))
        ax.grid(alpha=0.3)
        plain_ticks(ax)
        ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))   # counts
    axes[0].legend(fontsize=8, loc="best")
    return fig


def _interval(ax, n, mean, lo, hi, label: str) -> None:
    """The running mean's interval where it is given: a band over two or more n, an error bar at a
    single n (the last, when n is the mean interval's floor), where a band would have no width to show."""
    if n.size >= 2:
        ax.fill_between(n, lo, hi, alpha=0.3, lw=0, label=label)
    elif n.size == 1:
        ax.errorbar(n, mean, yerr=[mean - lo, hi - mean], fmt="none", ecolor="C0", alpha=0.6, capsize=4,
                    lw=2, label=label)


def _convergence_range(mean, lo, hi) -> tuple[float, float]:
    """y range holding the running mean from n = 1 and its interval where given (``lo``, ``hi``),
    never below 0: the mean of a maximum |error| is not negative."""
    values = np.concatenate([mean, lo, hi])
    values = values[np.isfinite(values)]
    top, bottom = values.max(), values.min()
    pad = 0.1 * (top - bottom) if top > bottom else 0.1 * abs(top) or 1.0
    return max(0.0, bottom - pad), top + pad


def ensemble_figures(ds):
    """{file name: Figure} of an ensemble; envelopes only when the file holds full histories."""
    finished = ds["status"].values.astype(str) == FINISHED
    if not finished.any():
        raise ValueError("no finished realisation to plot")
    sds, figs = ensemble_stats(ds, window=None), {}
    for q in QUANTITIES:
        if "error" in ds:
            figs[f"envelope_{q}.png"] = _envelope(ds, q, finished, sds)
        figs[f"hist_max_{q}.png"] = _histograms(ds, q, finished, sds)
        figs[f"convergence_{q}.png"] = _convergence(ds, q, finished)
    return figs


def plot_ensemble(ds, out_dir) -> list[Path]:
    """Write an ensemble's figures to ``out_dir``."""
    return save_figures(ensemble_figures(ds), out_dir)
