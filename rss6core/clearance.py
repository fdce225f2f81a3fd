"""Clearance realisations: the sampling laws of docs/model.md section 4 (paper sec. 2.2-2.4).

One realisation fixes, per leg i, the clearance sizes and eccentricities of the
revolute A_i (radial, in the plane normal to w_i, and axial along w_i) and of
the spherical joints C_i and B_i.  Eccentricities are in the base frame:
e_A = journal (crank) centre minus bearing (base) centre, e_C = ball (rod) minus
socket (crank), e_B = ball (rod) minus socket (platform).
- radial magnitude ~ Normal(mu, sigma) truncated to [0, delta_r] (eq. 5),
  direction ~ U(0, 2 pi) in the plane normal to w_i;
- axial ~ Normal(mu_a, sigma_a) truncated to [-delta_a, delta_a] (eq. 7);
- spherical magnitude k_s delta_s, k_s ~ U(0, 1), direction uniform on the
  sphere (eta_d1 = arccos(1 - 2 u)); the paper's eta_d1 = pi u (eq. 9, not
  uniform on the sphere) is the option ``direction = "paper"``.
Realisation r of a run with seed s draws from its own stream
SeedSequence([s, r]), so results do not depend on chunking or worker count.
Every law inverts a CDF, so a draw is a function of a vector of uniforms
(:func:`clearances_from_uniforms`, at most :func:`uniform_dimension` of them):
plain Monte Carlo takes them from the realisation's stream, randomised
quasi-Monte Carlo (pipeline/ensemble/sampler.py) from a scrambled Sobol' point, and a
Sobol' sensitivity design (pipeline/studies/sensitivity.py) by name, six per block of
:data:`UNIFORM_BLOCKS` (:func:`clearances_from_named_uniforms`).
"""
from __future__ import annotations

import math

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

RELATIVE_BAND_REACH = 2.0   # a [sampling] size_tolerance draws sizes up to this multiple of the nominal
# each [clearance] size and the [contact] radius of the joint it belongs to
CLEARANCE_RADII = {"revolute_radial_m": "journal_radius_m", "revolute_axial_m": "journal_radius_m",
                   "spherical_C_m": "sphere_radius_m", "spherical_B_m": "sphere_radius_m"}

__all__ = ["CLEARANCE_RADII", "SIZE_UNIFORMS", "FAMILIES", "UNIFORM_BLOCKS", "size_band", "SizeBand", "ClearanceDraw",
           "UniformVector", "NamedUniforms", "realization_rng", "truncated_normal", "sphere_directions",
           "draw_clearances", "clearances_from_uniforms", "eccentricities_inside", "clearances_from_named_uniforms",
           "uniform_dimension"]


def realization_rng(seed: int, realization: int) -> np.random.Generator:
    """The random stream of realisation ``realization`` of a run seeded ``seed``."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(realization)]))


class UniformVector:
    """Given uniforms on [0, 1) handed out in order with a Generator's ``uniform(low, high, size)``
    signature, so one draw routine serves a random stream and a quasi-random point alike."""

    def __init__(self, u):
        self.u, self.used = np.asarray(u, float).ravel(), 0

    def uniform(self, low=0.0, high=1.0, size=None) -> np.ndarray:
        shape = () if size is None else (int(size),) if np.ndim(size) == 0 else tuple(int(n) for n in size)
        count = math.prod(shape)
        if self.used + count > self.u.size:
            raise ValueError(f"the draw needs more than the {self.u.size} uniforms given")
        out = self.u[self.used:self.used + count].reshape(shape)
        self.used += count
        # on [0, 1) the arithmetic below is the identity (0 + 1 u == u exactly): a copy does the same
        return out.copy() if shape and _unit(low, high) else low + (high - low) * out


class NamedUniforms:
    """Given uniforms on [0, 1) by block name (:data:`UNIFORM_BLOCKS`, six per block, legs 1-6), for
    a design whose inputs are named rather than laid out in stream order (a Sobol' design)."""

    def __init__(self, blocks: dict):
        self.blocks = {name: np.asarray(u, float) for name, u in blocks.items()}

    def take(self, name: str, low, high, size) -> np.ndarray:
        if name not in self.blocks:
            raise ValueError(f"the draw needs the uniforms {name!r}, which were not given")
        u = self.blocks[name]
        return low + (high - low) * u.reshape(tuple(np.atleast_1d(size)))


def _unit(low, high) -> bool:
    """Whether [low, high) is [0, 1) (a quick answer for Python floats, the common case)."""
    if isinstance(low, float) and isinstance(high, float):
        return low == 0.0 and high == 1.0
    return np.array_equal(low, 0.0) and np.array_equal(high, 1.0)


def _uniform(rng, name: str, low=0.0, high=1.0, size=None):
    """Uniforms on [low, high) of the block ``name`` from a Generator, a :class:`UniformVector` (in
    order; the name unused) or a :class:`NamedUniforms` (by name)."""
    if isinstance(rng, NamedUniforms):
        return rng.take(name, low, high, size)
    if isinstance(rng, np.random.Generator):   # Generator.uniform's doubles and arithmetic, without its
        u = rng.random(size)                   # per-value call (a third of the time for 12 000 values)
        return u if _unit(low, high) else low + (high - low) * u
    return rng.uniform(low, high, size)


def _kernel():
    """:mod:`.draw_kernel`, imported at the first draw: only a process that draws pays numba's import
    (the local workers' fork server preloads it; docs/performance.md section 30)."""
    from . import draw_kernel
    return draw_kernel


def _normal_law(mean, std, low, high, legs: int):
    """Normal(mean, std) truncated to [low, high], each broadcast to ``legs`` values, as the compiled
    kernel reads it (:class:`.draw_kernel.TruncatedNormal`): a point law where a std is not positive."""
    mean, std = np.asarray(mean, float), np.asarray(std, float)
    point = bool(np.any(std <= 0))
    lo, hi = (0.0, 0.0) if point else (ndtr((np.asarray(low) - mean) / std), ndtr((np.asarray(high) - mean) / std))
    return _kernel().TruncatedNormal(point, *(np.full(legs, x, float) for x in (mean, std, lo, hi, low, high)))


def _law_uniforms(rng, name: str, law, shape: tuple) -> np.ndarray:
    """The uniforms of a truncated normal's block ``name`` (none, an empty array, for a point law)."""
    return np.empty((0, shape[-1])) if law.point else _uniform(rng, name, size=shape)


def truncated_normal(rng: np.random.Generator, mean, std, low, high, size, name: str = "") -> np.ndarray:
    """Normal(mean, std) truncated to [low, high] (parameters per last axis of ``size``), by inverting
    the CDF (one uniform per draw, of the block ``name``; none when a std is not positive: then the law
    is the point mean)."""
    shape = tuple(int(n) for n in np.atleast_1d(size))
    law = _normal_law(mean, std, low, high, shape[-1])
    u, out = _law_uniforms(rng, name, law, shape), np.empty(shape)
    _kernel().truncated_normals(law, u.reshape(-1, shape[-1]), out.reshape(-1, shape[-1]))
    return out


def sphere_directions(rng: np.random.Generator, size: int, law: str = "uniform", joint: str = "") -> np.ndarray:
    """Unit vectors (size, 3): uniform on the sphere, or the paper's eta_d1 = pi u variant (polar
    then azimuth uniforms, blocks ``<joint>_polar`` and ``<joint>_azimuth``)."""
    u1, u2 = _uniform(rng, f"{joint}_polar", size=size), _uniform(rng, f"{joint}_azimuth", size=size)
    out = np.empty((size, 3))
    _kernel().sphere_directions_into(u1, u2, law == "uniform", out)
    return out


def eccentricities_inside(draw, w, size, margin: float, first: int, stop: int) -> bool:
    """Whether steps [first, stop) of a per-step draw (eccentricities (steps, 6, 3) m) lie inside their
    clearances ``size`` (18,) m, A, C, B, with ``margin`` on the squared lengths (the revolute's radial
    part off its axis w (6, 3)); one compiled pass (:func:`.draw_kernel.inside_clearances`)."""
    # writable C-ordered float arrays: the argument types of the one compiled overload (draw_kernel._load)
    e_A, e_C, e_B = (np.require(a, float, "CW") for a in (draw.e_A, draw.e_C, draw.e_B))
    return _kernel().inside_clearances(e_A, e_C, e_B, np.array(w, float), np.array(size, float),
                                       float(margin), int(first), int(stop))


@dataclass(frozen=True)
class SizeBand:
    """A joint family's clearance-size tolerance band (m): uniform on [low, high], or the family's
    nominal size + Normal(0, std) truncated to [low, high]."""
    law: str      # 'normal' or 'uniform'
    low: float    # m
    high: float   # m
    std: float    # m, the normal law's standard deviation (0 for 'uniform')


@dataclass(frozen=True)
class ClearanceDraw:
    """The clearance sizes (m) and eccentricity vectors (m, base frame) of one realisation."""
    radial_size: np.ndarray   # (6,) delta_r of A_i
    axial_size: np.ndarray    # (6,) delta_a of A_i
    size_C: np.ndarray        # (6,)
    size_B: np.ndarray        # (6,)
    e_A: np.ndarray           # (6, 3) radial + axial
    e_C: np.ndarray           # (6, 3)
    e_B: np.ndarray           # (6, 3)


def size_band(scene, family: str):
    """The family's size band: its [tolerance.<family>], else the relative [sampling] size_tolerance
    as Normal(nominal, tolerance nominal) truncated to [0, RELATIVE_BAND_REACH nominal], else None
    (nominal sizes)."""
    band, nominal = getattr(scene.tolerance, family), getattr(scene.clearance, family)
    tol = scene.sampling.size_tolerance
    if band is None and tol > 0.0 and nominal > 0.0:
        return SizeBand("normal", 0.0, RELATIVE_BAND_REACH * nominal, tol * nominal)
    return band


def _sizes(rng, name: str, nominal: float, band) -> np.ndarray:
    """Six clearance sizes (m) of one family from six uniforms (block ``name``): nominal, or drawn
    from ``band``."""
    if band is None:
        if not isinstance(rng, NamedUniforms):
            rng.uniform(size=6)  # keep the stream's layout the same with and without tolerances
        return np.full(6, nominal)
    if band.law == "uniform":
        return _uniform(rng, name, band.low, band.high, size=6)
    return truncated_normal(rng, nominal, band.std, band.low, band.high, 6, name)


SIZE_UNIFORMS = 24   # a draw takes its uniforms for the 4 x 6 clearance sizes first
FAMILIES = ("revolute_radial", "revolute_axial", "spherical_C", "spherical_B")   # in that order
SIZE_BLOCKS = ("A_radial_size", "A_axial_size", "C_size", "B_size")              # the families' sizes
# the blocks of six uniforms (legs 1-6) a draw takes, in stream order (A_radial_magnitude and A_axial
# are skipped where their law is a point)
UNIFORM_BLOCKS = SIZE_BLOCKS + ("A_radial_magnitude", "A_radial_angle", "A_axial", "C_magnitude", "C_polar",
                                "C_azimuth", "B_magnitude", "B_polar", "B_azimuth")


def uniform_dimension(steps: int | None = None, scene=None) -> int:
    """Most uniforms one draw uses: 4 x 6 sizes, then the nine blocks of :data:`UNIFORM_BLOCKS` (A's
    radial magnitude, angle and axial, C's and B's magnitude and two direction angles), each over every
    step and leg (fewer where a law is degenerate); with
    a ``scene`` that has uncertain inputs, theirs after these (rss6core/uncertain.py)."""
    extra = 0 if scene is None else scene.uncertain.dimension
    return SIZE_UNIFORMS + 9 * 6 * (1 if steps is None else steps) + extra


def draw_clearances(scene, seed: int, realization: int, steps: int | None = None,
                    uniforms=None, out: dict | None = None) -> ClearanceDraw:
    """Draw realisation ``realization`` of the scene's clearance laws.

    From its own stream, or with ``uniforms(realization, dimension) -> ndarray`` (e.g. a
    quasi-Monte Carlo design) from the uniforms it returns.  With ``steps`` the sizes are
    drawn once and the eccentricities ``steps`` times (leading axis), as the paper level
    redraws them every time step (sec. 2).  ``out``: per-step eccentricity arrays {"e_A", "e_C", "e_B"}
    (steps, 6, 3), C-ordered, to fill in place (the paper level's padded history) instead of new ones.
    """
    if uniforms is not None:
        return clearances_from_uniforms(scene, uniforms(realization, uniform_dimension(steps, scene)), steps, out)
    return _draw(scene, realization_rng(seed, realization), steps, out)


def clearances_from_uniforms(scene, u, steps: int | None = None, out: dict | None = None) -> ClearanceDraw:
    """The draw as a function of a vector of at most ``uniform_dimension(steps)`` uniforms in [0, 1)
    (``out`` as for :func:`draw_clearances`)."""
    return _draw(scene, UniformVector(u), steps, out)


def clearances_from_named_uniforms(scene, blocks: dict) -> ClearanceDraw:
    """The draw as a function of its uniforms by block (:data:`UNIFORM_BLOCKS`, six each): the same
    laws and arithmetic as :func:`clearances_from_uniforms`; a size block is needed only where the
    family's size varies (:func:`size_band`)."""
    return _draw(scene, NamedUniforms(blocks), None)


def _draw(scene, rng, steps: int | None, out: dict | None = None) -> ClearanceDraw:
    """The draw from ``rng`` (a Generator, a :class:`UniformVector` or :class:`NamedUniforms`),
    uniforms taken in a fixed order (:data:`UNIFORM_BLOCKS`), turned into eccentricities by the
    compiled kernel (:func:`.draw_kernel.eccentricities_into`)."""
    cl, law = scene.clearance, scene.sampling
    dr, da, dC, dB = (_sizes(rng, name, getattr(cl, f), size_band(scene, f))
                      for f, name in zip(FAMILIES, SIZE_BLOCKS))
    shape = (1 if steps is None else steps, 6)
    kernel = _kernel()
    radial = _normal_law(law.radial_mean * dr, law.radial_std * dr, 0.0, dr, 6)
    radial_u = _law_uniforms(rng, "A_radial_magnitude", radial, shape)
    angle_u = _uniform(rng, "A_radial_angle", size=shape)
    axial = _normal_law(law.axial_mean * da, law.axial_std * da, -da, da, 6)
    axial_u = _law_uniforms(rng, "A_axial", axial, shape)
    u = scene.geometry.base_angles
    # the plane normal to w_i is spanned by the horizontal radial direction and Z
    plane_x = np.stack([np.cos(u), np.sin(u), 0 * u], -1)
    plane_y = np.tile([0.0, 0.0, 1.0], (6, 1))
    # fresh writable C-ordered copies: the argument types of the one compiled overload (draw_kernel._load)
    revolute = kernel.Revolute(radial, radial_u, angle_u, axial, axial_u, plane_x, plane_y,
                               np.array(scene.geometry.w, float, order="C"))
    C, B = (_sphere(rng, joint, size, shape, law.direction) for joint, size in (("C", dC), ("B", dB)))
    e_A, e_C, e_B = ((np.empty(shape + (3,)) for _ in range(3)) if out is None else
                     (out["e_A"], out["e_C"], out["e_B"]))
    kernel.eccentricities_into(revolute, C, B, e_A, e_C, e_B)
    if steps is None:   # own copies, not views that would keep their buffer alive with the draw
        e_A, e_C, e_B = e_A[0].copy(), e_C[0].copy(), e_B[0].copy()
    return ClearanceDraw(dr, da, dC, dB, e_A, e_C, e_B)


def _sphere(rng, joint: str, size: np.ndarray, shape: tuple, law: str):
    """A spherical joint's sizes and uniforms as the kernel reads them (:class:`.draw_kernel.Sphere`):
    magnitude k_s, then polar, then azimuth uniforms."""
    magnitude_u = _uniform(rng, f"{joint}_magnitude", size=shape)
    polar_u = _uniform(rng, f"{joint}_polar", size=shape)
    azimuth_u = _uniform(rng, f"{joint}_azimuth", size=shape)
    return _kernel().Sphere(np.array(size, float), magnitude_u, polar_u, azimuth_u, law == "uniform")
