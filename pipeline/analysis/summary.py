"""Scene summaries for ``rss6 check``: what a user checks before launching a run."""
from __future__ import annotations

import re

import numpy as np

from rss6core import (crank_inertia, crank_on_motor_frequency, draws_per_realisation, inverse_dynamics,
                      models_with, natural_frequencies, rigid_motion, rod_inertia)

from ..files.schema import display_unit
from ..vocabulary import DIRECTIONS, FINISHED
from .workspace import format_workspace, workspace_summary

__all__ = ["CLEARANCE_LEVELS", "scene_summary", "format_summary", "error_summary", "format_errors",
           "failure_reasons"]


def scene_summary(scene) -> dict:
    """JSON-ready summary: crank angles, torques and link masses along the scene's trajectory, and its
    workspace report (:func:`.workspace.workspace_summary`)."""
    motion = rigid_motion(scene)
    loads = inverse_dynamics(scene, motion)
    alpha = np.degrees(motion.alpha)
    omega = natural_frequencies(scene)
    return {
        "scene": scene.name,
        "source": scene.source_path,
        "duration_s": scene.trajectory.duration,
        "time_step_s": scene.time_step,
        "steps": len(scene.times) - 1,
        "home_crank_angles_deg": alpha[0].tolist(),
        "crank_angle_range_deg": np.stack([alpha.min(0), alpha.max(0)], -1).tolist(),
        "max_actuator_torque_Nm": np.abs(loads.torque).max(0).tolist(),
        "max_joint_force_N": {j: np.linalg.norm(f, axis=-1).max(0).tolist() for j, f in
                              (("A", loads.force_A), ("C", loads.force_C), ("B", loads.force_B))},
        "link_masses_kg": {"crank": crank_inertia(scene).mass, "rod": rod_inertia(scene).mass,
                           "platform": scene.platform.mass},
        "model": scene.simulation.model,
        "elements_per_link": scene.simulation.elements_per_link,
        "dof": int(len(omega)),
        "natural_frequencies_Hz": (omega[:12] / (2 * np.pi)).tolist(),
        # undamped explicit limit; Rayleigh stiffness damping lowers it further
        "critical_time_step_s": float(2.0 / omega[-1]),
        **clearance_summary(scene),
        **workspace_summary(scene),
    }


def clearance_summary(scene) -> dict:
    """Clearances (m), the bands their sizes are drawn from (m; none: nominal sizes), their sampling
    laws, the contact settings and what ``rss6 run`` runs by default."""
    import dataclasses

    from rss6core import size_band
    bands = {f: size_band(scene, f) for f in dataclasses.asdict(scene.clearance)}
    return {"clearances_m": dataclasses.asdict(scene.clearance),
            "size_bands_m": {f: dataclasses.asdict(b) for f, b in bands.items() if b is not None},
            "sampling": dataclasses.asdict(scene.sampling),
            "contact": {**dataclasses.asdict(scene.contact),
                        "time_step_s": scene.simulation.contact_time_step,
                        "integrator": scene.simulation.contact_integrator,
                        "start": scene.simulation.contact_start},
            "actuator": actuator_summary(scene),
            "uncertain_inputs": uncertain_summary(scene),
            "run_default_level": run_default_level(scene)}


def actuator_summary(scene) -> dict:
    """How the motors drive the cranks at the contact level; for a servo its stiffness (N m/rad) and the
    frequency of the rigid crank on it, sqrt(k_m / J_A) / 2 pi (Hz, J_A the crank's inertia about A)."""
    k_m = scene.actuator.motor_stiffness
    if k_m is None:
        return {"drive": "prescribed"}
    return {"drive": "servo", "stiffness_N_m_per_rad": k_m,
            "crank_on_motor_Hz": crank_on_motor_frequency(scene, k_m)}


def uncertain_summary(scene) -> dict:
    """The [uncertain.*] inputs (key, each, draws, law with its parameters in the key's TOML unit)
    and [correlation.*] matrices: empty for a scene without."""
    u = scene.uncertain
    return {"inputs": {i.name: {"parameter": i.parameter, "each": i.each, "draws": i.count, "law": i.law_text(),
                                "units": i.draw_units} for i in u.inputs},
            "correlations": {c.name: {"inputs": list(c.inputs), "matrix": [list(r) for r in c.matrix]}
                             for c in u.correlations}}


CLEARANCE_LEVELS = models_with("draws_clearances")   # the levels whose realisations draw clearances


def run_default_level(scene) -> str | None:
    """The scene's level for ``rss6 run``, or None when its realisations do not differ (no clearances,
    no uncertain inputs) while the scene has clearances: an ensemble of it would be N identical runs."""
    c = scene.clearance
    sizes = (c.revolute_radial, c.revolute_axial, c.spherical_C, c.spherical_B)
    model = scene.simulation.model
    return model if draws_per_realisation(scene, model) or not any(sizes) else None


def format_summary(s: dict) -> str:
    """Human-readable table of :func:`scene_summary` (degrees, N m, N, kg)."""
    legs = "".join(f"{i:>9d}" for i in range(1, 7))
    row = lambda name, vals, fmt="9.3f": f"{name:<24s}" + "".join(f"{v:{fmt}}" for v in vals)  # noqa: E731
    lines = [
        f"scene {s['scene']!r} ({s['source']}): valid",
        f"trajectory {s['duration_s']} s in {s['steps']} steps of {s['time_step_s']} s",
        f"link masses: crank {s['link_masses_kg']['crank']:.4f} kg, rod "
        f"{s['link_masses_kg']['rod']:.4f} kg, platform {s['link_masses_kg']['platform']:.4f} kg",
        f"{'leg':<24s}{legs}",
        row("home crank angle [deg]", s["home_crank_angles_deg"]),
        row("min crank angle [deg]", [r[0] for r in s["crank_angle_range_deg"]]),
        row("max crank angle [deg]", [r[1] for r in s["crank_angle_range_deg"]]),
        row("max |torque| [N m]", s["max_actuator_torque_Nm"]),
    ] + [row(f"max |F_{j}| [N]", v) for j, v in s["max_joint_force_N"].items()] + [
        f"elastic model: {s['elements_per_link']} elements per link, {s['dof']} DOFs; lowest "
        f"natural frequencies [Hz]: " + ", ".join(f"{f:.1f}" for f in s["natural_frequencies_Hz"][:6]),
        f"explicit critical time step 2/omega_max: {s['critical_time_step_s']:.3e} s"]
    return "\n".join(lines + format_workspace(s) + _clearance_lines(s))


def _clearance_lines(s: dict) -> list[str]:
    join = lambda d: ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}"  # noqa: E731
                               for k, v in d.items())
    level = s["run_default_level"]
    bands = ", ".join(f"{f} {b['law']} {1e3 * b['low']:g}-{1e3 * b['high']:g}"
                      + (f" (std {1e3 * b['std']:g})" if b["law"] == "normal" else "")
                      for f, b in s["size_bands_m"].items())
    return ["clearances [mm]: " + ", ".join(f"{k} {1e3 * v:g}" for k, v in s["clearances_m"].items()),
            "clearance sizes drawn per joint [mm]: " + (bands or "none (every joint at its nominal size)"),
            "sampling (fractions of the clearance): " + join(s["sampling"]),
            "contact (SI): " + join(s["contact"]),
            _actuator_line(s["actuator"]),
            *_uncertain_lines(s["uncertain_inputs"]),
            f"rss6 run default level: {level}" if level else
            f"rss6 run default level: none (the scene's {s['model']!r} has no clearances; "
            "rss6 run asks for --model)"]


def _actuator_line(a: dict) -> str:
    if a["drive"] == "prescribed":
        return "actuator: prescribed (each crank at its commanded angle)"
    return (f"actuator: servo, {a['stiffness_N_m_per_rad']:g} N m/rad about the commanded angle at the contact "
            f"level (the rigid crank on it: {a['crank_on_motor_Hz']:.1f} Hz; the lower levels prescribe the angle)")


def _uncertain_lines(u: dict) -> list[str]:
    """One line per uncertain input and correlation (none for a scene without)."""
    lines = [f"uncertain input {name}: {i['parameter']}, each {i['each']} ({i['draws']} draws), {i['law']}"
             for name, i in u["inputs"].items()]
    return lines + [f"correlation {name}: Gaussian copula over {', '.join(c['inputs'])}, matrix {c['matrix']}"
                    for name, c in u["correlations"].items()]


def error_summary(ds) -> dict:
    """JSON-ready max and mean |error| per quantity and direction of a run Dataset, SI: the whole run
    under ``max_abs_error``/``mean_abs_error``, the startup and steady windows under
    ``max_abs_error_by_window``/``mean_abs_error_by_window`` ({window: {quantity: {direction: value}}})."""
    from ..files.schema import unit_json
    from .stats import in_window
    out = {"steady_after_s": float(ds.attrs["steady_after_s"]), "settle_time_s": float(ds.attrs["settle_time_s"])}
    for name in ("max_abs_error", "mean_abs_error"):
        out[name] = _table(in_window(ds, "whole")[name])
        out[f"{name}_by_window"] = {w: _table(in_window(ds, w)[name]) for w in ("startup", "steady")}
    out["unit"] = unit_json()
    return out


def _table(var) -> dict:
    """{quantity: {direction: value}} of a (quantity, direction) DataArray; None for NaN (an empty window)."""
    from .stats import json_number
    return {str(q): {str(d): json_number(var.sel(quantity=q, direction=d)) for d in var.direction.values}
            for q in var.quantity.values}


def contact_peaks(peak) -> dict:
    """Max contact force per joint family {A, C, B} (N) from per-joint peaks A1..A6, C1..C6, B1..B6."""
    peak = np.asarray(peak, float).reshape(3, 6)
    return {family: float(np.max(row)) for family, row in zip("ACB", peak)}


def format_errors(summary: dict) -> str:
    """Table of :func:`error_summary` in the paper's display units: the whole run's maxima and means,
    then the maxima of the startup and steady windows."""
    from ..files.records import file_window_label
    head = f"{'':<39s}" + "".join(f"{d:>11s}" for d in DIRECTIONS)
    rows = [("max_abs_error", "whole", summary["max_abs_error"]),
            ("mean_abs_error", "whole", summary["mean_abs_error"])]
    rows += [("max_abs_error", w, summary["max_abs_error_by_window"][w]) for w in ("startup", "steady")]
    lines = [head]
    for stat, window, table in rows:
        if window == "startup":
            lines.append(f"maxima per window, {file_window_label('startup', summary)} and "
                         f"{file_window_label('steady', summary)}:")
        for q, vals in table.items():
            units = [display_unit(q, d) for d in DIRECTIONS]
            label = f"{stat.split('_')[0]} |{q[:5]}| [{units[0][1]}; {units[3][1]}]"
            if window != "whole":
                label = f"{window[:7]} " + label
            cells = [np.nan if vals[d] is None else vals[d] * f for d, (f, _) in zip(DIRECTIONS, units)]
            lines.append(f"{label:<39s}" + "".join(f"{c:11.3e}" for c in cells))
    return "\n".join(lines)


_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


# what a failed run's refusal points to (the scene's magnitudes, a near-singular pose, an explicit step)
CHECK_HINT = "`rss6 check` shows the scene's values, its workspace and its explicit critical step"


def every_realisation_failed(ds, path, so: str = "it has no statistics") -> str | None:
    """The one-line refusal of an ensemble (or a single run's file) whose realisations all failed, naming
    the file, what follows (``so``: no statistics, nothing to plot) and the most frequent reason; None
    when one finished, or for a file without statuses (a statistics file)."""
    if "status" not in ds.variables and "status" not in ds.attrs:
        return None
    status, _ = _statuses(ds)
    if status.size == 0 or (status == FINISHED).any():
        return None
    count, message = _grouped_failures(ds)[0]
    why = (f"the run failed, so {so} ({message})" if status.size == 1 else
           f"all {status.size} realisations failed, so {so} (the most frequent reason, "
           f"{count} of {status.size}: {message})")
    return f"{path}: {why}; {CHECK_HINT}"


def _statuses(ds) -> tuple[np.ndarray, np.ndarray]:
    """The status and message of every realisation of an ensemble, or of a single run's file (attributes)."""
    if "status" in ds.variables:
        status = ds["status"].values.astype(str)
        messages = ds["status_message"].values.astype(str) if "status_message" in ds.variables else ""
        return status, np.broadcast_to(np.asarray(messages, dtype=str), status.shape)
    return np.array([str(ds.attrs["status"])]), np.array([str(ds.attrs.get("status_message", ""))])


def _grouped_failures(ds) -> list[tuple[int, str]]:
    """(count, first message) of each reason the failed realisations give (their messages alike but for
    their numbers: time, step, size), most frequent first."""
    status, messages = _statuses(ds)
    messages = messages[status != FINISHED]
    reasons, first, counts = np.unique([_NUMBER.sub("#", m) for m in messages], return_index=True,
                                       return_counts=True)
    return [(int(counts[i]), messages[first[i]] or "(no message)") for i in np.lexsort((first, -counts))]


def failure_reasons(ds, shown: int = 5) -> list[str]:
    """Lines naming how many realisations of an ensemble failed and why: one line per reason (the
    messages alike but for their numbers: time, step, size), most frequent first, at most ``shown``,
    each with its first realisation's message; empty when none failed."""
    status = ds["status"].values.astype(str)
    failed = int((status != FINISHED).sum())
    if not failed:
        return []
    grouped = _grouped_failures(ds)
    lines = [f"{failed} of {len(status)} realisations failed:"]
    lines += [f"  {count} x {message}" + (" (the first; the rest differ only in their numbers)" if count > 1 else "")
              for count, message in grouped[:shown]]
    if len(grouped) > shown:
        lines.append(f"  ... and {len(grouped) - shown} other reasons "
                     f"({sum(count for count, _ in grouped[shown:])} realisations)")
    return lines
