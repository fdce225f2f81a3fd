"""``rss6 report``: the seed paper's section 6 reproduced with the pipeline, as docs/results.md.

For every scene given it runs (or, where the files exist, reuses: the ensembles
resume like ``rss6 run``) into DATA:
- ``SCENE_paper.nc``, ``SCENE_contact.nc``: N realisations with full histories;
- ``SCENE_quasi-static.nc``: N realisations (the rigid-link clearance kinematics);
- ``SCENE_elastic.nc``: the ideal-joint elastic run (one, deterministic);
- ``SCENE_contact_only{A,C,B}.nc``: the contact level with one joint family's
  clearances as in the scene and the other two switched off (10 um, see OFF);
then writes OUT/results.md and OUT/results/*.png from those files alone.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rss6core import parse_scene
from rss6core.kinematics import rigid_motion
from rss6core.models import default_integrator, default_time_step

from .run import EnsembleSpec, run_ensemble
from .scenes import find_scene
from .plots import axis_unit, draw_envelope, plt, save_figure
from .stats import summarize
from .store import (DIRECTIONS, EnsembleFileError, display_unit, load_netcdf, open_ensemble, run_dataset,
                    write_netcdf)

__all__ = ["ReportPlan", "with_clearance", "run_scene", "write_report", "PAPER_VALUES", "OFF"]

# m: clearance of a switched-off joint family at the contact level, which needs positive
# clearances; the contact error shrinks in proportion to the clearance (tested), so a 10 um
# family adds about 1/25 of what it adds at 0.25 mm.  1 um joints are so stiff (Hertz K grows
# as clearance^-1/2) that Newton fails at 0.1 ms steps.
OFF = 1e-5
FAMILY_KEYS = {"A": ("revolute_radial_m", "revolute_axial_m"), "C": ("spherical_C_m",),
               "B": ("spherical_B_m",)}
LEVELS = ("paper", "contact")

# docs/model.md section 9 (paper sec. 6), SI: (statistic, quantity, direction) -> {clearance mm: value}
PAPER_VALUES = {
    ("max", "displacement", "x"): {0.25: 0.0104e-3, 0.50: 0.0204e-3},
    ("max", "displacement", "y"): {0.25: 0.0129e-3, 0.50: 0.0172e-3},
    ("max", "displacement", "z"): {0.25: 0.0047e-3, 0.50: 0.0077e-3},
    ("mean", "velocity", "x"): {0.25: 1.4934e-3},
    ("mean", "velocity", "y"): {0.25: 1.0358e-3},
    ("mean", "velocity", "z"): {0.25: 6.1585e-3},
    ("max", "acceleration", "x"): {0.25: 524.398e-3},
    ("max", "acceleration", "y"): {0.25: 1087.2e-3},
    ("max", "acceleration", "z"): {0.25: 2881.3e-3},
    ("max", "acceleration", "rx"): {0.25: 8.414},
    ("max", "acceleration", "ry"): {0.25: 2.889},
    ("max", "acceleration", "rz"): {0.25: 23.0},
}


@dataclass(frozen=True)
class ReportPlan:
    """How much to run: realisations per ensemble and per joint-family ensemble, where, with which seed."""
    n: int = 1000
    family_n: int = 100
    workers: int = 2
    scheduler: str | None = None
    seed: int = 0


def with_clearance(text: str, values: dict[str, float], source: str = "<report>") -> str:
    """Scene TOML text with keys of its [clearance] table set to ``values`` (m), checked by re-parsing."""
    lines, table, seen = text.splitlines(), None, set()
    for i, line in enumerate(lines):
        head = re.match(r"\s*\[([^\]]+)\]", line)
        if head:
            table = head.group(1).strip()
            continue
        key = re.match(r"\s*([A-Za-z_]+)\s*=", line)
        if table == "clearance" and key and key.group(1) in values:
            lines[i] = f"{key.group(1)} = {values[key.group(1)]!r}"
            seen.add(key.group(1))
    missing = set(values) - seen
    if missing:
        raise ValueError(f"{source}: [clearance] has no {', '.join(sorted(missing))} to set")
    out = "\n".join(lines) + "\n"
    scene = parse_scene(out, source)
    wrong = [k for k, v in values.items() if getattr(scene.clearance, k.removesuffix("_m")) != v]
    if wrong:   # e.g. the key set twice in the table
        raise ValueError(f"{source}: [clearance] {', '.join(wrong)} did not take the value set")
    return out


def _only(text: str, family: str, source: str) -> str:
    """The scene with every joint family but ``family`` switched off (OFF)."""
    return with_clearance(text, {k: OFF for f, keys in FAMILY_KEYS.items() if f != family
                                 for k in keys}, source)


def _ensemble(scene, text, source, model, n, path, plan: ReportPlan, store):
    sim = scene.simulation
    spec = EnsembleSpec(text, source, model, default_integrator(scene, model),
                        default_time_step(scene, model), sim.elements_per_link, plan.seed, store)
    return run_ensemble(spec, n, path, workers=plan.workers, scheduler=plan.scheduler)


def run_scene(config, data: Path, plan: ReportPlan) -> dict[str, Path]:
    """Run (or resume) every file the report needs for one scene; returns their paths by role."""
    from rss6core.models import simulate
    scene = find_scene(config)
    data.mkdir(parents=True, exist_ok=True)
    paths = {}
    path = data / f"{scene.name}_elastic.nc"
    if not path.exists():
        result = simulate(scene, "elastic")
        write_netcdf(run_dataset(scene, result, model="elastic", integrator=scene.simulation.integrator,
                                 dt=scene.time_step, elements=scene.simulation.elements_per_link,
                                 wall_time=0.0), path)
    paths["elastic"] = path
    for model, store in (("quasi-static", "summary"), ("paper", "full"), ("contact", "full")):
        path = data / f"{scene.name}_{model}.nc"
        _ensemble(scene, scene.source_text, str(config), model, plan.n, path, plan, store)
        paths[model] = path
    for family in FAMILY_KEYS:
        path = data / f"{scene.name}_contact_only{family}.nc"
        _ensemble(scene, _only(scene.source_text, family, str(config)), str(config), "contact",
                  plan.family_n, path, plan, "summary")
        paths[f"only{family}"] = path
    return paths


# --- statistics ---------------------------------------------------------------

def _finished(ds):
    return ds["status"].values == "finished"


def _sample(ds, stat: str, quantity: str, direction: str) -> np.ndarray:
    return ds[f"{stat}_abs_error"].sel(quantity=quantity, direction=direction).values[_finished(ds)]


def _summary(ds, stat, quantity, direction) -> dict:
    return summarize(_sample(ds, stat, quantity, direction))


def _median(ds, stat, quantity, direction) -> float:
    """The median that _summary reports as q50, without its confidence intervals' bootstrap."""
    return float(np.median(_sample(ds, stat, quantity, direction)))


def _fmt(value: float, f: float) -> str:
    v = value * f
    return "nan" if not np.isfinite(v) else f"{v:.3g}" if abs(v) >= 1e-3 else f"{v:.2e}"


def _cell(s: dict, key: str, f: float) -> str:
    lo, hi = s["ci95"].get(key, [np.nan, np.nan])
    return f"{_fmt(s[key], f)} [{_fmt(lo, f)}, {_fmt(hi, f)}]"


def _clearance_mm(scene) -> float:
    return round(scene.clearance.spherical_B * 1e3, 3)


# --- figures ------------------------------------------------------------------

def _rigid_figure(scene, t, out: Path) -> Path:
    pm = rigid_motion(scene, t).platform
    fig, axes = plt.subplots(3, 6, figsize=(17, 7.5), constrained_layout=True, sharex=True)
    fig.suptitle(f"scene {scene.name}: ideal rigid platform motion (eq. 35), the reference of every error")
    labels = ("x", "y", "z", "n1", "n2", "n3")
    for row, (q, values) in enumerate((("displacement", pm.pose), ("velocity", pm.pose_rate),
                                       ("acceleration", pm.pose_acc))):
        for k in range(6):
            f, unit = axis_unit(q, DIRECTIONS[k])
            ax = axes[row, k]
            ax.plot(t, values[:, k] * f, color="0.3", lw=1.2)
            ax.set(title=f"{labels[k]} {q}", ylabel=f"[{unit}]")
            ax.grid(alpha=0.3)
            if row == 2:
                ax.set_xlabel("time [s]")
    return save_figure(fig, out / f"{scene.name}_rigid.png")


def _error_figure(scene, quantity: str, runs: dict, out: Path) -> Path:
    """Like the paper's figs. 11-16: the platform error (actual minus rigid) of the elastic level
    (ideal joints) and, per clearance level, one realisation and the ensemble envelope.
    ``runs``: the scene's opened files by role, as write_report holds them."""
    elastic = runs["elastic"]
    fig, axes = plt.subplots(len(LEVELS), 6, figsize=(18, 3.3 * len(LEVELS) + 0.6),
                             constrained_layout=True, sharex=True)
    fig.suptitle(f"scene {scene.name} ({_clearance_mm(scene)} mm clearances): platform {quantity} "
                 "error, actual minus ideal rigid motion")
    for row, level in enumerate(LEVELS):
        ds = runs[level]
        t = ds["time"].values
        err = ds["error"].sel(quantity=quantity).values[_finished(ds)]        # (R, T, 6)
        for k, d in enumerate(DIRECTIONS):
            f, unit = axis_unit(quantity, d)
            ax = axes[row, k]
            e = err[..., k] * f
            draw_envelope(ax, t, e, f"{level}: 5-95 % of {e.shape[0]} realisations",
                          f"{level}: max |error| over realisations", color="C0", ls="--", lw=0.7)
            ax.plot(t, e[0], color="C3", lw=0.8, label=f"{level}: realisation 0")
            ax.plot(elastic["time"].values, elastic["error"].sel(quantity=quantity).values[:, k] * f,
                    color="k", lw=1.0, label="elastic, ideal joints")
            ax.set(title=f"{level} level: {d}", ylabel=f"{d} [{unit}]")
            ax.grid(alpha=0.3)
            if row == len(LEVELS) - 1:
                ax.set_xlabel("time [s]")
        axes[row, 0].legend(fontsize=7, loc="lower left")
    return save_figure(fig, out / f"{scene.name}_{quantity}.png")


def _open_run(path):
    """A single-run file (the elastic level), opened into memory; EnsembleFileError if unreadable."""
    ds = load_netcdf(path)
    if "error" not in ds:
        raise EnsembleFileError(f"{path}: not an rss6 run file (no 'error' variable); delete it and "
                                "rerun rss6 report")
    return ds


# --- the document ---------------------------------------------------------------

_ROWS = list(PAPER_VALUES)


def _setting_line(ds) -> str:
    a = ds.attrs
    dt, sim = float(a["time_step_s"]), parse_scene(a["scene_toml"]).simulation
    step = f"step {dt * 1e3:g} ms"
    if a["model"] == "contact" and sim.contact_refinements:
        finest = dt / 2 ** sim.contact_refinements
        step = (f"adaptive step {dt * 1e3:g} ms, halved down to {finest * 1e6:g} us where"
                f" the local error estimate exceeds {sim.contact_tolerance:g} m")
    return (f"{a['model']}: {a['integrator']}, {step}, "
            f"{a['elements_per_link']} elements per link, {int(_finished(ds).sum())} finished / "
            f"{ds.sizes['realization']} realisations, seed {a['seed']}")


def _comparison_table(scene, ens: dict) -> list[str]:
    mm = _clearance_mm(scene)
    head = ["statistic (per realisation)", "dir", "unit", f"paper, {mm} mm"]
    for level in ("quasi-static", "paper", "contact"):
        head += [f"{level}: median [95 % CI]", f"{level}: 95 % quantile [95 % CI]"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for stat, q, d in _ROWS:
        f, unit = display_unit(q, d)
        paper = PAPER_VALUES[(stat, q, d)].get(mm)
        cells = [_label(stat, q), d, unit, _fmt(paper, f) if paper is not None else "-"]
        for level in ("quasi-static", "paper", "contact"):
            s = _summary(ens[level], stat, q, d)
            cells += [_cell(s, "q50", f), _cell(s, "q95", f)]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _label(stat: str, quantity: str) -> str:
    """'max |displacement error|' with the bars escaped for a markdown table."""
    bar = "\\|"
    return f"{stat} {bar}{quantity} error{bar}"


def _growth_table(scenes: list, ens: dict) -> list[str]:
    (s1, e1), (s2, e2) = sorted(((s, ens[s.name]) for s in scenes), key=lambda p: _clearance_mm(p[0]))[:2]
    m1, m2 = _clearance_mm(s1), _clearance_mm(s2)
    head = ["statistic", "dir", f"paper {m2}/{m1} mm"] + [f"{lv} median {m2}/{m1} mm"
                                                         for lv in ("quasi-static", "paper", "contact")]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for stat, q, d in _ROWS:
        pv = PAPER_VALUES[(stat, q, d)]
        cells = [_label(stat, q), d,
                 f"{pv[m2] / pv[m1]:.2f}" if m1 in pv and m2 in pv else "-"]
        for level in ("quasi-static", "paper", "contact"):
            cells.append(f"{_median(e2[level], stat, q, d) / _median(e1[level], stat, q, d):.2f}")
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _family_table(scene, ens: dict) -> list[str]:
    runs = [("all joints", ens["contact"])] + [(f"only {f}", ens[f"only{f}"]) for f in FAMILY_KEYS]
    head = ["statistic", "dir", "unit"] + [f"{name} ({int(_finished(ds).sum())} of {ds.sizes['realization']})"
                                           for name, ds in runs] + ["elastic (no clearance)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    el = ens["elastic"]
    for stat, q, d in _ROWS:
        f, unit = display_unit(q, d)
        cells = [_label(stat, q), d, unit]
        cells += [_fmt(_median(ds, stat, q, d), f) for _, ds in runs]
        cells.append(_fmt(float(el[f"{stat}_abs_error"].sel(quantity=q, direction=d)), f))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _largest_family(ens: dict, stat, q, d) -> tuple[str, float]:
    values = {f: _median(ens[f"only{f}"], stat, q, d) for f in FAMILY_KEYS}
    best = max(values, key=values.get)
    return best, values[best] / max(sum(values.values()), 1e-300)


def _explanations(scene, ens: dict) -> list[str]:
    """The physical reasons for the large differences from the paper, with this run's numbers."""
    mm = _clearance_mm(scene)
    out = []
    paper_dx = max(v.get(mm, np.nan) for (st, q, d), v in PAPER_VALUES.items()
                   if q == "displacement")
    qs = max(_median(ens["quasi-static"], "max", "displacement", d) for d in "xyz")
    ct = max(_median(ens["contact"], "max", "displacement", d) for d in "xyz")
    el = max(float(ens["elastic"]["max_abs_error"].sel(quantity="displacement", direction=d)) for d in "xyz")
    sag = _median(ens["contact"], "mean", "displacement", "z")
    how = ("eccentricities at the clearance boundary along the rigid joint reactions"
           if scene.simulation.quasi_static_eccentricity == "reaction" else
           "the drawn eccentricities through the linearised leg closure")
    if np.isfinite(paper_dx):
        out.append(
            f"- **Displacement ({scene.name}).** The paper's largest displacement error is "
            f"{paper_dx * 1e3:.4g} mm; our contact level's median per-realisation maximum is "
            f"{ct * 1e3:.3g} mm ({ct / paper_dx:.3g} times), and the rigid-link clearance kinematics alone "
            f"(quasi-static level, {how}) gives {qs * 1e3:.3g} mm "
            f"({qs / paper_dx:.3g} times). A joint with a {mm} mm clearance lets the platform move by the "
            "clearance's order through the leg closure (docs/model.md section 9), so an error of hundredths "
            f"of a millimetre at {mm} mm clearance cannot come from the clearances: the paper's eq. 33 "
            "keeps only the part of each clearance vector along the link axes (virtual lengths) and "
            "redraws it every step, which averages the kinematic error instead of letting the joints "
            "rest on their walls. The elastic (ideal-joint) error alone is "
            f"{el * 1e3:.3g} mm. Most of the contact level's z error is a steady sag: its median mean "
            f"|z error| is {sag * 1e3:.3g} mm against a median maximum of "
            f"{_median(ens['contact'], 'max', 'displacement', 'z') * 1e3:.3g} mm, because under "
            "gravity every joint rests on the wall of its clearance, and each leg's closure adds up "
            "the offsets of its three joints (A, C, B).")
    pv = PAPER_VALUES[("mean", "velocity", "z")].get(mm)
    if pv is not None:
        lv = _median(ens["paper"], "mean", "velocity", "z")
        cv = _median(ens["contact"], "mean", "velocity", "z")
        dt = float(ens["paper"].attrs["time_step_s"])
        out.append(
            f"- **Mean velocity (z).** Paper {pv * 1e3:.4g} mm/s; our `paper` level (the seed's "
            f"method) {lv * 1e3:.3g} mm/s, our contact level {cv * 1e3:.3g} mm/s. Redrawing the "
            f"eccentricities every {dt * 1e3:g} ms step makes the joint offsets white noise: their "
            "difference quotient is of order clearance / step (the stability study shows this "
            "statistic doubling with every halving of the step), so the paper's velocity errors "
            "measure its time step, not the robot. The contact level's joints move only when the "
            "loads push them across the clearance and the joints strike; its mean velocity error is "
            f"{cv / pv:.3g} times the paper's.")
    pa = PAPER_VALUES[("max", "acceleration", "z")].get(mm)
    if pa is not None:
        la = _median(ens["paper"], "max", "acceleration", "z")
        ca = _median(ens["contact"], "max", "acceleration", "z")
        fam, share = _largest_family(ens, "max", "acceleration", "z")
        out.append(
            f"- **Maximum acceleration (z).** Paper {pa * 1e3:.4g} mm/s^2; our `paper` level "
            f"{la * 1e3:.3g} mm/s^2 (white-noise offsets over a step squared), our contact level "
            f"{ca * 1e3:.3g} mm/s^2. The contact level's peaks are impacts: a joint crossing its "
            "clearance strikes the far wall under the Lankarani-Nikravesh law, in well under a "
            "millisecond, and the platform acceleration follows the impact force. Its size depends "
            "on the contact stiffness and on resolving it in time, which is why the contact level "
            "halves its step where an impact needs it (README, 'Speed and accuracy': a fixed step "
            "fine enough for these peaks would have to be fine for the whole run). Of the "
            "three joint families "
            f"switched on one at a time, {fam} gives the largest median peak ({100 * share:.0f} % "
            "of the three runs' sum).")
    return out


def write_report(configs: list, out: Path, plan: ReportPlan, data: Path | None = None) -> Path:
    """Run what is missing and write OUT/results.md with its figures in OUT/results/."""
    out = Path(out)
    data = Path(data) if data is not None else out / "results-data"
    figs = out / "results"
    figs.mkdir(parents=True, exist_ok=True)
    scenes, ens = [], {}
    for config in configs:
        scene = find_scene(config)
        if scene.name in ens:
            raise ValueError(f"{config}: scene name {scene.name!r} given twice")
        ens[scene.name] = {k: (_open_run(p) if k == "elastic" else open_ensemble(p))
                           for k, p in run_scene(config, data, plan).items()}
        scenes.append(scene)
    rel = lambda p: Path(p).relative_to(out).as_posix() if Path(p).is_relative_to(out) else str(p)  # noqa: E731
    md = ["# Results: the seed paper's section 6 with rss6", "",
          "Generated by `rss6 report " + " ".join(map(str, configs)) + f" -o {out} -n {plan.n} "
          f"--family-n {plan.family_n}`; every number and figure below comes from the netCDF files "
          f"that command wrote to `{rel(data)}/` (rerunning it reuses them). Errors are actual minus "
          "ideal rigid platform pose (docs/model.md section 6); 'max' and 'mean' are each realisation's "
          "maximum and mean over time of |error|, summarised over the realisations as a median and a "
          "95 % quantile, each with its distribution-free 95 % confidence interval. Units: mm, mm/s, "
          "mm/s^2 for x, y, z; rad, rad/s, rad/s^2 for rx, ry, rz.", ""]
    for scene in scenes:
        e = ens[scene.name]
        md += [f"## Scene `{scene.name}` ({_clearance_mm(scene)} mm clearances)", "",
               "Runs: " + "; ".join(_setting_line(e[k]) for k in ("quasi-static", "paper", "contact"))
               + ".", ""]
        t = e["contact"]["time"].values
        md += [f"![rigid motion]({rel(_rigid_figure(scene, t, figs))})", ""]
        for q in ("displacement", "velocity", "acceleration"):
            md += [f"![{q} error]({rel(_error_figure(scene, q, e, figs))})", ""]
        md += ["### Beside the paper's numbers (docs/model.md section 9)", ""] + _comparison_table(scene, e)
        md += ["", "### Which joint family contributes most (contact level)", "",
               "Medians over the finished realisations of each run (finished of run in the header); a "
               f"switched-off family keeps a {OFF * 1e6:g} um clearance: the contact level needs one, "
               "and its error is about proportional to the clearance, so such a family adds about "
               f"{OFF / scene.clearance.spherical_B * 100:.0f} % of what it adds at the scene's "
               "clearance.", ""] + _family_table(scene, e)
        md += ["", "### Where we differ from the paper, and why", ""] + _explanations(scene, e) + [""]
    if len(scenes) >= 2:
        md += ["## How the errors grow with the clearance", "",
               "Ratio of the medians of the larger-clearance scene to the smaller one (the paper "
               "reports displacement at both sizes only).", ""] + _growth_table(scenes, ens) + [""]
    path = out / "results.md"
    path.write_text("\n".join(md) + "\n", encoding="utf-8")
    return path
