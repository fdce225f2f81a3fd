"""What a drawn-clearance answer leaves out: the joints resting on their walls under the robot's loads.

The quasi-static level with ``quasi_static_eccentricity = "drawn"`` (the paper's law) and the paper level
place each joint's element anywhere inside its play; under gravity and inertia loads the elements rest
against their walls, which the contact level shows and the quasi-static level's ``"reaction"`` mode
reproduces to 1.5 % of the error on a slowed trajectory (docs/guide.md, "One realisation of each
level"): on the paper scene the steady z displacement error is about 1 mm against 0.07-0.1 mm drawn.
A designer's answer (``rss6 reliability``, ``allocate``, ``budget``, and the statistics ``run`` and ``stats``
print) at such a level says so, with the loaded state's steady maxima from one quasi-static run at the nominal
sizes, so that the size of what the answer leaves out is on the screen beside it.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from rss6core import model_level, parse_scene, simulate

from ..scenes.variant import scene_variant, uncertain_tables
from ..vocabulary import DIRECTIONS, FAMILIES

__all__ = ["leaves_out_loaded_joints", "loaded_joint_maxima", "loaded_joints_note", "loaded_breaches"]

TRANSLATIONS = FAMILIES["translation"]   # x, y, z: the directions the loaded maxima are given in


def leaves_out_loaded_joints(scene, model: str) -> bool:
    """Whether ``model`` on ``scene`` places the joints inside their play rather than where the loads
    push them: the paper level, and the quasi-static level with drawn eccentricities."""
    level = model_level(model)
    if not level.draws_clearances or level.contact_joints:
        return False
    return level.redraws_every_step or scene.simulation.quasi_static_eccentricity == "drawn"


def _loaded_scene(scene):
    """The nominal robot (no [uncertain.*] inputs) at its nominal clearance sizes (no size bands, no
    relative size tolerance) with the quasi-static level's joints at their walls along the rigid joint
    forces."""
    tolerance = [f.name for f in dataclasses.fields(scene.tolerance) if getattr(scene.tolerance, f.name) is not None]
    overrides = {"simulation": {"quasi_static_eccentricity": "reaction"}}
    if scene.sampling.size_tolerance > 0.0:
        overrides["sampling"] = {"size_tolerance": 0.0}
    drop = {"tolerance": tolerance} | uncertain_tables(scene)
    return parse_scene(scene_variant(scene.source_text, overrides, scene.name, add=True, drop=drop), scene.name)


def loaded_joint_maxima(scene) -> np.ndarray:
    """max |displacement error| (m) in x, y, z over the steady window (t >= steady_after_s) of one
    quasi-static run of the nominal robot with its joints at their walls, at the nominal sizes."""
    loaded = _loaded_scene(scene)
    result = simulate(loaded, "quasi-static")
    steady = result.t >= loaded.simulation.steady_after
    return np.abs(result.displacement[steady][:, [DIRECTIONS.index(d) for d in TRANSLATIONS]]).max(axis=0)


def loaded_joints_note(scene, model: str, specs=(), robot: str = "the nominal robot at its nominal sizes"
                       ) -> list[str]:
    """The lines a designer's answer at a level that leaves the loaded joints out ends with (none
    otherwise): what the answer assumes and the loaded state's steady displacement maxima of ``robot``
    (``scene``, described so), then a warning naming each of ``specs`` (Spec or Event) they are already past."""
    if not leaves_out_loaded_joints(scene, model):
        return []
    maxima = loaded_joint_maxima(scene)
    x, y, z = 1e3 * maxima
    where = ("redraws each joint anywhere inside its play every step" if model_level(model).redraws_every_step
             else "places each joint anywhere inside its play (quasi_static_eccentricity = \"drawn\")")
    lines = [f"note: the {model} level {where}; the scene's loads push the joints against their walls, where "
             f"one quasi-static run of {robot} (\"reaction\") gives steady "
             f"displacement maxima x, y, z = {x:.3g}, {y:.3g}, {z:.3g} mm: this answer does not include that; "
             "the contact level does (docs/guide.md, \"One realisation of each level\")"]
    broken = loaded_breaches(maxima, specs)
    if broken:
        lines.append(f"warning: under its loads {robot} is past the limit of {'; '.join(broken)}: judge it with "
                     "quasi_static_eccentricity = \"reaction\" in the scene's [simulation] or at the contact level")
    return lines


def loaded_breaches(maxima: np.ndarray, limits) -> list[str]:
    """Each translation limit of ``limits`` (Spec or Event on a max |displacement| over the steady or whole
    run) that the loaded state's steady maxima (m, x y z) are already past, as "'SPEC' (z 0.288 mm)"; a limit
    on the spread (@std) is not a limit on one robot's maximum, and a lower limit (>=, >) is not one the loaded
    joints' added error can break, so both are left out."""
    out = []
    for limit in limits:
        if (limit.quantity != "displacement" or getattr(limit, "measure", "max") != "max"
                or limit.window == "startup" or getattr(limit, "statistic", None) == "std"
                or getattr(limit, "op", "<=") not in ("<=", "<")):
            continue
        past = limit.exceeds if hasattr(limit, "exceeds") else (lambda value, spec=limit: not spec.holds(value))
        over = [f"{d} {maxima[TRANSLATIONS.index(d)] / limit.factor:.3g} {limit.unit}" for d in limit.directions
                if d in TRANSLATIONS and past(maxima[TRANSLATIONS.index(d)])]
        if over:
            out.append(f"{limit.text!r} ({', '.join(over)})")
    return out
