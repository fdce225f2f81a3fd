"""Compiled time stepping of the contact level (L4): whole steps, one realisation after another.

The contact level spends almost all its time in small dense work per
realisation (18 contact pairs, six 12x12 leg systems, a 6x6 border), where
numpy's per-call overhead is many times the arithmetic.  This module runs
that work compiled with numba, one realisation after another, so a
realisation's result never depends on its batch.  It computes what the
vectorised functions of :mod:`.contact_dynamics` compute (its "numpy" engine:
``_contacts``, ``_generalized``, ``_tangent``, ``_solve_arrow`` and the step
``advance``; the tests compare them).  One module, because numba's on-disk
cache of a function is invalidated only by changes to its own file, and
:func:`advance_chunk` compiles the Newton iteration into itself.

The Newton iteration (:func:`newton_one`):
- joint maps G (per leg, 9x12) take the joint-node vector [crank node 0,
  crank tip, rod C end, rod B end] (link frames) to the relative
  displacements [e_A, e_C, e_B] (base frame); only the blocks (row j, column
  block c) listed in ``_PATTERN`` are non-zero;
- Lankarani-Nikravesh normal force (eq. 17) and modified Coulomb friction
  (eq. 18) with their Jacobians, as in :mod:`.contact_laws`;
- a block-arrow Newton matrix: six leg blocks bordered by the 6 platform DOFs.

The steps (:func:`advance_chunk`) carry every live realisation of a batch
through a run of base steps: the integrator's predictor, the links' internal
forces, the static condensation onto the joint nodes, the Newton iteration,
the recovery of the link interiors, the corrector, and the adaptive step's
accept-or-halve decision, without numpy's per-call overhead, which dominated
wherever a few realisations refine a step while the others wait.  Per
realisation, a refined base step follows the same attempts as ``advance``'s
recursion: a failed attempt at level l is retried at level l + 1 from the same
instant; after an accepted step the next attempt takes the coarsest level
whose step starts at the instant reached.  The dense products (six legs at a
time per link type) go to BLAS through ``np.dot``.

Arrays (R the batch, N the system size, T the chunk's instants on the finest
grid, L the step levels):
- state d, v, a and, for the alpha-weighted integrators, M a, C v + K d and the
  generalised contact forces g (R, N), updated in place;
- contact memory: stored impact speeds, in-contact flags, penetration rates (R, 6, 4);
- levels ``lv``: fine-grid intervals per step, h (s), the platform mass weight,
  beta h^2, gamma h, |beta - 1/6| h^2 (L,), the condensed leg matrices (L, 12, 12)
  and per link type the condensation r -> [r_i E_ii^-1, r_b - r_i P] (L, n, n_i + 6)
  and recovery [y, x_b] -> x (L, n_i + 6, n) maps (:meth:`.contact_dynamics._Condensed.maps`);
- ``layout``: crank DOFs, [M; K] of crank and rod, M of crank and rod, the crank's
  joint-node indices;
- chunk: loads F (T, N), platform mass matrices (T, 6, 6), joint maps G, platform
  point maps J, rod frames Rr, ideal relative angular velocities (T, 6, 3, 3), t (T,) s.

Small helpers take scalars and whole arrays with indices rather than views, and
are inlined: each array argument costs two atomic reference-count updates,
which had been a third of the run time.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["newton_step", "advance_chunk", "ball", "NEWTON_FAILED", "DIVERGED"]

# reassociation and fused multiply-add, but no finite-math assumption: a diverging
# realisation's inf and nan must survive to be reported.  Every fastmath function is inlined
# into the entry point that runs it (inline="always"): a compiled callee is also linked as a
# copy into each caller and optimised again there, which with reassociation gives other
# round-off, and which copy a call binds to depended on which was loaded first, so a process
# that compiled the kernel and one that loaded it from numba's cache differed at 1e-11.
_FAST = {"contract", "reassoc", "nsz", "arcp"}
# non-zero 3x3 blocks of a leg's joint map G: relative displacement j <- joint-node block c
_PATTERN = np.array([[0, 0], [1, 1], [1, 2], [2, 3]], np.int64)


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
    (3, 3); law = [exponent, restitution, mu_d, v0, v1].  Returns (penetration m, its rate m/s)."""
    out = np.empty(21)
    delta, rate = _pair(e[0], e[1], e[2], de[0], de[1], de[2], size, k, impact, law[0], law[1], law[2],
                        law[3], law[4], omega[0], omega[1], omega[2], radius, out)
    f[:] = out[:3]
    De[:, :] = out[3:12].reshape((3, 3))
    Dv[:, :] = out[12:].reshape((3, 3))
    return delta, rate


@njit(cache=True, fastmath=_FAST, inline="always")
def relative(G, J, xb, xp, e):
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
                    s += G[leg, 3 * j + a, 3 * c + b] * xb[leg, 3 * c + b]
                e[leg, j, a] += s
        for a in range(3):
            s = 0.0
            for b in range(6):
                s += J[leg, a, b] * xp[b]
            e[leg, 2, a] -= s


@njit(cache=True, fastmath=_FAST, inline="always")
def _evaluate(G, J, w, omega, radius, params, law, impact, xb, xp, ub, up,
              e, de, f, De, Dv, delta, rate, gl, gp, out):
    """Contact forces, Jacobians, penetrations and generalised forces of one realisation."""
    relative(G, J, xb, xp, e)
    relative(G, J, ub, up, de)
    exponent, restitution, mu, v0, v1 = law[0], law[1], law[2], law[3], law[4]
    for leg in range(6):
        w0, w1, w2 = w[leg, 0], w[leg, 1], w[leg, 2]
        sA = w0 * e[leg, 0, 0] + w1 * e[leg, 0, 1] + w2 * e[leg, 0, 2]
        # A radial: the journal's eccentricity projected on the bearing plane (normal to w)
        d, r = _pair(e[leg, 0, 0] - sA * w0, e[leg, 0, 1] - sA * w1, e[leg, 0, 2] - sA * w2,
                     de[leg, 0, 0], de[leg, 0, 1], de[leg, 0, 2], params[leg, 0], params[leg, 4],
                     impact[leg, 0], exponent, restitution, mu, v0, v1, omega[leg, 0, 0], omega[leg, 0, 1],
                     omega[leg, 0, 2], radius[0], out)
        _store(out, f, De, Dv, leg, 0)
        delta[leg, 0], rate[leg, 0] = d, r
        for a in range(3):     # De @ Pw, Pw = I - w w^T
            s = De[leg, 0, a, 0] * w0 + De[leg, 0, a, 1] * w1 + De[leg, 0, a, 2] * w2
            De[leg, 0, a, 0] -= s * w0
            De[leg, 0, a, 1] -= s * w1
            De[leg, 0, a, 2] -= s * w2
        # A axial: the journal's faces, along +-w, radial stiffness, no friction
        sign = 1.0 if sA >= 0.0 else -1.0
        da = abs(sA) - params[leg, 1]
        ra = sign * (w0 * de[leg, 0, 0] + w1 * de[leg, 0, 1] + w2 * de[leg, 0, 2])
        Fa, dFa, dFra = _normal_law(da, ra, impact[leg, 1], params[leg, 4], exponent, restitution)
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
            d, r = _pair(e[leg, j, 0], e[leg, j, 1], e[leg, j, 2], de[leg, j, 0], de[leg, j, 1],
                         de[leg, j, 2], params[leg, 1 + j], params[leg, 4 + j], impact[leg, 1 + j],
                         exponent, restitution, mu, v0, v1, omega[leg, j, 0], omega[leg, j, 1],
                         omega[leg, j, 2], radius[j], out)
            _store(out, f, De, Dv, leg, j)
            delta[leg, 1 + j], rate[leg, 1 + j] = d, r
        # generalised forces: G^T f on the joint nodes, -sum J^T f_B on the platform
        for c in range(12):
            gl[leg, c] = 0.0
        for q in range(_PATTERN.shape[0]):
            j, c = _PATTERN[q, 0], _PATTERN[q, 1]
            for b in range(3):
                s = 0.0
                for a in range(3):
                    s += G[leg, 3 * j + a, 3 * c + b] * f[leg, j, a]
                gl[leg, 3 * c + b] += s
    for b in range(6):
        s = 0.0
        for leg in range(6):
            for a in range(3):
                s += J[leg, a, b] * f[leg, 2, a]
        gp[b] = -s


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
def _lu_solve(A, piv, X, m):
    """Solve A X = X in place for the first m columns of X, A as left by _lu."""
    n = A.shape[0]
    for k in range(n):
        p = piv[k]
        if p != k:
            for c in range(m):
                X[k, c], X[p, c] = X[p, c], X[k, c]
    for i in range(n):
        for k in range(i):
            a = A[i, k]
            if a != 0.0:
                for c in range(m):
                    X[i, c] -= a * X[k, c]
    for i in range(n - 1, -1, -1):
        inv = 1.0 / A[i, i]
        for k in range(i + 1, n):
            a = A[i, k]
            if a != 0.0:
                for c in range(m):
                    X[i, c] -= a * X[k, c]
        for c in range(m):
            X[i, c] *= inv


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


@njit(cache=True, fastmath=_FAST, inline="always")
def _newton_update(G, J, Rr, Sl, Sp, D, res_l, res_p, dl, dp, A, Ainv, Up, rhat, M, top, top0, tb,
                   z, schur, ypiv, y, border, lower, DG, DJ, DR):
    """Solve the block-arrow Newton system [L B; C P] [dl; dp] = [res_l; res_p] of one realisation.

    L = Sl - G^T diag(D) G per leg is block tridiagonal in the joint nodes' 3x3 blocks
    (crank node 0 - crank tip: crank; tip - rod C end: joint C; C end - B end: rod), so
    each leg is eliminated block by block down to its B end (no pivoting: the blocks are
    the links' condensed step matrices, SPD, plus the contact stiffness); B = E Rr^T D_B J
    and C = J^T D_B Rr (E the B-end rows) border it, P = Sp - sum J^T D_B J.  The 6x6 Schur
    complement on the platform is solved with pivoting, then each leg back-substituted.
    """
    for a in range(6):
        for b in range(6):
            schur[a, b] = Sp[a, b]
        y[a] = res_p[a]
    for leg in range(6):
        # DG_q = D_j G_jc for the pattern's blocks; joint-node block c has pattern entry q = c
        for q in range(_PATTERN.shape[0]):
            j, c = _PATTERN[q, 0], _PATTERN[q, 1]
            for u in range(3):
                for b in range(3):
                    DG[q, u, b] = (D[leg, j, u, 0] * G[leg, 3 * j, 3 * c + b]
                                   + D[leg, j, u, 1] * G[leg, 3 * j + 1, 3 * c + b]
                                   + D[leg, j, u, 2] * G[leg, 3 * j + 2, 3 * c + b])
        # diagonal blocks Sl_cc - G_c^T DG_c, off-diagonal: Sl (links) and - G_1^T D_C G_2 (joint C)
        for c in range(4):
            j = _PATTERN[c, 0]
            for a in range(3):
                g0, g1, g2 = (G[leg, 3 * j, 3 * c + a], G[leg, 3 * j + 1, 3 * c + a],
                              G[leg, 3 * j + 2, 3 * c + a])
                for b in range(3):
                    A[c, a, b] = Sl[3 * c + a, 3 * c + b] - (g0 * DG[c, 0, b] + g1 * DG[c, 1, b]
                                                             + g2 * DG[c, 2, b])
        for a in range(3):
            g0, g1, g2 = G[leg, 3, 3 + a], G[leg, 4, 3 + a], G[leg, 5, 3 + a]          # G_1 (tip)
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
                        M[a, b] = -(G[leg, 3, 6 + a] * DG[1, 0, b] + G[leg, 4, 6 + a] * DG[1, 1, b]
                                    + G[leg, 5, 6 + a] * DG[1, 2, b])
                    else:
                        M[a, b] = Sl[3 * (k + 1) + a, 3 * k + b]
            for a in range(3):                      # W_k Ahat_k^-1
                for b in range(3):
                    top[a, b] = M[a, 0] * Ainv[leg, k, 0, b] + M[a, 1] * Ainv[leg, k, 1, b] \
                        + M[a, 2] * Ainv[leg, k, 2, b]
            for a in range(3):
                s = res_l[leg, 3 * (k + 1) + a]
                for b in range(3):
                    s -= top[a, b] * rhat[leg, k, b]
                    A[k + 1, a, b] -= (top[a, 0] * Up[leg, k, 0, b] + top[a, 1] * Up[leg, k, 1, b]
                                       + top[a, 2] * Up[leg, k, 2, b])
                rhat[leg, k + 1, a] = s
            _inv3(A, k + 1, Ainv, leg, k + 1)
        # border B_b = Rr^T D_B J (3x6), partner C_b = J^T D_B Rr (6x3), P -= J^T D_B J
        for u in range(3):
            for b in range(6):
                DJ[u, b] = D[leg, 2, u, 0] * J[leg, 0, b] + D[leg, 2, u, 1] * J[leg, 1, b] \
                    + D[leg, 2, u, 2] * J[leg, 2, b]
            for b in range(3):
                DR[u, b] = D[leg, 2, u, 0] * Rr[leg, 0, b] + D[leg, 2, u, 1] * Rr[leg, 1, b] \
                    + D[leg, 2, u, 2] * Rr[leg, 2, b]
        for a in range(3):
            for b in range(6):
                border[a, b] = Rr[leg, 0, a] * DJ[0, b] + Rr[leg, 1, a] * DJ[1, b] + Rr[leg, 2, a] * DJ[2, b]
        for a in range(6):
            for b in range(3):
                lower[a, b] = J[leg, 0, a] * DR[0, b] + J[leg, 1, a] * DR[1, b] + J[leg, 2, a] * DR[2, b]
            for b in range(6):
                schur[a, b] -= J[leg, 0, a] * DJ[0, b] + J[leg, 1, a] * DJ[1, b] + J[leg, 2, a] * DJ[2, b]
        # the B end: x_3 = Ahat_3^-1 (rhat_3 - border dp) = top0 - tb dp
        for a in range(3):
            top0[leg, a] = (Ainv[leg, 3, a, 0] * rhat[leg, 3, 0] + Ainv[leg, 3, a, 1] * rhat[leg, 3, 1]
                            + Ainv[leg, 3, a, 2] * rhat[leg, 3, 2])
            for b in range(6):
                tb[leg, a, b] = (Ainv[leg, 3, a, 0] * border[0, b] + Ainv[leg, 3, a, 1] * border[1, b]
                                 + Ainv[leg, 3, a, 2] * border[2, b])
        # Schur complement: P - sum C Ahat_3^-1 B, right-hand side rp - sum C Ahat_3^-1 rhat_3
        for a in range(6):
            for b in range(6):
                schur[a, b] -= (lower[a, 0] * tb[leg, 0, b] + lower[a, 1] * tb[leg, 1, b]
                                + lower[a, 2] * tb[leg, 2, b])
            y[a] -= lower[a, 0] * top0[leg, 0] + lower[a, 1] * top0[leg, 1] + lower[a, 2] * top0[leg, 2]
    _lu(schur, ypiv)
    for a in range(6):
        dp[a] = y[a]
    _lu_solve(schur, ypiv, dp.reshape((6, 1)), 1)
    for leg in range(6):
        for a in range(3):
            s = top0[leg, a]
            for b in range(6):
                s -= tb[leg, a, b] * dp[b]
            dl[leg, 9 + a] = s
        for k in range(2, -1, -1):          # x_k = Ahat_k^-1 (rhat_k - U_k x_{k+1})
            for a in range(3):
                s = rhat[leg, k, a]
                for b in range(3):
                    s -= Up[leg, k, a, b] * dl[leg, 3 * (k + 1) + b]
                z[a] = s
            for a in range(3):
                dl[leg, 3 * k + a] = (Ainv[leg, k, a, 0] * z[0] + Ainv[leg, k, a, 1] * z[1]
                                      + Ainv[leg, k, a, 2] * z[2])


@njit(cache=True)
def newton_scratch():
    """Work arrays of one realisation's Newton iteration (see :func:`newton_one`)."""
    return (np.empty((6, 3, 3)), np.empty((6, 3, 3)), np.empty((6, 3, 3, 3)), np.empty((6, 3, 3, 3)),
            np.empty((6, 3, 3, 3)), np.empty(21),
            np.empty((6, 12)), np.empty((6, 12)), np.empty(6), np.empty(6), np.empty((6, 12)),
            np.empty(6), np.empty((6, 12)), np.empty(6), np.empty((6, 12)), np.empty(6),
            np.empty((4, 3, 3)), np.empty((6, 4, 3, 3)), np.empty((6, 3, 3, 3)), np.empty((6, 4, 3)),
            np.empty((3, 3)), np.empty((3, 3)), np.empty((6, 3)), np.empty((6, 3, 6)), np.empty(3),
            np.empty((6, 6)), np.empty(6, np.int64), np.empty(6), np.empty((3, 6)), np.empty((6, 3)),
            np.empty((_PATTERN.shape[0], 3, 3)), np.empty((3, 6)), np.empty((3, 3)))


@njit(cache=True, fastmath=_FAST, inline="always")
def newton_one(G, J, Rr, omega, w, radius, Sl, Sp, params, law, impact, rb, rp, db, dpp, vb, vpp,
               a_l, a_p, bh2, gh, wf, limits, f, gl, gp, delta, rate, scratch):
    """Joint-node accelerations a_l (6, 12) and platform accelerations a_p (6,) of one realisation's
    step, in place; returns (converged, iterations).

    Solves Sl a_l - rb - wf gl(x, v) = 0, Sp a_p - rp - wf gp(x, v) = 0 with
    x = d + bh2 a, v = v_pred + gh a (the integrator's corrector), Newton with
    backtracking where a full step makes the residual worse (contact kinks).  Converged
    when the update the residual calls for (the last solve's gain times the residual)
    moves no joint by more than tol_d (m) and changes no velocity by more than tol_v
    (m/s), at most limits[2] iterations (limits = [tol_d, tol_v, max iterations]: an array, so
    its calls have 29 arguments: Python passes 31 or more as *args, which numba cannot inline).
    Writes the contact forces f (6, 3, 3), generalised forces gl, gp and the penetrations and
    rates (6, 4) [A radial, A axial, C, B] at the accepted iterate.
    """
    tol_d, tol_v, max_iterations = limits[0], limits[1], int(limits[2])
    (e, de, De, Dv, D, pair, xb, ub, xp, up, res_l, res_p, dl, dp, base_l, base_p,
     A, Ainv, Up, rhat, M, top, top0, tb, z, schur, ypiv, y, border, lower, DG, DJ, DR) = scratch
    ok = False
    n_it = 0
    last = np.inf
    gain = np.inf
    lam = 1.0
    for it in range(max_iterations + 1):
        for leg in range(6):
            for c in range(12):
                xb[leg, c] = db[leg, c] + bh2 * a_l[leg, c]
                ub[leg, c] = vb[leg, c] + gh * a_l[leg, c]
        for b in range(6):
            xp[b] = dpp[b] + bh2 * a_p[b]
            up[b] = vpp[b] + gh * a_p[b]
        _evaluate(G, J, w, omega, radius, params, law, impact, xb, xp, ub, up,
                  e, de, f, De, Dv, delta, rate, gl, gp, pair)
        norm2 = 0.0
        for leg in range(6):
            for a in range(12):
                s = -rb[leg, a] - wf * gl[leg, a]
                for b in range(12):
                    s += Sl[a, b] * a_l[leg, b]
                res_l[leg, a] = s
                norm2 += s * s
        for a in range(6):
            s = -rp[a] - wf * gp[a]
            for b in range(6):
                s += Sp[a, b] * a_p[b]
            res_p[a] = s
            norm2 += s * s
        norm = np.sqrt(norm2)
        est = gain * norm
        if it > 0 and bh2 * est <= tol_d and gh * est <= tol_v:
            ok = True
        if norm == 0.0:
            ok = True
        if ok or it == max_iterations:
            break
        if norm > last and lam > 1.0 / 256.0:
            # backtrack: halve the last update
            lam *= 0.5
            for leg in range(6):
                for c in range(12):
                    a_l[leg, c] = base_l[leg, c] - lam * dl[leg, c]
            for b in range(6):
                a_p[b] = base_p[b] - lam * dp[b]
            n_it += 1
            continue
        last = norm
        for leg in range(6):
            for j in range(3):
                for a in range(3):
                    for b in range(3):
                        D[leg, j, a, b] = wf * (bh2 * De[leg, j, a, b] + gh * Dv[leg, j, a, b])
        _newton_update(G, J, Rr, Sl, Sp, D, res_l, res_p, dl, dp, A, Ainv, Up, rhat, M, top, top0, tb,
                       z, schur, ypiv, y, border, lower, DG, DJ, DR)
        size = 0.0
        for leg in range(6):
            for c in range(12):
                size = max(size, abs(dl[leg, c]))
        for b in range(6):
            size = max(size, abs(dp[b]))
        gain = size / max(norm, 1e-300)
        for leg in range(6):
            for c in range(12):
                base_l[leg, c] = a_l[leg, c]
                a_l[leg, c] -= dl[leg, c]
        for b in range(6):
            base_p[b] = a_p[b]
            a_p[b] -= dp[b]
        lam = 1.0
        n_it += 1
    return ok, n_it


@njit(cache=True, fastmath=_FAST)
def newton_step(G, J, Rr, omega, w, radius, Sl, Sp, params, law, impact,
                rb, rp, db, dpp, vb, vpp, ab, ap, bh2, gh, wf, tol_d, tol_v, max_iterations,
                f, gl, gp, delta, rate, done, count):
    """:func:`newton_one` for every realisation of a batch (leading axis R), one after another;
    ab (R, 6, 12) and ap (R, 6) are updated in place, done and count receive its returns."""
    scratch = newton_scratch()
    limits = np.array([tol_d, tol_v, max_iterations])
    for r in range(ab.shape[0]):
        done[r], count[r] = newton_one(G, J, Rr, omega, w, radius, Sl, Sp, params[r], law, impact[r],
                                       rb[r], rp[r], db[r], dpp[r], vb[r], vpp[r], ab[r], ap[r],
                                       bh2, gh, wf, limits, f[r], gl[r], gp[r],
                                       delta[r], rate[r], scratch)


# --- whole steps: predictor, condensation, Newton, recovery, adaptive control ---

NEWTON_FAILED = 1   # failure codes written to ``fail``
DIVERGED = 2


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
def _platform(Mp, x, scale, out):
    """The platform's part of out (N,): scale Mp x over the last six entries."""
    N = out.shape[0]
    for a in range(6):
        s = 0.0
        for b in range(6):
            s += Mp[a, b] * x[N - 6 + b]
        out[N - 6 + a] = scale * s


@njit(cache=True, fastmath=_FAST, inline="always")
def _internal(x, u, layout, coef, Mp, work, out):
    """C u + K x (Rayleigh C = l1 M + l2 K) into out (N,): per link type one product
    [l1 u, x + l2 u] (6, 2n) @ [M; K] (2n, n); the platform has mass only (l1 Mp u)."""
    nc, Wc, Wr = layout[0], layout[1], layout[2]
    l1, l2 = coef[0], coef[1]
    Zc, Zr, Ic, Ir = work[0], work[1], work[2], work[3]
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
    np.dot(Zc, Wc, Ic)
    np.dot(Zr, Wr, Ir)
    _scatter(Ic, Ir, out)
    _platform(Mp, u, l1, out)


@njit(cache=True, fastmath=_FAST, inline="always")
def _mass(acc, layout, Mp, work, out):
    """M a into out (N,), per link type one product a (6, n) @ M (n, n), and the platform's."""
    nc, Mc, Mr = layout[0], layout[3], layout[4]
    Ac, Ar, Ic, Ir = work[4], work[5], work[2], work[3]
    N = out.shape[0]
    step = (N - 6) // 6
    nr = step - nc
    _gather(acc, 0, nc, Ac, 0)
    _gather(acc, nc, nr, Ar, 0)
    np.dot(Ac, Mc, Ic)
    np.dot(Ar, Mr, Ir)
    _scatter(Ic, Ir, out)
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
def _attempt(r, level, k0, k1, lv, layout, coef, F, Mp, G, J, Rr, omega, w, radius, params, law,
             newton_limits, d, v, a, Ma, rest, g, stored, in_contact, crate, work, scratch):
    """One step of realisation r from instant k0 to k1 with level ``level``'s step: predictor,
    right-hand side, condensation, Newton, recovery, corrector.  Leaves the candidate state in
    work and returns (converged, Newton iterations)."""
    hs, coef_p, bh2s, ghs, S, Tc, Uc, Tr, Ur = lv[1], lv[2], lv[3], lv[4], lv[6], lv[7], lv[8], lv[9], lv[10]
    nc, cb = layout[0], layout[5]
    beta, gamma, am, af, floor = coef[2], coef[3], coef[4], coef[5], coef[7]
    (Zc, Zr, Ic, Ir, Ac, Ar, Yc, Yr, dp, vp, rhs, tmp, a_new, d_new, v_new, rb, db, vb, ab, dpp, vpp,
     ap, impact, Sp, f, gl, gp, delta, rate, e, jb, jp) = work
    N = d.shape[1]
    step = (N - 6) // 6
    nr = step - nc
    ni_c, ni_r = Yc.shape[1] - 6, Yr.shape[1] - 6
    h = hs[level]
    wf = 1.0 - af
    c2 = (0.5 - beta) * h * h
    c1 = (1.0 - gamma) * h
    for n in range(N):
        dp[n] = d[r, n] + h * v[r, n] + c2 * a[r, n]
        vp[n] = v[r, n] + c1 * a[r, n]
    _internal(dp, vp, layout, coef, Mp[k1], work, tmp)
    weighted = am != 0.0 or af != 0.0
    for n in range(N):
        rhs[n] = wf * (F[k1, n] - tmp[n])
        if weighted:
            rhs[n] += af * (F[k0, n] + g[r, n] - rest[r, n]) - am * Ma[r, n]
    # condensation onto the joint nodes: [r_i inv, r_b - r_i P] per link type
    _gather(rhs, 0, nc, Ac, 0)
    _gather(rhs, nc, nr, Ar, 0)
    np.dot(Ac, Tc[level], Yc)
    np.dot(Ar, Tr[level], Yr)
    for leg in range(6):
        for q in range(6):
            rb[leg, q] = Yc[leg, ni_c + q]
            rb[leg, 6 + q] = Yr[leg, ni_r + q]
    _joint_nodes(dp, cb, nc, db, dpp)
    _joint_nodes(vp, cb, nc, vb, vpp)
    _joint_nodes(a[r], cb, nc, ab, ap)
    for leg in range(6):
        for m in range(4):
            impact[leg, m] = stored[r, leg, m] if in_contact[r, leg, m] else max(crate[r, leg, m], floor)
    for i in range(6):
        for j in range(6):
            Sp[i, j] = coef_p[level] * Mp[k1, i, j]
    ok, count = newton_one(G[k1], J[k1], Rr[k1], omega[k1], w, radius, S[level], Sp, params[r], law,
                           impact, rb, rhs[N - 6:], db, dpp, vb, vpp, ab, ap, bh2s[level], ghs[level], wf,
                           newton_limits, f, gl, gp,
                           delta, rate, scratch)
    # recovery: [y, x_b] -> link vectors
    for leg in range(6):
        for q in range(6):
            Yc[leg, ni_c + q] = ab[leg, q]
            Yr[leg, ni_r + q] = ab[leg, 6 + q]
    np.dot(Yc, Uc[level], Ac)
    np.dot(Yr, Ur[level], Ar)
    _scatter(Ac, Ar, a_new)
    for b in range(6):
        a_new[N - 6 + b] = ap[b]
    bh2, gh = bh2s[level], ghs[level]
    for n in range(N):
        d_new[n] = dp[n] + bh2 * a_new[n]
        v_new[n] = vp[n] + gh * a_new[n]
    return ok, count


@njit(cache=True, fastmath=_FAST, inline="always")
def _jump(r, k1, a, layout, G, J, work):
    """Largest change of a joint's relative acceleration over the candidate step, |delta a| (m/s^2)."""
    ab, ap, e, jb, jp = work[18], work[21], work[29], work[30], work[31]
    _joint_nodes(a[r], layout[5], layout[0], jb, jp)
    for leg in range(6):           # ab, ap: the joint nodes of the new accelerations
        for q in range(12):
            jb[leg, q] = ab[leg, q] - jb[leg, q]
    for b in range(6):
        jp[b] = ap[b] - jp[b]
    relative(G[k1], J[k1], jb, jp, e)
    big = 0.0
    for leg in range(6):
        for j in range(3):
            big = max(big, np.sqrt(e[leg, j, 0] ** 2 + e[leg, j, 1] ** 2 + e[leg, j, 2] ** 2))
    return big


@njit(cache=True, fastmath=_FAST, inline="always")
def _accept(r, k1, layout, coef, Mp, t, d, v, a, Ma, rest, g, stored, in_contact, crate,
            peak, cpeak, work):
    """Make the candidate step in work realisation r's state: contact memory, weighted terms, peaks."""
    cb = layout[5]
    am, af, settle_at = coef[4], coef[5], coef[6]
    a_new, d_new, v_new, impact, f, gl, gp, delta, rate = (work[12], work[13], work[14], work[22],
                                                           work[24], work[25], work[26], work[27], work[28])
    N = d.shape[1]
    step = (N - 6) // 6
    for n in range(N):
        d[r, n], v[r, n], a[r, n] = d_new[n], v_new[n], a_new[n]
    for leg in range(6):
        for m in range(4):
            closed = delta[leg, m] > 0.0
            if closed and not in_contact[r, leg, m]:
                stored[r, leg, m] = impact[leg, m]
            in_contact[r, leg, m] = closed
            crate[r, leg, m] = rate[leg, m]
    if am != 0.0 or af != 0.0:
        _mass(a_new, layout, Mp[k1], work, Ma[r])
        _internal(d_new, v_new, layout, coef, Mp[k1], work, rest[r])
        for n in range(N):
            g[r, n] = 0.0
        for leg in range(6):
            base = leg * step
            for q in range(6):
                g[r, base + cb[q]] = gl[leg, q]
                g[r, base + step - 6 + q] = gl[leg, 6 + q]
        for b in range(6):
            g[r, N - 6 + b] = gp[b]
    if t[k1] >= settle_at:
        for b in range(6):
            peak[r, 0, b] = max(peak[r, 0, b], abs(d_new[N - 6 + b]))
            peak[r, 1, b] = max(peak[r, 1, b], abs(v_new[N - 6 + b]))
            peak[r, 2, b] = max(peak[r, 2, b], abs(a_new[N - 6 + b]))
        for leg in range(6):
            for j in range(3):
                mag = np.sqrt(f[leg, j, 0] ** 2 + f[leg, j, 1] ** 2 + f[leg, j, 2] ** 2)
                cpeak[r, 6 * j + leg] = max(cpeak[r, 6 * j + leg], mag)


@njit(cache=True)
def work_arrays(N, nc, nr, ni_c, ni_r):
    """Per-realisation work arrays of :func:`advance_chunk` (see ``_attempt``)."""
    return (np.empty((6, 2 * nc)), np.empty((6, 2 * nr)), np.empty((6, nc)), np.empty((6, nr)),
            np.empty((6, nc)), np.empty((6, nr)), np.empty((6, ni_c + 6)), np.empty((6, ni_r + 6)),
            np.empty(N), np.empty(N), np.empty(N), np.empty(N), np.empty(N), np.empty(N), np.empty(N),
            np.empty((6, 12)), np.empty((6, 12)), np.empty((6, 12)), np.empty((6, 12)), np.empty(6),
            np.empty(6), np.empty(6), np.empty((6, 4)), np.empty((6, 6)), np.empty((6, 3, 3)),
            np.empty((6, 12)), np.empty(6), np.empty((6, 4)), np.empty((6, 4)), np.empty((6, 3, 3)),
            np.empty((6, 12)), np.empty(6))


@njit(cache=True, fastmath=_FAST)
def advance_chunk(live, first, n_base, every, lv, layout, coef, F, Mp, G, J, Rr, omega, t, w, radius,
                  params, law, newton_limits, refinements, d, v, a, Ma, rest, g, stored, in_contact,
                  crate, peak, cpeak, hist, alive, fail, fail_at, steps, iters, refined, work, scratch):
    """Carry realisations ``live`` through base steps first .. first + n_base - 1 (the chunk's
    instants on the finest grid start at the first one's start), in place.

    coef = [lambda_1, lambda_2, beta, gamma, alpha_m, alpha_f, settle time (s), impact speed
    floor (m/s), tolerance (m), divergence limit (m)]; newton_limits = [tol_d (m), tol_v (m/s),
    max iterations].  A realisation that fails gets ``fail`` (NEWTON_FAILED, DIVERGED) and
    fail_at = [t (s), h (s), largest |d| (m)], and stops.  Histories are kept at base steps
    divisible by ``every``.
    """
    spans, errs = lv[0], lv[5]
    tolerance, limit = coef[8], coef[9]
    N = d.shape[1]
    fine = spans[0]
    for r in live:
        for s in range(n_base):
            k_start = s * fine
            k, level = k_start, 0
            while k < k_start + fine:
                k1 = k + spans[level]
                ok, count = _attempt(r, level, k, k1, lv, layout, coef, F, Mp, G, J, Rr, omega, w,
                                     radius, params, law, newton_limits, d, v, a, Ma, rest, g, stored,
                                     in_contact, crate, work, scratch)
                iters[r] += count
                d_new = work[13]
                big = 0.0                           # largest |d|; inf if any is inf or nan
                for n in range(N):
                    big = max(big, abs(d_new[n]))
                    if not np.isfinite(d_new[n]):
                        big = np.inf
                sound = ok and big < limit
                accept = True
                if level < refinements:
                    accept = sound
                    if sound and tolerance > 0.0:
                        accept = errs[level] * _jump(r, k1, a, layout, G, J, work) <= tolerance
                if not accept:
                    refined[r] += 1
                    level += 1
                    continue
                if not sound:
                    alive[r] = False
                    fail[r] = NEWTON_FAILED if not ok else DIVERGED
                    fail_at[r, 0], fail_at[r, 1], fail_at[r, 2] = t[k1], lv[1][level], big
                    break
                _accept(r, k1, layout, coef, Mp, t, d, v, a, Ma, rest, g, stored, in_contact, crate,
                        peak, cpeak, work)
                steps[r] += 1
                k = k1
                level = 0
                while (k - k_start) % spans[level] != 0:
                    level += 1
            if not alive[r]:
                break
            if (first + s) % every == 0:
                for b in range(6):
                    hist[0, r, (first + s) // every, b] = d[r, N - 6 + b]
                    hist[1, r, (first + s) // every, b] = v[r, N - 6 + b]
                    hist[2, r, (first + s) // every, b] = a[r, N - 6 + b]
