"""``rss6 report``: the seed paper's section 6 reproduced with the pipeline, as docs/results.md.

For every scene given it runs (or, where the files exist, reuses: the ensembles
resume like ``rss6 run``) into DATA:
- ``SCENE_paper.nc``, ``SCENE_contact.nc``: N realisations with full histories;
- ``SCENE_quasi-static.nc``: N realisations (the rigid-link clearance kinematics);
- ``SCENE_elastic.nc``: the ideal-joint elastic run (one, deterministic);
- ``SCENE_contact_only{A,C,B}.nc``: the contact level with one joint family's
  clearances as in the scene and the other two switched off (10 um, see OFF);
- of a scene with [uncertain.*] inputs (manufacturing tolerances), which every level above draws,
  the elastic run is ``SCENE_elastic_nominal-inputs.nc`` and it and the joint-family runs hold
  those inputs at nominal, with ``SCENE_contact_nominal-inputs.nc`` as their all-joints run, so
  that the family table attributes the clearances' error alone;
- beside each file of such a variant of the scene, its scene text as ``<file>.toml``, which the file's
  ``history`` runs (``rss6 run SCENE_contact_onlyA.toml ...`` in DATA gives the same file);
then writes OUT/results.md and OUT/results/*.png from those files alone.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rss6core import (MODELS, default_integrator, default_time_step, model_level, models_with, parse_scene,
                      simulate, size_band)

from ..ensemble.cluster import WORKER_TIMEOUT_S, dask_client
from ..ensemble.run import EnsembleSpec, ensemble
from ..scenes.catalogue import find_scene
from ..analysis.plot_common import save_figure
from . import report_text as text
from .report_figures import LEVELS, error_figure, rigid_figure
from .report_text import clearance_mm as _clearance_mm
from ..scenes.variant import scene_variant, uncertain_tables
from ..analysis.estimators import min_n_for_quantile
from ..analysis.stats import ensemble_stats, in_window, level_notes
from ..files.opening import open_ensemble
from ..files.reading import load_netcdf
from ..files.records import file_window_label, run_dataset
from ..files.schema import EnsembleFileError, display_unit
from ..files.writing import write_netcdf
from ..vocabulary import CONFIDENCE, QUANTILES

__all__ = ["ReportPlan", "with_clearance", "run_scene", "write_report", "report_command", "PAPER_VALUES", "OFF",
           "LEVELS", "error_figure", "rigid_figure"]

# m: clearance of a switched-off joint family at the contact level, which needs positive
# clearances; the contact error shrinks in proportion to the clearance (tested), so a 10 um
# family adds about 1/25 of what it adds at 0.25 mm.  1 um joints are so stiff (Hertz K grows
# as clearance^-1/2) that Newton fails at 0.1 ms steps.
OFF = 1e-5
FAMILY_KEYS = {"A": ("revolute_radial_m", "revolute_axial_m"), "C": ("spherical_C_m",),
               "B": ("spherical_B_m",)}

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
    worker_timeout: float = WORKER_TIMEOUT_S   # s without workers before an external scheduler is given up
    overwrite_tracked: bool = False   # given --overwrite-tracked: the command results.md quotes needs it again


def with_clearance(text: str, values: dict[str, float], source: str = "<report>") -> str:
    """Scene TOML text with keys of its [clearance] table set to ``values`` (m), made on the parsed
    data; its first line records the override (see pipeline.scenes.variant)."""
    return scene_variant(text, {"clearance": values}, source)


def _only(text: str, family: str, source: str) -> str:
    """The scene with every joint family but ``family`` switched off (OFF, and without its
    [tolerance.<family>] band, which would otherwise set its sizes) and its uncertain inputs at nominal."""
    off = [k for f, keys in FAMILY_KEYS.items() if f != family for k in keys]
    drop = {"tolerance": [k.removesuffix("_m") for k in off]} | uncertain_tables(parse_scene(text, source))
    return scene_variant(text, {"clearance": {k: OFF for k in off}}, source, drop=drop)


def _nominal_inputs(text: str, source: str) -> str:
    """The scene with its [uncertain.*] inputs (and their correlations) held at nominal."""
    return scene_variant(text, {}, source, drop=uncertain_tables(parse_scene(text, source)))


def _elastic_run(scene, data: Path) -> Path:
    """Run (unless its file exists) the ideal-joint elastic level, which draws no clearances: one run,
    of the nominal robot where the scene has uncertain inputs; returns its file."""
    nominal = "_nominal-inputs" if scene.uncertain else ""
    path = data / f"{scene.name}_elastic{nominal}.nc"
    if not path.exists():
        if scene.uncertain:
            scene = parse_scene(_nominal_inputs(scene.source_text, scene.name), scene.name)
        result = simulate(scene, "elastic")
        ds = run_dataset(scene, result, model="elastic", integrator=default_integrator(scene, "elastic"),
                         dt=default_time_step(scene, "elastic"), elements=scene.simulation.elements_per_link)
        write_netcdf(ds.assign_attrs(_variant_history(ds, _variant_toml(scene.source_text, path))
                                     if nominal else {}), path)
    return path


def _variant_toml(text: str, path: Path) -> Path:
    """Write the scene ``text`` of a variant run beside its file ``path`` (unless it is there already, so
    that a rerun touches nothing); returns it."""
    toml = path.with_suffix(".toml")
    if not toml.is_file() or toml.read_text(encoding="utf-8") != text:
        toml.write_text(text, encoding="utf-8")
    return toml


def _variant_history(ds, toml: Path) -> dict:
    """The ``history`` of a variant run's file: its command with the variant's scene file ``toml`` (beside it)
    for the scene's name, which would rerun the shipped scene instead."""
    words = str(ds.attrs["history"]).split(" ")
    return {"history": " ".join(words[:2] + [toml.name] + words[3:])}


def _ensemble(scene, text, source, model, n, path, plan: ReportPlan, store, client) -> None:
    """Run or resume one of the report's ensembles into ``path`` (the report reads it again, into memory);
    a variant of the scene (``text`` not its own) is written beside it, which the file's history runs."""
    sim = scene.simulation
    spec = EnsembleSpec(text, source, model, default_integrator(scene, model),
                        default_time_step(scene, model), sim.elements_per_link, plan.seed, store)
    toml = _variant_toml(text, path) if text != scene.source_text else None
    ensemble(spec, n, path, workers=plan.workers, scheduler=plan.scheduler, worker_timeout=plan.worker_timeout,
             client=client, annotate=(lambda ds: _variant_history(ds, toml)) if toml else None).dataset.close()


def run_scene(config, data: Path, plan: ReportPlan, client=None) -> dict[str, Path]:
    """Run (or resume) every file the report needs for one scene; returns their paths by role.
    ``client``: an open dask client for all its ensembles, else each starts its own cluster."""
    scene = find_scene(config)
    data.mkdir(parents=True, exist_ok=True)
    paths = {"elastic": _elastic_run(scene, data)}
    for model, store in (("quasi-static", "summary"), ("paper", "full"), ("contact", "full")):
        path = data / f"{scene.name}_{model}.nc"
        _ensemble(scene, scene.source_text, str(config), model, plan.n, path, plan, store, client)
        paths[model] = path
    for family in FAMILY_KEYS:
        path = data / f"{scene.name}_contact_only{family}.nc"
        _ensemble(scene, _only(scene.source_text, family, str(config)), str(config), "contact",
                  plan.family_n, path, plan, "summary", client)
        paths[f"only{family}"] = path
    if scene.uncertain:   # the family runs' all-joints run: every clearance, inputs at nominal
        path = paths["nominal"] = data / f"{scene.name}_contact_nominal-inputs.nc"
        _ensemble(scene, _nominal_inputs(scene.source_text, str(config)), str(config), "contact",
                  plan.family_n, path, plan, "summary", client)
    return paths


# --- statistics: every number from pipeline.analysis.stats.ensemble_stats ---------------------------

def _stat(sds, stat: str, quantity: str, direction: str, statistic: str = "q50",
          bound: str = "estimate") -> float:
    """One number of a statistics Dataset: ``statistic`` of the per-realisation ``stat`` |error|."""
    return float(sds[f"{stat}_abs_error"].sel(statistic=statistic, bound=bound, quantity=quantity,
                                              direction=direction))


def _fmt(value: float, f: float) -> str:
    v = value * f if value is not None else np.nan
    return "-" if not np.isfinite(v) else f"{v:.3g}" if abs(v) >= 1e-3 else f"{v:.2e}"


def _cell(sds, stat, q, d, statistic: str, f: float) -> str:
    lo, est, hi = (_fmt(_stat(sds, stat, q, d, statistic, b), f) for b in ("lower", "estimate", "upper"))
    return f"{est} [{lo}, {hi}]"


def _banded(scene) -> bool:
    """Whether any joint family draws its clearance sizes from a tolerance band."""
    return any(size_band(scene, k.removesuffix("_m")) is not None for keys in FAMILY_KEYS.values() for k in keys)


def _clearance_words(scene) -> str:
    mm = _clearance_mm(scene)
    words = f"{mm} mm nominal clearances drawn from tolerance bands" if _banded(scene) else f"{mm} mm clearances"
    return words + (f" and {len(scene.uncertain.inputs)} manufacturing inputs" if scene.uncertain else "")


def _rigid_figure(scene, t, out: Path) -> Path:
    return save_figure(rigid_figure(scene, t), out / f"{scene.name}_rigid.png")


def _error_figure(scene, quantity: str, runs: dict, out: Path) -> Path:
    return save_figure(error_figure(scene, quantity, runs), out / f"{scene.name}_{quantity}.png")


def _open_run(path):
    """A single-run file (the elastic level), opened into memory; EnsembleFileError if unreadable."""
    ds = load_netcdf(path)
    if "error" not in ds:
        raise EnsembleFileError(f"{path}: not an rss6 run file (no 'error' variable); delete it and "
                                "rerun rss6 report")
    return ds


# --- the document ---------------------------------------------------------------

_ROWS = list(PAPER_VALUES)
_LEVELS = ("quasi-static", "paper", "contact")


def _setting_line(ds, sds) -> str:
    a = ds.attrs
    dt, sim = float(a["time_step_s"]), parse_scene(a["scene_toml"]).simulation
    step, level = f"step {dt * 1e3:g} ms", model_level(a["model"])
    if level.contact_joints and sim.contact_refinements:   # the contact kernel's adaptive step
        finest = dt / 2 ** sim.contact_refinements
        step = (f"adaptive step {dt * 1e3:g} ms, halved down to {finest * 1e6:g} us where"
                f" the local error estimate exceeds {sim.contact_tolerance:g} m")
    if level.contact_start:
        step += f", {sim.contact_start} start"
    return (f"{a['model']}: {a['integrator']}, {step}, "
            f"{a['elements_per_link']} elements per link, {_count(sds)} realisations, seed {a['seed']}")


def _count(sds) -> str:
    """'F finished / N' of a statistics Dataset."""
    return f"{sds.attrs['n_finished']} finished / {sds.attrs['n_finished'] + sds.attrs['n_failed']}"


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + [
        "| " + " | ".join(r) + " |" for r in rows]


MARKS = ("†", "‡", "§", "¶")


def _level_marks(st: dict) -> tuple[dict, list[str]]:
    """Which cells of the comparison table do not measure the robot in operation, by level and quantity
    (pipeline.analysis.stats.level_notes over the whole run: the paper level's velocities and accelerations
    measure the step, a drawn start's impacts are in the contact level's): {(level, quantity): mark} and
    the notes, each after its mark."""
    notes, marks = {}, {}
    for level in _LEVELS:
        for q in dict.fromkeys(q for _, q, _ in _ROWS):
            said = level_notes(st[level].attrs, {q}, {"whole"})
            for note in said:
                notes.setdefault(note, MARKS[len(notes)])
            marks[(level, q)] = "".join(notes[n] for n in said)
    return marks, [f"{mark} {note}." for note, mark in notes.items()]


def _comparison_table(scene, st: dict) -> list[str]:
    """The paper's numbers beside each level's median and 95 % quantile over the whole run, the cells that do
    not measure the robot marked (:func:`_level_marks`), with the marks' notes below."""
    mm = _clearance_mm(scene)
    head = ["statistic (per realisation)", "dir", "unit", f"paper, {mm} mm"]
    for level in (text.labelled(f"{lv}, {file_window_label('whole', st[lv].attrs)}", scene) for lv in _LEVELS):
        head += [f"{level}: median [95 % CI]", f"{level}: 95 % quantile [95 % CI]"]
    rows, (marks, notes) = [], _level_marks(st)
    for stat, q, d in _ROWS:
        f, unit = display_unit(q, d)
        cells = [_label(stat, q), d, unit, _fmt(PAPER_VALUES[(stat, q, d)].get(mm), f)]
        for level in _LEVELS:
            m = f" {marks[(level, q)]}" if marks[(level, q)] else ""
            cells += [_cell(st[level], stat, q, d, p, f) + m for p in ("q50", "q95")]
        rows.append(cells)
    return _table(head, rows) + ([""] + ["- " + n for n in notes] if notes else [])


def _label(stat: str, quantity: str) -> str:
    """'max |displacement error|' with the bars escaped for a markdown table."""
    bar = "\\|"
    return f"{stat} {bar}{quantity} error{bar}"


def _growth_table(scenes: list, st: dict) -> list[str]:
    fixed = sorted((s for s in scenes if not _banded(s)), key=_clearance_mm)
    (s1, e1), (s2, e2) = ((s, st[s.name]) for s in (fixed[0], fixed[-1]))
    m1, m2 = _clearance_mm(s1), _clearance_mm(s2)
    head = ["statistic", "dir", f"paper {m2}/{m1} mm"] + [f"{lv} median {m2}/{m1} mm" for lv in _LEVELS]
    rows = []
    for stat, q, d in _ROWS:
        pv = PAPER_VALUES[(stat, q, d)]
        rows.append([_label(stat, q), d, f"{pv[m2] / pv[m1]:.2f}" if m1 in pv and m2 in pv else "-"]
                    + [f"{_stat(e2[lv], stat, q, d) / _stat(e1[lv], stat, q, d):.2f}" for lv in _LEVELS])
    return _table(head, rows)


def _family_table(scene, st: dict) -> list[str]:
    """Medians of the contact level with all joints and with one family at a time, and the elastic run's
    maximum; of a scene with uncertain inputs, every run at nominal inputs (the all-joints run a family run)."""
    runs = [(name, st[role]) for name, role in _family_runs(scene)]
    head = ["statistic", "dir", "unit"] + [f"{name} ({_count(sds)})" for name, sds in runs]
    rows = []
    for stat, q, d in _ROWS:
        f, unit = display_unit(q, d)
        rows.append([_label(stat, q), d, unit] + [_fmt(_stat(sds, stat, q, d), f) for _, sds in runs]
                    + [_fmt(_stat(st["elastic"], stat, q, d, "max"), f)])
    return _table(head + ["elastic (" + text.labelled("no clearance", scene, True, False) + ")"], rows)


def _family_runs(scene) -> list[tuple[str, str]]:
    """The family table's columns as (label, role): the all-joints run (at nominal inputs where the scene has
    uncertain ones), then each family alone."""
    return [("all joints", "nominal" if scene.uncertain else "contact")] + [(f"only {f}", f"only{f}")
                                                                             for f in FAMILY_KEYS]


def _window_table(sds, attrs) -> list[str]:
    """Medians [95 % CI] of the contact level's per-realisation summaries in the startup and steady
    windows and over the whole run, from its statistics by window ``sds``; ``attrs``: its file's."""
    windows = ("startup", "steady", "whole")
    head = ["statistic (per realisation)", "dir", "unit"] + [
        f"{file_window_label(w, attrs)}: median [95 % CI]" for w in windows] + ["steady: 5 % - 95 % quantile"]
    rows, steady = [], in_window(sds, "steady")
    for stat, q, d in _ROWS:
        f, unit = display_unit(q, d)
        spread = " - ".join(_fmt(_stat(steady, stat, q, d, p), f) for p in ("q05", "q95"))
        rows.append([_label(stat, q), d, unit] + [_cell(in_window(sds, w), stat, q, d, "q50", f)
                                                  for w in windows] + [spread])
    return _table(head, rows)


def _largest_family(st: dict, stat, q, d) -> tuple[str, float, str]:
    """The family whose run has the largest median, its share of the three medians, and whether the data
    resolve it: its median's lower bound above every other's upper bound (else said, with the runner-up)."""
    values = {f: _stat(st[f"only{f}"], stat, q, d) for f in FAMILY_KEYS}
    best = max(values, key=values.get)
    lower = _stat(st[f"only{best}"], stat, q, d, bound="lower")
    overlapping = [f for f in FAMILY_KEYS if f != best and not lower > _stat(st[f"only{f}"], stat, q, d, bound="upper")]
    n = int(st[f"only{best}"].attrs["n_finished"])
    said = (f"; not resolved at n = {n}: its median's interval does not clear {' and '.join(overlapping)}'s"
            if overlapping else "")
    return best, values[best] / max(sum(values.values()), 1e-300), said


def _displacement_fields(scene, st: dict, paper_dx: float) -> dict:
    """The numbers of text.DISPLACEMENT (mm) from the statistics Datasets."""
    qs = max(_stat(st["quasi-static"], "max", "displacement", d) for d in "xyz")
    ct = max(_stat(st["contact"], "max", "displacement", d) for d in "xyz")
    el = max(_stat(st["elastic"], "max", "displacement", d, "max") for d in "xyz")
    return {"scene": scene.name, "mm": _clearance_mm(scene), "paper_dx": paper_dx * 1e3,
            "contact_dx": ct * 1e3, "contact_ratio": ct / paper_dx, "qs_dx": qs * 1e3,
            "qs_ratio": qs / paper_dx, "how": text.HOW[scene.simulation.quasi_static_eccentricity],
            "contact_what": f" ({text.contents(scene)})" if scene.uncertain else "",
            "qs_what": ("the rigid-link kinematics of the clearances and the drawn manufacturing inputs together"
                        if scene.uncertain else "the rigid-link clearance kinematics alone"),
            "elastic_what": f", {text.contents(scene, nominal=True)}" if scene.uncertain else "",
            "elastic_dx": el * 1e3, "sag": _stat(st["contact"], "mean", "displacement", "z") * 1e3,
            "contact_z": _stat(st["contact"], "max", "displacement", "z") * 1e3}


def _explanations(scene, st: dict, dt: float, by_window, start: str) -> list[str]:
    """The physical reasons for the large differences from the paper, filled from this run's
    statistics (templates in pipeline.studies.report_text); ``dt``: the paper level's step, s;
    ``by_window``: the contact level's statistics by window (its attributes: the windows' times),
    ``start`` its initial state."""
    mm = _clearance_mm(scene)
    out = []
    paper_dx = max(v.get(mm, np.nan) for (_, q, _), v in PAPER_VALUES.items() if q == "displacement")
    if np.isfinite(paper_dx):
        out.append(text.DISPLACEMENT.format(**_displacement_fields(scene, st, paper_dx)))
    pv = PAPER_VALUES[("mean", "velocity", "z")].get(mm)
    if pv is not None:
        lv, cv = (_stat(st[lv], "mean", "velocity", "z") for lv in ("paper", "contact"))
        out.append(text.VELOCITY.format(paper_v=pv * 1e3, paper_level_v=lv * 1e3, contact_v=cv * 1e3,
                                        dt_ms=dt * 1e3, contact_v_ratio=cv / pv))
    pa = PAPER_VALUES[("max", "acceleration", "z")].get(mm)
    if pa is not None:
        la, ca = (_stat(st[lv], "max", "acceleration", "z") for lv in ("paper", "contact"))
        fam, share, resolved = _largest_family(st, "max", "acceleration", "z")
        startup, steady = (_stat(in_window(by_window, w), "max", "acceleration", "z") for w in ("startup", "steady"))
        out.append(text.ACCELERATION.format(paper_a=pa * 1e3, paper_level_a=la * 1e3, contact_a=ca * 1e3,
                                            startup_a=startup * 1e3, steady_a=steady * 1e3,
                                            steady=text.window_times("steady", by_window.attrs),
                                            start=text.start_text(text.START_PEAKS, start, by_window.attrs),
                                            family=fam, share=100 * share, resolved=resolved, family_what=(
                                                f" ({text.contents(scene, nominal=True)})" if scene.uncertain else "")))
    return out


def _open_scene(config, data: Path, plan: ReportPlan, client) -> dict:
    """The scene's files by role, run where missing (on ``client``) and opened into memory; of an ensemble
    that an earlier, larger -n (--family-n) grew, only the first -n realisations, as the command says."""
    def first(role, ds):
        n = plan.family_n if role.startswith("only") or role == "nominal" else plan.n
        return ds.sel(realization=ds["realization"].values < n)
    paths = run_scene(config, data, plan, client)
    opened = {k: (_open_run(p) if _one_run(k) else first(k, open_ensemble(p))) for k, p in paths.items()}
    for role, ds in opened.items():   # as rss6 run says it, and results.md under the tables
        if note := text.failure_note(ds):
            print(f"rss6 report: {paths[role]}: {note}", file=sys.stderr)
    return opened


def _one_run(role: str) -> bool:
    """Whether the file of ``role`` (a level's name or onlyA/C/B) holds one deterministic run: a
    level that draws no clearances has no ensemble."""
    return role in MODELS and role not in models_with("draws_clearances")


def _inputs_paragraph(scene) -> list[str]:
    """The paragraph (and blank line) naming a scene's uncertain inputs, which its levels draw; none without."""
    if not scene.uncertain:
        return []
    names = ", ".join(i.name for i in scene.uncertain.inputs)
    return [text.INPUTS.format(count=len(scene.uncertain.inputs), names=names), ""]


def _scene_section(scene, e: dict, st: dict, figs: Path, rel) -> list[str]:
    md = [f"## Scene `{scene.name}` ({_clearance_words(scene)})", "",
          "Runs: " + "; ".join(_setting_line(e[k], st[k]) for k in _LEVELS) + ".", ""]
    md += [f"![rigid motion]({rel(_rigid_figure(scene, e['contact']['time'].values, figs))})", ""]
    for q in ("displacement", "velocity", "acceleration"):
        md += [f"![{q} error]({rel(_error_figure(scene, q, e, figs))})", ""]
    md += ["### Beside the paper's numbers (docs/model.md section 9)", ""] + _inputs_paragraph(scene)
    steady = text.window_times("steady", e["contact"].attrs)
    md += [text.COMPARISON.format(whole=file_window_label("whole", e["contact"].attrs), steady=steady), ""]
    md += _comparison_table(scene, st) + text.failure_notes([(lv, e[lv]) for lv in _LEVELS])
    md += ["", f"### Which joint family contributes most ({text.labelled('contact level', scene, True, False)})",
           "", text.FAMILY.format(off_um=OFF * 1e6, off_percent=OFF / scene.clearance.spherical_B * 100)
           + (text.FAMILY_NOMINAL if scene.uncertain else ""), ""] + _family_table(scene, st)
    md += text.failure_notes([(name, e[role]) for name, role in _family_runs(scene)])
    contact = e["contact"]
    by_window = ensemble_stats(contact, window=None)
    start = parse_scene(contact.attrs["scene_toml"]).simulation.contact_start
    md += ["", f"### Start-up and steady operation ({text.labelled('contact level', scene, brackets=False)})", "",
           text.WINDOWS_PARAGRAPH.format(**{w: text.window_times(w, contact.attrs) for w in ("startup", "steady")})
           + " " + text.start_text(text.START, start, contact.attrs), ""]
    md += _window_table(by_window, contact.attrs) + text.failure_notes([("contact", contact)])
    md += ["", "### Where we differ from the paper, and why", ""]
    return md + _explanations(scene, st, float(e["paper"].attrs["time_step_s"]), by_window, start) + [""]


def write_report(configs: list, out: Path, plan: ReportPlan, data: Path | None = None) -> Path:
    """Run what is missing and write OUT/results.md with its figures in OUT/results/."""
    out = Path(out)
    data = Path(data) if data is not None else out / "results-data"
    figs = out / "results"
    figs.mkdir(parents=True, exist_ok=True)
    scenes, ens, st = [], {}, {}
    with dask_client(plan.workers, plan.scheduler) as client:   # one cluster for every ensemble
        for config in configs:
            scene = find_scene(config)
            if scene.name in ens:
                raise ValueError(f"{config}: scene name {scene.name!r} given twice")
            ens[scene.name] = _open_scene(config, data, plan, client)
            st[scene.name] = {k: ensemble_stats(ds) for k, ds in ens[scene.name].items()}
            scenes.append(scene)
    rel = lambda p: Path(p).relative_to(out).as_posix() if Path(p).is_relative_to(out) else str(p)  # noqa: E731
    md = ["# Results: the seed paper's section 6 with rss6", "",
          text.INTRO.format(command=report_command(configs, out, plan), data=rel(data), confidence=95,
                            min_n_q95=min_n_for_quantile(QUANTILES["q95"], CONFIDENCE)), ""]
    for scene in scenes:
        md += _scene_section(scene, ens[scene.name], st[scene.name], figs, rel)
    if len({_clearance_mm(s) for s in scenes if not _banded(s)}) >= 2:
        md += ["## How the errors grow with the clearance", "", text.GROWTH, ""]
        md += _growth_table(scenes, st) + [""]
    path = out / "results.md"
    path.write_text("\n".join(md) + "\n" + kept_studies(path), encoding="utf-8")
    return path


def report_command(configs, out, plan: ReportPlan) -> str:
    """The command that regenerates the report (results.md quotes it): its scenes, folder and sizes, and
    the seed and --overwrite-tracked where they were given."""
    return ("rss6 report " + " ".join(map(str, configs)) + f" -o {out} -n {plan.n} --family-n {plan.family_n}"
            + (f" --seed {plan.seed}" if plan.seed else "")
            + (" --overwrite-tracked" if plan.overwrite_tracked else ""))


KEPT_MARKER = "<!-- rss6 report keeps what follows: sections written from other commands' output -->"


def kept_studies(path: Path) -> str:
    """The part of an existing results.md from :data:`KEPT_MARKER` on (the studies of other commands,
    such as ``rss6 map``, which the report does not run), so that regenerating the report keeps it."""
    if not path.is_file():
        return ""
    text = path.read_text(encoding="utf-8")
    at = text.find(KEPT_MARKER)
    return "" if at < 0 else text[at:]
