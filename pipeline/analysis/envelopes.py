"""|error| envelopes over realisations, with the stored maxima marked where the samples miss them.

The envelopes are sampled on a file's output grid, the stored maxima come from every internal step:
the ensemble figures' and the report's envelope panels, and the marks on a single run's histories."""
from __future__ import annotations

import numpy as np

from ..files.records import window_masks, window_reductions
from ..vocabulary import QUANTILES, WINDOWS
from .estimators import estimates, quantile_estimates
from .plot_common import mark_steady
from .stats import in_window, windows_of

__all__ = ["output_grid", "draw_abs_envelope", "STORED_MAX_LABEL", "marked_windows", "stored_maxima", "finer_maxima",
           "envelope_marks", "mark_stored_maxima", "steady_samples", "draw_envelope"]


def output_grid(t) -> str:
    """How a curve sampled at times t (s) is labelled: its output grid and step, which at the
    contact level is coarser than the internal steps the stored maxima come from."""
    step = float(np.median(np.diff(t))) if np.size(t) > 1 else float("nan")
    return f"{step:g} s output grid"


def draw_abs_envelope(ax, t, e, who: str = "", **peak_style) -> None:
    """|e| of realisations e (R, T) against time t: its 5-95 % band, median and maximum, each
    labelled as sampled on the output grid (the stored maxima may lie higher)."""
    a, grid = np.abs(e), output_grid(t)
    lo, mid, hi = quantile_estimates(a, [QUANTILES[q] for q in ("q05", "q50", "q95")], axis=0)
    ax.fill_between(t, lo, hi, color="C0", alpha=0.3, lw=0, label=f"{who}5-95 % of |error|, {grid}")
    ax.plot(t, mid, color="C0", lw=1.0, label=f"{who}median |error|, {grid}")
    ax.plot(t, estimates(a, ("max",))[..., 0], label=f"{who}max |error|, {grid}", gid="sampled max",
            **peak_style)


STORED_MAX_LABEL = "max |error| over internal steps (file's stored maximum)"


def marked_windows(ds) -> list[str]:
    """The windows whose stored maxima are marked: startup and steady, else the whole run."""
    return [w for w in windows_of(ds) if w != "whole"] or ["whole"]


def stored_maxima(ds, sds, q: str) -> dict[str, np.ndarray]:
    """{window: (direction,) SI} the file's maximum |q error| per window of :func:`marked_windows`, over
    the finished realisations (``sds``: :func:`pipeline.analysis.stats.ensemble_stats`, every window)."""
    return {w: in_window(sds, w)["max_abs_error"].sel(statistic="max", bound="estimate", quantity=q)
            .transpose("direction").values for w in marked_windows(ds)}


def finer_maxima(ds, t, sampled, stored: dict) -> dict[str, tuple[float, float, np.ndarray]]:
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
    return stored, finer_maxima(ds, ds["time"].values, estimates(np.abs(err), ("max",))[..., 0], stored)


def mark_stored_maxima(ax, finer: dict, k: int, f: float, signed: bool = False) -> None:
    """Dashed lines at the stored maxima of direction ``k`` (SI, shown times ``f``) over their
    windows' spans; at plus and minus the value on a signed history."""
    for w, (t0, t1, peak) in finer.items():
        if not np.isfinite(peak[k]):
            continue
        for sign in (1, -1) if signed else (1,):
            ax.plot([t0, t1], [sign * peak[k] * f] * 2, color="C3", ls="--", lw=1.2,
                    label=STORED_MAX_LABEL, gid=f"stored max {w}" + (" negative" if sign < 0 else ""))


def steady_samples(ds) -> np.ndarray:
    """(time,) which output samples lie in the file's steady window (t >= steady_after_s); none
    where it has no steady window apart from a start-up one, or only one sample there."""
    none = np.zeros(ds.sizes["time"], bool)
    if "steady" not in windows_of(ds):
        return none
    masks = window_masks(ds["time"].values, float(ds.attrs.get("settle_time_s", 0.0)),
                         float(ds.attrs.get("steady_after_s", 0.0)))
    steady = masks[WINDOWS.index("steady")]
    return steady if masks[WINDOWS.index("startup")].any() and steady.sum() > 1 else none


def draw_envelope(ax, ds, e, finer: dict, k: int, f: float, steady: bool = False) -> None:
    """An envelope panel of |e| (R, T) in direction ``k`` (shown times ``f``) on the file's output
    grid, with the stored maxima that exceed it (``finer``: :func:`envelope_marks`): over the whole
    run with the steady window's start marked or, with ``steady``, over the steady window alone, on
    axes of its own, where the contact level's start-up impacts (100-1000x larger) do not flatten it."""
    t = ds["time"].values
    keep = steady_samples(ds) if steady else np.ones(t.size, bool)
    draw_abs_envelope(ax, t[keep], e[:, keep] * f, color="k", ls="--", lw=0.8)
    mark_stored_maxima(ax, {w: v for w, v in finer.items() if w == "steady" or not steady}, k, f)
    if steady:
        ax.set_xlim(t[keep][0], t[keep][-1])
    else:
        mark_steady(ax, ds)
    ax.set_ylim(bottom=0)
