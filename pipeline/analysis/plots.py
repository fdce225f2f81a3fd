"""PNG figures of rss6 files: error envelopes, histograms of maxima, Monte Carlo convergence of an
ensemble, and the error histories of a single run (``rss6 simulate -o``).

Every builder returns a matplotlib Figure (tests check its text for overlaps) and the ``plot_*``
functions save them.  Statistics drawn come from :mod:`pipeline.analysis.stats`.  Within a figure each
direction family (translations, rotations) has one unit; the steady window has envelope panels of
its own; a histogram whose spread the level's numerics do not resolve (:func:`resolutions`) is a
note with the common value instead."""
from __future__ import annotations

import textwrap
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["plot_ensemble", "plot_run", "ensemble_figures", "run_figures", "figure_unit", "family_units",
           "draw_abs_envelope", "mark_steady", "mark_stored_maxima", "stored_maxima", "envelope_marks",
           "legend_entries", "draw_envelope", "steady_samples", "Resolution", "resolutions", "closure_gain",
           "output_grid", "figure_title", "save_figure", "plain_ticks", "sensitivity_figures",
           "plot_sensitivity"]

from rss6core import TOL_DISPLACEMENT, TOL_VELOCITY, closure_matrix, parse_scene, rigid_motion  # noqa: E402

from ..files.records import window_label, window_masks, window_reductions  # noqa: E402
from ..vocabulary import DIRECTIONS as _DIRS  # noqa: E402
from ..vocabulary import FAMILIES as _FAMILIES  # noqa: E402
from ..vocabulary import QUANTITIES, WINDOWS  # noqa: E402
from .stats import (MIN_N_MEAN, ensemble_stats, estimates, in_window, quantile_estimates,  # noqa: E402
                    running_mean_interval, windows_of)
from ..vocabulary import CONFIDENCE, FINISHED

_BASE = {"displacement": ("m", "rad"), "velocity": ("m/s", "rad/s"),
         "acceleration": ("m/s$^2$", "rad/s$^2$")}
FAMILIES = tuple(_FAMILIES.values())   # translations, rotations: one unit each per figure


def figure_unit(quantity: str, direction: str, values=None) -> tuple[float, str]:
    """Display factor from SI and unit of a figure axis, suited to the magnitude of ``values``
    (SI): the SI unit (m, m/s, m/s^2; rad, rad/s, rad/s^2) when they reach 1, else its milli-
    unit (mm, mm/s, mm/s^2; mrad, ...).  Without values: the milli-unit."""
    unit = _BASE[quantity][direction not in ("x", "y", "z")]
    peak = np.nanmax(np.abs(values)) if values is not None and np.size(values) else np.nan
    if np.isfinite(peak) and peak >= 1.0:
        return 1.0, unit
    return 1e3, "m" + unit


def _direction_peaks(*values) -> np.ndarray:
    """(direction,) the largest finite |value| per direction over arrays (..., direction), SI;
    NaN where none is finite."""
    peaks = np.full(len(_DIRS), -np.inf)
    for v in values:
        a = np.abs(np.asarray(v, float)).reshape(-1, len(_DIRS))
        peaks = np.maximum(peaks, np.max(np.where(np.isfinite(a), a, -np.inf), axis=0, initial=-np.inf))
    return np.where(np.isfinite(peaks), peaks, np.nan)


def family_units(quantity: str, *values) -> dict[str, tuple[float, str]]:
    """{direction: (factor from SI, unit)} of one figure: one :func:`figure_unit` per direction
    family (FAMILIES), chosen by the family's largest |value| over every array of ``values``
    ((..., direction) SI), so that no two panels of a family show one quantity in two units."""
    peaks, units = _direction_peaks(*values), {}
    for family in FAMILIES:
        p = peaks[[_DIRS.index(d) for d in family]]
        units |= dict.fromkeys(family, figure_unit(quantity, family[0], p[np.isfinite(p)]))
    return units


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


def resolutions(ds, quantity: str) -> dict[str, Resolution]:
    """{direction: Resolution} of a file's level for ``quantity``: round-off (ROUND_OFF) at every
    level but contact (:func:`_contact_resolutions`)."""
    if ds.attrs.get("model") != "contact":
        return dict.fromkeys(_DIRS, Resolution(ROUND_OFF_FLOOR, ROUND_OFF, "round-off"))
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
        return dict.fromkeys(_DIRS, Resolution(ROUND_OFF_FLOOR, 2 * a, f"twice the level's {100 * a:g} % "
                                                                       f"accuracy in {quantity}"))
    if quantity == "acceleration":
        return dict.fromkeys(_DIRS, Resolution(ROUND_OFF_FLOOR, ROUND_OFF, "round-off"))
    eps, base = (TOL_DISPLACEMENT, "m") if quantity == "displacement" else (TOL_VELOCITY, "m/s")
    what = f"Newton's {_si(eps, base)} tolerance"
    if adaptive:
        eps, what = sim.contact_tolerance, f"{_si(sim.contact_tolerance, 'm')} contact tolerance"
    gains = dict(zip(_DIRS, closure_gain(scene)))
    return {d: Resolution(2 * g * eps, ROUND_OFF, f"twice the {what} through the legs' closure, "
                                                  f"x {g:.2g}" + ("" if d in FAMILIES[0] else " rad/m"))
            for d, g in gains.items()}


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
    the finished realisations (``sds``: :func:`pipeline.analysis.stats.ensemble_stats`, every window)."""
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


def _envelope(ds, q: str, finished, sds):
    """|q error| envelopes per direction over the whole run and, where the file has a steady
    window, over that window alone on axes of its own (a block of panels per view)."""
    err = ds["error"].sel(quantity=q).transpose("realization", "time", "direction").values[finished]
    stored, finer = envelope_marks(ds, sds, q, err)
    units = family_units(q, err, *stored.values())
    views = ["whole"] + (["steady"] if steady_samples(ds).any() else [])
    fig, axes = plt.subplots(2 * len(views), 3, figsize=(13, 1 + 5.5 * len(views)), constrained_layout=True)
    fig.suptitle(figure_title(f"|{q} error| envelope over realisations", ds, err.shape[0]))
    t_s = float(ds.attrs.get("steady_after_s", np.nan))
    for i, view in enumerate(views):
        for k, (ax, d) in enumerate(zip(axes.ravel()[6 * i:6 * i + 6], _DIRS)):
            f, unit = units[d]
            draw_envelope(ax, ds, err[..., k], finer, k, f, steady=view == "steady")
            ax.set(xlabel="time [s]", ylabel=f"|{d} error| [{unit}]",
                   title=d if view == "whole" else f"{d}, {window_label('steady', t_s)}")
            ax.grid(alpha=0.3)
            plain_ticks(ax)
    _figure_legend(fig, axes.ravel())
    return fig


def _peaks(ds, q: str, finished, window: str = "whole") -> np.ndarray:
    return in_window(ds, window)["max_abs_error"].sel(quantity=q).transpose(
        "realization", "direction").values[finished]


def _histograms(ds, q: str, finished, sds):
    """Histograms of the per-realisation maxima, a 2 x 3 block of directions per analysis window
    (startup above steady; the whole run's where the file has no windows), each panel on its own
    x range (the contact level's startup maxima exceed the steady ones a hundredfold) in one unit
    per direction family; a panel whose spread the level's numerics do not resolve says so."""
    peaks = {w: _peaks(ds, q, finished, w) for w in _marked_windows(ds)}      # (R, 6) each
    peaks = {w: p for w, p in peaks.items() if np.isfinite(p).any()} or {"whole": _peaks(ds, q, finished)}
    units, res = family_units(q, *peaks.values()), resolutions(ds, q)
    fig, axes = plt.subplots(2 * len(peaks), 3, figsize=(13, 1 + 5.5 * len(peaks)), constrained_layout=True)
    fig.suptitle(figure_title(f"per-realisation max |{q} error| per analysis window", ds, int(finished.sum())))
    t_s = float(ds.attrs.get("steady_after_s", np.nan))
    for i, (w, peak) in enumerate(peaks.items()):
        for k, (ax, d) in enumerate(zip(axes.ravel()[6 * i:6 * i + 6], _DIRS)):
            panel = _Panel(q, d, w, i, units[d], res[d], window_label(w, t_s))
            _histogram_panel(ax, peak[:, k], in_window(sds, w)["max_abs_error"].sel(
                statistic="q95", quantity=q, direction=d), panel)
    fig.supxlabel(_histogram_key(t_s, sds), fontsize=9)
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
    if np.ptp(x) <= panel.resolution.limit(np.max(x)):
        _unresolved_note(ax, x, panel)
        return
    x = x * f
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


def _unresolved_note(ax, x, panel: _Panel) -> None:
    """In place of a histogram of maxima ``x`` (R,) SI whose spread is within the level's
    resolution (a histogram of numerical noise): how many agree to what, and their median, its
    last digit of the resolution's order."""
    (f, unit), res = panel.unit, panel.resolution
    limit, base = res.limit(np.max(x)), _BASE[panel.quantity][panel.direction not in FAMILIES[0]]
    decimals = max(0, int(-np.floor(np.log10(limit * f))))
    value = f"{np.median(x) * f:.{decimals}f} {unit}"
    text = [f"all {x.size} realisations agree within {_si(limit, base)}", f"({res.source}):", value,
            f"spread {_si(np.ptp(x), base)}, below what the level resolves: no histogram"]
    if x.size == 1:
        text = ["one realisation:", value]
    ax.text(0.5, 0.5, "\n".join(textwrap.fill(line, 46) for line in text), transform=ax.transAxes,
            ha="center", va="center", fontsize=9, gid="within resolution")
    ax.set(xticks=[], yticks=[], ylabel="")


def _si(value: float, unit: str) -> str:
    """``value`` (SI, in ``unit``) with the SI prefix that puts it in [1, 1000), 3 digits: '20 nm'."""
    prefixes = ((1.0, ""), (1e-3, "m"), (1e-6, "µ"), (1e-9, "n"), (1e-12, "p"))
    scale, prefix = next((p for p in prefixes if abs(value) >= p[0]), prefixes[0 if value == 0 else -1])
    return f"{value / scale:.3g} {prefix}{unit}"


def _mark_q95(ax, cell, f: float, i: int, window: str) -> None:
    """A dashed line at the q95 estimate of ``cell`` (bound: estimate, lower, upper; SI, shown times
    ``f``) and, only where pipeline.analysis.stats gives one, its interval as a capped bar above the bars."""
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


def _convergence(ds, q: str, finished, confidence: float = CONFIDENCE):
    peak = _peaks(ds, q, finished)
    n = np.arange(1, peak.shape[0] + 1)
    iid = str(ds.attrs.get("sampler", "mc")) == "mc"   # a QMC prefix has no running iid interval
    units = family_units(q, peak)
    fig, axes = _grid(figure_title(f"running mean of max |{q} error| (whole run) with its "
                                   f"{100 * confidence:g} % interval (given from n = {MIN_N_MEAN})"
                                   if iid else f"running mean of max |{q} error| (whole run, randomised "
                                   "QMC: intervals from the replicates, rss6 stats)",
                                   ds, peak.shape[0]))
    for k, (ax, d) in enumerate(zip(axes, _DIRS)):
        f, unit = units[d]
        mean, (lo, hi) = running_mean_interval(peak[:, k] * f, confidence)
        has = np.isfinite(lo) & np.isfinite(hi) & iid
        if has.any():
            ax.fill_between(n[has], lo[has], hi[has], alpha=0.3, lw=0,
                            label=f"{100 * confidence:g} % interval")
        ax.plot(n, mean, lw=1.2, marker="." if n.size <= 30 else None, label="running mean")
        ax.set(xlabel="realisations n", ylabel=f"mean max |{d} error| [{unit}]", title=d)
        ax.set_xlim(0.5, n[-1] + 0.5)
        ax.set_ylim(*_convergence_range(mean, lo[has], hi[has]))
        ax.grid(alpha=0.3)
        plain_ticks(ax)
        ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))   # counts
    axes[0].legend(fontsize=8, loc="best")
    return fig


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


def _history(ds, q: str, sds):
    """One run's signed error history per direction, sampled on the output grid, with the stored
    maxima marked where they exceed what the samples show."""
    err = ds["error"].sel(quantity=q).transpose("time", "direction").values       # (T, 6)
    t = ds["time"].values
    stored = stored_maxima(ds, sds, q)
    finer = _finer_maxima(ds, t, err, stored)
    units = family_units(q, err, *stored.values())
    fig, axes = _grid(figure_title(f"{q} error history (actual minus ideal rigid motion)", ds))
    for k, (ax, d) in enumerate(zip(axes, _DIRS)):
        f, unit = units[d]
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
