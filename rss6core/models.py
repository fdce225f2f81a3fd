"""The model ladder behind one entry point: ``simulate(scene, model=...)``.

Every level reports the same outputs: the platform pose error (actual minus
ideal rigid pose) as displacement, velocity and acceleration over time.
- rigid (L0): the reference itself, so its error is zero by definition;
- quasi-static (L1): rigid links, clearance eccentricities through the
  linearised leg closure (:mod:`.quasi_static`); needs a realisation;
- elastic (L2): kineto-elastodynamics with ideal joints (:mod:`.elastic`);
- paper (L3): the seed's method, clearances redrawn every step on top of L2
  (:mod:`.paper_method`); needs a realisation;
- contact (L4): clearance joints as contact pairs on top of L2
  (:mod:`.contact_dynamics`); the realisation's draw is the initial eccentricity.
:func:`simulate_batch` runs many realisations of one scene and shares what they
share: L2 is computed once for all realisations of L2 and L3, and L4 integrates
the batch as one array.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from .assembly import build_elastic_model, dense_matrices, end_maps
from .clearance import draw_clearances, uniform_dimension
from .elastic import simulate_elastic
from .integrators import Integrator, make_integrator
from .kinematics import RigidMotion, rigid_motion
from .levels import (check_uncertain_level, default_integrator, default_time_step, draws_per_realisation,
                     model_level, models_with)
from .paper_method import PaperClosure, output_step, paper_contact_forces, paper_draw, paper_result
from .quasi_static import quasi_static_result
from .realised import (ReferenceMotion, is_nominal, motion_error, realised_clearances, realised_contact_laws,
                       realised_geometry, realised_motion, realised_scene, scene_is_nominal)
from .results import SimulationResult, time_grid
from .status import FAILED, FINISHED, check_history
from .uncertain import draw_inputs

__all__ = ["simulate", "simulate_batch", "Level", "prepare_level", "stored_draw", "stored_inputs",
           "natural_frequencies", "degrees_of_freedom"]


def stored_draw(scene, model: str, seed: int, realization: int, dt: float, uniforms=None):
    """The draw an ensemble file records for a realisation: the paper level's first step, else the
    draw (``uniforms`` as in :func:`.clearance.draw_clearances`)."""
    if model_level(model).redraws_every_step:
        steps = len(time_grid(scene.trajectory.duration, dt))
        inputs = stored_inputs(scene, seed, realization, uniforms, steps)
        sized = scene if inputs is None else realised_clearances(scene, inputs)
        return output_step(paper_draw(sized, seed, realization, steps, uniforms))
    return realised_draw(scene, seed, realization, uniforms)


def realised_draw(scene, seed: int, realization: int, uniforms=None):
    """A realisation's clearance draw with the sizes its [uncertain.*] inputs draw (the scene's
    otherwise): :func:`.realised.realised_clearances`."""
    inputs = stored_inputs(scene, seed, realization, uniforms)
    drawn = scene if inputs is None else realised_clearances(scene, inputs)
    return draw_clearances(drawn, seed, realization, uniforms=uniforms)


def stored_inputs(scene, seed: int, realization: int, uniforms=None, steps: int | None = None):
    """The uncertain inputs an ensemble file records for a realisation (:class:`.uncertain.InputDraw`),
    None for a scene without; with ``uniforms``, from the coordinates after the clearance draw's (one
    draw, or ``steps`` of them: the paper level's)."""
    if not scene.uncertain:
        return None
    return draw_inputs(scene, seed, realization, uniforms, offset=uniform_dimension(steps))


def simulate(scene, model: str | None = None, integrator: str | None = None,
             dt: float | None = None, elements: int | None = None, seed: int = 0,
             realization: int = 0) -> SimulationResult:
    """One run of ``model`` (default: the scene's) along the scene's trajectory.

    Clearance levels use realisation ``realization`` of the run seeded ``seed``;
    the same pair always gives the same result.
    """
    return simulate_batch(scene, model, integrator, dt, elements, seed, [realization])[0]


def simulate_batch(scene, model: str | None = None, integrator: str | None = None,
                   dt: float | None = None, elements: int | None = None, seed: int = 0,
                   realizations=(0,), tolerance: float | None = None,
                   refinements: int | None = None, uniforms=None) -> list[SimulationResult]:
    """Realisations ``realizations`` of the run seeded ``seed``, one result each, in order.

    ``uniforms(realization, dimension)``, if given, supplies each draw's uniforms (a quasi-Monte
    Carlo design, see :func:`.clearance.draw_clearances`) instead of the realisation's stream.

    ``tolerance`` (m) and ``refinements`` set the contact level's adaptive step
    (default: the scene's; see :func:`.contact_dynamics.simulate_contact`).
    """
    level = prepare_level(scene, model, integrator, dt, elements, tolerance, refinements)
    return level.simulate(seed, realizations, uniforms)


@dataclass(frozen=True)
class Level:
    """One level's settings on one scene, with what all its realisations share computed once: the
    rigid motion (quasi-static; elastic with [uncertain.*] inputs), the ideal-joint elastic run (elastic,
    paper) and the leg closure (paper).  Made by :func:`prepare_level`; an ensemble worker keeps it
    for all its chunks."""
    scene: object
    model: str
    integrator: Integrator | None   # None for the rigid and quasi-static levels
    dt: float                       # s
    elements: int
    tolerance: float | None = None  # m, the contact level's adaptive step (None: the scene's)
    refinements: int | None = None
    motion: RigidMotion | None = None
    elastic: SimulationResult | None = None
    closure: PaperClosure | None = None

    def simulate(self, seed: int, realizations, uniforms=None) -> list[SimulationResult]:
        """Realisations ``realizations`` of the run seeded ``seed``, one result each, in order
        (``uniforms``: a quasi-Monte Carlo design, as in :func:`simulate_batch`)."""
        realizations = list(realizations)
        kind = model_level(self.model)
        if self.scene.uncertain and kind.redraws_every_step:
            return [self._realised_paper(seed, r, uniforms) for r in realizations]
        if self.scene.uncertain:
            return self.simulate_draws([realised_draw(self.scene, seed, r, uniforms) if kind.draws_clearances else None
                                        for r in realizations],
                                       [stored_inputs(self.scene, seed, r, uniforms) for r in realizations])
        if not kind.draws_clearances:      # every realisation is the same run
            return [self.elastic if kind.elastic_links else self._rigid()] * len(realizations)
        if kind.redraws_every_step:
            return self._paper(seed, realizations, uniforms)
        return self.simulate_draws([draw_clearances(self.scene, seed, r, uniforms=uniforms)
                                    for r in realizations])

    def simulate_draws(self, draws: list, inputs: list | None = None) -> list[SimulationResult]:
        """The quasi-static or contact level on given clearance draws, one result each (the
        sensitivity study's designed inputs; an ensemble's draws come from :meth:`simulate`); with
        [uncertain.*] inputs also given input draws (:class:`.uncertain.InputDraw`), one per draw."""
        kind = model_level(self.model)
        if bool(self.scene.uncertain) != (inputs is not None):
            raise ValueError("given draws need given uncertain inputs exactly when the scene has [uncertain.*] "
                             "tables")
        if inputs is not None and kind.contact_joints:
            return self._realised_contact(draws, inputs)
        if inputs is not None:
            return [self._realised(draw, given) for draw, given in zip(draws, inputs, strict=True)]
        if not kind.function_of_one_draw:
            raise ValueError(f"the {self.model} level takes no given draws "
                             f"({' or '.join(models_with('function_of_one_draw'))} do)")
        if not kind.contact_joints:
            mode = self.scene.simulation.quasi_static_eccentricity
            return [quasi_static_result(self.scene, self.motion, draw, mode) for draw in draws]
        dynamics, start = _contact_solver()
        batch = dynamics.simulate_contact(self.scene, draws, self.elements, self.integrator, self.dt,
                                          tolerance=self.tolerance, refinements=self.refinements,
                                          initial=start.contact_initial_state)
        return [dataclasses.replace(batch.result(k), draw=draw) for k, draw in enumerate(draws)]

    def _rigid(self) -> SimulationResult:
        """The rigid level's result: its error is zero by definition."""
        t = time_grid(self.scene.trajectory.duration, self.dt)
        zero = np.zeros((len(t), 6))
        return SimulationResult(t, zero, zero, zero, FINISHED, "", len(t) - 1)

    def _realised(self, draw, inputs) -> SimulationResult:
        """One realised robot (rss6core/realised.py) of the drawn ``inputs`` driven by the nominal
        commands: its geometric error, plus the clearance closure of ``draw`` about its motion at a
        clearance level.  A realised robot equal to the nominal one reuses the nominal motion: its
        geometric error is exactly zero."""
        if model_level(self.model).elastic_links:
            return self._realised_elastic(inputs)
        geometry = realised_geometry(self.scene.geometry, inputs)
        nominal = is_nominal(self.scene.geometry, geometry)
        try:
            real = self.motion if nominal else realised_motion(geometry, self.motion)
        except (ArithmeticError, np.linalg.LinAlgError) as exc:   # a realised robot out of its workspace
            return self._failed_kinematics(exc, inputs)
        geometric = [np.zeros_like(self.motion.platform.pose)] * 3 if nominal else motion_error(real, self.motion)
        if not model_level(self.model).draws_clearances:
            outcome = check_history(geometric[0], real.t, "geometric displacement error")
            return SimulationResult(real.t, *geometric, outcome.status, outcome.message, outcome.steps, inputs=inputs)
        result = quasi_static_result(self.scene, real, draw, self.scene.simulation.quasi_static_eccentricity)
        return dataclasses.replace(result if nominal else _plus(result, geometric), inputs=inputs)

    def _realised_elastic(self, inputs) -> SimulationResult:
        """The elastic level on one realised robot: its finite-element model from the realised scene
        (lengths, joint positions, modulus, density, platform), the elastic motion superposed on the
        realised rigid motion under the nominal commands, plus that motion's geometric error.  A
        realised scene equal to the nominal one reuses the nominal elastic run (the same bits)."""
        scene = realised_scene(self.scene, inputs)
        if scene_is_nominal(self.scene, scene):
            return dataclasses.replace(self.elastic, inputs=inputs)
        nominal_scene = self.scene
        try:
            real = realised_motion(scene.geometry, self.motion)
            result = simulate_elastic(scene, self.elements, self.integrator, self.dt, motion=lambda t: realised_motion(
                scene.geometry, rigid_motion(nominal_scene, t)))
        except (ArithmeticError, np.linalg.LinAlgError) as exc:
            return self._failed_kinematics(exc, inputs)
        return dataclasses.replace(_plus(result, motion_error(real, self.motion)), inputs=inputs)

    def _realised_contact(self, draws, inputs) -> list[SimulationResult]:
        """The contact level on realised robots (docs/model.md section 4b): those whose geometry,
        material and platform are the nominal ones (their friction, restitution and clearances drawn)
        as one batch about the nominal motion; each other one on its own about its realised motion,
        whose geometric error its peaks and histories include."""
        scenes = [realised_scene(self.scene, given) for given in inputs]
        out = [None] * len(draws)
        same = [k for k, scene in enumerate(scenes) if scene_is_nominal(self.scene, scene)]
        if same:
            batch = self._contact([draws[k] for k in same], [inputs[k] for k in same], self.scene, None)
            for k, result in zip(same, batch):
                out[k] = result
        for k in (k for k in range(len(draws)) if out[k] is None):
            out[k] = self._contact([draws[k]], [inputs[k]], scenes[k],
                                   ReferenceMotion(self.scene, scenes[k].geometry))[0]
        return out

    def _contact(self, draws, inputs, scene, reference) -> list[SimulationResult]:
        """One contact batch of ``scene`` (a realised one with its ``reference`` motion, or the
        nominal with None): the link matrices at the nominal link lengths (the realised material),
        each draw's joint laws, the geometric error added to the histories."""
        dynamics, start = _contact_solver()
        geometry = dataclasses.replace(scene.geometry, crank_length=self.scene.geometry.crank_length,
                                       rod_length=self.scene.geometry.rod_length)
        try:
            batch = dynamics.simulate_contact(
                scene, draws, self.elements, self.integrator, self.dt, tolerance=self.tolerance,
                refinements=self.refinements, initial=start.contact_initial_state, reference=reference,
                model=dynamics.build_joint_model(dataclasses.replace(scene, geometry=geometry), self.elements),
                laws=[realised_contact_laws(self.scene, given) for given in inputs])
        except (ArithmeticError, np.linalg.LinAlgError) as exc:   # a realised robot out of its workspace
            return [self._failed_kinematics(exc, given) for given in inputs]
        out = [dataclasses.replace(batch.result(k), draw=draw, inputs=given)
               for k, (draw, given) in enumerate(zip(draws, inputs, strict=True))]
        if reference is None:
            return out
        error = reference.at(out[0].t).error
        return [_plus(result, (error[:, 0], error[:, 1], error[:, 2])) for result in out]

    def _realised_paper(self, seed: int, r: int, uniforms) -> SimulationResult:
        """The paper level on one realised robot: its elastic run and geometric error
        (:meth:`_realised_elastic`) plus the paper's closure of the per-step draw (with the drawn
        sizes) about its realised motion, contact forces with its material and restitutions."""
        steps = len(self.elastic.t)
        inputs = stored_inputs(self.scene, seed, r, uniforms, steps)
        scene = realised_scene(self.scene, inputs)
        draw = paper_draw(realised_clearances(self.scene, inputs), seed, r, steps, uniforms)
        elastic, closure = self.elastic, self.closure
        if not scene_is_nominal(self.scene, scene):
            elastic = self._realised_elastic(inputs)
            if elastic.status == FAILED:
                return elastic
            reference = ReferenceMotion(self.scene, scene.geometry)
            closure = PaperClosure(scene, elastic.t, motion=lambda t: reference.at(t).motion)
        xi = realised_contact_laws(self.scene, inputs).restitution.T.ravel()
        result = paper_result(elastic, closure, draw, paper_contact_forces(scene, draw, self.dt, xi),
                              output_step(draw))
        return dataclasses.replace(result, inputs=inputs)

    def _failed_kinematics(self, exc, inputs) -> SimulationResult:
        """A realised robot out of its workspace: NaN errors and the reason, not an exception."""
        t = time_grid(self.scene.trajectory.duration, self.scene.simulation.time_step) if self.motion is None \
            else self.motion.t
        nan = np.full((len(t), 6), np.nan)
        return SimulationResult(t, nan, nan, nan, FAILED,
                                f"the realised robot's forward kinematics failed: {exc}", 0, inputs=inputs)

    def _paper(self, seed: int, realizations: list, uniforms) -> list[SimulationResult]:
        elastic = self.elastic
        out = []
        for r in realizations:
            draw = paper_draw(self.scene, seed, r, len(elastic.t), uniforms)
            out.append(paper_result(elastic, self.closure, draw,
                                    paper_contact_forces(self.scene, draw, self.dt), output_step(draw)))
        return out


def _plus(result: SimulationResult, geometric) -> SimulationResult:
    """``result`` with the geometric error (displacement, velocity, acceleration) added."""
    return dataclasses.replace(result, displacement=result.displacement + geometric[0],
                               velocity=result.velocity + geometric[1],
                               acceleration=result.acceleration + geometric[2])


def _contact_solver():
    """The modules contact_dynamics and contact_start, imported on first use: the contact level's
    compiled kernel brings numba (0.3 s of import per process), which reading a scene and running
    the other levels do without (a paper-level ensemble's main process and workers)."""
    from . import contact_dynamics, contact_start
    return contact_dynamics, contact_start


def prepare_level(scene, model: str | None = None, integrator: str | None = None,
                  dt: float | None = None, elements: int | None = None, tolerance: float | None = None,
                  refinements: int | None = None) -> Level:
    """``model`` (default: the scene's) on ``scene`` with the given settings (default: the scene's),
    its shared part computed: the elastic run for the elastic and paper levels, for instance."""
    sim = scene.simulation
    model = model or sim.model
    kind = model_level(model)
    check_uncertain_level(scene, model)
    dt = default_time_step(scene, model) if dt is None else dt
    elements = elements or sim.elements_per_link
    if not kind.elastic_links:
        t = time_grid(scene.trajectory.duration, dt)
        return Level(scene, model, None, dt, elements,
                     motion=rigid_motion(scene, t) if draws_per_realisation(scene, model) else None)
    method = make_integrator(integrator or default_integrator(scene, model), sim.newmark_beta,
                             sim.newmark_gamma, sim.hht_alpha, sim.spectral_radius)
    if kind.contact_joints:
        return Level(scene, model, method, dt, elements, tolerance, refinements)
    elastic = simulate_elastic(scene, elements, method, dt)
    closure = PaperClosure(scene, elastic.t) if kind.redraws_every_step else None
    motion = rigid_motion(scene, elastic.t) if scene.uncertain else None
    return Level(scene, model, method, dt, elements, motion=motion, elastic=elastic, closure=closure)


def natural_frequencies(scene, elements: int | None = None, t: float = 0.0) -> np.ndarray:
    """Undamped natural angular frequencies (rad/s, ascending) of the whole robot at time t."""
    model = build_elastic_model(scene, elements or scene.simulation.elements_per_link)
    maps = end_maps(model, rigid_motion(scene, np.array([t])), scene.geometry)
    M, K = dense_matrices(model, maps[0])
    return np.sqrt(np.abs(scipy.linalg.eigh(K, M, eigvals_only=True)))


def degrees_of_freedom(scene, model: str, elements: int | None = None) -> int:
    """Unknowns a level solves for: the 6 pose errors (rigid, quasi-static), else the finite-element
    model's degrees of freedom (the contact level's with its joints' own nodes)."""
    kind = model_level(model)
    if not kind.elastic_links:
        return 6
    elements = elements or scene.simulation.elements_per_link
    build = _contact_solver()[0].build_joint_model if kind.contact_joints else build_elastic_model
    return build(scene, elements).dofs
