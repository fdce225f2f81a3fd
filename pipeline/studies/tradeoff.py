"""Speed against accuracy (``rss6 tradeoff``): every level, integrator, step and mesh against a reference.

The same realisations (same seed) are run for each setting (pipeline.studies.setting) and its
ensemble statistics compared with the reference setting's; the cheapest setting within a
tolerance is recommended, and the Pareto front of cost against error drawn.
"""
from __future__ import annotations

import dataclasses
import textwrap

import numpy as np
import xarray as xr

from rss6core import MODELS, BeamTheory, default_integrator, default_time_step, degrees_of_freedom, max_link_modes

from ..files.schema import MIXED_UNITS, _unit_table
from ..vocabulary import DIRECTIONS, QUANTITIES
from .setting import (TRADEOFF_STATISTICS, Setting, _adaptive, _contact_step, _scene_for, load_compiled_kernels,
                      measure, refined, relative_errors)

__all__ = ["default_settings", "tradeoff", "pareto_front", "recommend", "write_tradeoff", "tradeoff_figure"]


def default_settings(scene) -> tuple[list[Setting], Setting]:
    """The settings compared by default: each level at its default step and integrator (the core's
    rules) on the scene's mesh, and variations of them; and the reference: the contact level's
    adaptive step at a hundredth of the tolerance, down to a quarter of the finest adaptive row's
    smallest step, on a mesh twice the scene's (impact peaks excite the links' higher modes)."""
    step = {m: default_time_step(scene, m) for m in MODELS}     # s, by level
    el, (tol, levels) = scene.simulation.elements_per_link, _adaptive(scene)
    half, dtc = max(1, el // 2), step["contact"]

    def default(model: str, **changes) -> Setting:
        """``model`` at its default integrator and step on the scene's mesh, with ``changes``."""
        return dataclasses.replace(Setting(model, default_integrator(scene, model), step[model], el), **changes)

    out = [default("quasi-static", integrator="newmark")]
    out += [default("elastic", integrator=i) for i in ("newmark", "hht", "generalized-alpha")]
    out += [default("elastic", elements=half), default("elastic", dt=step["elastic"] / 2)]
    out += [default("paper"), default("paper", dt=step["paper"] / 2)]
    out += [default("contact", dt=_contact_step(scene, f * dtc)) for f in (2.0, 1.0, 0.5, 0.25)]
    out += [default("contact", elements=half), default("contact", integrator="newmark")]
    out += [default("contact", tolerance=f * tol, refinements=levels) for f in (4.0, 1.0, 0.25)]
    out += [default("contact", elements=m, tolerance=tol, refinements=levels) for m in (half, 2 * el)]
    other = BeamTheory("euler-bernoulli" if scene.beam.theory == "timoshenko" else "timoshenko",
                       not scene.beam.rotary_inertia)
    out += [default("elastic", beam=other), default("contact", tolerance=tol, refinements=levels, beam=other)]
    out += _reduced_settings(scene, default, tol, levels)
    reference = default("contact", dt=_contact_step(scene, dtc / 2), elements=2 * el, tolerance=tol / 100,
                        refinements=levels + 2)
    return out + [reference], reference


LINK_MODES = (2, 4, 8)   # Craig-Bampton modes per link of the reduced rows


def _reduced_settings(scene, default, tol: float, levels: int) -> list[Setting]:
    """The elastic, paper and (adaptive) contact rows with each link reduced to LINK_MODES
    Craig-Bampton modes on the scene's mesh (a scene that reduces its links already gets none, nor
    does one whose cranks are servo-driven: the reduced crank has no journal rotation)."""
    if scene.beam.link_modes or scene.actuator.motor_stiffness is not None:
        return []
    modes = [m for m in LINK_MODES if m < max_link_modes(scene.simulation.elements_per_link)]
    return ([default("elastic", link_modes=m) for m in modes] + [default("paper", link_modes=m) for m in modes]
            + [default("contact", tolerance=tol, refinements=levels, link_modes=m) for m in modes])


def full_mesh_errors(scene, settings: list[Setting], runs: dict) -> np.ndarray:
    """Relative errors (setting, quantity, direction, statistic) of each reduced-link setting's
    statistics against the same setting on the full mesh (NaN where that was not measured)."""
    out = np.full((len(settings), 3, 6, len(TRADEOFF_STATISTICS)), np.nan)
    for i, s in enumerate(settings):
        if not _scene_for(scene, s).beam.link_modes:
            continue
        full = next((f for f in (dataclasses.replace(s, link_modes=None), dataclasses.replace(s, link_modes=0))
                     if f in runs and not _scene_for(scene, f).beam.link_modes), None)
        if full is not None:
            out[i] = relative_errors(runs[s]["statistics"], runs[full]["statistics"])
    return out


def tradeoff(scene, n: int, seed: int = 0, settings=None, reference: Setting | None = None,
             log=print) -> xr.Dataset:
    """Cost and error of every setting against the reference; the reference's own convergence
    (its step halved and mesh doubled) is measured and stored in the attributes."""
    if settings is None:
        settings, reference = default_settings(scene)
    reference = reference or settings[-1]
    if reference not in settings:
        settings = list(settings) + [reference]
    load_compiled_kernels(scene, settings, seed)
    runs = _measure_all(scene, settings, n, seed, log)
    check = refined(reference)
    fine = measure(scene, check, n, seed)
    log(f"  reference check ({check.label}): {fine['seconds_per_realization']:.3g} s per realisation")
    ds = xr.Dataset(_setting_variables(scene, settings, runs)
                    | _error_variables(settings, runs, reference, fine),
                    coords=_coordinates(settings),
                    attrs=_attributes(scene, reference, check, fine, n, seed))
    ds["max_relative_error"] = ds["relative_error"].max(("quantity", "direction", "statistic"))
    ds["max_relative_error"].attrs.update(units="1", long_name="largest relative_error of the setting")
    ds["modes"] = ("setting", [degrees_of_freedom(_scene_for(scene, s), s.model, s.elements) for s in settings],
                   {"units": "1", "long_name": "degrees of freedom of the model (link DOFs after any "
                                               "Craig-Bampton reduction)"})
    ds["relative_error_full_mesh"] = (("setting", "quantity", "direction", "statistic"),
                                      full_mesh_errors(scene, settings, runs),
                                      {"units": "1", "long_name": "relative error of a reduced-link setting's "
                                       "statistic against the same setting on the full mesh (NaN: not reduced)"})
    ds["max_relative_error_full_mesh"] = ds["relative_error_full_mesh"].max(("quantity", "direction", "statistic"))
    ds["max_relative_error_full_mesh"].attrs.update(units="1", long_name="largest relative_error_full_mesh")
    return ds


def _measure_all(scene, settings: list[Setting], n: int, seed: int, log) -> dict:
    """Every setting's measurement (:func:`measure`) by setting, each logged as it is done."""
    runs = {}
    for s in settings:
        runs[s] = measure(scene, s, n, seed)
        log(f"  {s.label}: {runs[s]['seconds_per_realization']:.3g} s per realisation"
            + (f", {runs[s]['failed']} failed" if runs[s]["failed"] else ""))
    return runs


def _setting_variables(scene, settings: list[Setting], runs: dict) -> dict:
    """The variables along ``setting`` that describe each setting and its cost."""
    return {
        "model": ("setting", [s.model for s in settings], {"long_name": "model level"}),
        "integrator": ("setting", [s.integrator for s in settings], {"long_name": "time integrator"}),
        "dt": ("setting", [s.dt for s in settings], {"units": "s", "long_name": "time step"}),
        "elements_per_link": ("setting", [s.elements for s in settings],
                              {"units": "1", "long_name": "beam elements per crank and per rod"}),
        "beam_theory": ("setting", [(s.beam or scene.beam).label for s in settings],
                        {"long_name": "beam theory of the links"}),
        "link_modes": ("setting", [_scene_for(scene, s).beam.link_modes for s in settings],
                       {"units": "1", "long_name": "Craig-Bampton modes per link (0: full mesh)"}),
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
                   {"units": "1", "long_name": "failed realisations"})}


def _error_variables(settings: list[Setting], runs: dict, reference: Setting, fine: dict) -> dict:
    """Each setting's statistics and their relative errors against the reference's, and the
    reference's change when its step is halved and its mesh doubled (``fine``)."""
    ref = runs[reference]["statistics"]
    rel = np.stack([relative_errors(runs[s]["statistics"], ref) for s in settings])
    convergence = relative_errors(ref, fine["statistics"])
    return {
        "statistic_value": (("setting", "quantity", "direction", "statistic"),
                            np.stack([runs[s]["statistics"] for s in settings]),
                            {"long_name": "statistic of the setting's ensemble", "units": MIXED_UNITS}),
        "relative_error": (("setting", "quantity", "direction", "statistic"), rel,
                           {"units": "1", "long_name": "relative error of the statistic against the "
                                                       "reference setting's"}),
        "reference_change": (("quantity", "direction", "statistic"), convergence,
                             {"units": "1", "long_name": "reference vs its step halved and mesh "
                                                         "doubled"})}


def _coordinates(settings: list[Setting]) -> dict:
    return {"setting": ("setting", [s.label for s in settings], {"long_name": "setting"}),
            "quantity": list(QUANTITIES), "direction": list(DIRECTIONS), "statistic": list(TRADEOFF_STATISTICS),
            "unit": (("quantity", "direction"), _unit_table(), {"long_name": "SI unit of each element"})}


def _attributes(scene, reference: Setting, check: Setting, fine: dict, n: int, seed: int) -> dict:
    return {"title": f"rss6 speed/accuracy trade-off, scene {scene.name!r}",
            "history": f"rss6 tradeoff {scene.name} -n {n} --seed {seed}",
            "reference": reference.label, "reference_check": check.label,
            "reference_check_seconds_per_realization": fine["seconds_per_realization"],
            "realizations": n, "seed": seed, "scene_name": scene.name, "scene_toml": scene.source_text,
            "settle_time_s": scene.simulation.settle_time}


def pareto_front(cost: np.ndarray, error: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """Indices of the settings no other setting beats in both cost and error, by cost; only ``valid``
    ones (default all) take part: a setting some of whose realisations failed has neither a cost nor
    an error of the whole ensemble."""
    order = np.argsort(cost, kind="stable")
    valid = np.ones(len(cost), bool) if valid is None else np.asarray(valid, bool)
    front, best = [], np.inf
    for i in order:
        if valid[i] and error[i] < best:
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
              "link_modes", "stiffness_scale", "tolerance_m", "refinements", "seconds_per_realization", "failed",
              "max_rel_error", "max_rel_error_vs_full_mesh"] + _columns()
    rows = []
    for i in range(ds.sizes["setting"]):
        rel = ds["relative_error"].values[i].reshape(-1)
        rows.append([str(ds["setting"].values[i]), str(ds["model"].values[i]),
                     str(ds["integrator"].values[i]), f"{float(ds['dt'].values[i]):.6g}",
                     str(int(ds["elements_per_link"].values[i])), str(ds["beam_theory"].values[i]),
                     str(int(ds["modes"].values[i])), str(int(ds["link_modes"].values[i])),
                     f"{float(ds['stiffness_scale'].values[i]):g}",
                     f"{float(ds['tolerance'].values[i]):g}", str(int(ds["refinements"].values[i])),
                     f"{float(ds['seconds_per_realization'].values[i]):.6g}",
                     str(int(ds["failed"].values[i])), f"{float(ds['max_relative_error'].values[i]):.6g}",
                     f"{float(ds['max_relative_error_full_mesh'].values[i]):.6g}"]
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
    """Cost against error of every setting (a cross where some realisations failed); the Pareto front of
    the others numbered and named in a side list."""
    from ..analysis.plot_common import plt   # the Agg backend, set once there
    cost = ds["seconds_per_realization"].values
    err = np.maximum(ds["max_relative_error"].values, 1e-6)
    labels, models = ds["setting"].values, ds["model"].values
    fig, (ax, side) = plt.subplots(1, 2, figsize=(13, 6.5), constrained_layout=True,
                                   gridspec_kw={"width_ratios": [2.2, 1]})
    whole = ds["failed"].values == 0
    for m in dict.fromkeys(models):
        level, colour = models == m, _COLOURS.get(m, "grey")
        ax.scatter(cost[level & whole], err[level & whole], color=colour, label=m, zorder=3)
        ax.scatter(cost[level & ~whole], err[level & ~whole], color=colour, marker="x", zorder=3)
    if not whole.all():
        ax.scatter([], [], color="grey", marker="x", label="some realisations failed (off the front)")
    front = pareto_front(cost, err, whole)
    ax.plot(cost[front], err[front], "k--", lw=1, label="Pareto front", zorder=2)
    ax.axhline(tolerance, color="grey", lw=0.8, ls=":", label=f"tolerance {100 * tolerance:g} %")
    ref = labels == ds.attrs["reference"]
    ax.scatter(cost[ref], err[ref], marker="*", s=200, color="tab:red", edgecolor="k",
               label="reference", zorder=4)
    if rec["setting"]:
        i = labels == rec["setting"]
        ax.scatter(cost[i], err[i], s=160, facecolor="none", edgecolor="k", lw=1.5,
                   label=f"cheapest within tolerance ({rec['speedup_vs_reference']:.1f}x cheaper)",
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
