"""PNG figures of an ensemble file: error envelopes, histograms of maxima, Monte Carlo convergence."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["plot_ensemble", "axis_unit", "draw_envelope", "save_figure"]

from .store import DIRECTIONS as _DIRS  # noqa: E402
from .stats import quantile_estimates, running_mean_interval  # noqa: E402
from .store import display_unit  # noqa: E402


def axis_unit(q: str, d: str) -> tuple[float, str]:
    """Display factor and unit, with the square typeset for matplotlib."""
    f, unit = display_unit(q, d)
    return f, unit.replace("^2", "$^2$")


def _grid(title: str):
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.5), constrained_layout=True)
    fig.suptitle(title)
    return fig, axes.ravel()


def save_figure(fig, path: Path) -> Path:
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def draw_envelope(ax, t, e, band: str = "5-95 %", peak: str = "max |error|", **peak_style) -> None:
    """The 5-95 % band over realisations of e (R, T) and the max |e| over them, against time t."""
    lo, hi = quantile_estimates(e, [0.05, 0.95], axis=0)
    ax.fill_between(t, lo, hi, color="C0", alpha=0.3, lw=0, label=band)
    ax.plot(t, np.nanmax(np.abs(e), axis=0), label=peak, **peak_style)


def _envelope(ds, q: str, out: Path, finished) -> Path:
    err = ds["error"].sel(quantity=q).values[finished]            # (R, T, 6)
    t = ds["time"].values
    fig, axes = _grid(f"{ds.attrs['model']} level, scene {ds.attrs['scene_name']}: {q} error "
                      f"envelope over {err.shape[0]} realisations")
    for k, (ax, d) in enumerate(zip(axes, _DIRS)):
        f, unit = axis_unit(q, d)
        e = err[..., k] * f
        draw_envelope(ax, t, e, color="k", ls="--", lw=0.8)
        ax.plot(t, quantile_estimates(e, 0.5, axis=0), lw=1.2, label="median")
        ax.set(xlabel="time [s]", ylabel=f"{d} error [{unit}]", title=d)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    return save_figure(fig, out / f"envelope_{q}.png")


def _histograms(ds, q: str, out: Path, finished) -> Path:
    peak = ds["max_abs_error"].sel(quantity=q).values[finished]    # (R, 6)
    fig, axes = _grid(f"per-realisation max |{q} error| over {peak.shape[0]} realisations")
    for k, (ax, d) in enumerate(zip(axes, _DIRS)):
        f, unit = axis_unit(q, d)
        ax.hist(peak[:, k] * f, bins=min(30, max(5, peak.shape[0] // 4)), color="C0", alpha=0.8)
        ax.set(xlabel=f"max |{d} error| [{unit}]", ylabel="realisations", title=d)
        ax.grid(alpha=0.3)
    return save_figure(fig, out / f"hist_max_{q}.png")


def _convergence(ds, q: str, out: Path, finished) -> Path:
    peak = ds["max_abs_error"].sel(quantity=q).values[finished]
    n = np.arange(1, peak.shape[0] + 1)
    fig, axes = _grid(f"Monte Carlo convergence: running mean of max |{q} error| with 95 % CI "
                      "(pipeline.stats: none below 8 realisations)")
    for k, (ax, d) in enumerate(zip(axes, _DIRS)):
        f, unit = axis_unit(q, d)
        x = peak[:, k] * f
        mean, (lo, hi) = running_mean_interval(x, 0.95)
        ax.fill_between(n, lo, hi, alpha=0.3, label="95 % CI")
        ax.plot(n, mean, lw=1.2, label="running mean")
        ax.set(xlabel="realisations", ylabel=f"mean max |{d} error| [{unit}]", title=d)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    return save_figure(fig, out / f"convergence_{q}.png")


def plot_ensemble(ds, out_dir) -> list[Path]:
    """Write the figures to ``out_dir``; envelopes only when the file holds full histories."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    finished = ds["status"].values == "finished"
    if not finished.any():
        raise ValueError("no finished realisation to plot")
    paths = []
    for q in ("displacement", "velocity", "acceleration"):
        if "error" in ds:
            paths.append(_envelope(ds, q, out, finished))
        paths.append(_histograms(ds, q, out, finished))
        paths.append(_convergence(ds, q, out, finished))
    return paths
