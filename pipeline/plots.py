"""PNG figures of rss6 files: error envelopes, histograms of maxima, Monte Carlo convergence of an
ensemble, and the error histories of a single run (``rss6 simulate -o``).

Every builder returns a matplotlib Figure (tests check its text for overlaps) and the ``plot_*``
functions save them.  Statistics drawn come from :mod:`pipeline.stats`."""
from __future__ import annotations

import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["plot_ensemble", "plot_run", "ensemble_figures", "run_figures", "figure_unit",
           "draw_abs_envelope", "mark_steady", "mark_stored_maxima", "stored_maxima", "envelope_marks",
           "envelope_unit", "legend_entries",
           "output_grid", "figure_title", "save_figure", "plain_ticks", "sensitivity_figures",
           "plot_sensitivity"]

from .stats import (MIN_N_MEAN, ensemble_stats, estimates, in_window, quantile_estimates,  # noqa: E402
                    running_mean_interval, windows_of)
from .store import DIRECTIONS as _DIRS  # noqa: E402
from .store import WINDOWS, window_label, window_masks, window_reductions  # noqa: E402

QUANTITIES = ("displacement", "velocity", "acceleration")
_BASE = {"displacement": ("m", "rad"), "velocity": ("m/s", "rad/s"),
         "acceleration": ("m/s$^2$", "rad/s$^2$")}


def figure_unit(quantity: str, direction: str, values=None) -> tuple[float, str]:
    """Display factor from SI and unit of a figure axis, suited to the magnitude of ``values``
    (SI): the SI unit (m, m/s, m/s^2; rad, rad/s, rad/s^2) when they reach 1, else its milli-
    unit (mm, mm/s, mm/s^2; mrad, ...).  Without values: the milli-unit."""
    unit = _BASE[quantity][direction not in ("x", "y", "z")]
    peak = np.nanmax(np.abs(values)) if values is not None and np.size(values) else np.nan
    if np.isfinite(peak) and peak >= 1.0:
        return 1.0, unit
    return 1e3, "m" + unit


def figure_title(what: str, ds, n: int | None = None, width: int = 110) -> str:
    """A title naming what is drawn, the scene, the level, n and the file, wrapped to ``width``."""
    a = ds.attrs
    source = Path(str(ds.encoding.get("source", "in-memory data"))).name
    count = "" if n is None else f", n = {n}"
    head = f"{what}: scene {a.get('scene_name', '?')}, {a.get('model', '?')} level{count}, {source}"
    return "\n".join(textwrap.wrap(head, width))


def plain_ticks(ax) -> None:
    """Tick labels as plain numbers: no offset text or exponent to collide with titles."""
    for axis in ("x", "y"):
        if getattr(ax, f"get_{axis}scale")() == "linear":
            ax.ticklabel_format(axis=axis, style="plain", useOffset=False)


def _grid(title: str):
    fig, axes = plt.subplots(2, 3, figsize=(13, 7), constrained_layout=True)
    fig.suptitle(title)
    return fig, axes.ravel()


def save_figure(fig, path: Path) -> Path:
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def mark_steady(ax, ds) -> None:
    """A dotted vertical line at the start of the steady window (the file's steady_after_s, s)."""
    if "steady_after_s" in ds.attrs:
        t_s = float(ds.attrs["steady_after_s"])
        ax.axvline(t_s, color="0.4", ls=":", lw=1.0, label=f"steady from {t_s:g} s")


def output_grid(t) -> str:
    """How a curve sampled at times t (s) is labelled: its output grid and step, which at the
    contact level is coarser than the internal steps the stored maxima come from."""
    step = float(np.median(np.diff(t))) if np.size(t) > 1 else float("nan")
    return f"{step:g} s output grid"


def draw_abs_envelope(ax, t, e, who: str = "", **peak_style) -> None:
    """|e| of realisations e (R, T) against time t: its 5-95 % band, median and maximum, each
    labelled as sampled on the output grid (the stored maxima may lie higher)."""
    a, grid = np.abs(e), output_grid(t)
    lo, mid, hi = quantile_estimates(a, [0.05, 0.5, 0.95], axis=0)
    ax.fill_between(t, lo, hi, color="C0", alpha=0.3, lw=0, label=f"{who}5-95 % of |error|, {grid}")
    ax.plot(t, mid, color="C0", lw=1.0, label=f"{who}median |error|, {grid}")
    ax.plot(t, estimates(a, ("max",))[..., 0], label=f"{who}max |error|, {grid}", gid="sampled max",
            **peak_style)


STORED_MAX_LABEL = "max |error| over internal steps (file's stored maximum)"


def _marked_windows(ds) -> list[str]:
    """The windows whose stored maxima are marked: startup and steady, else the whole run."""
    return [w for w in windows_of(ds) if w != "whole"] or ["whole"]


def stored_maxima(ds, sds, q: str) -> dict[str, np.ndarray]:
    """{window: (direction,) SI} the file's maximum |q error| per window of _marked_windows, over
    the finished realisations (``sds``: :func:`pipeline.stats.ensemble_stats`, every window)."""
    return {w: in_window(sds, w)["max_abs_error"].sel(statistic="max", bound="estimate", quantity=q)
            .transpose("direction").values for w in _marked_windows(ds)}


def _finer_maxima(ds, t, sampled, stored: dict) -> dict[str, tuple[float, float, np.ndarray]]:
    """{window: (start s, end s, stored maxima)} where the stored maxima exceed the maxima of the
    plotted samples ``sampled`` (T, direction) in that window (the contact level's come from every
    internal step); other directions NaN.  Samples per window as the file's summaries take them."""
    masks = window_masks(t, float(ds.attrs.get("settle_time_s", 0.0)),
                         float(ds.attrs.get("steady_after_s", 0.0)))
    shown = window_reductions(np.asarray(sampled)[None], masks)[0][:, 0]     # (window, direction)
    out = {}
    for w, peak in stored.items():
        i = WINDOWS.index(w)
        above = peak > shown[i] * (1 + 1e-9)      # elsewhere the two are one computation, equal
        if above.any() and masks[i].any():
            span = t[masks[i]]
            out[w] = (float(span[0]), float(span[-1]), np.where(above, peak, np.nan))
    return out


def envelope_marks(ds, sds, q: str, err) -> tuple[dict, dict]:
    """The file's stored maxima of |q error| (:func:`stored_maxima`) and those of them above the
    maximum over realisations of err (R, T, direction), the envelope sampled on the output grid
    (for :func:`mark_stored_maxima`)."""
    stored = stored_maxima(ds, sds, q)
    return stored, _finer_maxima(ds, ds["time"].values, estimates(np.abs(err), ("max",))[..., 0], stored)


def mark_stored_maxima(ax, finer: dict, k: int, f: float, signed: bool = False) -> None:
    """Dashed lines at the stored maxima of direction ``k`` (SI, shown times ``f``) over their
    windows' spans; at plus and minus the value on a signed history."""
    for w, (t0, t1, peak) in finer.items():
        if not np.isfinite(peak[k]):
            continue
        for sign in (1, -1) if signed else (1,):
            ax.plot([t0, t1], [sign * peak[k] * f] * 2, color="C3", ls="--", lw=1.2,
                    label=STORED_MAX_LABEL, gid=f"stored max {w}" + (" negative" if sign < 0 else ""))


def envelope_unit(q: str, d: str, e, stored: dict, k: int) -> tuple[float, str]:
    """:func:`figure_unit` for the envelope of e (R, T) in direction ``d`` (index k) together with
    the stored maxima that :func:`mark_stored_maxima` draws beside it."""
    return figure_unit(q, d, np.concatenate([np.ravel(e), [v[k] for v in stored.values()]]))


def legend_entries(axes) -> dict:
    """Every distinct label of ``axes`` with its first handle, so that a mark drawn in any panel is
    explained even when the first panel lacks it."""
    handles = {}
    for ax in axes:
        for h, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, h)
    return handles


def _figure_legend(fig, axes) -> None:
    """One legend under the panels with every distinct label of ``axes`` (:func:`legend_entries`)."""
    handles = legend_entries(axes)
    fig.legend(handles.values(), handles.keys(), loc="outside lower center", fontsize=8,
               ncols=min(3, len(handles)))


def _envelope(ds, q: str, finished, sds):
    err = ds["error"].sel(quantity=q).transpose("realization", "time", "direction").values[finished]
    t = ds["time"].values
    stored, finer = envelope_marks(ds, sds, q, err)
    fig, axes = _grid(figure_title(f"|{q} error| envelope over realisations", ds, err.shape[0]))
    for k, (ax, d) in enumerate(zip(axes, _DIRS)):
        f, unit = envelope_unit(q, d, err[..., k], stored, k)
        draw_abs_envelope(ax, t, err[..., k] * f, color="k", ls="--", lw=0.8)
        mark_stored_maxima(ax, finer, k, f)
        mark_steady(ax, ds)
        ax.set(xlabel="time [s]", ylabel=f"|{d} error| [{unit}]", title=d)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        plain_ticks(ax)
    _figure_legend(fig, axes)
    return fig


def _peaks(ds, q: str, finished, window: str = "whole") -> np.ndarray:
    return in_window(ds, window)["max_abs_error"].sel(quantity=q).transpose(
        "realization", "direction").values[finished]


def _histograms(ds, q: str, finished, sds):
    """Histograms of the per-realisation maxima, a 2 x 3 block of directions per analysis window
    (startup above steady; the whole run's where the file has no windows), each panel on its own
    x range: the contact level's startup maxima exceed the steady ones a hundredfold."""
    peaks = {w: _peaks(ds, q, finished, w) for w in _marked_windows(ds)}      # (R, 6) each
    peaks = {w: p for w, p in peaks.items() if np.isfinite(p).any()} or {"whole": _peaks(ds, q, finished)}
    fig, axes = plt.subplots(2 * len(peaks), 3, figsize=(13, 1 + 5.5 * len(peaks)), constrained_layout=True)
    fig.suptitle(figure_title(f"per-realisation max |{q} error| per analysis window", ds, int(finished.sum())))
    t_s = float(ds.attrs.get("steady_after_s", np.nan))
    for i, (w, peak) in enumerate(peaks.items()):
        for k, (ax, d) in enumerate(zip(axes.ravel()[6 * i:6 * i + 6], _DIRS)):
            _histogram_panel(ax, peak[:, k], in_window(sds, w)["max_abs_error"].sel(
                statistic="q95", quantity=q, direction=d), (q, d, w, i, t_s))
    fig.supxlabel(_histogram_key(t_s, sds), fontsize=9)
    return fig


BARS_TOP = 0.6   # axes fraction the tallest bar reaches: the q95 interval bar and legend sit above


def _histogram_panel(ax, peak, q95, where: tuple) -> None:
    """One window's and direction's histogram of maxima ``peak`` (R,) SI, with its mean and the q95
    cell of pipeline.stats; ``where``: (quantity, direction, window, colour index, steady_after_s)."""
    q, d, w, i, t_s = where
    f, unit = figure_unit(q, d, peak)
    x = peak[np.isfinite(peak)] * f
    label = window_label(w, t_s)
    ax.set(xlabel=f"max |{d} error| [{unit}]", ylabel="realisations", title=f"{d}, {label}")
    if not x.size:
        return
    mean = estimates(x, ("mean",))[0]
    counts, _, _ = ax.hist(x, bins=min(30, max(5, x.size // 4)), color=f"C{i}", alpha=0.5,
                           label=f"{w}, mean {mean:.3g}")
    ax.axvline(mean, color=f"C{i}", lw=1.2, gid=f"mean {w}")
    _mark_q95(ax, q95, f, i, w)
    ax.set_ylim(0, max(counts.max(), 1) / BARS_TOP)
    ax.legend(fontsize=7, loc="upper left")
    ax.grid(alpha=0.3)
    plain_ticks(ax)
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(5))
    ax.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))   # counts


def _mark_q95(ax, cell, f: float, i: int, window: str) -> None:
    """A dashed line at the q95 estimate of ``cell`` (bound: estimate, lower, upper; SI, shown times
    ``f``) and, only where pipeline.stats gives one, its interval as a capped bar above the bars."""
    est, lo, hi = (float(cell.sel(bound=b)) * f for b in ("estimate", "lower", "upper"))
    text = f"{window}, q95 est. {est:.3g}"
    if np.isfinite(lo) and np.isfinite(hi):
        ax.plot([lo, hi], [BARS_TOP + 0.07] * 2, color=f"C{i}", lw=1.5, marker="|", ms=7,
                transform=ax.get_xaxis_transform(), gid=f"q95 interval {window}")
        text += f" [{lo:.3g}, {hi:.3g}]"
    ax.axvline(est, color=f"C{i}", lw=1.2, ls="--", label=text, gid=f"q95 {window}")


def _histogram_key(t_s: float, sds) -> str:
    """The line under the histograms: the windows' time spans and what the marks are."""
    conf = f"{100 * float(sds.attrs['confidence']):g} %"
    marks = (f"solid: mean; dashed: q95 estimate; bar: its {conf} interval, where rss6 stats gives one "
             f"(from n = {int(sds.attrs['min_n_q95'])})")
    return f"startup: t < {t_s:g} s; steady: t >= {t_s:g} s; {marks}" if np.isfinite(t_s) else marks


def _convergence(ds, q: str, finished, confidence: float = 0.95):
    peak = _peaks(ds, q, finished)
    n = np.arange(1, peak.shape[0] + 1)
    iid = str(ds.attrs.get("sampler", "mc")) == "mc"   # a QMC prefix has no running iid interval
    fig, axes = _grid(figure_title(f"running mean of max |{q} error| (whole run) with its "
                                   f"{100 * confidence:g} % interval (given from n = {MIN_N_MEAN})"
                                   if iid else f"running mean of max |{q} error| (whole run, randomised "
                                   "QMC: intervals from the replicates, rss6 stats)",
                                   ds, peak.shape[0]))
    for k, (ax, d) in enumerate(zip(axes, _DIRS)):
        f, unit = figure_unit(q, d, peak[:, k])
        mean, (lo, hi) = running_mean_interval(peak[:, k] * f, confidence)
        has = np.isfinite(lo) & np.isfinite(hi) & iid
        if has.any():
            ax.fill_between(n[has], lo[has], hi[has], alpha=0.3, lw=0,
                            label=f"{100 * confidence:g} % interval")
        ax.plot(n, mean, lw=1.2, label="running mean")
        ax.set(xlabel="realisations n", ylabel=f"mean max |{d} error| [{unit}]", title=d)
        ax.set_ylim(*_convergence_range(mean, lo, hi, has))
        ax.grid(alpha=0.3)
        plain_ticks(ax)
    axes[0].legend(fontsize=8, loc="best")
    return fig


def _convergence_range(mean, lo, hi, has) -> tuple[float, float]:
    """y range from where the interval exists (else the running mean), never below 0: the mean of
    a maximum |error| is not negative."""
    top = np.nanmax(hi[has]) if has.any() else np.nanmax(mean)
    bottom = np.nanmin(lo[has]) if has.any() else np.nanmin(mean)
    pad = 0.1 * (top - bottom) if top > bottom else 0.1 * abs(top) or 1.0
    return max(0.0, bottom - pad), top + pad


def ensemble_figures(ds):
    """{file name: Figure} of an ensemble; envelopes only when the file holds full histories."""
    finished = ds["status"].values.astype(str) == "finished"
    if not finished.any():
        raise ValueError("no finished realisation to plot")
    sds, figs = ensemble_stats(ds, window=None), {}
    for q in QUANTITIES:
        if "error" in ds:
            figs[f"envelope_{q}.png"] = _envelope(ds, q, finished, sds)
        figs[f"hist_max_{q}.png"] = _histograms(ds, q, finished, sds)
        figs[f"convergence_{q}.png"] = _convergence(ds, q, finished)
    return figs


def _history(ds, q: str, sds):
    """One run's signed error history per direction, sampled on the output grid, with the stored
    maxima marked where they exceed what the samples show."""
    err = ds["error"].sel(quantity=q).transpose("time", "direction").values       # (T, 6)
    t = ds["time"].values
    stored = stored_maxima(ds, sds, q)
    finer = _finer_maxima(ds, t, err, stored)
    fig, axes = _grid(figure_title(f"{q} error history (actual minus ideal rigid motion)", ds))
    for k, (ax, d) in enumerate(zip(axes, _DIRS)):
        f, unit = figure_unit(q, d, np.concatenate([err[:, k], [v[k] for v in stored.values()]]))
        ax.plot(t, err[:, k] * f, color="C0", lw=1.0, label=f"error, sampled on the {output_grid(t)}", gid="history")
        mark_stored_maxima(ax, finer, k, f, signed=True)
        mark_steady(ax, ds)
        ax.set(xlabel="time [s]", ylabel=f"{d} error [{unit}]", title=d)
        ax.grid(alpha=0.3)
        plain_ticks(ax)
    _figure_legend(fig, axes)
    return fig


def run_figures(ds):
    """{file name: Figure} of a single run (``rss6 simulate -o``): its error histories."""
    if "error" not in ds:
        raise ValueError("no error histories in the file")
    sds = ensemble_stats(ds, window=None)
    return {f"history_{q}.png": _history(ds, q, sds) for q in QUANTITIES}


def _save_all(figs: dict, out_dir) -> list[Path]:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [save_figure(fig, out / name) for name, fig in figs.items()]


def plot_ensemble(ds, out_dir) -> list[Path]:
    """Write an ensemble's figures to ``out_dir``."""
    return _save_all(ensemble_figures(ds), out_dir)


def plot_run(ds, out_dir) -> list[Path]:
    """Write a single run's error-history figures to ``out_dir``."""
    return _save_all(run_figures(ds), out_dir)


_DESIGN_NAMES = {"families": "joint family", "joints": "joint"}
_GROUP_LABELS = {"revolute_radial": "A radial", "revolute_axial": "A axial", "spherical_C": "C",
                 "spherical_B": "B"}


def _sobol_panel(ax, da, groups: list[str], direction: str) -> None:
    """S1 and ST bars per group with their interval as error bars, on one direction's axis."""
    x = np.arange(len(groups))
    for k, (index, shift) in enumerate((("S1", -0.2), ("ST", 0.2))):
        cell = da.sel(index=index, direction=direction)
        est = cell.sel(bound="estimate").values
        err = np.abs(np.stack([est - cell.sel(bound="lower").values,
                               cell.sel(bound="upper").values - est]))
        ax.bar(x + shift, est, width=0.4, yerr=err, capsize=2, color=f"C{k}", label=index,
               error_kw={"lw": 0.8})
    ax.set_xticks(x, [_GROUP_LABELS.get(g, g) for g in groups], fontsize=8,
                  rotation=90 if len(groups) > 6 else 0)
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set(ylabel="Sobol' index [1]", title=direction)
    ax.grid(alpha=0.3, axis="y")


def sensitivity_figures(ds, quantities=QUANTITIES) -> dict:
    """{file name: Figure}: per statistic, quantity and grouping, a bar chart per direction of the
    first-order (S1) and total (ST) Sobol' indices with their bootstrap intervals."""
    figs = {}
    conf = f"{100 * float(ds.attrs['confidence']):g} %"
    for stat, what in (("max_abs_error", "max"), ("mean_abs_error", "mean")):
        for design in dict.fromkeys(str(v) for v in ds["group_design"].values):
            groups = [str(g) for g, d in zip(ds["group"].values, ds["group_design"].values) if d == design]
            for q in quantities:
                da = ds[f"{stat}_sobol"].sel(quantity=q, group=groups)
                window = da.attrs.get("analysis_window", "whole run")
                fig, axes = _grid(figure_title(
                    f"Sobol' indices of per-realisation {what} |{q} error|, {window}, by "
                    f"{_DESIGN_NAMES.get(design, design)}, bars: {conf} bootstrap intervals", ds,
                    int(ds.attrs["n_base_samples"])))
                for ax, d in zip(axes, _DIRS):
                    _sobol_panel(ax, da, groups, d)
                axes[0].legend(fontsize=8, loc="upper right")
                figs[f"sobol_{what}_{q}_{design}.png"] = fig
    return figs


def plot_sensitivity(ds, out_dir) -> list[Path]:
    """Write a sensitivity file's bar charts to ``out_dir``."""
    return _save_all(sensitivity_figures(ds), out_dir)
