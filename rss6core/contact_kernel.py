"""Compiled time stepping of the contact level (L4): whole steps, one realisation after another.

The contact level spends almost all its time in small dense work per
realisation (18 contact pairs, six 12x12 leg systems, a 6x6 border), where
numpy's per-call overhead is many times the arithmetic.  This module runs
that work compiled with numba, one realisation after another, so a
realisation's result never depends on its batch.  It computes what the
vectorised functions of :mod:`.contact_dynamics` (``_contacts``, ``_generalized``,
``_tangent``, ``_solve_arrow``) and the numpy stepper (:mod:`.contact_numpy`,
``NumpyStepper._step``) compute; the tests compare them.  One module, because numba's on-disk
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

import contextlib
import copy
from collections import namedtuple

import llvmlite.binding as llvm
import numpy as np
from numba import njit, types
from numba.core import inline_closurecall, ir
from numba.extending import get_cython_function_address

from .status import DIVERGED, NEWTON_FAILED   # the failure codes written to ``fail``

__all__ = ["newton_step", "advance_chunk", "fast_inlining", "own_subroutines", "kernel_compiling", "ball",
           "predict_one", "correct_one", "coarsest_next", "balance_next", "Levels", "Layout", "Settings",
           "ChunkArrays", "Frame", "Law", "Joints", "State", "Records", "Out", "System", "make_work", "make_scratch"]

# reassociation and fused multiply-add, but no finite-math assumption: a diverging
# realisation's inf and nan must survive to be reported.  Every fastmath function is inlined
# into the entry point that runs it (inline="always"): a compiled callee is also linked as a
# copy into each caller and optimised again there, which with reassociation gives other
# round-off, and which copy a call binds to depended on which was loaded first, so a process
# that compiled the kernel and one that loaded it from numba's cache differed at 1e-11.
_FAST = {"contract", "reassoc", "nsz", "arcp"}
GROWTH = 8.0    # a local error estimate's growth when the step doubles (h^3: :func:`coarsest_next`)
# non-zero 3x3 blocks of a leg's joint map G: relative displacement j <- joint-node block c; block q
# is Rc, -Rc, Rr, Rr (:func:`_gmap`)
_PATTERN = np.array([[0, 0], [1, 1], [1, 2], [2, 3]], np.int64)
# BLAS's dgemm (SciPy's, as np.dot in numba uses) called by its symbol name, so the kernel stays
# cacheable; np.dot's three-argument form needs numba's reference counting, which the entry
# points leave out.  Arguments: addresses of Fortran's character, integer (int32) and double arguments.
llvm.add_symbol("rss6_dgemm", get_cython_function_address("scipy.linalg.cython_blas", "dgemm"))
_dgemm = types.ExternalFunction("rss6_dgemm", types.void(*[types.uintp] * 13))



# --- compiling: numba's inliner without its quadratic copies ---

class _BlockCopier:
    """``copy`` as numba's inliner (``inline_closurecall``) sees it while :func:`fast_inlining` holds.

    The inliner copies a callee's IR block by block, each with ``copy.deepcopy`` and its own memo, so
    every block copies the callee's whole variable scope again: blocks times variables, which was two
    thirds of the contact kernel's compile (150 of 228 s).  Here the blocks of one IR share one copy of
    their scope (the scope and everything reachable from it are copied once, then seed each block's
    memo): the same statements and names, as a single deepcopy of all the blocks would give.
    The inliner renames every callee variable into the caller's scope right after the copy, so the
    copies' scopes were equal and are dropped either way; the inlined IR is the same
    (``python benchmarks/kernel_compile.py [--plain]`` prints hashes of the kernels' LLVM IR and
    assembly; tests/test_fast_inlining.py compares a small kernel's)."""

    def __init__(self):
        self._scope, self._count, self._memo = None, -1, {}

    def deepcopy(self, x, memo=None):
        if memo is not None or not isinstance(x, ir.Block) or not _SCOPE_COUNTABLE:
            return copy.deepcopy(x, memo)
        scope = x.scope
        if scope is not self._scope or len(scope.localvars._con) != self._count:   # another IR, or grown
            self._scope, self._count, self._memo = scope, len(scope.localvars._con), {}
            copy.deepcopy(scope, self._memo)
        return copy.deepcopy(x, dict(self._memo))   # a dict's copy costs less than a ChainMap's lookups

    def __getattr__(self, name):
        return getattr(copy, name)


# the numba internals the copier relies on (numba 0.60-0.68): without them numba's own inliner runs
_SCOPE_COUNTABLE = hasattr(ir, "Scope") and hasattr(ir, "VarMap") and hasattr(ir.VarMap(), "_con")
_SWAPPABLE = getattr(inline_closurecall, "copy", None) is copy and _SCOPE_COUNTABLE


@contextlib.contextmanager
def fast_inlining():
    """Compile (a kernel's first call in a process) with :class:`_BlockCopier` as the inliner's
    ``copy``; costs nothing once compiled or loaded.  numba compiles under one lock, so no other
    compile sees the swap.  A numba whose inliner no longer works this way keeps its own."""
    if not _SWAPPABLE:
        yield
        return
    saved = inline_closurecall.copy
    inline_closurecall.copy = _BlockCopier()
    try:
        yield
    finally:
        inline_closurecall.copy = saved


@contextlib.contextmanager
def own_subroutines():
    """Compile with a subroutine cache of the kernels' own.  numba compiles some operations (``x ** 2``)
    as subroutines that take the caller's fastmath flags but are kept per process by code and
    signature alone (``cached_internal_func``, numba issue 7168), so the first caller's flags won: a
    process that had compiled a draw kernel's ``x ** 2`` first gave the contact kernel that square
    without its flags, and a peak contact force one unit in the last place off a process that had
    not.  A numba without that cache keeps its own."""
    context = advance_chunk.targetctx
    if not isinstance(getattr(context, "cached_internal_func", None), dict):
        yield
        return
    saved = context.cached_internal_func
    context.cached_internal_func = {}
    try:
        yield
    finally:
        context.cached_internal_func = saved


@contextlib.contextmanager
def kernel_compiling():
    """What a kernel's call or compile runs under: :func:`fast_inlining` and :func:`own_subroutines`
    (both cost nothing once the kernel is compiled or loaded)."""
    with fast_inlining(), own_subroutines():
        yield

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
ChunkArrays = namedtuple("ChunkArrays", "F Mp Rc J Rr omega t offset filled")
ChunkArrays.__doc__ = """A chunk's instants on the finest grid (T): loads F (T, N), platform mass matrices
(T, 6, 6), crank frames Rc (T, 6, 3, 3) (with Rr the joint maps' blocks, :func:`_gmap`), platform point
maps J (T, 6, 3, 6), rod frames Rr (T, 6, 3, 3),
ideal relative angular velocities omega (T, 6, 3, 3) rad/s, t (T,) s, and the reference motion's own
error against the ideal pose (T, 3, 6) [displacement, velocity, acceleration] (zero for the nominal
robot; a realised robot's geometric error, rss6core/realised.py), which the peaks add; filled (n_base,)
whether a base step's interior instants hold values (its ends always do: a refined step of an unfilled
base step pauses the chunk, :func:`advance_chunk`)."""
Frame = namedtuple("Frame", "Rc J Rr omega")
Frame.__doc__ = """One instant of a chunk: Rc (6, 3, 3), J (6, 3, 6), Rr (6, 3, 3), omega (6, 3, 3)."""
Law = namedtuple("Law", "exponent v0 v1")
Law.__doc__ = """Contact law shared by every joint: force exponent, stick and slip velocities (m/s)."""
Joints = namedtuple("Joints", "size axial stiffness mu restitution w radius law")
Joints.__doc__ = """Per realisation (R): radial clearances [A radial, C, B] (R, 6, 3) m, A axial (R, 6) m,
stiffnesses [A, C, B] (R, 6, 3) N/m^1.5, friction coefficients mu_d and restitutions [A, C, B]
(R, 6, 3) (A's axial faces take A's); revolute axes w (6, 3), radii [journal, sphere, sphere] (3,) m,
the :class:`Law`."""
State = namedtuple("State", "d v a Ma balance stored in_contact crate a_past h_past coarsest")
State.__doc__ = """The batch's state (R, N): d, v, a and, for the alpha-weighted integrators, M a and
the force balance F + g - (C v + K d) (loads, generalised contact forces, internal forces:
:func:`balance_next`); contact memory (R, 6, 4): stored impact speeds, in-contact flags,
penetration rates; Newton's predictor (:func:`_predict`): the two accepted accelerations before a
(R, 2, N) and the steps between them (R, 2) s (0: not yet known); the step-size memory (R,): the
coarsest level the next step may take (:func:`coarsest_next`)."""
Records = namedtuple("Records", "peak cpeak hist alive fail fail_t fail_h fail_size steps iters refined")
Records.__doc__ = """Per realisation: peaks per window [startup, steady] (R, 2, 3, 6), contact force peaks
(R, 18), histories (3, R, T_out, 6), alive, failure code (:mod:`.status`), time (s), step (s) and
largest |d| (m) at failure, steps, Newton iterations, refined steps."""
Out = namedtuple("Out", "f gl gp delta rate")
Out.__doc__ = """Newton's results at the accepted iterate: contact forces (6, 3, 3), generalised forces on
the joint nodes (6, 12) and the platform (6,), penetrations and rates (6, 4)."""
Work = namedtuple("Work", "Zc Zr Ic Ir Ac Ar Yc Yr dp vp rhs tmp a_new d_new v_new rb db vb ab dpp vpp ap "
                  "impact Sp f gl gp delta rate e jb jp dims scale op")
Scratch = namedtuple("Scratch", "e de De Dv D pair xb ub xp up res_l res_p dl dp base_l base_p A Ainv Up "
                     "rhat M top top0 X z schur ypiv y E RD EJ v DG")


def make_work(N, nc, nr, ni_c, ni_r) -> Work:
    """Per-realisation work arrays of :func:`advance_chunk` (N system size, nc/nr crank/rod DOFs per
    leg, ni_c/ni_r their interior DOFs), each named (a missing or repeated name is a TypeError)."""
    e = np.empty
    return Work(Zc=e((6, 2 * nc)), Zr=e((6, 2 * nr)), Ic=e((6, nc)), Ir=e((6, nr)), Ac=e((6, nc)), Ar=e((6, nr)),
                Yc=e((6, ni_c + 6)), Yr=e((6, ni_r + 6)), dp=e(N), vp=e(N), rhs=e(N), tmp=e(N), a_new=e(N),
                d_new=e(N), v_new=e(N), rb=e((6, 12)), db=e((6, 12)), vb=e((6, 12)), ab=e((6, 12)), dpp=e(6),
                vpp=e(6), ap=e(6), impact=e((6, 4)), Sp=e((6, 6)), f=e((6, 3, 3)), gl=e((6, 12)), gp=e(6),
                delta=e((6, 4)), rate=e((6, 4)), e=e((6, 3, 3)), jb=e((6, 12)), jp=e(6), dims=e(3, np.int32),
                scale=np.array([1.0, 0.0]), op=np.array([ord("N")], np.uint8))


def make_scratch() -> Scratch:
    """Work arrays of one realisation's Newton iteration (see :func:`newton_one`), each named."""
    e = np.empty
    return Scratch(e=e((6, 3, 3)), de=e((6, 3, 3)), De=e((6, 3, 3, 3)), Dv=e((6, 3, 3, 3)), D=e((6, 3, 3, 3)),
                   pair=e(21), xb=e((6, 12)), ub=e((6, 12)), xp=e(6), up=e(6), res_l=e((6, 12)), res_p=e(6),
                   dl=e((6, 12)), dp=e(6), base_l=e((6, 12)), base_p=e(6), A=e((4, 3, 3)), Ainv=e((6, 4, 3, 3)),
                   Up=e((6, 3, 3, 3)), rhat=e((6, 4, 3)), M=e((3, 3)), top=e((3, 3)), top0=e((6, 3)),
                   X=e((6, 3, 3)), z=e(3), schur=e((6, 6)), ypiv=e(6, np.int64), y=e(6), E=e((3, 3)),
                   RD=e((3, 3)), EJ=e((3, 6)), v=e(3), DG=e((_PATTERN.shape[0], 3, 3)))


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
def ball(e, de, size, k, impact, law, mu, restitution, omega, radius, f, De, Dv):
    """:func:`_pair` on (3,) arrays e, de, omega: force into f, d f/d e into De, d f/d de into Dv
    (3, 3); law a :class:`Law`, mu and restitution the pair's.  Returns (penetration m, its rate m/s)."""
    out = np.empty(21)
    delta, rate = _pair(e[0], e[1], e[2], de[0], de[1], de[2], size, k, impact, law.exponent, restitution,
                        mu, law.v0, law.v1, omega[0], omega[1], omega[2], radius, out)
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
    exponent, v0, v1 = jt.law.exponent, jt.law.v0, jt.law.v1
    for leg in range(6):
        w0, w1, w2 = w[leg, 0], w[leg, 1], w[leg, 2]
        sA = w0 * e[leg, 0, 0] + w1 * e[leg, 0, 1] + w2 * e[leg, 0, 2]
        kA = jt.stiffness[r, leg, 0]
        # A radial: the journal's eccentricity projected on the bearing plane (normal to w)
        d, rt = _pair(e[leg, 0, 0] - sA * w0, e[leg, 0, 1] - sA * w1, e[leg, 0, 2] - sA * w2,
                      de[leg, 0, 0], de[leg, 0, 1], de[leg, 0, 2], jt.size[r, leg, 0], kA,
                      impact[leg, 0], exponent, jt.restitution[r, leg, 0], jt.mu[r, leg, 0], v0, v1,
                      omega[leg, 0, 0], omega[leg, 0, 1],
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
        Fa, dFa, dFra = _normal_law(da, ra, impact[leg, 1], kA, exponent, jt.restitution[r, leg, 0])
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
                          exponent, jt.restitution[r, leg, j], jt.mu[r, leg, j], v0, v1, omega[leg, j, 0],
                          omega[leg, j, 1],
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


@njit(cache=True, fastmath=_FAST, inline="always")
def _leg_chain(Rc, Rr, Sl, D, res_l, leg, s):
    """Eliminate leg ``leg``'s block-tridiagonal chain L = Sl - G^T diag(D) G down to its B end:
    the pivots' inverses s.Ainv, the upper blocks s.Up and the reduced right-hand sides s.rhat."""
    A, Ainv, Up, rhat, M, top, DG = s.A, s.Ainv, s.Up, s.rhat, s.M, s.top, s.DG
    # DG_q = D_j G_jc for the pattern's blocks; joint-node block c has pattern entry q = c
    for q in range(_PATTERN.shape[0]):
        j, c = _PATTERN[q, 0], _PATTERN[q, 1]
        for u in range(3):
            for b in range(3):
                DG[q, u, b] = (D[leg, j, u, 0] * _gmap(Rc, Rr, leg, q, 0, b)
                               + D[leg, j, u, 1] * _gmap(Rc, Rr, leg, q, 1, b)
                               + D[leg, j, u, 2] * _gmap(Rc, Rr, leg, q, 2, b))
    # diagonal blocks Sl_cc - G_c^T DG_c, off-diagonal: Sl (links) and - G_1^T D_C G_2 (joint C)
    for c in range(4):
        for a in range(3):
            g0, g1, g2 = _gmap(Rc, Rr, leg, c, 0, a), _gmap(Rc, Rr, leg, c, 1, a), _gmap(Rc, Rr, leg, c, 2, a)
            for b in range(3):
                A[c, a, b] = Sl[3 * c + a, 3 * c + b] - (g0 * DG[c, 0, b] + g1 * DG[c, 1, b] + g2 * DG[c, 2, b])
    for a in range(3):
        g0, g1, g2 = -Rc[leg, 0, a], -Rc[leg, 1, a], -Rc[leg, 2, a]          # G_1 (tip)
        for b in range(3):
            Up[leg, 0, a, b] = Sl[a, 3 + b]
            Up[leg, 1, a, b] = -(g0 * DG[2, 0, b] + g1 * DG[2, 1, b] + g2 * DG[2, 2, b])
            Up[leg, 2, a, b] = Sl[6 + a, 9 + b]
    # forward elimination down the chain: Ahat_{k+1} = A_{k+1} - W_k Ahat_k^-1 U_k
    for a in range(3):
        rhat[leg, 0, a] = res_l[leg, a]
    _inv3(A, 0, Ainv, leg, 0)
    for k in range(3):
        # W_k, the block below the diagonal: Sl (k = 0, 2) or - G_2^T D_C G_1 (k = 1)
        for a in range(3):
            for b in range(3):
                if k == 1:
                    M[a, b] = -(Rr[leg, 0, a] * DG[1, 0, b] + Rr[leg, 1, a] * DG[1, 1, b]
                                + Rr[leg, 2, a] * DG[1, 2, b])
                else:
                    M[a, b] = Sl[3 * (k + 1) + a, 3 * k + b]
        for a in range(3):                      # W_k Ahat_k^-1
            for b in range(3):
                top[a, b] = M[a, 0] * Ainv[leg, k, 0, b] + M[a, 1] * Ainv[leg, k, 1, b] \
                    + M[a, 2] * Ainv[leg, k, 2, b]
        for a in range(3):
            q = res_l[leg, 3 * (k + 1) + a]
            for b in range(3):
                q -= top[a, b] * rhat[leg, k, b]
                A[k + 1, a, b] -= (top[a, 0] * Up[leg, k, 0, b] + top[a, 1] * Up[leg, k, 1, b]
                                   + top[a, 2] * Up[leg, k, 2, b])
            rhat[leg, k + 1, a] = q
        _inv3(A, k + 1, Ainv, leg, k + 1)


@njit(cache=True, fastmath=_FAST, inline="always")
def _leg_border(J, Rr, D, leg, s):
    """Leg ``leg``'s share of the platform's Schur complement and right-hand side in s.  With the
    border B = Rr^T D_B J and its partner C = J^T D_B Rr, the share J^T D_B J + C Ahat_3^-1 B is
    J^T E J, E = D_B + (D_B Rr) X, X = Ahat_3^-1 Rr^T D_B (kept for the back substitution), and
    C Ahat_3^-1 rhat_3 = J^T (D_B Rr) top0, top0 = Ahat_3^-1 rhat_3: 3x3 work instead of 3x6."""
    E, RD, EJ, v, X, DR, Ainv, rhat = s.E, s.RD, s.EJ, s.v, s.X, s.DG[3], s.Ainv, s.rhat   # DG_3 = D_B Rr
    for a in range(3):
        for b in range(3):
            RD[a, b] = Rr[leg, 0, a] * D[leg, 2, 0, b] + Rr[leg, 1, a] * D[leg, 2, 1, b] \
                + Rr[leg, 2, a] * D[leg, 2, 2, b]
    for a in range(3):
        for b in range(3):
            X[leg, a, b] = Ainv[leg, 3, a, 0] * RD[0, b] + Ainv[leg, 3, a, 1] * RD[1, b] \
                + Ainv[leg, 3, a, 2] * RD[2, b]
        s.top0[leg, a] = (Ainv[leg, 3, a, 0] * rhat[leg, 3, 0] + Ainv[leg, 3, a, 1] * rhat[leg, 3, 1]
                          + Ainv[leg, 3, a, 2] * rhat[leg, 3, 2])
    for a in range(3):
        for b in range(3):
            E[a, b] = D[leg, 2, a, b] + DR[a, 0] * X[leg, 0, b] + DR[a, 1] * X[leg, 1, b] + DR[a, 2] * X[leg, 2, b]
        v[a] = DR[a, 0] * s.top0[leg, 0] + DR[a, 1] * s.top0[leg, 1] + DR[a, 2] * s.top0[leg, 2]
    for a in range(3):
        for b in range(6):
            EJ[a, b] = E[a, 0] * J[leg, 0, b] + E[a, 1] * J[leg, 1, b] + E[a, 2] * J[leg, 2, b]
    for a in range(6):
        for b in range(6):
            s.schur[a, b] -= J[leg, 0, a] * EJ[0, b] + J[leg, 1, a] * EJ[1, b] + J[leg, 2, a] * EJ[2, b]
        s.y[a] -= J[leg, 0, a] * v[0] + J[leg, 1, a] * v[1] + J[leg, 2, a] * v[2]


@njit(cache=True, fastmath=_FAST, inline="always")
def _back_substitute(J, s):
    """The platform update s.dp from the Schur complement, then each leg's s.dl up its chain:
    x_3 = top0 - X (J dp), x_k = Ahat_k^-1 (rhat_k - U_k x_{k+1})."""
    dl, dp, z, Ainv, Up, rhat = s.dl, s.dp, s.z, s.Ainv, s.Up, s.rhat
    _lu(s.schur, s.ypiv)
    for a in range(6):
        dp[a] = s.y[a]
    _lu_solve(s.schur, s.ypiv, dp)
    for leg in range(6):
        for a in range(3):
            q = 0.0
            for b in range(6):
                q += J[leg, a, b] * dp[b]
            z[a] = q
        for a in range(3):
            dl[leg, 9 + a] = s.top0[leg, a] - (s.X[leg, a, 0] * z[0] + s.X[leg, a, 1] * z[1]
                                               + s.X[leg, a, 2] * z[2])
        for k in range(2, -1, -1):
            for a in range(3):
                q = rhat[leg, k, a]
                for b in range(3):
                    q -= Up[leg, k, a, b] * dl[leg, 3 * (k + 1) + b]
                z[a] = q
            for a in range(3):
                dl[leg, 3 * k + a] = Ainv[leg, k, a, 0] * z[0] + Ainv[leg, k, a, 1] * z[1] + Ainv[leg, k, a, 2] * z[2]


@njit(cache=True, fastmath=_FAST, inline="always")
def _newton_update(fr, Sl, Sp, s):
    """Solve the block-arrow Newton system [L B; C P] [s.dl; s.dp] = [s.res_l; s.res_p] of one realisation.

    L = Sl - G^T diag(D) G per leg is block tridiagonal in the joint nodes' 3x3 blocks
    (crank node 0 - crank tip: crank; tip - rod C end: joint C; C end - B end: rod), so
    each leg is eliminated block by block down to its B end (no pivoting: the blocks are
    the links' condensed step matrices, SPD, plus the contact stiffness); B = I_B Rr^T D_B J
    and C = J^T D_B Rr (I_B the identity's B-end rows) border it, P = Sp - sum J^T D_B J.  The 6x6 Schur
    complement on the platform is solved with pivoting, then each leg back-substituted.
    """
    for a in range(6):
        for b in range(6):
            s.schur[a, b] = Sp[a, b]
        s.y[a] = s.res_p[a]
    for leg in range(6):
        _leg_chain(fr.Rc, fr.Rr, Sl, s.D, s.res_l, leg, s)
        _leg_border(fr.J, fr.Rr, s.D, leg, s)
    _back_substitute(fr.J, s)


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
                        s.D[leg, j, a, b] = wf * (bh2 * s.De[leg, j, a, b] + gh * s.Dv[leg, j, a, b])
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


@njit(cache=True, fastmath=_FAST, inline="always")
def _inv3(A, c, out, leg, k):
    """out[leg, k] = A[c]^-1 (3x3) by the adjugate (the pivots here are SPD-dominated, see below)."""
    c00 = A[c, 1, 1] * A[c, 2, 2] - A[c, 1, 2] * A[c, 2, 1]
    c01 = A[c, 1, 2] * A[c, 2, 0] - A[c, 1, 0] * A[c, 2, 2]
    c02 = A[c, 1, 0] * A[c, 2, 1] - A[c, 1, 1] * A[c, 2, 0]
    inv = 1.0 / (A[c, 0, 0] * c00 + A[c, 0, 1] * c01 + A[c, 0, 2] * c02)
    out[leg, k, 0, 0], out[leg, k, 1, 0], out[leg, k, 2, 0] = c00 * inv, c01 * inv, c02 * inv
    out[leg, k, 0, 1] = (A[c, 0, 2] * A[c, 2, 1] - A[c, 0, 1] * A[c, 2, 2]) * inv
    out[leg, k, 1, 1] = (A[c, 0, 0] * A[c, 2, 2] - A[c, 0, 2] * A[c, 2, 0]) * inv
    out[leg, k, 2, 1] = (A[c, 0, 1] * A[c, 2, 0] - A[c, 0, 0] * A[c, 2, 1]) * inv
    out[leg, k, 0, 2] = (A[c, 0, 1] * A[c, 1, 2] - A[c, 0, 2] * A[c, 1, 1]) * inv
    out[leg, k, 1, 2] = (A[c, 0, 2] * A[c, 1, 0] - A[c, 0, 0] * A[c, 1, 2]) * inv
    out[leg, k, 2, 2] = (A[c, 0, 0] * A[c, 1, 1] - A[c, 0, 1] * A[c, 1, 0]) * inv


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
    as far as known (the numpy twin: :func:`.contact_numpy._extrapolated`).  It saves a fifth of
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
            work.rhs[n] += af * st.balance[r, n] - am * st.Ma[r, n]
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
    N = st.d.shape[1]
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
        _mass(work.a_new, layout, ch.Mp[k1], work, work.tmp)
        for n in range(N):
            st.balance[r, n] = balance_next(work.tmp[n], st.Ma[r, n], st.balance[r, n], cfg.alpha_m, cfg.alpha_f)
            st.Ma[r, n] = work.tmp[n]
    if ch.t[k1] >= cfg.settle_at:
        _peaks(r, 1 if ch.t[k1] >= cfg.steady_at else 0, ch.offset[k1], work, rec)


@njit(cache=True, fastmath=_FAST, inline="always")
def balance_next(ma_new, ma, balance, alpha_m, alpha_f):
    """The force balance F + g - (C v + K d) (N) at the end of an accepted alpha-weighted step, from
    the step's own equation (1 - alpha_m) M a+ + alpha_m M a + (1 - alpha_f) (C v+ + K d+ - F+ - g+)
    + alpha_f (C v + K d - F - g) = 0: (1 - alpha_m) M a+ + alpha_m M a - alpha_f balance, over
    1 - alpha_f.  It replaces recomputing C v+ + K d+ (two link products per step); the two differ by
    the joint nodes' Newton residual, which the next step's right-hand side then carries.  The
    numpy engine calls this same function."""
    return ((1.0 - alpha_m) * ma_new + alpha_m * ma - alpha_f * balance) / (1.0 - alpha_f)


@njit(cache=True, fastmath=_FAST, inline="always")
def _peaks(r, w, offset, work, rec):
    """Realisation r's peaks of |platform error| (the step's plus the reference's own ``offset``
    (3, 6)) in window w and of |contact force| updated with the candidate step."""
    N = work.d_new.shape[0]
    for b in range(6):
        rec.peak[r, w, 0, b] = max(rec.peak[r, w, 0, b], abs(work.d_new[N - 6 + b] + offset[0, b]))
        rec.peak[r, w, 1, b] = max(rec.peak[r, w, 1, b], abs(work.v_new[N - 6 + b] + offset[1, b]))
        rec.peak[r, w, 2, b] = max(rec.peak[r, w, 2, b], abs(work.a_new[N - 6 + b] + offset[2, b]))
    f = work.f
    for leg in range(6):
        for j in range(3):
            mag = np.sqrt(f[leg, j, 0] ** 2 + f[leg, j, 1] ** 2 + f[leg, j, 2] ** 2)
            rec.cpeak[r, 6 * j + leg] = max(rec.cpeak[r, 6 * j + leg], mag)


@njit(cache=True, fastmath=_FAST, inline="always")
def coarsest_next(level, estimate, tolerance):
    """The coarsest level the step after an accepted one of ``level`` may take: each level coarser
    doubles h, and where the acceleration is smooth the estimate |beta - 1/6| h^2 |delta a| grows as
    h^3, so the estimate (m) predicted for a step 2^j times longer is ``estimate`` 8^j; the next step
    is not tried coarser than where that prediction exceeds ``tolerance`` (m).  Where that step is
    still refused it is halved as before.  The numpy engine calls this same function."""
    coarsest, predicted = level, estimate * GROWTH
    while coarsest > 0 and predicted <= tolerance:
        coarsest -= 1
        predicted *= GROWTH
    return coarsest


@njit(cache=True, fastmath=_FAST, inline="always")
def _largest(x):
    """Largest |x|; inf if any entry is inf or nan."""
    big = 0.0
    for n in range(x.shape[0]):
        big = max(big, abs(x[n]))
        if not np.isfinite(x[n]):
            big = np.inf
    return big


STEP_DONE, STEP_FAILED, STEP_NEEDS_FINE = 0, 1, 2   # what :func:`_base_step` returns


@njit(cache=True, fastmath=_FAST, inline="always")
def _base_step(r, k_start, lv, layout, cfg, ch, jt, st, rec, work, scratch):
    """Carry realisation r through one base step from fine instant k_start, halving where Newton fails
    or the local error estimate exceeds the tolerance: a failed attempt at level l is retried at
    l + 1 from the same instant; after an accepted step the next attempt takes the coarsest level
    whose step starts at the instant reached, but none coarser than the step-size memory
    (:func:`coarsest_next`) allows.  Returns STEP_DONE, STEP_FAILED (recorded in rec), or
    STEP_NEEDS_FINE where a refined step needs the base step's interior instants, which the chunk
    has not filled: nothing of the step is kept then (no state changes before a refined step is
    accepted; the counts are restored), and the step is taken again once they are."""
    k, level = k_start, st.coarsest[r]
    iters, refined = rec.iters[r], rec.refined[r]
    while k < k_start + lv.span[0]:
        if level > 0 and not ch.filled[k_start // lv.span[0]]:
            rec.iters[r], rec.refined[r] = iters, refined
            return STEP_NEEDS_FINE
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
        estimate = 0.0
        if sound and cfg.tolerance > 0.0:
            estimate = lv.error[level] * _jump(r, k1, st.a, layout, ch, work)
        accept = True
        if level < cfg.refinements:
            accept = sound and estimate <= cfg.tolerance
        if not accept:
            rec.refined[r] += 1
            level += 1
            continue
        if not sound:
            rec.alive[r] = False
            rec.fail[r] = NEWTON_FAILED if not ok else DIVERGED
            rec.fail_t[r], rec.fail_h[r], rec.fail_size[r] = ch.t[k1], lv.h[level], big
            return STEP_FAILED
        _remember(r, lv.h[level], st)
        _accept(r, k1, layout, cfg, ch, st, rec, work)
        rec.steps[r] += 1
        k = k1
        st.coarsest[r] = coarsest_next(level, estimate, cfg.tolerance)
        level = 0
        while (k - k_start) % lv.span[level] != 0:
            level += 1
        level = max(level, st.coarsest[r])
    return STEP_DONE


@njit(cache=True, fastmath=_FAST, _nrt=False)
def advance_chunk(live, first, n_base, every, lv, layout, cfg, ch, jt, st, rec, work, scratch, begin, pause):
    """Carry realisations ``live`` through base steps first .. first + n_base - 1 (the chunk's
    instants on the finest grid start at the first one's start), in place, realisation r from its
    chunk step begin[r]; a realisation that fails is recorded in rec (:class:`Records`) and stops.
    Histories are kept at base steps divisible by ``every``.  Where a step needs instants the chunk
    has not filled, pause = [r, step] and the call returns (the caller fills them and goes on from
    there); else pause = [-1, -1].  Returns the number of realisations still alive."""
    N = st.d.shape[1]
    alive = 0
    pause[0], pause[1] = -1, -1
    for r in live:
        for s in range(begin[r], n_base):
            code = _base_step(r, s * lv.span[0], lv, layout, cfg, ch, jt, st, rec, work, scratch)
            if code == STEP_NEEDS_FINE:
                pause[0], pause[1] = r, s
                return alive
            if code == STEP_FAILED:
                break
            if (first + s) % every == 0:
                k = (first + s) // every
                for b in range(6):
                    rec.hist[0, r, k, b] = st.d[r, N - 6 + b]
                    rec.hist[1, r, k, b] = st.v[r, N - 6 + b]
                    rec.hist[2, r, k, b] = st.a[r, N - 6 + b]
        alive += rec.alive[r]
    return alive
