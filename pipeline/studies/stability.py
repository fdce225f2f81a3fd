"""Where methods fail (``rss6 stability``): time-step sweeps per level, integrator and contact stiffness.

Each sweep runs the same realisations (same seed) at a range of steps (pipeline.studies.setting)
and classifies every step as stable, inaccurate or failed against the sweep's finest step; an
explicit sweep brackets the central-difference limit 2/omega_max of the undamped robot.
"""
from __future__ import annotations

import dataclasses
import textwrap
import time

import numpy as np
import xarray as xr

from rss6core import (MODELS, Integrator, build_elastic_model, default_integrator, default_time_step,
                      max_link_modes, models_with, natural_frequencies, quasi_static_state, simulate_elastic)

from ..files.records import error_summaries
from ..vocabulary import FINISHED, QUANTITIES, STEP_WORDS, step_measured
from .setting import Setting, _adaptive, _contact_step, _dividing, load_compiled_kernels, measure, relative_errors

__all__ = ["stability", "write_stability", "stability_figure", "summary_lines"]


def _horizon(scene, duration: float):
    return dataclasses.replace(scene, trajectory=dataclasses.replace(scene.trajectory, duration=duration))


def _explicit_limit(scene) -> float:
    """2/omega_max (s): the central-difference limit of the undamped elastic model at t = 0."""
    return 2.0 / natural_frequencies(scene)[-1]


def _classify(run: dict, ref: dict, tolerance: float, growth: float = 10.0) -> tuple[str, str, float]:
    """stable / inaccurate / failed, the reason, and the largest relative change vs the finest step."""
    change = float(np.nanmax(relative_errors(run["statistics"], ref["statistics"])))
    if run["failed"]:
        return "failed", run["message"], change
    if not np.all(np.isfinite(run["statistics"])):
        return "failed", "non-finite state", change
    if np.nanmax(run["statistics"][..., 0] / np.maximum(ref["statistics"][..., 0], 1e-300)) > growth:
        return "failed", f"energy growth: error peaks over {growth:g} x the finest step's", change
    if change > tolerance:
        return "inaccurate", f"statistics change {100 * change:.1f} % vs the finest step", change
    return "stable", "", change


def stability(scene, tolerance: float = 0.05, n: int = 2, seed: int = 0, horizon: float = 0.2,
              explicit_steps: int = 400, log=print) -> xr.Dataset:
    """Time-step sweeps per level and integrator (and contact stiffness) as a Dataset like
    :func:`tradeoff`: the stability map (dimension ``run``) and each sweep's measured limits
    (dimension ``sweep``).  Implicit sweeps cover min(duration, horizon) for the contact level and
    the whole trajectory otherwise; the explicit sweep ``explicit_steps`` steps around 2/omega_max."""
    dt = {m: default_time_step(scene, m) for m in MODELS}       # s, by level
    ig_paper, ig_contact = default_integrator(scene, "paper"), default_integrator(scene, "contact")
    el = scene.simulation.elements_per_link
    short = _horizon(scene, min(scene.trajectory.duration, horizon))
    limit = _explicit_limit(scene)
    rows = []

    def sweep(sc, level, integrator, steps, scale=1.0, n_real=n, adaptive=(0.0, 0)):
        runs = {h: measure(sc, Setting(level, integrator, h, el, scale, *adaptive), n_real, seed)
                for h in steps}
        name = integrator + (f" adaptive {adaptive[0]:g} m, {adaptive[1]} halvings" if adaptive[1] else "")
        rows.extend(_rows(runs, level, name, scale, sc.trajectory.duration, tolerance, log,
                          lambda h: f"dt {h:.3g} s K x{scale:g}"))

    T = scene.trajectory.duration

    def steps(total, hs):
        return sorted({_dividing(total, h) for h in hs})

    for ig in ("newmark", "hht", "generalized-alpha"):
        sweep(scene, "elastic", ig, steps(T, [f * dt["elastic"] for f in (16.0, 8.0, 4.0, 2.0, 1.0, 0.5)]),
              n_real=1)
    rows.extend(_explicit_sweep(scene, limit, explicit_steps, tolerance, seed, log))
    reduced = _reduced_links(scene)
    if reduced is not None:    # the reduction drops the element-scale modes: a larger explicit limit
        rows.extend(_explicit_sweep(reduced, _explicit_limit(reduced), explicit_steps, tolerance, seed, log,
                                    f", Craig-Bampton {reduced.beam.link_modes} modes"))
    sweep(scene, "paper", ig_paper, steps(T, [f * dt["paper"] for f in (2.0, 1.0, 0.5, 0.25)]))
    contact_steps = sorted({_contact_step(scene, f * dt["contact"]) for f in (8.0, 4.0, 2.0, 1.0, 0.5)})
    load_compiled_kernels(short, [Setting("contact", ig_contact, contact_steps[-1], el)], seed)
    for ig in (ig_contact, "newmark"):
        for scale in (1.0, 10.0):
            sweep(short, "contact", ig, contact_steps, scale)
    # the adaptive step from the same base steps: where Newton fails it halves the step instead
    adaptive = _adaptive(scene)
    for scale in (1.0, 10.0):
        sweep(short, "contact", ig_contact, contact_steps, scale, adaptive=adaptive)
    return _stability_dataset(rows, limit, tolerance, n, seed, scene, horizon)


STABILITY_LINK_MODES = 4   # Craig-Bampton modes per link of the reduced explicit sweep


def _reduced_links(scene):
    """The scene with STABILITY_LINK_MODES Craig-Bampton modes per link, or None if it reduces its links
    already or its mesh cannot."""
    if scene.beam.link_modes or STABILITY_LINK_MODES > max_link_modes(scene.simulation.elements_per_link):
        return None
    return dataclasses.replace(scene, beam=dataclasses.replace(scene.beam, link_modes=STABILITY_LINK_MODES))


def _explicit_sweep(scene, limit, steps, tolerance, seed, log, variant: str = ""):
    """Central differences around 2/omega_max on the undamped robot, every mode excited.

    2/omega_max is the undamped limit; with the scene's stiffness-proportional damping the step
    matrix holds lambda_2 K (the damping is treated implicitly), which moves the limit.  The run
    starts from the quasi-static state plus a seeded random velocity of 1e-6 m/s (rad/s) scale and
    lasts ``steps`` quarter-limit steps; it fails when the elastic displacement passes 1 mm.
    ``variant`` names the model in the integrator column (a reduced-link sweep's own limit).
    """
    still = dataclasses.replace(_horizon(scene, steps * 0.25 * limit), damping=dataclasses.replace(
        scene.damping, mass_coefficient=0.0, stiffness_coefficient=0.0))
    model = build_elastic_model(still, scene.simulation.elements_per_link)
    d, v, a = quasi_static_state(still, model)
    v = v + np.random.default_rng(seed).normal(size=v.shape) * 1e-6
    H = still.trajectory.duration
    runs = {}
    for h in sorted({_dividing(H, f * limit) for f in (0.25, 0.5, 0.9, 0.97, 1.03, 1.1, 1.5)}):
        start = time.perf_counter()
        r = simulate_elastic(still, model.elements, Integrator.central_difference(), h, model=model,
                             initial=(d, v, a), divergence_limit=1e-3)
        peaks = error_summaries(r)[0]
        runs[h] = {"statistics": np.stack([peaks, peaks], -1), "failed": int(r.status != FINISHED),
                   "message": r.message, "seconds_per_realization": time.perf_counter() - start}
    return _rows(runs, "elastic", "central-difference (undamped)" + variant, 1.0, H, tolerance, log,
                 lambda h: f"dt {h:.4g} s = {h / limit:.3f} x 2/omega_max")


def _rows(runs: dict, level, integrator, scale, horizon, tolerance, log, describe) -> list[dict]:
    """Rows of the stability map for one sweep {step: measured run}, each classified against the
    sweep's finest step; ``describe(step)`` names the step in the log line."""
    ref = runs[min(runs)]
    rows = []
    for h in sorted(runs):
        status, reason, change = _classify(runs[h], ref, tolerance)
        rows.append({"level": level, "integrator": integrator, "dt_s": h, "stiffness_scale": scale,
                     "horizon_s": horizon, "status": status, "reason": reason,
                     "max_rel_change": change if np.isfinite(change) else 1e300,
                     "seconds_per_realization": runs[h]["seconds_per_realization"],
                     "velocity_mean_peak": float(np.nanmax(runs[h]["statistics"][1, :3, 0]))})
        log(f"  {level} {integrator} {describe(h)}: {_row_words(status, reason, h == min(runs))}")
    return rows


def _row_words(status: str, reason: str, reference: bool) -> str:
    """A row's verdict for the log: the finest step is the reference the others are judged against, so a
    stable one is called that (it is accurate only against itself); a reason follows its verdict after ':'."""
    if reference and status == "stable":
        return "reference (the finest step, which the others are compared with)"
    return status + (f": {reason}" if reason else "") + (" (the reference)" if reference else "")


_RUN_VARIABLES = {   # name: (CSV column, attributes)
    "level": ("level", {"long_name": "model level"}),
    "integrator": ("integrator", {"long_name": "time integrator (and adaptive step)"}),
    "dt_s": ("dt_s", {"units": "s", "long_name": "time step"}),
    "stiffness_scale": ("stiffness_scale", {"units": "1", "long_name": "contact stiffness factor"}),
    "horizon_s": ("horizon_s", {"units": "s", "long_name": "simulated time"}),
    "status": ("status", {"long_name": "stable, inaccurate or failed"}),
    "max_rel_change": ("max_rel_change", {"units": "1", "long_name": "largest relative change of "
                                          "the statistics vs the sweep's finest step"}),
    "seconds_per_realization": ("seconds_per_realization", {"units": "s", "long_name": "wall time per "
                                                                       "realisation, batched"}),
    "velocity_mean_peak": ("velocity_mean_peak_m_s", {
        "units": "m s-1", "long_name": "mean over realisations of max |velocity error|, largest "
                                       "of x, y, z"}),
    "reason": ("reason", {"long_name": "why not stable"}),
}
_LIMITS = ("largest_not_failed", "smallest_failed", "largest_accurate")
_LIMIT_NAMES = {"largest_accurate": "largest time step coarser than the sweep's finest (the reference) within "
                                    "the tolerance of it"}


def _stability_dataset(rows: list[dict], limit: float, tolerance, n, seed, scene,
                       horizon: float = 0.2) -> xr.Dataset:
    """The sweeps' rows as variables along ``run`` and each sweep's limits (s, NaN: none) along
    ``sweep``."""
    ds = xr.Dataset({k: ("run", [r[k] for r in rows], attrs) for k, (_, attrs) in _RUN_VARIABLES.items()})
    ds["sweep_name"] = ("run", [_sweep_name(r["level"], r["integrator"], r["stiffness_scale"])
                                for r in rows])
    names = list(dict.fromkeys(ds["sweep_name"].values))
    for lim in _LIMITS:
        ds[f"{lim}_s"] = ("sweep", [_limit(ds, name, lim) for name in names],
                          {"units": "s", "long_name": _LIMIT_NAMES.get(lim, lim.replace("_", " ") + " time step")
                           + " (NaN: none)"})
    ds = ds.assign_coords(sweep=names)
    ds.attrs = {"title": f"rss6 time-step stability map, scene {scene.name!r}",
                "history": f"rss6 stability {scene.name} --tolerance {tolerance:g} -n {n} --seed {seed} "
                           f"--horizon {horizon:g}",
                "central_difference_limit_s": limit, "tolerance": tolerance, "realizations": n,
                "seed": seed, "scene_name": scene.name, "scene_toml": scene.source_text}
    return ds


def _sweep_name(level, integrator, scale) -> str:
    return f"{level} {integrator}" + (f" K x{scale:g}" if scale != 1.0 else "")


def _limit(ds, name: str, which: str) -> float:
    """Per sweep: the largest step not failed, the smallest failed one, the largest stable one coarser than
    the finest (the reference, stable against itself only)."""
    sel = ds["sweep_name"].values == name
    status, dt = ds["status"].values[sel], ds["dt_s"].values[sel]
    pick = {"largest_not_failed": (status != "failed", np.max),
            "smallest_failed": (status == "failed", np.min),
            "largest_accurate": ((status == "stable") & (dt > dt.min()), np.max)}[which]
    return float(pick[1](dt[pick[0]])) if pick[0].any() else np.nan


def summary_lines(ds: xr.Dataset) -> list[str]:
    """Per sweep: its reference (finest) step, the largest not failed, the smallest failed, and the largest
    step within the tolerance of the reference; at a level whose statistics measure the step, that none can be."""
    tolerance = f"{100 * ds.attrs['tolerance']:g} %"
    lines = []
    for name in ds["sweep"].values:
        sel = ds["sweep_name"].values == name
        level, reference = ds["level"].values[sel][0], float(ds["dt_s"].values[sel].min())
        step = {lim: float(ds[f"{lim}_s"].sel(sweep=name)) for lim in _LIMITS}
        parts = [f"reference {reference:.3g} s"] + [
            f"{lim.replace('_', ' ')} " + (f"{step[lim]:.3g} s" if np.isfinite(step[lim]) else "-")
            for lim in ("largest_not_failed", "smallest_failed")]
        accurate = step["largest_accurate"]
        if measured := step_measured(level, QUANTITIES):
            parts.append(f"no step named accurate: its {' and '.join(measured)} errors {STEP_WORDS} (they do not "
                         "converge with the step)")
        elif np.isfinite(accurate):
            parts.append(f"largest step within {tolerance} of the reference's statistics {accurate:.3g} s")
        else:
            parts.append(f"none coarser than the reference is within {tolerance}")
        lines.append(f"{name}: " + ", ".join(parts))
    return lines


def write_stability(ds: xr.Dataset, outdir) -> None:
    """DIR/stability.csv (one line per run, from the Dataset), DIR/stability.nc, DIR/stability.png."""
    from pathlib import Path

    from ..files.writing import write_netcdf
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    table = ds[list(_RUN_VARIABLES)].to_dataframe()
    table.insert(table.columns.get_loc("status") + 1, "stable",
                 (table["status"] != "failed").astype(int))
    table = table.rename(columns={k: col for k, (col, _) in _RUN_VARIABLES.items()})
    table.to_csv(out / "stability.csv", index=False, float_format="%.6g")
    write_netcdf(ds, out / "stability.nc")
    _plot_stability(ds, out / "stability.png")


def _plot_stability(ds, path) -> None:
    from ..analysis.plot_common import save_figure
    save_figure(stability_figure(ds), path)


def stability_figure(ds):
    """Per sweep the status of every step, and the paper level's error against the step
    (:func:`_redrawn_panel`)."""
    from matplotlib.ticker import NullFormatter

    from ..analysis.plot_common import plt   # the Agg backend, set once there
    colour = {"stable": "tab:green", "inaccurate": "tab:orange", "failed": "tab:red"}
    level, status, dt = ds["level"].values, ds["status"].values, ds["dt_s"].values
    names = ds["sweep_name"].values
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.5), constrained_layout=True,
                             gridspec_kw={"width_ratios": [1.2, 1.2, 1]})
    for ax, lv in zip(axes[:2], ("elastic", "contact")):
        keys = list(dict.fromkeys(names[level == lv]))
        for y, key in enumerate(keys):
            sel = names == key
            ax.scatter(dt[sel], np.full(sel.sum(), y), c=[colour[s] for s in status[sel]], s=60)
        ax.set_yticks(range(len(keys)))
        ax.set_yticklabels([textwrap.fill(k.removeprefix(f"{lv} "), 18) for k in keys], fontsize=8)
        ax.set_ylim(-0.5, max(len(keys), 1) - 0.5)
        ax.set(xscale="log", xlabel="time step [s]")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(f"{lv} level: status per step", fontsize=10)
        ax.grid(True, which="both", lw=0.3)
    axes[0].axvline(ds.attrs["central_difference_limit_s"], color="k", ls="--", lw=0.8,
                    label="2/omega_max")
    for st, c in colour.items():
        axes[0].scatter([], [], color=c, label=st)
    fig.legend(*axes[0].get_legend_handles_labels(), fontsize=8, loc="outside lower center",
               ncol=4)
    _redrawn_panel(axes[2], ds)
    fig.suptitle(f"time-step stability: scene {ds.attrs.get('scene_name', '?')}, elastic, contact "
                 f"and paper levels, n = {ds.attrs.get('realizations')} per step, tolerance "
                 f"{100 * ds.attrs.get('tolerance', float('nan')):g} %", fontsize=10)
    return fig


def _redrawn_panel(ax, ds) -> None:
    """The error against the step of the level that redraws its clearances every step (the paper
    level), which grows as 1/dt: its offsets are white noise whose difference quotient is of
    order clearance / step."""
    from matplotlib.ticker import NullFormatter
    (name,) = models_with("redraws_every_step")
    dt = ds["dt_s"].values
    redrawn = ds["level"].values == name
    order = np.argsort(dt[redrawn])
    h, v = dt[redrawn][order], ds["velocity_mean_peak"].values[redrawn][order]
    ax.loglog(h, v * 1e3, "o-", color="tab:orange", label=f"{name} level")
    if len(h):
        ax.loglog(h, v[0] * 1e3 * h[0] / h, "k:", lw=0.8, label="proportional to 1/dt")
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("time step [s]")
    ax.set_ylabel("mean over realisations of max |velocity error|,\nlargest of x, y, z [mm/s]")
    ax.set_title(f"{name} level: error against time step", fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(True, which="both", lw=0.3)
