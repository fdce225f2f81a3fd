"""A setting of the trade-off and stability studies and its measurement: the ground both share.

A setting is one way to compute an ensemble (model level, integrator, time step, elements per
link, beam theory, Craig-Bampton modes per link, contact stiffness, adaptive step).  :func:`measure`
runs realisations 0..n-1 of it as one batch and gives the ensemble statistics users query, per
quantity and direction: the mean and the 95 % quantile over realisations (pipeline.analysis.stats.estimates) of each
realisation's max |error| (as stored in ensemble files: after the scene's settle time, over every
internal step for the contact level).  Relative errors are taken against a reference setting, with
a floor of 0.1 % of the largest translation (rotation) statistic of that quantity so that a
near-zero component cannot dominate.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from rss6core import BeamTheory, model_level, simulate_batch

from ..analysis.estimators import estimates
from ..files.records import error_summaries
from ..vocabulary import FINISHED

__all__ = ["Setting", "TRADEOFF_STATISTICS", "measure", "refined", "relative_errors"]

TRADEOFF_STATISTICS = ("mean", "q95")
RELATIVE_FLOOR = 1e-3


@dataclass(frozen=True)
class Setting:
    """One way to compute the ensemble: model level, integrator, time step (s), elements per link,
    beam theory (None: the scene's), Craig-Bampton modes per link (None: the scene's ``[beam]
    link_modes``, 0: the full mesh); for the contact level also the adaptive step's tolerance
    (m, 0: fixed step) and refinements."""
    model: str
    integrator: str
    dt: float
    elements: int
    stiffness_scale: float = 1.0
    tolerance: float = 0.0
    refinements: int = 0
    beam: BeamTheory | None = None
    link_modes: int | None = None

    @property
    def label(self) -> str:
        extra = f", K x{self.stiffness_scale:g}" if self.stiffness_scale != 1.0 else ""
        if self.beam is not None:
            extra += f", {self.beam.label}"
        if self.link_modes is not None:
            extra += f", Craig-Bampton {self.link_modes} modes" if self.link_modes else ", full mesh"
        if self.refinements:
            extra += (f", adaptive {self.tolerance:g} m down to "
                      f"{self.dt / 2 ** self.refinements * 1e6:g} us")
        if not model_level(self.model).elastic_links:   # no integrator, no mesh
            return f"{self.model} {self.dt * 1e3:g} ms"
        return f"{self.model} {self.integrator} {self.dt * 1e3:g} ms {self.elements} el{extra}"


def _scene_for(scene, setting: Setting):
    """The scene as ``setting`` computes it: its beam theory, link modes and contact stiffness."""
    if setting.beam is not None and setting.beam != scene.beam:
        scene = dataclasses.replace(scene, beam=setting.beam)
    if setting.link_modes is not None and setting.link_modes != scene.beam.link_modes:
        scene = dataclasses.replace(scene, beam=dataclasses.replace(scene.beam, link_modes=setting.link_modes))
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


def load_compiled_kernels(scene, settings, seed: int = 0) -> None:
    """Run one realisation of the cheapest (largest-step) setting whose level calls compiled kernels, untimed,
    so that no timed setting pays numba's compile (minutes on an empty cache) or its load from the cache,
    which would make the first such setting look dear and could change the recommended one."""
    from rss6core import level_kernels
    compiled = [s for s in settings if level_kernels(s.model)]
    if compiled:
        measure(scene, max(compiled, key=lambda s: s.dt), 1, seed)


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


def refined(setting: Setting) -> Setting:
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

