"""Speed against accuracy (``rss6 tradeoff``) and where methods fail (``rss6 stability``).

Both run the same realisations (same seed) for many settings (model level,
integrator, time step, elements per link, beam theory) and compare the ensemble statistics
users query, per quantity and direction: the mean and the 95 % quantile over
realisations (pipeline.analysis.estimators.estimates) of each realisation's max |error| (as
stored in ensemble files: after the scene's settle time, over every internal
step for the contact level).  Relative errors are taken against a reference setting, with a floor
of 0.1 % of the largest translation (rotation) statistic of that quantity so
that a near-zero component cannot dominate.
"""
from __future__ import annotations

import dataclasses
import textwrap
import time
from dataclasses import dataclass

import numpy as np
import xarray as xr

from rss6core import (BeamTheory, Integrator, build_elastic_model, degrees_of_freedom, natural_frequencies,
                      quasi_static_state, simulate_batch, simulate_elastic)

from ..analysis.estimators import estimates
from ..files.records import error_summaries
from ..files.schema import MIXED_UNITS, _unit_table
from ..vocabulary import DIRECTIONS, FINISHED, QUANTITIES

__all__ = ["Setting", "TRADEOFF_STATISTICS", "measure", "relative_errors", "default_settings", "tradeoff",
           "pareto_front", "recommend", "write_tradeoff", "stability", "write_stability"]

TRADEOFF_STATISTICS = ("mean", "q95")
RELATIVE_FLOOR = 1e-3


@dataclass(frozen=True)
class Setting:
    """One way to compute the ensemble: model level, integrator, time step (s), elements per link,
    beam theory (None: the scene's); for the contact level also the adaptive step's tolerance
    (m, 0: fixed step) and refinements."""
    model: str
    integrator: str
    dt: float
    elements: int
    stiffness_scale: float = 1.0
    tolerance: float = 0.0
    refinements: int = 0
    beam: BeamTheory | None = None

    @property
    def label(self) -> str:
        extra = f", K x{self.stiffness_scale:g}" if self.stiffness_scale != 1.0 else ""
        if self.beam is not None:
            extra += f", {self.beam.label}"
        if self.refinements:
            extra += (f", adaptive {self.tolerance:g} m down to "
                      f"{self.dt / 2 ** self.refinements * 1e6:g} us")
        if self.model in ("rigid", "quasi-static"):
            return f"{self.model} {self.dt * 1e3:g} ms"
        return f"{self.model} {self.integrator} {self.dt * 1e3:g} ms {self.elements} el{extra}"


def _scene_for(scene, setting: Setting):
    if setting.beam is not None and setting.beam != scene.beam:
        scene = dataclasses.replace(scene, beam=setting.beam)
    if setting.stiffness_scale == scene.contact.stiffness_scale:
        return scene
    return dataclasses.replace(scene, contact=dataclasses.replace(
        scene.contact, stiffness_scale=setting.stiffness_scale))


def measure(scene, setting: Setting, n: int, seed: int = 0) -> dict:
    """Run realisations 0..n-1 of ``setting`` as one batch: seconds per realisation, the ensemble
    statistics (quantity, direction, statistic) in SI units, failures and their first message."""
    start = time.perf_counter()
    results = simulate_batch(_scene_for(scene, setting), setting.model, setting.integrator, setting.dt,
                             setting.elements, seed, range(n), setting.tolerance, setting.refinements)
    wall = (time.perf_counter() - start) / n
    peaks = np.stack([error_summaries(r, scene.simulation.settle_time)[0] for r in results])  # (n, 3, 6)
    failed = [r for r in results if r.status != FINISHED]
    stats = estimates(peaks, TRADEOFF_STATISTICS)            # (3, 6, statistic), failed runs left out
    return {"seconds_per_realization": wall, "statistics": stats, "failed": len(failed),
            "message": failed[0].message if failed else ""}


def relative_errors(stats: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """|stat - ref| / max(|ref|, floor) per (quantity, direction, statistic); see the module doc."""
    ref = np.abs(reference)
    floor = np.empty_like(ref)
    for group in (slice(0, 3), slice(3, 6)):          # translations, rotations
        floor[:, group] = RELATIVE_FLOOR * ref[:, group].max(axis=1, keepdims=True)
    return np.abs(stats - reference) / np.maximum(ref, np.maximum(floor, 1e-300))


def _dividing(total: float, h: float) -> float:
    """The step nearest ``h`` that divides ``total`` into whole steps."""
    return total / max(1, round(total / h))


def _contact_step(scene, h: float) -> float:
    """The contact step nearest ``h`` that the output step is a whole multiple of (or a multiple of it)."""
    dt = scene.simulation.time_step
    return _dividing(dt, h) if h <= dt else dt * round(h / dt)


def _refine(setting: Setting) -> Setting:
    """Step halved and mesh doubled; an adaptive step's tolerance / 8 as well, since the local
    error estimate it bounds scales as h^3 where the acceleration is smooth."""
    return dataclasses.replace(setting, dt=setting.dt / 2, elements=2 * setting.elements,
                               tolerance=setting.tolerance / 8)


ADAPTIVE_TOLERANCE = 1e-8   # m, the adaptive rows' tolerance for scenes that set none
ADAPTIVE_REFINEMENTS = 4


def _adaptive(scene) -> tuple[float, int]:
    """The scene's adaptive contact step (tolerance m, refinements), or the defaults where it sets none."""
    sim = scene.simulation
    return sim.contact_tolerance or ADAPTIVE_TOLERANCE, sim.contact_refinements or ADAPTIVE_REFINEMENTS


def default_settings(scene) -> tuple[list[Setting], Setting]:
    """The settings compared by default, and the reference: the contact level's adaptive step at a
    hundredth of the tolerance, down to a quarter of the finest adaptive row's smallest step, on a
    mesh twice the scene's (impact peaks excite the links' higher modes)."""
    sim = scene.simulation
    dt, dtc, el = sim.time_step, sim.contact_time_step, sim.elements_per_link
    ig, igc = sim.integrator, sim.contact_integrator
    tol, levels = _adaptive(scene)
    half = max(1, el // 2)
    out = [Setting("quasi-static", "newmark", dt, el)]
    out += [Setting("elastic", i, dt, el) for i in ("newmark", "hht", "generalized-alpha")]
    out += [Setting("elastic", ig, dt, half), Setting("elastic", ig, dt / 2, el)]
    out += [Setting("paper", ig, dt, el), Setting("paper", ig, dt / 2, el)]
    out += [Setting("contact", igc, _contact_step(scene, f * dtc), el) for f in (2.0, 1.0, 0.5, 0.25)]
    out += [Setting("contact", igc, dtc, half), Setting("contact", "newmark", dtc, el)]
    out += [Setting("contact", igc, dtc, el, 1.0, f * tol, levels) for f in (4.0, 1.0, 0.25)]
    out += [Setting("contact", igc, dtc, m, 1.0, tol, levels) for m in (half, 2 * el)]
    other = BeamTheory("euler-bernoulli" if scene.beam.theory == "timoshenko" else "timoshenko",
                       not scene.beam.rotary_inertia)
    out += [Setting("elastic", ig, dt, el, beam=other), Setting("contact", igc, dtc, el, 1.0, tol, levels,
                                                                 beam=other)]
    reference = Setting("contact", igc, _contact_step(scene, dtc / 2), 2 * el, 1.0, tol / 100, levels + 2)
    return out + [reference], reference


def tradeoff(scene, n: int, seed: int = 0, settings=None, reference: Setting | None = None,
             log=print) -> xr.Dataset:
    """Cost and error of every setting against the reference; the reference's own convergence
    (its step halved and mesh doubled) is measured and stored in the attributes."""
    if settings is None:
        settings, reference = default_settings(scene)
    reference = reference or settings[-1]
    if reference not in settings:
        settings = list(settings) + [reference]
    runs = {}
    for s in settings:
        runs[s] = measure(scene, s, n, seed)
        log(f"  {s.label}: {runs[s]['seconds_per_realization']:.3g} s per realisation"
            + (f", {runs[s]['failed']} failed" if runs[s]["failed"] else ""))
    check = _refine(reference)
    fine = measure(scene, check, n, seed)
    log(f"  reference check ({check.label}): {fine['seconds_per_realization']:.3g} s per realisation")
    ref = runs[reference]["statistics"]
    rel = np.stack([relative_errors(runs[s]["statistics"], ref) for s in settings])
    convergence = relative_errors(ref, fine["statistics"])
    ds = xr.Dataset(
        {"model": ("setting", [s.model for s in settings], {"long_name": "model level"}),
         "integrator": ("setting", [s.integrator for s in settings], {"long_name": "time integrator"}),
         "dt": ("setting", [s.dt for s in settings], {"units": "s", "long_name": "time step"}),
         "elements_per_link": ("setting", [s.elements for s in settings],
                               {"units": "1", "long_name": "beam elements per crank and per rod"}),
         "beam_theory": ("setting", [(s.beam or scene.beam).label for s in settings],
                         {"long_name": "beam theory of the links"}),
         "stiffness_scale": ("setting", [s.stiffness_scale for s in settings],
                             {"units": "1", "long_name": "contact stiffness factor"}),
         "tolerance": ("setting", [s.tolerance for s in settings],
                       {"units": "m", "long_name": "adaptive contact step's local error bound "
                                                    "(0: fixed step)"}),
         "refinements": ("setting", [s.refinements for s in settings],
                         {"units": "1", "long_name": "halvings of the contact step allowed"}),
         "seconds_per_realization": ("setting", [runs[s]["seconds_per_realization"] for s in settings],
                                     {"units": "s", "long_name": "wall time per realisation, batched"}),
         "failed": ("setting", [runs[s]["failed"] for s in settings],
                    {"units": "1", "long_name": "failed realisations"}),
         "statistic_value": (("setting", "quantity", "direction", "statistic"),
                             np.stack([runs[s]["statistics"] for s in settings]),
                             {"long_name": "statistic of the setting's ensemble", "units": MIXED_UNITS}),
         "relative_error": (("setting", "quantity", "direction", "statistic"), rel,
                            {"units": "1", "long_name": "relative error of the statistic against the "
                                                        "reference setting's"}),
         "reference_change": (("quantity", "direction", "statistic"), convergence,
                              {"units": "1", "long_name": "reference vs its step halved and mesh "
                                                          "doubled"})},
        coords={"setting": ("setting", [s.label for s in settings], {"long_name": "setting"}),
                "quantity": list(QUANTITIES), "direction": list(DIRECTIONS), "statistic": list(TRADEOFF_STATISTICS),
                "unit": (("quantity", "direction"), _unit_table(), {"long_name": "SI unit of each element"})},
        attrs={"title": f"rss6 speed/accuracy trade-off, scene {scene.name!r}",
               "history": f"rss6 tradeoff {scene.name} -n {n} --seed {seed}",
               "reference": reference.label, "reference_check": check.label,
               "reference_check_seconds_per_realization": fine["seconds_per_realization"],
               "realizations": n, "seed": seed, "scene_name": scene.name, "scene_toml": scene.source_text,
               "settle_time_s": scene.simulation.settle_time})
    ds["max_relative_error"] = ds["relative_error"].max(("quantity", "direction", "statistic"))
    ds["max_relative_error"].attrs.update(units="1", long_name="largest relative_error of the setting")
    ds["modes"] = ("setting", [degrees_of_freedom(scene, s.model, s.elements) for s in settings],
                   {"units": "1", "long_name": "modes kept (no modal reduction is offered: all DOFs)"})
    return ds


def pareto_front(cost: np.ndarray, error: np.ndarray) -> np.ndarray:
    """Indices of the settings no other setting beats in both cost and error, by cost."""
    order = np.argsort(cost, kind="stable")
    front, best = [], np.inf
    for i in order:
        if error[i] < best:
            front.append(i)
            best = error[i]
    return np.array(front, int)


def recommend(ds: xr.Dataset, tolerance: float) -> dict:
    """The cheapest setting (not the reference) whose every statistic is within ``tolerance``."""
    cost, err = ds["seconds_per_realization"].values, ds["max_relative_error"].values
    ok = (err <= tolerance) & (ds["failed"].values == 0) & (ds["setting"].values != ds.attrs["reference"])
    ref = int(np.flatnonzero(ds["setting"].values == ds.attrs["reference"])[0])
    if not ok.any():
        return {"setting": None, "reference": ds.attrs["reference"], "tolerance": tolerance,
                "best_error": float(np.nanmin(np.where(ds["setting"].values != ds.attrs["reference"],
                                                         err, np.nan)))}
    i = int(np.flatnonzero(ok)[np.argmin(cost[ok])])
    return {"setting": str(ds["setting"].values[i]), "reference": ds.attrs["reference"],
            "tolerance": tolerance, "max_relative_error": float(err[i]),
            "seconds_per_realization": float(cost[i]), "speedup_vs_reference": float(cost[ref] / cost[i])}


def _columns() -> list[str]:
    return [f"rel_err_{q}_{d}_{s}" for q in QUANTITIES for d in DIRECTIONS for s in TRADEOFF_STATISTICS]


def write_tradeoff(ds: xr.Dataset, outdir, tolerance: float) -> dict:
    """DIR/tradeoff.csv, DIR/tradeoff.nc and DIR/tradeoff.png; returns the recommendation."""
    from pathlib import Path

    from ..files.writing import write_netcdf
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    header = ["setting", "model", "integrator", "dt_s", "elements_per_link", "beam_theory", "modes",
              "stiffness_scale",
              "tolerance_m", "refinements", "seconds_per_realization", "failed", "max_rel_error"] + _columns()
    rows = []
    for i in range(ds.sizes["setting"]):
        rel = ds["relative_error"].values[i].reshape(-1)
        rows.append([str(ds["setting"].values[i]), str(ds["model"].values[i]),
                     str(ds["integrator"].values[i]), f"{float(ds['dt'].values[i]):.6g}",
                     str(int(ds["elements_per_link"].values[i])), str(ds["beam_theory"].values[i]),
                     str(int(ds["modes"].values[i])),
                     f"{float(ds['stiffness_scale'].values[i]):g}",
                     f"{float(ds['tolerance'].values[i]):g}", str(int(ds["refinements"].values[i])),
                     f"{float(ds['seconds_per_realization'].values[i]):.6g}",
                     str(int(ds["failed"].values[i])), f"{float(ds['max_relative_error'].values[i]):.6g}"]
                    + [f"{x:.6g}" for x in rel])
    _write_csv(out / "tradeoff.csv", header, rows)
    write_netcdf(ds, out / "tradeoff.nc")
    rec = recommend(ds, tolerance)
    _plot_tradeoff(ds, out / "tradeoff.png", tolerance, rec)
    return rec


def _write_csv(path, header, rows) -> None:
    import csv
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)


_COLOURS = {"rigid": "k", "quasi-static": "tab:green", "elastic": "tab:blue", "paper": "tab:orange",
            "contact": "tab:red"}


def _plot_tradeoff(ds, path, tolerance, rec) -> None:
    from ..analysis.plot_common import save_figure
    save_figure(tradeoff_figure(ds, tolerance, rec), path)


def tradeoff_figure(ds, tolerance, rec):
    """Cost against error of every setting; the Pareto front numbered and named in a side list."""
    from ..analysis.plot_common import plt   # the Agg backend, set once there
    cost = ds["seconds_per_realization"].values
    err = np.maximum(ds["max_relative_error"].values, 1e-6)
    labels, models = ds["setting"].values, ds["model"].values
    fig, (ax, side) = plt.subplots(1, 2, figsize=(13, 6.5), constrained_layout=True,
                                   gridspec_kw={"width_ratios": [2.2, 1]})
    for m in dict.fromkeys(models):
        sel = models == m
        ax.scatter(cost[sel], err[sel], color=_COLOURS.get(m, "grey"), label=m, zorder=3)
    front = pareto_front(cost, err)
    ax.plot(cost[front], err[front], "k--", lw=1, label="Pareto front", zorder=2)
    ax.axhline(tolerance, color="grey", lw=0.8, ls=":", label=f"tolerance {100 * tolerance:g} %")
    ref = labels == ds.attrs["reference"]
    ax.scatter(cost[ref], err[ref], marker="*", s=200, color="tab:red", edgecolor="k",
               label="reference", zorder=4)
    if rec["setting"]:
        i = labels == rec["setting"]
        ax.scatter(cost[i], err[i], s=160, facecolor="none", edgecolor="k", lw=1.5,
                   label=f"cheapest within tolerance ({rec['speedup_vs_reference']:.0f}x cheaper)",
                   zorder=5)
    ax.set(xscale="log", yscale="log", xlabel="wall time per realisation, batched [s]",
           ylabel="max relative error of the ensemble statistics [1]")
    ax.legend(fontsize=7, loc="lower left")
    ax.grid(True, which="both", lw=0.3)
    _number_points(fig, ax, cost[front], err[front])
    side.axis("off")
    side.text(0, 1, "Pareto front (every setting is in tradeoff.csv):\n" + "\n".join(
        textwrap.fill(f"{n + 1}: {labels[i]}", 44, subsequent_indent="   ")
        for n, i in enumerate(front)),
        va="top", fontsize=7, family="monospace", transform=side.transAxes)
    fig.suptitle("\n".join(textwrap.wrap(
        f"speed against accuracy: scene {ds.attrs.get('scene_name', '?')}, every level, "
        f"n = {ds.attrs.get('realizations')} per setting; reference {ds.attrs['reference']}", 110)),
        fontsize=10)
    return fig


def _number_points(fig, ax, x, y) -> None:
    """Number the points 1, 2, ...; each label takes the first offset overlapping no earlier one
    (a label that finds none is left out: the side list still names the point)."""
    renderer = fig.canvas.get_renderer()
    placed = []
    for n, (xi, yi) in enumerate(zip(x, y)):
        for dx, dy in ((5, 4), (5, -10), (-12, 4), (-12, -10), (5, 14), (-12, 14)):
            a = ax.annotate(str(n + 1), (xi, yi), fontsize=7, xytext=(dx, dy),
                            textcoords="offset points")
            box = a.get_window_extent(renderer)
            if not any(box.overlaps(b) for b in placed):
                placed.append(box)
                break
            a.remove()


# ---------------------------------------------------------------------------------------------
# stability


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
    sim = scene.simulation
    dt, dtc, el = sim.time_step, sim.contact_time_step, sim.elements_per_link
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
        sweep(scene, "elastic", ig, steps(T, [f * dt for f in (16.0, 8.0, 4.0, 2.0, 1.0, 0.5)]), n_real=1)
    rows.extend(_explicit_sweep(scene, limit, explicit_steps, tolerance, seed, log))
    sweep(scene, "paper", sim.integrator, steps(T, [f * dt for f in (2.0, 1.0, 0.5, 0.25)]))
    contact_steps = sorted({_contact_step(scene, f * dtc) for f in (8.0, 4.0, 2.0, 1.0, 0.5)})
    for ig in (sim.contact_integrator, "newmark"):
        for scale in (1.0, 10.0):
            sweep(short, "contact", ig, contact_steps, scale)
    # the adaptive step from the same base steps: where Newton fails it halves the step instead
    adaptive = _adaptive(scene)
    for scale in (1.0, 10.0):
        sweep(short, "contact", sim.contact_integrator, contact_steps, scale, adaptive=adaptive)
    return _stability_dataset(rows, limit, tolerance, n, seed, scene, horizon)


def _explicit_sweep(scene, limit, steps, tolerance, seed, log):
    """Central differences around 2/omega_max on the undamped robot, every mode excited.

    2/omega_max is the undamped limit; with the scene's stiffness-proportional damping the step
    matrix holds lambda_2 K (the damping is treated implicitly), which moves the limit.  The run
    starts from the quasi-static state plus a seeded random velocity of 1e-6 m/s (rad/s) scale and
    lasts ``steps`` quarter-limit steps; it fails when the elastic displacement passes 1 mm.
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
    return _rows(runs, "elastic", "central-difference (undamped)", 1.0, H, tolerance, log,
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
        log(f"  {level} {integrator} {describe(h)}: {status} {reason}")
    return rows


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
                          {"units": "s", "long_name": lim.replace("_", " ") + " time step (NaN: none)"})
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
    """Per sweep: the largest step not failed, the smallest failed one, the largest stable one."""
    sel = ds["sweep_name"].values == name
    status, dt = ds["status"].values[sel], ds["dt_s"].values[sel]
    pick = {"largest_not_failed": (status != "failed", np.max),
            "smallest_failed": (status == "failed", np.min),
            "largest_accurate": (status == "stable", np.max)}[which]
    return float(pick[1](dt[pick[0]])) if pick[0].any() else np.nan


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
    """Per sweep the status of every step, and the paper level's error against the step."""
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
    paper = level == "paper"
    order = np.argsort(dt[paper])
    h, v = dt[paper][order], ds["velocity_mean_peak"].values[paper][order]
    axes[2].loglog(h, v * 1e3, "o-", color="tab:orange", label="paper level")
    if len(h):
        axes[2].loglog(h, v[0] * 1e3 * h[0] / h, "k:", lw=0.8, label="proportional to 1/dt")
    axes[2].xaxis.set_minor_formatter(NullFormatter())
    axes[2].set_xlabel("time step [s]")
    axes[2].set_ylabel("mean over realisations of max |velocity error|,\nlargest of x, y, z [mm/s]")
    axes[2].set_title("paper level: error against time step", fontsize=10)
    axes[2].legend(fontsize=7)
    axes[2].grid(True, which="both", lw=0.3)
    fig.suptitle(f"time-step stability: scene {ds.attrs.get('scene_name', '?')}, elastic, contact "
                 f"and paper levels, n = {ds.attrs.get('realizations')} per step, tolerance "
                 f"{100 * ds.attrs.get('tolerance', float('nan')):g} %", fontsize=10)
    return fig
