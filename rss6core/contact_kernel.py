"""Compiled time stepping of the contact level (L4): whole steps, one realisation after another.

The contact level spends almost all its time in small dense work per
realisation (18 contact pairs, six 12x12 leg systems, a 6x6 border), where
numpy's per-call overhead is many times the arithmetic.  This module runs
that work compiled with numba, one realisation after another, so a
realisation's result never depends on its batch.  It computes what the
vectorised functions of :mod:`.contact_dynamics` compute (its "numpy" engine:
``_contacts``, ``_generalized``, ``_tangent``, ``_solve_arrow`` and
``NumpyStepper._step``; the tests compare them).  One module, because numba's on-disk
cache of a function is invalidated only by changes to its own file, and
:func:`advance_chunk` compiles the Newton iteration into itself.

The Newton iteration (:func:`newton_one`):
- joint maps G (per leg, 9x12) take the joint-node vector [crank node 0,
  crank tip, rod C end, rod B end] (link frames) to the relative
  displacements [e_A, e_C, e_B] (base frame); only the blocks (row j, column
  block c) listed in ``_PATTERN`` are non-zero, and they are the link frames
  [Rc, -Rc, Rr, Rr] (:func:`_gmap`), so the kernel reads Rc and Rr, not G;
- Lankarani-Nikravesh normal force (eq. 17) and modified Coulomb friction
  (eq. 18) with their Jacobians, as in :mod:`.contact_laws`;
- a block-arrow Newton matrix: six leg blocks bordered by the 6 platform DOFs.

The steps (:func:`advance_chunk`) carry every live realisation of a batch
through a run of base steps: the integrator's predictor, the links' internal
forces, the static condensation onto the joint nodes, the Newton iteration,
the recovery of the link interiors, the corrector, and the adaptive step's
accept-or-halve decision, without numpy's per-call overhead, which dominated
wherever a few realisations refine a step while the others wait.  Per
realisation, a refined base step follows the same attempts as ``NumpyStepper._step``'s
recursion: a failed attempt at level l is retried at level l + 1 from the same
instant; after an accepted step the next attempt takes the coarsest level
whose step starts at the instant reached.  The dense products (six legs at a
time per link type) go to BLAS's dgemm (:func:`_product`).

Everything the kernel reads is a named structure read by name (:class:`Levels`,
:class:`Layout`, :class:`Settings`, :class:`ChunkArrays`, :class:`Joints`, :class:`State`,
:class:`Records`, :class:`Work`, :class:`Scratch`): numba compiles namedtuples of arrays and
scalars in nopython mode, and a reordered field is then a renamed field, not a silently wrong vector.

Small helpers take scalars and whole arrays with indices rather than views, and
are inlined: each array argument costs two atomic reference-count updates,
which had been a third of the run time.  The entry points :func:`advance_chunk` and
:func:`newton_step` allocate nothing and are compiled without numba's reference counting
(``_nrt=False``): the caller's arrays outlive the call, and the counting that inlining
left (views, named structures) was still a fifth of the steps' time.
"""
from __future__ import annotations

from collections import namedtuple

import llvmlite.binding as llvm
import numpy as np
from numba import njit, types
from numba.extending import get_cython_function_address

from .status import DIVERGED, NEWTON_FAILED   # the failure codes written to ``fail``

__all__ = ["newton_step", "advance_chunk", "ball", "predict_one", "correct_one", "Levels", "Layout",
           "Settings", "ChunkArrays", "Frame", "Law", "Joints", "State", "Records", "Out", "System",
           "make_work", "make_scratch"]

# reassociation and fused multiply-add, but no finite-math assumption: a diverging
# realisation's inf and nan must survive to be reported.  Every fastmath function is inlined
# into the entry point that runs it (inline="always"): a compiled callee is also linked as a
# copy into each caller and optimised again there, which with reassociation gives other
# round-off, and which copy a call binds to depended on which was loaded first, so a process
# that compiled the kernel and one that loaded it from numba's cache differed at 1e-11.
_FAST = {"contract", "reassoc", "nsz", "arcp"}
# non-zero 3x3 blocks of a leg's joint map G: relative displacement j <- joint-node block c; block q
# is Rc, -Rc, Rr, Rr (:func:`_gmap`)
_PATTERN = np.array([[0, 0], [1, 1], [1, 2], [2, 3]], np.int64)
# BLAS's dgemm (SciPy's, as np.dot in numba uses) called by its symbol name, so the kernel stays
# cacheable; np.dot's three-argument form needs numba's reference counting, which the entry
# points leave out.  Arguments: addresses of Fortran's character, integer (int32) and double arguments.
llvm.add_symbol("rss6_dgemm", get_cython_function_address("scipy.linalg.cython_blas", "dgemm"))
_dgemm = types.ExternalFunction("rss6_dgemm", types.void(*[types.uintp] * 13))


# --- named structures: every array and constant the kernel reads, by name ---

Levels = namedtuple("Levels", "span h coef_p d_pred v_pred d_corr v_corr error legs crank_T crank_P rod_T rod_P")
Levels.__doc__ = """Step levels l = 0 (the base step) .. L - 1 (finest): fine-grid intervals per step, h (s),
the platform mass weight of the step matrix, the predictor/corrector weights
(:class:`.integrators.StepWeights`), |beta - 1/6| h^2 (s^2) (L,); the condensed leg matrices
(L, 12, 12) and per link type the condensation r -> [r_i E_ii^-1, r_b - r_i P] (L, n, n_i + 6) and
P = E_ii^-1 E_ib (L, n_i, 6), which recovers the interior x_i = y - x_b P^T
(:meth:`.contact_dynamics._Condensed.maps`)."""
Layout = namedtuple("Layout", "crank_dofs crank_MK rod_MK crank_M rod_M crank_boundary crank_interior")
Layout.__doc__ = """The links' layout: crank DOFs, [M; K] of crank and rod, M of crank and rod, the crank's
joint-node indices (6,) and the others (n_i,) in order (a rod's joint nodes are its last six DOFs)."""
Settings = namedtuple("Settings", "mass_damping stiffness_damping alpha_m alpha_f settle_at steady_at "
                      "impact_floor tolerance divergence_limit tol_d tol_v max_iterations refinements")
Settings.__doc__ = """Rayleigh lambda_1 (1/s), lambda_2 (s); alpha_m, alpha_f; settle time (s); start of the
steady window (s, peaks of steps ending from then on go to window 1, earlier ones to 0); impact speed
floor (m/s); local error tolerance (m); divergence limit (m); Newton's tolerances on displacement (m)
and velocity (m/s) and its iteration cap; step refinements allowed."""
ChunkArrays = namedtuple("ChunkArrays", "F Mp Rc J Rr omega t")
ChunkArrays.__doc__ = """A chunk's instants on the finest grid (T): loads F (T, N), platform mass matrices
(T, 6, 6), crank frames Rc (T, 6, 3, 3) (with Rr the joint maps' blocks, :func:`_gmap`), platform point
maps J (T, 6, 3, 6), rod frames Rr (T, 6, 3, 3),
ideal relative angular velocities omega (T, 6, 3, 3) rad/s, t (T,) s."""
Frame = namedtuple("Frame", "Rc J Rr omega")
Frame.__doc__ = """One instant of a chunk: Rc (6, 3, 3), J (6, 3, 6), Rr (6, 3, 3), omega (6, 3, 3)."""
Law = namedtuple("Law", "exponent restitution mu v0 v1")
Law.__doc__ = """Contact law: force exponent, restitution, mu_d, stick and slip velocities (m/s)."""
Joints = namedtuple("Joints", "size axial stiffness w radius law")
Joints.__doc__ = """Per realisation (R): radial clearances [A radial, C, B] (R, 6, 3) m, A axial (R, 6) m,
stiffnesses [A, C, B] (R, 6, 3) N/m^1.5; revolute axes w (6, 3), radii [journal, sphere, sphere]
(3,) m, the :class:`Law`."""
State = namedtuple("State", "d v a Ma rest g stored in_contact crate a_past h_past")
State.__doc__ = """The batch's state (R, N): d, v, a and, for the alpha-weighted integrators, M a,
C v + K d and the generalised contact forces g; contact memory (R, 6, 4): stored impact speeds,
in-contact flags, penetration rates; Newton's predictor (:func:`_predict`): the two accepted
accelerations before a (R, 2, N) and the steps between them (R, 2) s (0: not yet known)."""
Records = namedtuple("Records", "peak cpeak hist alive fail fail_t fail_h fail_size steps iters refined")
Records.__doc__ = """Per realisation: peaks per window [startup, steady] (R, 2, 3, 6), contact force peaks
(R, 18), histories (3, R, T_out, 6), alive, failure code (:mod:`.status`), time (s), step (s) and
largest |d| (m) at failure, steps, Newton iterations, refined steps."""
Out = namedtuple("Out", "f gl gp delta rate")
Out.__doc__ = """Newton's results at the accepted iterate: contact forces (6, 3, 3), generalised forces on
the joint nodes (6, 12) and the platform (6,), penetrations and rates (6, 4)."""
Work = namedtuple("Work", "Zc Zr Ic Ir Ac Ar Yc Yr dp vp rhs tmp a_new d_new v_new rb db vb ab dpp vpp ap "
                  "impact Sp f gl gp delta rate e jb jp dims scale op")
Scratch = namedtuple("Scratch", "e de De Dv pair xb ub xp up res_l res_p dl dp base_l base_p schur ypiv lanes")


def make_work(N, nc, nr, ni_c, ni_r) -> Work:
    """Per-realisation work arrays of :func:`advance_chunk` (N system size, nc/nr crank/rod DOFs per
    leg, ni_c/ni_r their interior DOFs)."""
    e = np.empty
    return Work(e((6, 2 * nc)), e((6, 2 * nr)), e((6, nc)), e((6, nr)), e((6, nc)), e((6, nr)),
                e((6, ni_c + 6)), e((6, ni_r + 6)), e(N), e(N), e(N), e(N), e(N), e(N), e(N),
                e((6, 12)), e((6, 12)), e((6, 12)), e((6, 12)), e(6), e(6), e(6), e((6, 4)), e((6, 6)),
                e((6, 3, 3)), e((6, 12)), e(6), e((6, 4)), e((6, 4)), e((6, 3, 3)), e((6, 12)), e(6),
                e(3, np.int32), np.array([1.0, 0.0]), np.array([ord("N")], np.uint8))


def make_scratch() -> Scratch:
    """Work arrays of one realisation's Newton iteration (see :func:`newton_one`); the lane buffer's
    padding lanes hold identity frames and zero Jacobians, so they compute finite numbers nobody reads."""
    e = np.empty
    lanes = np.zeros(_SLOTS * _LANES)
    for slot in (_RC, _RC + 4, _RC + 8, _RR, _RR + 4, _RR + 8):
        lanes[slot * _LANES + 6:(slot + 1) * _LANES] = 1.0
    return Scratch(e((6, 3, 3)), e((6, 3, 3)), e((6, 3, 3, 3)), e((6, 3, 3, 3)), e(21), e((6, 12)), e((6, 12)),
                   e(6), e(6), e((6, 12)), e(6), e((6, 12)), e(6), e((6, 12)), e(6), e((6, 6)), e(6, np.int64),
                   lanes)


@njit(cache=True, fastmath=_FAST, inline="always")
def predict_one(d, v, a, h, d_pred, v_pred):
    """The generalized-alpha predictor on plain floats: the twin of :func:`.integrators.predict`."""
    return d + h * v + d_pred * a, v + v_pred * a


@njit(cache=True, fastmath=_FAST, inline="always")
def correct_one(dp, vp, a, d_corr, v_corr):
    """The corrector on plain floats: the twin of :func:`.integrators.correct`."""
    return dp + d_corr * a, vp + v_corr * a


@njit(cache=True, fastmath=_FAST, inline="always")
def _normal_law(delta, rate, impact, k, exponent, restitution):
    """Lankarani-Nikravesh F_N (eq. 17), dF/d delta and dF/d delta_dot; zero apart or pulling."""
    if delta <= 0.0:
        return 0.0, 0.0, 0.0
    # Hertz's 3/2 (the scene default) as delta sqrt(delta): pow was a twentieth of the run
    spring = k * delta * np.sqrt(delta) if exponent == 1.5 else k * delta ** exponent
    c = 0.75 * (1.0 - restitution * restitution) / impact
    factor = 1.0 + c * rate
    force = spring * factor
    if force <= 0.0:
        return 0.0, 0.0, 0.0
    return force, exponent * spring / delta * factor, spring * c


@njit(cache=True, fastmath=_FAST, inline="always")
def _pair(e0, e1, e2, d0, d1, d2, size, k, impact, exponent, restitution, mu, v0, v1, o0, o1, o2, radius,
          out):
    """Ball-in-socket pair (journal in bearing) with relative displacement e and velocity d (base
    frame): out = [force on the ball side (3), d force/d e (3x3), d force/d d (3x3)] (21,);
    returns (penetration m, its rate m/s).

    Lankarani-Nikravesh (eq. 17) with exponent, restitution; modified Coulomb friction (eq. 18)
    with mu_d, v0, v1 opposing the sliding of the relative velocity plus omega x R n (omega the
    ideal relative angular velocity, rad/s; R = radius, m).  Scalars in, one array out: every
    array argument costs two atomic reference-count updates, more than the arithmetic here.
    """
    rho = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    safe = max(rho, 1e-300)
    n0, n1, n2 = e0 / safe, e1 / safe, e2 / safe
    n = (n0, n1, n2)
    delta = rho - size
    rate = n0 * d0 + n1 * d1 + n2 * d2
    F, dF, dFr = _normal_law(delta, rate, impact, k, exponent, restitution)
    Fs = F / safe
    for a in range(3):
        out[a] = -F * n[a]
        for b in range(3):
            nn = n[a] * n[b]
            out[3 + 3 * a + b] = -dF * nn - Fs * ((1.0 if a == b else 0.0) - nn)
            out[12 + 3 * a + b] = -dFr * nn
    if mu > 0.0 and F > 0.0:     # F = 0: no friction and no friction Jacobian
        # sliding velocity: relative velocity plus the ideal rotation's sliding, tangential part
        w0 = d0 + radius * (o1 * n2 - o2 * n1)
        w1 = d1 + radius * (o2 * n0 - o0 * n2)
        w2 = d2 + radius * (o0 * n1 - o1 * n0)
        vn = n0 * w0 + n1 * w1 + n2 * w2
        s0, s1, s2 = w0 - vn * n0, w1 - vn * n1, w2 - vn * n2
        speed = np.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        ramp = (speed - v0) / (v1 - v0)
        cd = min(max(ramp, 0.0), 1.0)
        dcd = 1.0 / (v1 - v0) if (speed >= v0 and speed <= v1) else 0.0
        ss = max(speed, 1e-300)
        t = (s0 / ss, s1 / ss, s2 / ss)
        scale = -mu * F
        slope = scale * cd / ss
        turn = scale * dcd
        tn = t[0] * n0 + t[1] * n1 + t[2] * n2
        for a in range(3):
            out[a] += scale * cd * t[a]
            # jac = dF_t/dv_t = scale (cd/|v_t| (I - t t^T) + dcd t t^T), taken times (I - n n^T)
            # (friction turns with the tangential part of de only): jac - (jac n) n^T
            jn = slope * (n[a] - t[a] * tn) + turn * t[a] * tn
            dft = -mu * cd * t[a]
            for b in range(3):
                tt = t[a] * t[b]
                jab = slope * ((1.0 if a == b else 0.0) - tt) + turn * tt
                out[3 + 3 * a + b] += dft * dF * n[b]
                out[12 + 3 * a + b] += jab - jn * n[b] + dft * dFr * n[b]
    return delta, rate


@njit(cache=True, fastmath=_FAST, inline="always")
def _store(out, f, De, Dv, leg, j):
    """Scatter a pair's out (see :func:`_pair`) into f[leg, j], De[leg, j], Dv[leg, j]."""
    for a in range(3):
        f[leg, j, a] = out[a]
        for b in range(3):
            De[leg, j, a, b] = out[3 + 3 * a + b]
            Dv[leg, j, a, b] = out[12 + 3 * a + b]


@njit(cache=True, fastmath=_FAST)
def ball(e, de, size, k, impact, law, omega, radius, f, De, Dv):
    """:func:`_pair` on (3,) arrays e, de, omega: force into f, d f/d e into De, d f/d de into Dv
    (3, 3); law a :class:`Law`.  Returns (penetration m, its rate m/s)."""
    out = np.empty(21)
    delta, rate = _pair(e[0], e[1], e[2], de[0], de[1], de[2], size, k, impact, law.exponent, law.restitution,
                        law.mu, law.v0, law.v1, omega[0], omega[1], omega[2], radius, out)
    f[:] = out[:3]
    De[:, :] = out[3:12].reshape((3, 3))
    Dv[:, :] = out[12:].reshape((3, 3))
    return delta, rate


@njit(cache=True, fastmath=_FAST, inline="always")
def _gmap(Rc, Rr, leg, q, a, b):
    """Entry (a, b) of leg ``leg``'s joint-map block q (``_PATTERN``): Rc, -Rc, Rr, Rr for q = 0..3
    (:class:`.contact_dynamics._Chunk`'s G), read from the link frames: Rc is a twelfth of G's memory
    and Rr is read anyway."""
    if q == 0:
        return Rc[leg, a, b]
    if q == 1:
        return -Rc[leg, a, b]
    return Rr[leg, a, b]


@njit(cache=True, fastmath=_FAST, inline="always")
def relative(Rc, Rr, J, xb, xp, e):
    """Relative displacements [e_A, e_C, e_B] (6, 3, 3) of the joint elements (base frame) into e,
    from the joint-node vector xb (6, 12) (link frames) and the platform's xp (6,)."""
    for leg in range(6):
        for j in range(3):
            for a in range(3):
                e[leg, j, a] = 0.0
        for q in range(_PATTERN.shape[0]):
            j, c = _PATTERN[q, 0], _PATTERN[q, 1]
            for a in range(3):
                s = 0.0
                for b in range(3):
                    s += _gmap(Rc, Rr, leg, q, a, b) * xb[leg, 3 * c + b]
                e[leg, j, a] += s
        for a in range(3):
            s = 0.0
            for b in range(6):
                s += J[leg, a, b] * xp[b]
            e[leg, 2, a] -= s


@njit(cache=True, fastmath=_FAST, inline="always")
def _evaluate(fr, jt, r, impact, xb, xp, ub, up, s, out):
    """Contact forces, Jacobians (into s), penetrations and generalised forces (into out) of
    realisation r at joint-node displacements xb, xp and velocities ub, up."""
    e, de, De, Dv, f, delta, rate = s.e, s.de, s.De, s.Dv, out.f, out.delta, out.rate
    Rc, Rr, J, w, omega, radius = fr.Rc, fr.Rr, fr.J, jt.w, fr.omega, jt.radius
    relative(Rc, Rr, J, xb, xp, e)
    relative(Rc, Rr, J, ub, up, de)
    exponent, restitution, mu, v0, v1 = jt.law.exponent, jt.law.restitution, jt.law.mu, jt.law.v0, jt.law.v1
    for leg in range(6):
        w0, w1, w2 = w[leg, 0], w[leg, 1], w[leg, 2]
        sA = w0 * e[leg, 0, 0] + w1 * e[leg, 0, 1] + w2 * e[leg, 0, 2]
        kA = jt.stiffness[r, leg, 0]
        # A radial: the journal's eccentricity projected on the bearing plane (normal to w)
        d, rt = _pair(e[leg, 0, 0] - sA * w0, e[leg, 0, 1] - sA * w1, e[leg, 0, 2] - sA * w2,
                      de[leg, 0, 0], de[leg, 0, 1], de[leg, 0, 2], jt.size[r, leg, 0], kA,
                      impact[leg, 0], exponent, restitution, mu, v0, v1, omega[leg, 0, 0], omega[leg, 0, 1],
                      omega[leg, 0, 2], radius[0], s.pair)
        _store(s.pair, f, De, Dv, leg, 0)
        delta[leg, 0], rate[leg, 0] = d, rt
        for a in range(3):     # De @ Pw, Pw = I - w w^T
            q = De[leg, 0, a, 0] * w0 + De[leg, 0, a, 1] * w1 + De[leg, 0, a, 2] * w2
            De[leg, 0, a, 0] -= q * w0
            De[leg, 0, a, 1] -= q * w1
            De[leg, 0, a, 2] -= q * w2
        # A axial: the journal's faces, along +-w, radial stiffness, no friction
        sign = 1.0 if sA >= 0.0 else -1.0
        da = abs(sA) - jt.axial[r, leg]
        ra = sign * (w0 * de[leg, 0, 0] + w1 * de[leg, 0, 1] + w2 * de[leg, 0, 2])
        Fa, dFa, dFra = _normal_law(da, ra, impact[leg, 1], kA, exponent, restitution)
        wl = (w0, w1, w2)
        for a in range(3):
            f[leg, 0, a] -= Fa * sign * wl[a]
            for b in range(3):
                ww = wl[a] * wl[b]
                De[leg, 0, a, b] -= dFa * ww
                Dv[leg, 0, a, b] -= dFra * ww
        delta[leg, 1], rate[leg, 1] = da, ra
        # spherical C and B
        for j in (1, 2):
            d, rt = _pair(e[leg, j, 0], e[leg, j, 1], e[leg, j, 2], de[leg, j, 0], de[leg, j, 1],
                          de[leg, j, 2], jt.size[r, leg, j], jt.stiffness[r, leg, j], impact[leg, 1 + j],
                          exponent, restitution, mu, v0, v1, omega[leg, j, 0], omega[leg, j, 1],
                          omega[leg, j, 2], radius[j], s.pair)
            _store(s.pair, f, De, Dv, leg, j)
            delta[leg, 1 + j], rate[leg, 1 + j] = d, rt
    _generalized(Rc, Rr, J, f, out.gl, out.gp)


@njit(cache=True, fastmath=_FAST, inline="always")
def _generalized(Rc, Rr, J, f, gl, gp):
    """Generalised contact forces: G^T f on the joint nodes (6, 12), -sum J^T f_B on the platform (6,)."""
    for leg in range(6):
        for c in range(12):
            gl[leg, c] = 0.0
        for q in range(_PATTERN.shape[0]):
            j, c = _PATTERN[q, 0], _PATTERN[q, 1]
            for b in range(3):
                s = 0.0
                for a in range(3):
                    s += _gmap(Rc, Rr, leg, q, a, b) * f[leg, j, a]
                gl[leg, 3 * c + b] += s
    for b in range(6):
        s = 0.0
        for leg in range(6):
            for a in range(3):
                s += J[leg, a, b] * f[leg, 2, a]
        gp[b] = -s


# --- the Newton update, six legs side by side (:func:`_newton_update`) ---
# Every leg does the same 3x3 block arithmetic, so the update runs it for all legs at once: each
# quantity is a "slot" of _LANES numbers (one per leg; lanes 6, 7 are padding) in one flat buffer
# (Scratch.lanes), and each helper loops over the lanes, outermost, around its small fixed loops.
# One buffer with constant offsets and unsigned indices lets LLVM prove the slots apart, so it
# vectorises the lane loop without run-time alias checks (numba leaves the SLP vectoriser off, and
# LLVM refuses checks for loops this short).  Slots (3x3 blocks row-major): D_j (3 blocks: A, C, B),
# Rc, Rr, J (3x6), Sl's blocks (S_00, S_11, S_22, S_33, U_0 = S_01, W_0 = S_10, U_2 = S_23,
# W_2 = S_32), the chain's pivots A_c and their inverses (4 blocks each), reduced right-hand sides
# rhat (4x3), D_j G_c (4 blocks), U_1 = Rc^T D_C Rr, W_1 = Rr^T D_C Rc, W_k Ahat_k^-1, Rr^T D_B,
# X = Ahat_3^-1 Rr^T D_B, E = D_B + D_B Rr X, E J (3x6), J^T E J (6x6), top0 = Ahat_3^-1 rhat_3,
# D_B Rr top0, J^T of that (6), J dp, a work vector, and the leg's update (4x3).
_LANES = 8
(_D, _RC, _RR, _J, _SL, _A, _AINV, _RHAT, _DG, _U1, _W1, _T, _RD, _X, _E, _EJ, _C, _TOP0, _V, _YL, _JDP, _Z,
 _DL, _SLOTS) = np.cumsum([0, 27, 9, 9, 18, 72, 36, 36, 12, 36, 9, 9, 9, 9, 9, 9, 18, 36, 3, 3, 6, 3, 3,
                           12]).tolist()
# Sl's 3x3 blocks in the _SL slots: (row block, column block), in slot order
_SL_BLOCKS = ((0, 0), (1, 1), (2, 2), (3, 3), (0, 1), (1, 0), (2, 3), (3, 2))


@njit(cache=True, inline="always")
def _ix(slot, lane):
    """Index of a slot's lane in the lane buffer; unsigned, so numba adds no negative-index wrap that
    would hide the lanes' consecutive addresses from LLVM."""
    return np.uint64(slot * _LANES + lane)


@njit(cache=True, fastmath=_FAST, inline="always")
def _lmm(W, x, xr, xc, y, yr, yc, out, n, m, sign, acc):
    """Per lane, out (n x m, row-major) = [out +] sign X Y with inner dimension 3, X(a, u) in slot
    x + a xr + u xc and Y(u, b) in slot y + u yr + b yc (strides give transposes).  The lane loop is
    the outer one: LLVM unrolls the small inner ones and vectorises it (with the lanes innermost, it
    unrolled the lane loop into scalar code first)."""
    for lane in range(_LANES):
        for a in range(n):
            for b in range(m):
                o, x0, y0 = out + a * m + b, x + a * xr, y + b * yc
                p = (W[_ix(x0, lane)] * W[_ix(y0, lane)] + W[_ix(x0 + xc, lane)] * W[_ix(y0 + yr, lane)]
                     + W[_ix(x0 + 2 * xc, lane)] * W[_ix(y0 + 2 * yr, lane)])
                W[_ix(o, lane)] = (W[_ix(o, lane)] if acc else 0.0) + sign * p


@njit(cache=True, fastmath=_FAST, inline="always")
def _lcopy(W, src, dst, n):
    """Slots src .. src + n - 1 into dst .. dst + n - 1."""
    for lane in range(_LANES):
        for i in range(n):
            W[_ix(dst + i, lane)] = W[_ix(src + i, lane)]


@njit(cache=True, fastmath=_FAST, inline="always")
def _linv3(W, src, dst):
    """Per lane, the 3x3 block in slot dst = inverse of the one in src, by the adjugate (the pivots are
    the links' SPD condensed blocks plus the contact stiffness)."""
    for lane in range(_LANES):
        a00, a01, a02 = W[_ix(src, lane)], W[_ix(src + 1, lane)], W[_ix(src + 2, lane)]
        a10, a11, a12 = W[_ix(src + 3, lane)], W[_ix(src + 4, lane)], W[_ix(src + 5, lane)]
        a20, a21, a22 = W[_ix(src + 6, lane)], W[_ix(src + 7, lane)], W[_ix(src + 8, lane)]
        c00 = a11 * a22 - a12 * a21
        c01 = a12 * a20 - a10 * a22
        c02 = a10 * a21 - a11 * a20
        inv = np.reciprocal(a00 * c00 + a01 * c01 + a02 * c02)
        W[_ix(dst, lane)], W[_ix(dst + 3, lane)], W[_ix(dst + 6, lane)] = c00 * inv, c01 * inv, c02 * inv
        W[_ix(dst + 1, lane)] = (a02 * a21 - a01 * a22) * inv
        W[_ix(dst + 4, lane)] = (a00 * a22 - a02 * a20) * inv
        W[_ix(dst + 7, lane)] = (a01 * a20 - a00 * a21) * inv
        W[_ix(dst + 2, lane)] = (a01 * a12 - a02 * a11) * inv
        W[_ix(dst + 5, lane)] = (a02 * a10 - a00 * a12) * inv
        W[_ix(dst + 8, lane)] = (a00 * a11 - a01 * a10) * inv


@njit(cache=True, fastmath=_FAST, inline="always")
def _load_legs(fr, Sl, res_l, W):
    """The instant's link frames Rc, Rr, platform maps J and the legs' residuals (into rhat) into
    their slots, leg ``leg`` in lane ``leg``; Sl's blocks (the same for every leg) into every lane."""
    for leg in range(6):
        for a in range(3):
            for b in range(3):
                W[_ix(_RC + 3 * a + b, leg)] = fr.Rc[leg, a, b]
                W[_ix(_RR + 3 * a + b, leg)] = fr.Rr[leg, a, b]
            for b in range(6):
                W[_ix(_J + 6 * a + b, leg)] = fr.J[leg, a, b]
        for c in range(12):
            W[_ix(_RHAT + c, leg)] = res_l[leg, c]
    for q in range(len(_SL_BLOCKS)):
        r0, c0 = 3 * _SL_BLOCKS[q][0], 3 * _SL_BLOCKS[q][1]
        for a in range(3):
            for b in range(3):
                v = Sl[r0 + a, c0 + b]
                for lane in range(_LANES):
                    W[_ix(_SL + 9 * q + 3 * a + b, lane)] = v


@njit(cache=True, fastmath=_FAST, inline="always")
def _pivot(W, c, j, g):
    """Every leg's pivot A_c = Sl_cc - G_c^T D_j G_c, G_c = +-(the frame in slot g), via D_j G_c
    (sign dropped) in slot _DG + 9 c."""
    _lmm(W, _D + 9 * j, 3, 1, g, 3, 1, _DG + 9 * c, 3, 3, 1.0, False)
    _lcopy(W, _SL + 9 * c, _A + 9 * c, 9)
    _lmm(W, g, 1, 3, _DG + 9 * c, 3, 1, _A + 9 * c, 3, 3, -1.0, True)


@njit(cache=True, fastmath=_FAST, inline="always")
def _chain_blocks(W):
    """The chain L = Sl - G^T diag(D) G of every leg: pivots (G blocks Rc, -Rc, Rr, Rr for
    c = 0..3, joints A, C, C, B) and the joint C coupling U_1 = Rc^T D_C Rr (above the diagonal),
    W_1 = Rr^T D_C Rc (below); the links' couplings are Sl's blocks."""
    _pivot(W, 0, 0, _RC)
    _pivot(W, 1, 1, _RC)
    _pivot(W, 2, 1, _RR)
    _pivot(W, 3, 2, _RR)
    _lmm(W, _RC, 1, 3, _DG + 18, 3, 1, _U1, 3, 3, 1.0, False)                 # Rc^T (D_C Rr)
    _lmm(W, _RR, 1, 3, _DG + 9, 3, 1, _W1, 3, 3, 1.0, False)                  # Rr^T (D_C Rc)


@njit(cache=True, fastmath=_FAST, inline="always")
def _chain_step(W, k):
    """Eliminate pivot k of every leg's chain: T = W_k Ahat_k^-1, rhat_{k+1} -= T rhat_k,
    A_{k+1} -= T U_k, then Ahat_{k+1}^-1 (W_k, U_k: Sl's blocks, or W_1, U_1 for joint C)."""
    lower, upper = (_SL + 45, _W1, _SL + 63)[k], (_SL + 36, _U1, _SL + 54)[k]
    _lmm(W, lower, 3, 1, _AINV + 9 * k, 3, 1, _T, 3, 3, 1.0, False)
    _lmm(W, _T, 3, 1, _RHAT + 3 * k, 1, 0, _RHAT + 3 * k + 3, 3, 1, -1.0, True)
    _lmm(W, _T, 3, 1, upper, 3, 1, _A + 9 * k + 9, 3, 3, -1.0, True)
    _linv3(W, _A + 9 * k + 9, _AINV + 9 * k + 9)


@njit(cache=True, fastmath=_FAST, inline="always")
def _border(W):
    """Every leg's share of the platform's Schur complement and right-hand side: with the border
    B = Rr^T D_B J and C = J^T D_B Rr, J^T D_B J + C Ahat_3^-1 B = J^T E J,
    E = D_B + (D_B Rr) X, X = Ahat_3^-1 Rr^T D_B, and C Ahat_3^-1 rhat_3 = J^T (D_B Rr) top0,
    top0 = Ahat_3^-1 rhat_3."""
    _lmm(W, _RR, 1, 3, _D + 18, 3, 1, _RD, 3, 3, 1.0, False)                  # Rr^T D_B
    _lmm(W, _AINV + 27, 3, 1, _RD, 3, 1, _X, 3, 3, 1.0, False)
    _lcopy(W, _D + 18, _E, 9)
    _lmm(W, _DG + 27, 3, 1, _X, 3, 1, _E, 3, 3, 1.0, True)                     # D_B + (D_B Rr) X
    _lmm(W, _E, 3, 1, _J, 6, 1, _EJ, 3, 6, 1.0, False)
    _lmm(W, _J, 1, 6, _EJ, 6, 1, _C, 3, 6, 1.0, False)                         # J^T E J, rows 0-2
    _lmm(W, _J + 3, 1, 6, _EJ, 6, 1, _C + 18, 3, 6, 1.0, False)                # rows 3-5
    _lmm(W, _AINV + 27, 3, 1, _RHAT + 9, 1, 0, _TOP0, 3, 1, 1.0, False)
    _lmm(W, _DG + 27, 3, 1, _TOP0, 1, 0, _V, 3, 1, 1.0, False)
    _lmm(W, _J, 1, 6, _V, 1, 0, _YL, 6, 1, 1.0, False)


@njit(cache=True, fastmath=_FAST, inline="always")
def _platform_solve(Sp, s):
    """The platform update s.dp: Schur complement Sp - sum_legs J^T E J, right-hand side
    res_p - sum_legs J^T (D_B Rr) top0, solved with pivoting."""
    W = s.lanes
    for a in range(6):
        for b in range(6):
            q = Sp[a, b]
            for leg in range(6):
                q -= W[_ix(_C + 6 * a + b, leg)]
            s.schur[a, b] = q
        q = s.res_p[a]
        for leg in range(6):
            q -= W[_ix(_YL + a, leg)]
        s.dp[a] = q
    _lu(s.schur, s.ypiv)
    _lu_solve(s.schur, s.ypiv, s.dp)


@njit(cache=True, fastmath=_FAST, inline="always")
def _back_step(W, k):
    """Every leg's x_k = Ahat_k^-1 (rhat_k - U_k x_{k+1}) (U_k: Sl's block, or U_1 for joint C)."""
    upper = (_SL + 36, _U1, _SL + 54)[k]
    _lcopy(W, _RHAT + 3 * k, _Z, 3)
    _lmm(W, upper, 3, 1, _DL + 3 * k + 3, 1, 0, _Z, 3, 1, -1.0, True)
    _lmm(W, _AINV + 9 * k, 3, 1, _Z, 1, 0, _DL + 3 * k, 3, 1, 1.0, False)


@njit(cache=True, fastmath=_FAST, inline="always")
def _back_substitute(s):
    """Every leg's update s.dl up its chain: x_3 = top0 - X (J dp), x_k = Ahat_k^-1 (rhat_k - U_k x_{k+1})."""
    W, dp = s.lanes, s.dp
    p0, p1, p2, p3, p4, p5 = dp[0], dp[1], dp[2], dp[3], dp[4], dp[5]
    for lane in range(_LANES):
        for a in range(3):
            W[_ix(_JDP + a, lane)] = (W[_ix(_J + 6 * a, lane)] * p0 + W[_ix(_J + 6 * a + 1, lane)] * p1
                                      + W[_ix(_J + 6 * a + 2, lane)] * p2 + W[_ix(_J + 6 * a + 3, lane)] * p3
                                      + W[_ix(_J + 6 * a + 4, lane)] * p4 + W[_ix(_J + 6 * a + 5, lane)] * p5)
    _lcopy(W, _TOP0, _DL + 9, 3)
    _lmm(W, _X, 3, 1, _JDP, 1, 0, _DL + 9, 3, 1, -1.0, True)
    _back_step(W, 2)          # constant k: the slots' offsets stay constants LLVM can tell apart
    _back_step(W, 1)
    _back_step(W, 0)
    for leg in range(6):
        for c in range(12):
            s.dl[leg, c] = W[_ix(_DL + c, leg)]


@njit(cache=True, fastmath=_FAST, inline="always")
def _newton_update(fr, Sl, Sp, s):
    """Solve the block-arrow Newton system [L B; C P] [s.dl; s.dp] = [s.res_l; s.res_p] of one
    realisation, the contact Jacobians D already in their slots (:func:`newton_one`).

    L = Sl - G^T diag(D) G per leg is block tridiagonal in the joint nodes' 3x3 blocks
    (crank node 0 - crank tip: crank; tip - rod C end: joint C; C end - B end: rod), so
    each leg is eliminated block by block down to its B end (no pivoting: the blocks are
    the links' condensed step matrices, SPD, plus the contact stiffness); B = E Rr^T D_B J
    and C = J^T D_B Rr (E the B-end rows) border it, P = Sp - sum J^T D_B J.  The 6x6 Schur
    complement on the platform is solved with pivoting, then each leg back-substituted.
    The six legs run side by side in the lanes of s.lanes (see ``_LANES``).
    """
    W = s.lanes
    _load_legs(fr, Sl, s.res_l, W)
    _chain_blocks(W)
    _linv3(W, _A, _AINV)
    _chain_step(W, 0)         # constant k: the slots' offsets stay constants LLVM can tell apart
    _chain_step(W, 1)
    _chain_step(W, 2)
    _border(W)
    _platform_solve(Sp, s)
    _back_substitute(s)


System = namedtuple("System", "Sl Sp impact rb rp db dpp vb vpp")
System.__doc__ = """One step's Newton problem on the joint nodes: condensed leg matrix Sl (12, 12), platform
step matrix Sp (6, 6), impact speeds (6, 4) m/s, right-hand sides rb (6, 12), rp (6,), predicted
displacements db, dpp and velocities vb, vpp (joint nodes (6, 12), platform (6,))."""


@njit(cache=True, fastmath=_FAST, inline="always")
def _residual(sy, a_l, a_p, wf, out, s):
    """Newton's residual Sl a_l - rb - wf gl, Sp a_p - rp - wf gp into s.res_l, s.res_p; its norm.
    Sl is block diagonal (crank, rod: :class:`.contact_dynamics._Condensed`): its zero blocks are
    skipped (adding 0 x changes no bit)."""
    norm2 = 0.0
    for leg in range(6):
        for a in range(12):
            q = -sy.rb[leg, a] - wf * out.gl[leg, a]
            first = 6 * (a // 6)
            for b in range(first, first + 6):
                q += sy.Sl[a, b] * a_l[leg, b]
            s.res_l[leg, a] = q
            norm2 += q * q
    for a in range(6):
        q = -sy.rp[a] - wf * out.gp[a]
        for b in range(6):
            q += sy.Sp[a, b] * a_p[b]
        s.res_p[a] = q
        norm2 += q * q
    return np.sqrt(norm2)


@njit(cache=True, fastmath=_FAST, inline="always")
def _trial(sy, a_l, a_p, bh2, gh, s):
    """The corrector at the iterate: joint-node displacements and velocities into s.xb, s.xp, s.ub, s.up."""
    for leg in range(6):
        for c in range(12):
            s.xb[leg, c], s.ub[leg, c] = correct_one(sy.db[leg, c], sy.vb[leg, c], a_l[leg, c], bh2, gh)
    for b in range(6):
        s.xp[b], s.up[b] = correct_one(sy.dpp[b], sy.vpp[b], a_p[b], bh2, gh)


@njit(cache=True, fastmath=_FAST, inline="always")
def _move(a_l, a_p, lam, s):
    """a = base - lam * update: a full Newton step (lam = 1, base set to the iterate) or a backtrack."""
    for leg in range(6):
        for c in range(12):
            a_l[leg, c] = s.base_l[leg, c] - lam * s.dl[leg, c]
    for b in range(6):
        a_p[b] = s.base_p[b] - lam * s.dp[b]


@njit(cache=True, fastmath=_FAST, inline="always")
def _take_update(a_l, a_p, s):
    """Apply the Newton update s.dl, s.dp to the iterate (kept as the base for backtracking); returns
    the update's largest entry."""
    size = 0.0
    for leg in range(6):
        for c in range(12):
            size = max(size, abs(s.dl[leg, c]))
            s.base_l[leg, c] = a_l[leg, c]
            a_l[leg, c] -= s.dl[leg, c]
    for b in range(6):
        size = max(size, abs(s.dp[b]))
        s.base_p[b] = a_p[b]
        a_p[b] -= s.dp[b]
    return size


@njit(cache=True, fastmath=_FAST, inline="always")
def newton_one(fr, jt, r, sy, a_l, a_p, bh2, gh, wf, cfg, out, s):
    """Joint-node accelerations a_l (6, 12) and platform accelerations a_p (6,) of realisation r's
    step, in place; returns (converged, iterations).

    Solves Sl a_l - rb - wf gl(x, v) = 0, Sp a_p - rp - wf gp(x, v) = 0 with
    x = d + bh2 a, v = v_pred + gh a (the integrator's corrector), Newton with
    backtracking where a full step makes the residual worse (contact kinks).  Converged
    when the update the residual calls for (the last solve's gain times the residual)
    moves no joint by more than cfg.tol_d (m) and changes no velocity by more than cfg.tol_v
    (m/s), at most cfg.max_iterations iterations.  Writes out (:class:`Out`) at the accepted iterate.
    """
    ok = False
    n_it = 0
    last = np.inf
    gain = np.inf
    lam = 1.0
    for it in range(cfg.max_iterations + 1):
        _trial(sy, a_l, a_p, bh2, gh, s)
        _evaluate(fr, jt, r, sy.impact, s.xb, s.xp, s.ub, s.up, s, out)
        norm = _residual(sy, a_l, a_p, wf, out, s)
        est = gain * norm
        if it > 0 and bh2 * est <= cfg.tol_d and gh * est <= cfg.tol_v:
            ok = True
        if norm == 0.0:
            ok = True
        if ok or it == cfg.max_iterations:
            break
        if norm > last and lam > 1.0 / 256.0:
            lam *= 0.5                    # backtrack: halve the last update
            _move(a_l, a_p, lam, s)
            n_it += 1
            continue
        last = norm
        for leg in range(6):
            for j in range(3):
                for a in range(3):
                    for b in range(3):
                        s.lanes[_ix(_D + 9 * j + 3 * a + b, leg)] = wf * (bh2 * s.De[leg, j, a, b]
                                                                          + gh * s.Dv[leg, j, a, b])
        _newton_update(fr, sy.Sl, sy.Sp, s)
        gain = _take_update(a_l, a_p, s) / max(norm, 1e-300)
        lam = 1.0
        n_it += 1
    return ok, n_it


@njit(cache=True, fastmath=_FAST, _nrt=False)
def newton_step(fr, jt, sy, ab, ap, bh2, gh, wf, cfg, out, done, count, scratch):
    """:func:`newton_one` for every realisation of a batch (leading axis R of ``jt``'s and ``sy``'s
    per-realisation arrays, ``out``'s, ab (R, 6, 12) and ap (R, 6)), one after another; ab and ap are
    updated in place, done and count (R,) receive its returns; scratch: :func:`make_scratch`."""
    for r in range(ab.shape[0]):
        one = System(sy.Sl, sy.Sp, sy.impact[r], sy.rb[r], sy.rp[r], sy.db[r], sy.dpp[r], sy.vb[r], sy.vpp[r])
        done[r], count[r] = newton_one(fr, jt, r, one, ab[r], ap[r], bh2, gh, wf, cfg,
                                       Out(out.f[r], out.gl[r], out.gp[r], out.delta[r], out.rate[r]), scratch)


@njit(cache=True, fastmath=_FAST, inline="always")
def _lu(A, piv):
    """In-place LU with partial pivoting of the square A."""
    n = A.shape[0]
    for k in range(n):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > big:
                big = abs(A[i, k])
                p = i
        piv[k] = p
        if p != k:
            for c in range(n):
                A[k, c], A[p, c] = A[p, c], A[k, c]
        inv = 1.0 / A[k, k]
        for i in range(k + 1, n):
            A[i, k] *= inv
            m = A[i, k]
            if m != 0.0:
                for c in range(k + 1, n):
                    A[i, c] -= m * A[k, c]


@njit(cache=True, fastmath=_FAST, inline="always")
def _lu_solve(A, piv, x):
    """Solve A x = x in place for the vector x, A as left by _lu."""
    n = A.shape[0]
    for k in range(n):
        p = piv[k]
        if p != k:
            x[k], x[p] = x[p], x[k]
    for i in range(n):
        for k in range(i):
            a = A[i, k]
            if a != 0.0:
                x[i] -= a * x[k]
    for i in range(n - 1, -1, -1):
        inv = 1.0 / A[i, i]
        for k in range(i + 1, n):
            a = A[i, k]
            if a != 0.0:
                x[i] -= a * x[k]
        x[i] *= inv


# --- whole steps: predictor, condensation, Newton, recovery, adaptive control ---

@njit(cache=True, fastmath=_FAST, inline="always")
def _gather(x, o, n, X, col):
    """Rows X[leg, col:col+n] = x[leg's link slice starting at o] for the six legs (x (N,))."""
    step = (x.shape[0] - 6) // 6
    for leg in range(6):
        for c in range(n):
            X[leg, col + c] = x[leg * step + o + c]


@njit(cache=True, fastmath=_FAST, inline="always")
def _scatter(Xc, Xr, out):
    """The six legs' crank rows Xc (6, n_c) and rod rows Xr (6, n_r) into out (N,); :func:`_gather` undone."""
    nc, nr = Xc.shape[1], Xr.shape[1]
    for leg in range(6):
        base = leg * (nc + nr)
        for c in range(nc):
            out[base + c] = Xc[leg, c]
        for c in range(nr):
            out[base + nc + c] = Xr[leg, c]


@njit(cache=True, fastmath=_FAST, inline="always")
def _product(X, A, out, work):
    """out = X @ A for C-contiguous X (m, k), A (k, n), out (m, n), by BLAS's column-major dgemm as
    out^T = A^T X^T (what np.dot(X, A, out) calls, so the same bits)."""
    m, k = X.shape
    work.dims[0], work.dims[1], work.dims[2] = A.shape[1], m, k
    d, op, one = work.dims.ctypes.data, work.op.ctypes.data, work.scale.ctypes.data
    _dgemm(op, op, d, d + 4, d + 8, one, A.ctypes.data, d, X.ctypes.data, d + 8, one + 8, out.ctypes.data, d)


@njit(cache=True, fastmath=_FAST, inline="always")
def _platform(Mp, x, scale, out):
    """The platform's part of out (N,): scale Mp x over the last six entries."""
    N = out.shape[0]
    for a in range(6):
        s = 0.0
        for b in range(6):
            s += Mp[a, b] * x[N - 6 + b]
        out[N - 6 + a] = scale * s


@njit(cache=True, fastmath=_FAST, inline="always")
def _internal(x, u, layout, cfg, Mp, work, out):
    """C u + K x (Rayleigh C = l1 M + l2 K) into out (N,): per link type one product
    [l1 u, x + l2 u] (6, 2n) @ [M; K] (2n, n); the platform has mass only (l1 Mp u)."""
    nc, l1, l2 = layout.crank_dofs, cfg.mass_damping, cfg.stiffness_damping
    Zc, Zr = work.Zc, work.Zr
    N = out.shape[0]
    step = (N - 6) // 6
    nr = step - nc
    for leg in range(6):
        base = leg * step
        for c in range(nc):
            Zc[leg, c] = l1 * u[base + c]
            Zc[leg, nc + c] = x[base + c] + l2 * u[base + c]
        for c in range(nr):
            Zr[leg, c] = l1 * u[base + nc + c]
            Zr[leg, nr + c] = x[base + nc + c] + l2 * u[base + nc + c]
    _product(Zc, layout.crank_MK, work.Ic, work)
    _product(Zr, layout.rod_MK, work.Ir, work)
    _scatter(work.Ic, work.Ir, out)
    _platform(Mp, u, l1, out)


@njit(cache=True, fastmath=_FAST, inline="always")
def _mass(acc, layout, Mp, work, out):
    """M a into out (N,), per link type one product a (6, n) @ M (n, n), and the platform's."""
    nc = layout.crank_dofs
    step = (out.shape[0] - 6) // 6
    _gather(acc, 0, nc, work.Ac, 0)
    _gather(acc, nc, step - nc, work.Ar, 0)
    _product(work.Ac, layout.crank_M, work.Ic, work)
    _product(work.Ar, layout.rod_M, work.Ir, work)
    _scatter(work.Ic, work.Ir, out)
    _platform(Mp, acc, 1.0, out)


@njit(cache=True, fastmath=_FAST, inline="always")
def _joint_nodes(x, cb, nc, xb, xp):
    """Joint-node vectors (6, 12) [crank node 0, crank tip, rod C end, rod B end] and platform (6,)."""
    N = x.shape[0]
    step = (N - 6) // 6
    for leg in range(6):
        base = leg * step
        for q in range(6):
            xb[leg, q] = x[base + cb[q]]
            xb[leg, 6 + q] = x[base + step - 6 + q]
    for b in range(6):
        xp[b] = x[N - 6 + b]


@njit(cache=True, fastmath=_FAST, inline="always")
def _predict(r, h, a, a_past, h_past, cb, nc, ab, ap):
    """Newton's first iterate for a step of h (s) of realisation r: joint-node (6, 12) and platform
    (6,) accelerations extrapolated to the step's end by the polynomial through the last accepted
    ones, a[r] and a_past[r] (2, N), h_past[r] (2,) s apart (0: not yet known), of degree 2, 1 or 0
    as far as known (the numpy twin: :func:`.contact_dynamics._extrapolated`).  It saves a fifth of
    the Newton updates on the paper scene; the converged step is the same to Newton's tolerance."""
    h1, h2 = h_past[r, 0], h_past[r, 1]
    w0, w1, w2 = 1.0, 0.0, 0.0
    if h2 > 0.0:     # Lagrange weights at t + h of the nodes t, t - h1, t - h1 - h2
        w0 = (h + h1) * (h + h1 + h2) / (h1 * (h1 + h2))
        w1 = -h * (h + h1 + h2) / (h1 * h2)
        w2 = h * (h + h1) / (h2 * (h1 + h2))
    elif h1 > 0.0:
        w0 = 1.0 + h / h1
        w1 = -h / h1
    N = a.shape[1]
    step = (N - 6) // 6
    for leg in range(6):
        base = leg * step
        for q in range(12):
            i = base + cb[q] if q < 6 else base + step - 12 + q
            ab[leg, q] = w0 * a[r, i] + w1 * a_past[r, 0, i] + w2 * a_past[r, 1, i]
    for b in range(6):
        i = N - 6 + b
        ap[b] = w0 * a[r, i] + w1 * a_past[r, 0, i] + w2 * a_past[r, 1, i]


@njit(cache=True, fastmath=_FAST, inline="always")
def _remember(r, h, st):
    """Shift realisation r's accelerations a[r] into its predictor history (:func:`_predict`) before
    a step of h (s) is accepted."""
    for n in range(st.a.shape[1]):
        st.a_past[r, 1, n] = st.a_past[r, 0, n]
        st.a_past[r, 0, n] = st.a[r, n]
    st.h_past[r, 1] = st.h_past[r, 0]
    st.h_past[r, 0] = h


@njit(cache=True, fastmath=_FAST, inline="always")
def _prepare(r, level, k0, k1, extrapolate, lv, layout, cfg, ch, st, work):
    """Realisation r's step from instant k0 to k1 at level ``level`` up to its Newton problem:
    predictor, right-hand side, condensation onto the joint nodes, impact speeds, platform matrix,
    Newton's first iterate (extrapolated, :func:`_predict`, or else the last accelerations)."""
    nc, cb, am, af = layout.crank_dofs, layout.crank_boundary, cfg.alpha_m, cfg.alpha_f
    N = st.d.shape[1]
    nr = (N - 6) // 6 - nc
    ni_c, ni_r = work.Yc.shape[1] - 6, work.Yr.shape[1] - 6
    h, d_pred, v_pred = lv.h[level], lv.d_pred[level], lv.v_pred[level]
    for n in range(N):
        work.dp[n], work.vp[n] = predict_one(st.d[r, n], st.v[r, n], st.a[r, n], h, d_pred, v_pred)
    _internal(work.dp, work.vp, layout, cfg, ch.Mp[k1], work, work.tmp)
    weighted = am != 0.0 or af != 0.0
    wf = 1.0 - af
    for n in range(N):
        work.rhs[n] = wf * (ch.F[k1, n] - work.tmp[n])
        if weighted:
            work.rhs[n] += af * (ch.F[k0, n] + st.g[r, n] - st.rest[r, n]) - am * st.Ma[r, n]
    # condensation onto the joint nodes: [r_i inv, r_b - r_i P] per link type
    _gather(work.rhs, 0, nc, work.Ac, 0)
    _gather(work.rhs, nc, nr, work.Ar, 0)
    _product(work.Ac, lv.crank_T[level], work.Yc, work)
    _product(work.Ar, lv.rod_T[level], work.Yr, work)
    for leg in range(6):
        for q in range(6):
            work.rb[leg, q] = work.Yc[leg, ni_c + q]
            work.rb[leg, 6 + q] = work.Yr[leg, ni_r + q]
    _joint_nodes(work.dp, cb, nc, work.db, work.dpp)
    _joint_nodes(work.vp, cb, nc, work.vb, work.vpp)
    if extrapolate:
        _predict(r, h, st.a, st.a_past, st.h_past, cb, nc, work.ab, work.ap)
    else:
        _joint_nodes(st.a[r], cb, nc, work.ab, work.ap)
    for leg in range(6):
        for m in range(4):
            work.impact[leg, m] = (st.stored[r, leg, m] if st.in_contact[r, leg, m]
                                   else max(st.crate[r, leg, m], cfg.impact_floor))
    for i in range(6):
        for j in range(6):
            work.Sp[i, j] = lv.coef_p[level] * ch.Mp[k1, i, j]


@njit(cache=True, fastmath=_FAST, inline="always")
def _recover(level, lv, layout, work):
    """The link vectors from the joint nodes' new accelerations x_b: the interiors x_i = y - x_b P^T
    (y from the condensation; :meth:`.contact_dynamics._Condensed.recover`; a loop over P, where a
    product with the whole recovery map [y, x_b] -> x multiplied its identity blocks too), then the
    corrector: the candidate a_new, d_new, v_new in work."""
    N = work.a_new.shape[0]
    step = (N - 6) // 6
    nc, cb, ci = layout.crank_dofs, layout.crank_boundary, layout.crank_interior
    Pc, Pr = lv.crank_P[level], lv.rod_P[level]
    ni_r = Pr.shape[0]
    for leg in range(6):
        base = leg * step
        for m in range(ci.shape[0]):
            x = work.Yc[leg, m]
            for q in range(6):
                x -= Pc[m, q] * work.ab[leg, q]
            work.a_new[base + ci[m]] = x
        for m in range(ni_r):
            x = work.Yr[leg, m]
            for q in range(6):
                x -= Pr[m, q] * work.ab[leg, 6 + q]
            work.a_new[base + nc + m] = x
        for q in range(6):
            work.a_new[base + cb[q]] = work.ab[leg, q]
            work.a_new[base + nc + ni_r + q] = work.ab[leg, 6 + q]
    for b in range(6):
        work.a_new[N - 6 + b] = work.ap[b]
    d_corr, v_corr = lv.d_corr[level], lv.v_corr[level]
    for n in range(N):
        work.d_new[n], work.v_new[n] = correct_one(work.dp[n], work.vp[n], work.a_new[n], d_corr, v_corr)


@njit(cache=True, fastmath=_FAST, inline="always")
def _attempt(r, level, k0, k1, extrapolate, lv, layout, cfg, ch, jt, st, work, scratch):
    """One step of realisation r from instant k0 to k1 with level ``level``'s step: predictor,
    right-hand side, condensation, Newton (from the extrapolated accelerations or the last ones),
    recovery, corrector.  Leaves the candidate state in work and returns (converged, Newton
    iterations)."""
    _prepare(r, level, k0, k1, extrapolate, lv, layout, cfg, ch, st, work)
    N = st.d.shape[1]
    fr = Frame(ch.Rc[k1], ch.J[k1], ch.Rr[k1], ch.omega[k1])
    sy = System(lv.legs[level], work.Sp, work.impact, work.rb, work.rhs[N - 6:], work.db, work.dpp,
                work.vb, work.vpp)
    out = Out(work.f, work.gl, work.gp, work.delta, work.rate)
    ok, count = newton_one(fr, jt, r, sy, work.ab, work.ap, lv.d_corr[level], lv.v_corr[level],
                           1.0 - cfg.alpha_f, cfg, out, scratch)
    _recover(level, lv, layout, work)
    return ok, count


@njit(cache=True, fastmath=_FAST, inline="always")
def _jump(r, k1, a, layout, ch, work):
    """Largest change of a joint's relative acceleration over the candidate step, |delta a| (m/s^2)."""
    jb, jp, e = work.jb, work.jp, work.e
    _joint_nodes(a[r], layout.crank_boundary, layout.crank_dofs, jb, jp)
    for leg in range(6):           # ab, ap: the joint nodes of the new accelerations
        for q in range(12):
            jb[leg, q] = work.ab[leg, q] - jb[leg, q]
    for b in range(6):
        jp[b] = work.ap[b] - jp[b]
    relative(ch.Rc[k1], ch.Rr[k1], ch.J[k1], jb, jp, e)
    big = 0.0
    for leg in range(6):
        for j in range(3):
            big = max(big, np.sqrt(e[leg, j, 0] ** 2 + e[leg, j, 1] ** 2 + e[leg, j, 2] ** 2))
    return big


@njit(cache=True, fastmath=_FAST, inline="always")
def _accept(r, k1, layout, cfg, ch, st, rec, work):
    """Make the candidate step in work realisation r's state: contact memory, weighted terms, peaks."""
    cb = layout.crank_boundary
    N = st.d.shape[1]
    step = (N - 6) // 6
    for n in range(N):
        st.d[r, n], st.v[r, n], st.a[r, n] = work.d_new[n], work.v_new[n], work.a_new[n]
    for leg in range(6):
        for m in range(4):
            closed = work.delta[leg, m] > 0.0
            if closed and not st.in_contact[r, leg, m]:
                st.stored[r, leg, m] = work.impact[leg, m]
            st.in_contact[r, leg, m] = closed
            st.crate[r, leg, m] = work.rate[leg, m]
    if cfg.alpha_m != 0.0 or cfg.alpha_f != 0.0:
        _mass(work.a_new, layout, ch.Mp[k1], work, st.Ma[r])
        _internal(work.d_new, work.v_new, layout, cfg, ch.Mp[k1], work, st.rest[r])
        for n in range(N):
            st.g[r, n] = 0.0
        for leg in range(6):
            base = leg * step
            for q in range(6):
                st.g[r, base + cb[q]] = work.gl[leg, q]
                st.g[r, base + step - 6 + q] = work.gl[leg, 6 + q]
        for b in range(6):
            st.g[r, N - 6 + b] = work.gp[b]
    if ch.t[k1] >= cfg.settle_at:
        _peaks(r, 1 if ch.t[k1] >= cfg.steady_at else 0, work, rec)


@njit(cache=True, fastmath=_FAST, inline="always")
def _peaks(r, w, work, rec):
    """Realisation r's peaks of |platform error| in window w and of |contact force| updated with the
    candidate step."""
    N = work.d_new.shape[0]
    for b in range(6):
        rec.peak[r, w, 0, b] = max(rec.peak[r, w, 0, b], abs(work.d_new[N - 6 + b]))
        rec.peak[r, w, 1, b] = max(rec.peak[r, w, 1, b], abs(work.v_new[N - 6 + b]))
        rec.peak[r, w, 2, b] = max(rec.peak[r, w, 2, b], abs(work.a_new[N - 6 + b]))
    f = work.f
    for leg in range(6):
        for j in range(3):
            mag = np.sqrt(f[leg, j, 0] ** 2 + f[leg, j, 1] ** 2 + f[leg, j, 2] ** 2)
            rec.cpeak[r, 6 * j + leg] = max(rec.cpeak[r, 6 * j + leg], mag)


@njit(cache=True, fastmath=_FAST, inline="always")
def _largest(x):
    """Largest |x|; inf if any entry is inf or nan."""
    big = 0.0
    for n in range(x.shape[0]):
        big = max(big, abs(x[n]))
        if not np.isfinite(x[n]):
            big = np.inf
    return big


@njit(cache=True, fastmath=_FAST, inline="always")
def _base_step(r, k_start, lv, layout, cfg, ch, jt, st, rec, work, scratch):
    """Carry realisation r through one base step from fine instant k_start, halving where Newton fails
    or the local error estimate exceeds the tolerance: a failed attempt at level l is retried at
    l + 1 from the same instant; after an accepted step the next attempt takes the coarsest level
    whose step starts at the instant reached.  Returns False where r failed (recorded in rec)."""
    k, level = k_start, 0
    while k < k_start + lv.span[0]:
        k1 = k + lv.span[level]
        for start in range(2):     # one call site: _attempt is inlined once
            # extrapolation can mislead Newton across an impact: where it fails from there, retry
            # from the last accepted accelerations (the predictor-free start) before refining
            ok, count = _attempt(r, level, k, k1, start == 0, lv, layout, cfg, ch, jt, st, work, scratch)
            rec.iters[r] += count
            if ok or st.h_past[r, 0] <= 0.0:
                break
        big = _largest(work.d_new)
        sound = ok and big < cfg.divergence_limit
        accept = True
        if level < cfg.refinements:
            accept = sound
            if sound and cfg.tolerance > 0.0:
                accept = lv.error[level] * _jump(r, k1, st.a, layout, ch, work) <= cfg.tolerance
        if not accept:
            rec.refined[r] += 1
            level += 1
            continue
        if not sound:
            rec.alive[r] = False
            rec.fail[r] = NEWTON_FAILED if not ok else DIVERGED
            rec.fail_t[r], rec.fail_h[r], rec.fail_size[r] = ch.t[k1], lv.h[level], big
            return False
        _remember(r, lv.h[level], st)
        _accept(r, k1, layout, cfg, ch, st, rec, work)
        rec.steps[r] += 1
        k = k1
        level = 0
        while (k - k_start) % lv.span[level] != 0:
            level += 1
    return True


@njit(cache=True, fastmath=_FAST, _nrt=False)
def advance_chunk(live, first, n_base, every, lv, layout, cfg, ch, jt, st, rec, work, scratch):
    """Carry realisations ``live`` through base steps first .. first + n_base - 1 (the chunk's
    instants on the finest grid start at the first one's start), in place; a realisation that fails
    is recorded in rec (:class:`Records`) and stops.  Histories are kept at base steps divisible by
    ``every``.  Returns the number of realisations still alive."""
    N = st.d.shape[1]
    alive = 0
    for r in live:
        for s in range(n_base):
            if not _base_step(r, s * lv.span[0], lv, layout, cfg, ch, jt, st, rec, work, scratch):
                break
            if (first + s) % every == 0:
                k = (first + s) // every
                for b in range(6):
                    rec.hist[0, r, k, b] = st.d[r, N - 6 + b]
                    rec.hist[1, r, k, b] = st.v[r, N - 6 + b]
                    rec.hist[2, r, k, b] = st.a[r, N - 6 + b]
        alive += rec.alive[r]
    return alive
