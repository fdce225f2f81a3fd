"""Compiled arithmetic of the clearance laws (docs/model.md section 4): uniforms in, eccentricities out.

:mod:`.clearance` takes the uniforms from the realisation's stream (or a design) in their fixed
order and hands them here; these kernels apply the laws' inverse CDFs and the vector products in one
pass over the joint-steps, without numpy's temporaries (a per-step draw of the paper level is 12 030
joint-steps).  No fastmath; scipy's own ``ndtri`` (its Cython export, called by symbol name so the
kernels stay cacheable).  The angles are uniform in turns (theta = 2 pi u), and their cosine and sine
come from :func:`turn`: the quadrant from 4 u, exactly, then fdlibm's polynomials on [-pi/4, pi/4],
branch-free and without a library call.  That is within 2e-16 of the exact values (numpy's float64
``sin(2 pi u)`` is within 7e-16: the product 2 pi u is rounded before the sine reduces it), and
about 20x cheaper than glibc's sin and cos, which took about half of the draw kernel's time
(docs/performance.md section 34).  On the uniform sphere the polar angle eta_1 = arccos z,
z = 1 - 2 u, is never formed: its cosine is z and its sine sqrt((1 - z)(1 + z)) (eta_1 lies in
[0, pi]); the paper's law eta_1 = pi u is half a turn of u.

Everything a kernel reads is a named structure read by name (:class:`TruncatedNormal`,
:class:`Revolute`, :class:`Sphere`).  numba is imported here only: a process that draws nothing
does without its 0.3 s import.
"""
from __future__ import annotations

import math
from collections import namedtuple

import llvmlite.binding as llvm
import numpy as np
from numba import njit, types
from numba.extending import get_cython_function_address

__all__ = ["TruncatedNormal", "Revolute", "Sphere", "truncated_normals", "sphere_directions_into",
           "eccentricities_into", "inside_clearances", "turn"]

TWO_PI = 2.0 * math.pi
# fdlibm's minimax polynomials of sin and cos on [-pi/4, pi/4] (k_sin.c, k_cos.c; error < 1 ulp)
_S = (-1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
      2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10)
_C = (4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
      -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11)

# scipy.special.ndtri's Cython export: double ndtri(double x, int skip_dispatch)
llvm.add_symbol("rss6_ndtri", get_cython_function_address("scipy.special.cython_special", "ndtri"))
_ndtri = types.ExternalFunction("rss6_ndtri", types.float64(types.float64, types.intc))

# Normal(mean, std) truncated to [low, high] per leg (arrays (legs,)), inverted from CDF values lo, hi
# of its ends (ndtr's, taken once per draw by the caller); ``point``: a std is not positive, the law
# is the point mean clipped to [low, high] and takes no uniforms
TruncatedNormal = namedtuple("TruncatedNormal", "point mean std lo hi low high")
# the revolute's draw: radial magnitude and axial offset (TruncatedNormal each) and their uniforms
# (steps, legs; empty for a point law), the radial angle's uniforms, the plane of the radial part
# spanned by plane_x, plane_y (legs, 3), the axis w (legs, 3)
Revolute = namedtuple("Revolute", "radial radial_u angle_u axial axial_u plane_x plane_y w")
# a spherical joint's draw: sizes (legs,) m, magnitude, polar and azimuth uniforms (steps, legs), and
# the direction law (uniform_sphere: eta_1 = arccos(1 - 2 u); else the paper's eta_1 = pi u)
Sphere = namedtuple("Sphere", "size magnitude_u polar_u azimuth_u uniform_sphere")


@njit(cache=True)
def _clip(x, low, high):
    """numpy's clip of a float: max then min, NaN kept."""
    if math.isnan(x):
        return x
    x = x if x > low else low
    return x if x < high else high


@njit(cache=True)
def turn(u):
    """(cos 2 pi u, sin 2 pi u) of a fraction u of a turn, u in [0, 1]: the nearest quarter turn q = 4 u
    rounded (u - q / 4 is exact), fdlibm's polynomials of the rest, x = 2 pi (u - q / 4) in
    [-pi/4, pi/4], turned by q quarters; selects, no branches, so that a loop of it vectorises."""
    q = math.floor(4.0 * u + 0.5)
    x = TWO_PI * (u - 0.25 * q)
    z = x * x
    s = x + (z * x) * (_S[0] + z * (_S[1] + z * (_S[2] + z * (_S[3] + z * (_S[4] + z * _S[5])))))
    c = 1.0 - (0.5 * z - z * (z * (_C[0] + z * (_C[1] + z * (_C[2] + z * (_C[3] + z * (_C[4] + z * _C[5])))))))
    k = int(q) & 3
    odd = (k & 1) == 1
    cos_part, sin_part = (s if odd else c), (c if odd else s)
    return (-cos_part if k == 1 or k == 2 else cos_part), (-sin_part if k >= 2 else sin_part)


@njit(cache=True)
def _truncated(law, u, leg):
    """One draw of leg ``leg``'s truncated normal from the uniform u (unused for a point law)."""
    if law.point:
        return _clip(law.mean[leg], law.low[leg], law.high[leg])
    x = law.mean[leg] + law.std[leg] * _ndtri(law.lo[leg] + u * (law.hi[leg] - law.lo[leg]), 0)
    return _clip(x, law.low[leg], law.high[leg])


@njit(cache=True)
def truncated_normals(law, u, out):
    """out[j, l] = leg l's truncated normal of the uniform u[j, l] (a point law reads no u)."""
    for j in range(out.shape[0]):
        for leg in range(out.shape[1]):
            out[j, leg] = _truncated(law, u[j, leg] if not law.point else 0.0, leg)


@njit(cache=True)
def _direction(u1, u2, uniform_sphere):
    """The unit vector (sin eta1 cos eta2, sin eta1 sin eta2, cos eta1) of the polar uniform u1 and
    azimuth eta2 = 2 pi u2: eta1 = arccos(1 - 2 u1) on the uniform sphere (its sine from the cosine
    z as sqrt((1 - z)(1 + z))), else the paper's eta1 = pi u1 (half a turn of u1)."""
    if uniform_sphere:
        z = 1.0 - 2.0 * u1
        sin1 = math.sqrt((1.0 - z) * (1.0 + z))
    else:
        z, sin1 = turn(0.5 * u1)
    cos2, sin2 = turn(u2)
    return sin1 * cos2, sin1 * sin2, z


@njit(cache=True)
def sphere_directions_into(u1, u2, uniform_sphere, out):
    """out[j] = the unit vector of polar uniform u1[j] and azimuth uniform u2[j] (out (n, 3))."""
    for j in range(out.shape[0]):
        out[j, 0], out[j, 1], out[j, 2] = _direction(u1[j], u2[j], uniform_sphere)


@njit(cache=True)
def _spherical(sphere, out):
    """out[j, l] = k_s delta_s times the direction, (magnitude_u[j, l] size[l]) times each component.
    The unit vectors first, in a flat loop of their own (one per law) that vectorises, which the
    interleaved (n, 3) stores of the scaled vectors kept scalar."""
    steps, legs = sphere.magnitude_u.shape
    polar, azimuth = sphere.polar_u.ravel(), sphere.azimuth_u.ravel()
    x, y, z = np.empty(steps * legs), np.empty(steps * legs), np.empty(steps * legs)
    if sphere.uniform_sphere:
        for i in range(steps * legs):
            x[i], y[i], z[i] = _direction(polar[i], azimuth[i], True)
    else:
        for i in range(steps * legs):
            x[i], y[i], z[i] = _direction(polar[i], azimuth[i], False)
    for j in range(steps):
        for leg in range(legs):
            i = j * legs + leg
            magnitude = sphere.magnitude_u[j, leg] * sphere.size[leg]
            out[j, leg, 0], out[j, leg, 1], out[j, leg, 2] = magnitude * x[i], magnitude * y[i], magnitude * z[i]


@njit(cache=True)
def eccentricities_into(rev, C, B, e_A, e_C, e_B):
    """e_A, e_C, e_B (steps, legs, 3) of a draw from its uniforms (steps, legs): the revolute's
    radial (truncated normal) magnitude r at angle theta = 2 pi u (:func:`turn`) plus the axial offset a,
    e_A = r cos(theta) plane_x + r sin(theta) plane_y + a w, and each sphere's k_s delta_s times a
    direction (:class:`Revolute`, :class:`Sphere`).  The turns first, in a flat loop of their own that
    vectorises (beside scipy's ndtri calls they ran scalar)."""
    steps, legs = e_A.shape[0], e_A.shape[1]
    angle = rev.angle_u.ravel()
    cosines, sines = np.empty(steps * legs), np.empty(steps * legs)
    for i in range(steps * legs):
        cosines[i], sines[i] = turn(angle[i])   # theta = 2 pi u
    for j in range(steps):
        for leg in range(legs):
            r = _truncated(rev.radial, rev.radial_u[j, leg] if not rev.radial.point else 0.0, leg)
            a = _truncated(rev.axial, rev.axial_u[j, leg] if not rev.axial.point else 0.0, leg)
            rc, rs = r * cosines[j * legs + leg], r * sines[j * legs + leg]
            for k in range(3):
                e_A[j, leg, k] = (rc * rev.plane_x[leg, k] + rs * rev.plane_y[leg, k]) + a * rev.w[leg, k]
    _spherical(C, e_C)
    _spherical(B, e_B)


@njit(cache=True)
def inside_clearances(e_A, e_C, e_B, w, size, margin, first, stop):
    """Whether every step in [first, stop) of a draw's eccentricities (steps, legs, 3) lies inside its
    joint's clearance with a margin: |e_A - (e_A . w) w|^2, |e_C|^2 and |e_B|^2 below ``margin`` times
    the squared size (``size`` (18,) m: A, C, B by leg; ``w`` (legs, 3) the revolute axes).  The same
    products as numpy's x x + y y + z z; a NaN fails, as in numpy's comparison.  Counted without an
    early exit, so that the loops vectorise.  Squares as products: numba compiles ``x ** 2`` as a
    subroutine shared per process with later callers (:func:`.contact_kernel.own_subroutines`)."""
    legs = e_A.shape[1]
    outside = 0
    for j in range(first, stop):
        for leg in range(legs):
            x, y, z = e_A[j, leg, 0], e_A[j, leg, 1], e_A[j, leg, 2]
            along = x * w[leg, 0] + y * w[leg, 1] + z * w[leg, 2]
            rx, ry, rz = x - along * w[leg, 0], y - along * w[leg, 1], z - along * w[leg, 2]
            outside += not (rx * rx + ry * ry + rz * rz < margin * (size[leg] * size[leg]))
    for e, offset in ((e_C, legs), (e_B, 2 * legs)):
        for j in range(first, stop):
            for leg in range(legs):
                x, y, z = e[j, leg, 0], e[j, leg, 1], e[j, leg, 2]
                outside += not (x * x + y * y + z * z < margin * (size[offset + leg] * size[offset + leg]))
    return outside == 0


def _load() -> None:
    """Compile, or load from numba's cache, the one overload of each draw kernel every draw calls
    (the argument types :mod:`.clearance` passes), at import: a fork server that preloads this
    module hands them to every worker it forks, which then neither compiles nor loads them."""
    legs = np.zeros(6)
    law = TruncatedNormal(False, legs, legs, legs, legs, legs, legs)
    u, vectors, out = np.zeros((1, 6)), np.zeros((6, 3)), np.zeros((1, 6, 3))
    truncated_normals(law, u, np.zeros((1, 6)))
    sphere = Sphere(legs, u, u, u, True)
    eccentricities_into(Revolute(law, u, u, law, u, vectors, vectors, vectors), sphere, sphere, out, out, out)
    inside_clearances(out, out, out, vectors, np.ones(18), 1.0, 0, 1)


_load()
