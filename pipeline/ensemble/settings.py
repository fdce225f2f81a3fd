"""The settings of a run resolved once, before any work: a level against its scene (model,
integrator, time step, mesh, initial state), the sampler's replicates and the cluster. Each
resolver checks everything it resolves and returns an immutable description; a mistake is an
OptionError naming the option (or a SceneError naming the scene file)."""
from __future__ import annotations

from dataclasses import dataclass

from rss6core import (SceneError, check_step_count, check_uncertain_level, default_integrator, default_time_step,
                      draws_per_realisation, max_link_modes, model_level, parse_scene, time_grid, uniform_dimension)

from ..scenes.variant import scene_variant
from ..vocabulary import OptionError
from .cluster import WORKER_TIMEOUT_S
from .run import EnsembleSpec
from .sampler import DEFAULT_REPLICATES, check_qmc

LOCAL_WORKERS = 2   # --workers' default where --scheduler is the alternative
MAX_LOCAL_WORKERS = 256   # a local cluster's processes at most (more machines: --scheduler)


@dataclass(frozen=True)
class LevelSettings:
    """A model level resolved against a scene: what one realisation computes, and how."""
    scene: object        # rss6core Scene, with the command line's contact start applied
    config: str          # the scene as the user named it (file path or shipped name)
    model: str
    integrator: str
    dt: float            # time step, s
    elements: int        # beam elements per link

    def ensemble_spec(self, seed: int, store: str = "summary", replicates: int | None = None) -> EnsembleSpec:
        return EnsembleSpec(self.scene.source_text, self.config, self.model, self.integrator, self.dt,
                            self.elements, seed, store, qmc_replicates=replicates)


def _with_start(scene, start: str | None):
    """The scene with ``start`` as its [simulation] contact_start, recorded in the scene text so an
    ensemble's workers and its file see it."""
    if start is None or start == scene.simulation.contact_start:
        return scene
    text = scene_variant(scene.source_text, {"simulation": {"contact_start": start}}, scene.source_path,
                         add=True)
    return parse_scene(text, scene.source_path)


def resolve_level(scene, config, *, model: str | None = None, integrator: str | None = None,
                  dt: float | None = None, elements: int | None = None, start: str | None = None) -> LevelSettings:
    """The command line's settings, else the scene's; the step is checked against the duration."""
    sim = scene.simulation
    given, model = model is not None, model or sim.model
    _check_uncertain(scene, model, from_option=given)
    if integrator is not None and not model_level(model).elastic_links:
        raise OptionError(f"--integrator {integrator}: the {model} level integrates nothing in time (its links "
                          "are rigid); integrators are for the elastic, paper and contact levels")
    if elements is not None and not model_level(model).elastic_links:
        raise OptionError(f"--elements {elements}: the {model} level's links are rigid (no mesh); elements are for "
                          "the elastic, paper and contact levels")
    if start is not None and not model_level(model).contact_start:
        raise OptionError(f"--start {start}: sets the contact level's initial state; this run is the "
                          f"{model} level")
    scene = _with_start(scene, start)
    step = dt or default_time_step(scene, model)
    try:
        check_step_count(scene.trajectory.duration, step)
    except ValueError as exc:
        if dt:
            raise OptionError(f"--dt: {exc}") from None
        raise SceneError(f"{scene.source_path}: time step: {exc}") from None
    if elements and scene.beam.link_modes > max_link_modes(elements):
        raise OptionError(f"--elements {elements}: a link of {elements} elements has at most "
                          f"{max_link_modes(elements)} interior DOFs, fewer than the scene's [beam] link_modes = "
                          f"{scene.beam.link_modes}")
    level = LevelSettings(scene, str(config), model, integrator or default_integrator(scene, model), step,
                          elements or sim.elements_per_link)
    _check_explicit_step(level, dt_given=dt is not None, integrator_given=integrator is not None)
    return level


def _check_explicit_step(level: LevelSettings, dt_given: bool, integrator_given: bool) -> None:
    """Refuse, before any work, an explicit integrator's step above its critical step on the scene's
    undamped elastic robot, Omega_crit / omega_max with Omega_crit = (gamma / 2)^(-1/2) (2 for central
    differences, Newmark's beta = 0 and gamma = 1/2; s): every realisation would diverge. The contact
    level's joints add stiffer modes, so there it is a necessary bound only, left to the run."""
    kind, sim = model_level(level.model), level.scene.simulation
    central = level.integrator == "central-difference"
    if not kind.elastic_links or kind.contact_joints or not (central or (level.integrator == "newmark"
                                                                         and sim.newmark_beta == 0)):
        return
    from rss6core import natural_frequencies
    gamma = 0.5 if central else sim.newmark_gamma
    critical = (gamma / 2) ** -0.5 / natural_frequencies(level.scene, level.elements)[-1]
    if level.dt <= critical:
        return
    scheme = "central differences" if central else f"Newmark with beta = 0, gamma = {gamma:g}"
    said = (f"--dt {level.dt:g} with {scheme}" if dt_given else
            f"--integrator {level.integrator} at the {level.model} level's step {level.dt:g} s" if integrator_given
            else f"[simulation] integrator = {level.integrator!r} ({scheme}) at the {level.model} level's step "
            f"{level.dt:g} s")
    message = (f"{said}: {level.dt / critical:.3g}x the explicit critical step {critical:.3g} s of the scene's "
               f"elastic robot on {level.elements} elements per link (2/omega_max for central differences), so "
               "every realisation would diverge; give a step at most that (dividing the duration) or an "
               "implicit integrator (newmark with beta >= 1/4, hht, generalized-alpha)")
    if dt_given or integrator_given:
        raise OptionError(message)
    raise SceneError(f"{level.scene.source_path}: {message}")


def _check_uncertain(scene, model: str, from_option: bool) -> None:
    """Refuse, before any work, a level that cannot take the scene's [uncertain.*] inputs yet: an
    OptionError naming --model, or a SceneError naming the scene's [simulation] model."""
    try:
        check_uncertain_level(scene, model)
    except ValueError as exc:
        if from_option:
            raise OptionError(f"--model {model}: {exc}") from None
        raise SceneError(f"{scene.source_path}: [simulation] model = {model!r}: {exc}") from None


def resolve_replicates(sampler: str, replicates: int | None, n: int, level: LevelSettings) -> int | None:
    """R for --sampler qmc (None for mc), checked against -n and the level's draws."""
    if sampler == "mc":
        if replicates is not None:
            raise OptionError("--replicates applies to --sampler qmc only")
        return None
    if not draws_per_realisation(level.scene, level.model):
        raise OptionError(f"--sampler qmc: the {level.model} level draws no clearances")
    replicates = DEFAULT_REPLICATES if replicates is None else replicates
    redraws = model_level(level.model).redraws_every_step
    steps = len(time_grid(level.scene.trajectory.duration, level.dt)) if redraws else None
    try:
        check_qmc(n, replicates, uniform_dimension(steps, level.scene))
    except ValueError as exc:
        raise OptionError(str(exc)) from None
    return replicates


@dataclass(frozen=True)
class ClusterSettings:
    """Where an ensemble's chunks run: ``workers`` local processes, or an external ``scheduler``."""
    workers: int
    scheduler: str | None = None
    worker_timeout: float = WORKER_TIMEOUT_S   # s without workers before an external run stops


def resolve_cluster(workers: int | None, scheduler: str | None = None,
                    worker_timeout: float | None = None) -> ClusterSettings:
    """--workers only without --scheduler (its workers are its own), --worker-timeout only with it."""
    if scheduler and workers is not None:
        raise OptionError(f"--workers {workers}: sets the local cluster; with --scheduler the "
                          "scheduler's own workers run the tasks")
    if worker_timeout is not None and not scheduler:
        raise OptionError(f"--worker-timeout {worker_timeout:g}: applies with --scheduler only "
                          "(a local cluster's workers are rss6's own)")
    return ClusterSettings(LOCAL_WORKERS if workers is None else workers, scheduler,
                           WORKER_TIMEOUT_S if worker_timeout is None else worker_timeout)
