"""rss6core: the physics of a 6-RSS robot with elastic links and clearance joints.

Pure numpy/scipy/numba: no dask, xarray or netCDF here (those live in ``pipeline``).  This module
is the core's public facade; ``pipeline`` imports the core from here only.

Scenes
- Scene: the immutable description of one robot, its motion and its run settings (SI).
- SceneError: a scene that cannot describe a physical robot; the message names the file and key.
- load_scene: a Scene from a TOML file.
- MAX_ELEMENTS_PER_LINK: the most beam elements per crank and per rod a scene or --elements may ask for.
- parse_scene: a Scene from TOML text.
- toml_spelling: a value as a TOML file spells it (true, "4"), for messages that quote one.
- CLEARANCE_RADII: each [clearance] key and the [contact] radius of its joint, which a clearance must stay below.
- RELATIVE_BAND_REACH: the multiple of its nominal up to which [sampling] size_tolerance draws a size.

Running a level
- MODELS: the model levels, cheapest first (rigid, quasi-static, elastic, paper, contact).
- MODEL_LEVELS: each level's ModelLevel by name, cheapest first: the one table of level properties.
- ModelLevel: one level's name, ladder rung, description and yes/no properties (draws_clearances, ...).
- model_level: the ModelLevel of a name, or ValueError naming the levels.
- models_with: the names of the levels with a yes/no property (e.g. "draws_clearances").
- INTEGRATORS: the time integrators a level accepts by name.
- CONTACT_STARTS: the contact level's initial states by name (drawn, equilibrium).
- TOL_DISPLACEMENT, TOL_VELOCITY: the contact level's Newton tolerances on the joints (m, m/s).
- simulate: one realisation of a level along the scene's trajectory.
- simulate_batch: many realisations of one level, sharing what they share.
- prepare_level: a level on a scene with what all its realisations share computed once.
- Level: what prepare_level returns; its ``simulate(seed, realizations)`` runs a batch.
- SimulationResult: what every level returns (error histories in SI, status and message).
- FINISHED, FAILED, STATUSES: the status vocabulary every level and every file uses.
- ContactBatch: the contact level's results for a batch of realisations (one SimulationResult each).
- time_grid: the output instants (s) of a duration and step, or ValueError if the step does not divide it.
- check_step_count: a run's number of steps, or ValueError outside 10 to 1,000,000.
- stored_draw: the clearance draw an ensemble file records for one realisation.
- stored_inputs: the uncertain inputs ([uncertain.*]) an ensemble file records for one realisation, or None.
- check_uncertain_level: ValueError naming a level that cannot take a scene's uncertain inputs yet.
- draws_per_realisation: whether a level's realisations on a scene differ (clearances or uncertain inputs).
- default_time_step: a scene's time step (s) for a level.
- default_integrator: a scene's integrator for a level.
- natural_frequencies: undamped angular frequencies (rad/s) of the elastic robot at one instant.
- degrees_of_freedom: how many unknowns a level solves for.
- closure_matrix: the quasi-static level's linearised leg closure at one instant (platform error per eccentricity).

Compiled kernels (numba; the contact level's)
- level_kernels: the compiled kernels a level calls (none but the contact level's).
- kernels_to_compile: those a level would compile first here (not in numba's cache for this machine).
- compile_kernels: compile every level's kernels into numba's cache now; seconds per kernel compiled.
- load_draw_kernels: import (compile or load) every level's draw kernels now; seconds it took.
- compile_kernel: compile one named contact-kernel entry point into numba's cache (two processes, one each).
- kernel_cache_folder: where numba's cache keeps them.

Clearance draws
- ClearanceDraw: one realisation's clearance sizes and eccentricity vectors (m).
- draw_clearances: one realisation's clearance sizes and eccentricities (m), from its seeded stream.
- clearances_from_uniforms: the same draw as a function of a vector of uniforms (quasi-Monte Carlo).
- clearances_from_named_uniforms: the same draw from its uniforms by block name (Sobol' designs).
- UNIFORM_BLOCKS: the names of those blocks of six uniforms (legs 1-6), in stream order.
- uniform_dimension: how many uniforms one draw uses at most.
- inputs_from_uniforms: a realisation's [uncertain.*] inputs (InputDraw) from one uniform per draw.
- realised_clearances: the scene with the clearance sizes a realisation's [uncertain.*] inputs draw.
- size_band: a joint family's clearance-size band ([tolerance.<family>] or [sampling] size_tolerance), or None.
- SIZE_UNIFORMS: how many of them (the first) set the clearance sizes.

The elastic level's parts (the stability study's explicit sweep)
- Integrator: a generalized-alpha family member (Newmark, HHT, central difference, ...).
- build_elastic_model: the finite-element model of the links with ideal joints.
- BeamTheory, BEAM_THEORIES: the links' beam theory (Euler-Bernoulli or Timoshenko, rotary inertia).
- max_link_modes: the most Craig-Bampton modes per link ([beam] link_modes) a mesh allows.
- quasi_static_state: the elastic state on the quasi-static path at one instant.
- simulate_elastic: the elastic level with a given model, integrator and initial state.

The workspace error map (quasi-static level at static poses; docs/model.md section 3)
- WorstCaseSizes, worst_case_sizes: the clearance sizes the worst case takes (m): nominal or a band's upper end.
- revolute_support, ball_support: the support functions of a joint's clearance set (m).
- StaticClosure, static_closure: the linearised closure G, its inverse and reachability at static poses.
- worst_case_error: the largest |pose error| any clearance state causes at each pose (m, rad), closed form.
- DrawnEccentricities, drawn_eccentricities: N realisations' e_A + e_C - e_B of a seeded run (m).
- sampled_errors: |pose error| of each drawn realisation at each pose (m, rad).

The rigid robot
- rigid_motion: the ideal rigid motion (platform and cranks) along the trajectory.
- workspace_quality: reach, transmission index and Jacobian condition number of every pose of the trajectory.
- TRAJECTORY_KINDS: the [trajectory] kinds by name (sinusoid, points, file).
- inverse_dynamics: actuator torques and joint forces of the rigid motion (N m, N).
- crank_inertia, rod_inertia, crank_on_motor_frequency: the rigid links' masses (kg) and inertias (kg m^2),
  and the rigid crank's frequency (Hz) on a servo of a given stiffness ([actuator]).
"""
from .elastic import quasi_static_state, simulate_elastic
from .results import ContactBatch, SimulationResult, check_step_count, time_grid
from .assembly import build_elastic_model
from .beam import BEAM_THEORIES, BeamTheory
from .link_reduction import max_link_modes
from .clearance import (RELATIVE_BAND_REACH, SIZE_UNIFORMS, UNIFORM_BLOCKS, ClearanceDraw,
                        clearances_from_named_uniforms, clearances_from_uniforms, draw_clearances, size_band,
                        uniform_dimension)
from .contact_options import CONTACT_STARTS, TOL_DISPLACEMENT, TOL_VELOCITY
from .dynamics import inverse_dynamics
from .integrators import INTEGRATORS, Integrator
from .kernels import (compile_kernel, compile_kernels, kernel_cache_folder, kernels_to_compile, level_kernels,
                      load_draw_kernels)
from .kinematics import rigid_motion, workspace_quality
from .levels import (MODEL_LEVELS, MODELS, ModelLevel, check_uncertain_level, default_integrator, default_time_step,
                     draws_per_realisation, model_level, models_with)
from .quasi_static import closure_matrix
from .models import (Level, degrees_of_freedom, natural_frequencies, prepare_level, simulate, simulate_batch,
                     stored_draw, stored_inputs)
from .scene import CLEARANCE_RADII, MAX_ELEMENTS_PER_LINK, Scene, SceneError, load_scene, parse_scene, toml_spelling
from .uncertain import inputs_from_uniforms
from .realised import realised_clearances
from .status import FAILED, FINISHED, STATUSES
from .trajectory_kinds import TRAJECTORY_KINDS
from .sections import crank_inertia, crank_on_motor_frequency, rod_inertia
from .workspace_map import (DrawnEccentricities, StaticClosure, WorstCaseSizes, ball_support, drawn_eccentricities,
                            revolute_support, sampled_errors, static_closure, worst_case_error, worst_case_sizes)

__version__ = "0.3.2"
__all__ = ["Scene", "SceneError", "load_scene", "parse_scene", "toml_spelling", "CLEARANCE_RADII",
           "RELATIVE_BAND_REACH",
           "MODELS", "MODEL_LEVELS", "ModelLevel", "model_level", "models_with", "INTEGRATORS", "CONTACT_STARTS",
           "TOL_DISPLACEMENT", "TOL_VELOCITY", "closure_matrix",
           "simulate", "simulate_batch", "prepare_level", "Level",
           "MAX_ELEMENTS_PER_LINK", "SimulationResult", "ContactBatch", "time_grid", "check_step_count", "FINISHED",
           "FAILED", "STATUSES",
           "stored_draw", "stored_inputs", "check_uncertain_level", "draws_per_realisation", "inputs_from_uniforms",
           "realised_clearances",
           "default_time_step", "default_integrator", "natural_frequencies",
           "degrees_of_freedom", "level_kernels", "kernels_to_compile", "compile_kernels", "compile_kernel",
           "load_draw_kernels", "kernel_cache_folder",
           "ClearanceDraw", "draw_clearances", "clearances_from_uniforms", "uniform_dimension", "size_band",
           "SIZE_UNIFORMS", "UNIFORM_BLOCKS", "clearances_from_named_uniforms", "Integrator", "build_elastic_model",
           "BeamTheory", "BEAM_THEORIES", "max_link_modes",
           "quasi_static_state", "simulate_elastic",
           "WorstCaseSizes", "worst_case_sizes", "revolute_support", "ball_support", "StaticClosure",
           "static_closure", "worst_case_error", "DrawnEccentricities", "drawn_eccentricities", "sampled_errors",
           "rigid_motion", "workspace_quality", "TRAJECTORY_KINDS", "inverse_dynamics", "crank_inertia",
           "crank_on_motor_frequency", "rod_inertia",
           "__version__"]
