"""The model levels and what each one is: the one table the core and the pipeline ask.

A leaf of the core (it imports nothing): the scene schema takes the level names from here, below
the ladder that runs them (:mod:`.models`), and code asks a level's property here instead of
comparing level names.  The levels, cheapest first, as docs/model.md's ladder L0-L4.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from types import MappingProxyType

__all__ = ["ModelLevel", "MODEL_LEVELS", "MODELS", "model_level", "models_with", "default_time_step",
           "default_integrator", "draws_per_realisation", "check_uncertain_level"]


@dataclass(frozen=True, kw_only=True)
class ModelLevel:
    """One model level's name and yes/no properties (no quantities: those are the scene's)."""
    name: str                           # as in [simulation] model, --model and a file's model attribute
    rung: str                           # its label on docs/model.md's ladder, L0 .. L4
    description: str                    # a few words for help texts
    elastic_links: bool = False         # flexible links integrated in time; else 6 pose unknowns, no steps
    draws_clearances: bool = False      # each realisation draws clearances; else all are one run
    redraws_every_step: bool = False    # the draw is renewed at every time step (the paper's method)
    function_of_one_draw: bool = False  # the error is a function of one draw (given draws, Sobol' indices)
    linear_in_clearances: bool = False  # the error scales exactly with the clearances (budget's exact scaling)
    contact_forces: bool = False        # it reports joint contact forces (max_contact_force)
    contact_joints: bool = False        # joints as contact pairs on their own nodes (the compiled numba kernel)
    contact_start: bool = False         # it takes [simulation] contact_start (--start)
    realised_robot: bool = False        # it runs the realised robot of a scene's [uncertain.*] inputs
    time_step_field: str = "time_step"  # the Simulation field holding its default time step (s)
    integrator_field: str = "integrator"  # the Simulation field naming its default integrator (files
                                          # record it even for the levels that integrate nothing)


MODEL_LEVELS = MappingProxyType({level.name: level for level in (
    ModelLevel(name="rigid", rung="L0", description="no error, a check (or a realised robot's geometric error)",
               realised_robot=True),
    ModelLevel(name="quasi-static", rung="L1", description="clearances, no dynamics", draws_clearances=True,
               function_of_one_draw=True, linear_in_clearances=True, realised_robot=True),
    ModelLevel(name="elastic", rung="L2", description="flexible links, no clearances", elastic_links=True,
               realised_robot=True),
    ModelLevel(name="paper", rung="L3", description="elastic + the paper's clearance closure", elastic_links=True,
               draws_clearances=True, redraws_every_step=True, contact_forces=True, realised_robot=True),
    ModelLevel(name="contact", rung="L4", description="clearance contact dynamics, by far the dearest",
               elastic_links=True, draws_clearances=True, function_of_one_draw=True, contact_forces=True,
               contact_joints=True, contact_start=True, realised_robot=True, time_step_field="contact_time_step",
               integrator_field="contact_integrator"),
)})
MODELS = tuple(MODEL_LEVELS)   # the level names, cheapest first

_PROPERTIES = tuple(f.name for f in dataclasses.fields(ModelLevel) if f.type == "bool")


def model_level(name: str) -> ModelLevel:
    """The level called ``name``, or ValueError naming the levels there are."""
    if name not in MODEL_LEVELS:
        raise ValueError(f"unknown model {name!r}; choose one of {', '.join(MODELS)}")
    return MODEL_LEVELS[name]


def models_with(prop: str) -> tuple[str, ...]:
    """The names of the levels (cheapest first) whose yes/no property ``prop`` holds."""
    if prop not in _PROPERTIES:
        raise ValueError(f"unknown level property {prop!r}; choose one of {', '.join(_PROPERTIES)}")
    return tuple(name for name, level in MODEL_LEVELS.items() if getattr(level, prop))


def draws_per_realisation(scene, model: str) -> bool:
    """Whether realisations of ``model`` on ``scene`` differ: the level draws clearances, or the scene
    has uncertain inputs (each realisation a realised robot: every level draws then)."""
    return model_level(model).draws_clearances or bool(scene.uncertain)


def check_uncertain_level(scene, model: str) -> None:
    """ValueError (one line, naming the level) if ``scene`` has uncertain inputs that ``model`` cannot
    take yet: never ignore them silently."""
    if scene.uncertain and not model_level(model).realised_robot:
        *some, last = models_with("realised_robot")
        raise ValueError(f"the {model} level cannot take [uncertain.*] inputs yet (the "
                         f"{', '.join(some)} and {last} levels can)")
    level = model_level(model)
    per_link = [i.name for i in scene.uncertain.inputs if i.each == "link"] if scene.uncertain else []
    if level.contact_joints and per_link:
        raise ValueError(f"[uncertain.{per_link[0]}] each = \"link\": the contact level takes one shared draw of "
                         "a link material (its kernel holds one crank and one rod matrix); set each = \"one\"")
    closure = level.draws_clearances and not level.elastic_links   # the level that reads quasi_static_eccentricity
    if scene.uncertain and scene.simulation.quasi_static_eccentricity == "reaction" and closure:
        raise ValueError("the quasi-static level's reaction eccentricities cannot take [uncertain.*] inputs "
                         "yet; set [simulation] quasi_static_eccentricity = \"drawn\"")


def default_time_step(scene, model: str) -> float:
    """The scene's time step (s) for ``model``: the contact level has its own, finer one."""
    return getattr(scene.simulation, model_level(model).time_step_field)


def default_integrator(scene, model: str) -> str:
    """The scene's integrator for ``model``: the contact level has its own (README, contact level)."""
    return getattr(scene.simulation, model_level(model).integrator_field)
