"""Compiled Newton iteration of the contact level (L4): one time step, every realisation of a batch.

The contact level spends almost all its time in small dense work per
realisation (18 contact pairs, six 12x12 leg systems, a 6x6 border), where
numpy's per-call overhead is many times the arithmetic.  This module runs
that work compiled with numba, one realisation after another, so a
realisation's result never depends on its batch.  It computes what the
vectorised functions of :mod:`.contact_dynamics` compute (``_contacts``,
``_generalized``, ``_tangent``, ``_solve_arrow``; the tests compare them):
- joint maps G (per leg, 9x12) take the joint-node vector [crank node 0,
  crank tip, rod C end, rod B end] (link frames) to the relative
  displacements [e_A, e_C, e_B] (base frame); only the blocks (row j, column
  block c) listed in ``_PATTERN`` are non-zero;
- Lankarani-Nikravesh normal force (eq. 17) and modified Coulomb friction
  (eq. 18) with their Jacobians, as in :mod:`.contact_laws`;
- a block-arrow Newton matrix: six leg blocks bordered by the 6 platform DOFs.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["newton_step", "ball"]

# reassociation and fused multiply-add, but no finite-math assumption: a diverging
# realisation's inf and nan must survive to be reported
_FAST = {"contract", "reassoc", "nsz", "arcp"}
# non-zero 3x3 blocks of a leg's joint map G: relative displacement j <- joint-node block c
_PATTERN = np.array([[0, 0], [1, 1], [1, 2], [2, 3]], np.int64)


@njit(cache=True, fastmath=_FAST)
def _normal_law(delta, rate, impact, k, exponent, restitution):
    """Lankarani-Nikravesh F_N (eq. 17), dF/d delta and dF/d delta_dot; zero apart or pulling."""
    if delta <= 0.0:
        return 0.0, 0.0, 0.0
    spring = k * delta ** exponent
    c = 0.75 * (1.0 - restitution * restitution) / impact
    factor = 1.0 + c * rate
    force = spring * factor
    if force <= 0.0:
        return 0.0, 0.0, 0.0
    return force, exponent * spring / delta * factor, spring * c


@njit(cache=True, fastmath=_FAST)
def ball(e, de, size, k, impact, law, omega, radius, f, De, Dv):
    """Ball-in-socket pair (journal in bearing): force on the ball side into f (3,), d f/d e into
    De and d f/d de into Dv (3, 3); returns (penetration m, its rate m/s).

    law = [exponent, restitution, mu_d, v0, v1]; omega (3,) the ideal relative angular
    velocity (rad/s) whose sliding (omega x R n) friction opposes, radius R (m).
    """
    rho = np.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    safe = max(rho, 1e-300)
    n0, n1, n2 = e[0] / safe, e[1] / safe, e[2] / safe
    n = (n0, n1, n2)
    delta = rho - size
    rate = n0 * de[0] + n1 * de[1] + n2 * de[2]
    F, dF, dFr = _normal_law(delta, rate, impact, k, law[0], law[1])
    Fs = F / safe
    for a in range(3):
        f[a] = -F * n[a]
        for b in range(3):
            nn = n[a] * n[b]
            De[a, b] = -dF * nn - Fs * ((1.0 if a == b else 0.0) - nn)
            Dv[a, b] = -dFr * nn
    mu = law[2]
    if mu > 0.0:
        v0, v1 = law[3], law[4]
        # sliding velocity: relative velocity plus the ideal rotation's sliding, tangential part
        w0 = de[0] + radius * (omega[1] * n2 - omega[2] * n1)
        w1 = de[1] + radius * (omega[2] * n0 - omega[0] * n2)
        w2 = de[2] + radius * (omega[0] * n1 - omega[1] * n0)
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
            f[a] += scale * cd * t[a]
            # jac = dF_t/dv_t = scale (cd/|v_t| (I - t t^T) + dcd t t^T), taken times (I - n n^T)
            # (friction turns with the tangential part of de only): jac - (jac n) n^T
            jn = slope * (n[a] - t[a] * tn) + turn * t[a] * tn
            dft = -mu * cd * t[a]
            for b in range(3):
                tt = t[a] * t[b]
                jab = slope * ((1.0 if a == b else 0.0) - tt) + turn * tt
                De[a, b] += dft * dF * n[b]
                Dv[a, b] += jab - jn * n[b] + dft * dFr * n[b]
    return delta, rate


@njit(cache=True, fastmath=_FAST)
def _evaluate(G, J, w, omega, radius, params, law, impact, xb, xp, ub, up,
              e, de, f, De, Dv, delta, rate, gl, gp, tmp3, tmpD, tmpV):
    """Contact forces, Jacobians, penetrations and generalised forces of one realisation."""
    for leg in range(6):
        # relative displacements and velocities [e_A, e_C, e_B] of the joint elements
        for j in range(3):
            for a in range(3):
                e[leg, j, a] = 0.0
                de[leg, j, a] = 0.0
        for q in range(_PATTERN.shape[0]):
            j, c = _PATTERN[q, 0], _PATTERN[q, 1]
            for a in range(3):
                s = 0.0
                sv = 0.0
                for b in range(3):
                    g = G[leg, 3 * j + a, 3 * c + b]
                    s += g * xb[leg, 3 * c + b]
                    sv += g * ub[leg, 3 * c + b]
                e[leg, j, a] += s
                de[leg, j, a] += sv
        for a in range(3):
            s = 0.0
            sv = 0.0
            for b in range(6):
                s += J[leg, a, b] * xp[b]
                sv += J[leg, a, b] * up[b]
            e[leg, 2, a] -= s
            de[leg, 2, a] -= sv
        wl = w[leg]
        sA = wl[0] * e[leg, 0, 0] + wl[1] * e[leg, 0, 1] + wl[2] * e[leg, 0, 2]
        # A radial: the journal's eccentricity projected on the bearing plane (normal to w)
        for a in range(3):
            tmp3[a] = e[leg, 0, a] - sA * wl[a]
        d, r = ball(tmp3, de[leg, 0], params[leg, 0], params[leg, 4], impact[leg, 0], law,
                    omega[leg, 0], radius[0], f[leg, 0], tmpD, tmpV)
        delta[leg, 0], rate[leg, 0] = d, r
        for a in range(3):     # De @ Pw, Pw = I - w w^T
            for b in range(3):
                De[leg, 0, a, b] = tmpD[a, b] - (tmpD[a, 0] * wl[0] + tmpD[a, 1] * wl[1]
                                                 + tmpD[a, 2] * wl[2]) * wl[b]
                Dv[leg, 0, a, b] = tmpV[a, b]
        # A axial: the journal's faces, along +-w, radial stiffness, no friction
        sign = 1.0 if sA >= 0.0 else -1.0
        da = abs(sA) - params[leg, 1]
        ra = sign * (wl[0] * de[leg, 0, 0] + wl[1] * de[leg, 0, 1] + wl[2] * de[leg, 0, 2])
        Fa, dFa, dFra = _normal_law(da, ra, impact[leg, 1], params[leg, 4], law[0], law[1])
        for a in range(3):
            f[leg, 0, a] -= Fa * sign * wl[a]
            for b in range(3):
                ww = wl[a] * wl[b]
                De[leg, 0, a, b] -= dFa * ww
                Dv[leg, 0, a, b] -= dFra * ww
        delta[leg, 1], rate[leg, 1] = da, ra
        # spherical C and B
        for j in (1, 2):
            d, r = ball(e[leg, j], de[leg, j], params[leg, 1 + j], params[leg, 4 + j],
                        impact[leg, 1 + j], law, omega[leg, j], radius[j], f[leg, j],
                        De[leg, j], Dv[leg, j])
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


@njit(cache=True, fastmath=_FAST)
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


@njit(cache=True, fastmath=_FAST)
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


@njit(cache=True, fastmath=_FAST)
def _newton_update(G, J, Rr, Sl, Sp, D, res_l, res_p, dl, dp, L, X, piv, schur, ypiv, y, border,
                   lower, DG, DJ, DR):
    """Solve the block-arrow Newton system [L B; C P] [dl; dp] = [res_l; res_p] of one realisation.

    L = Sl - G^T diag(D) G per leg; B = E Rr^T D_B J and C = J^T D_B Rr E^T (E the
    rod B-end rows); P = Sp - sum J^T D_B J.  Per leg L^-1 [res, E] (4 columns), then
    the 6x6 Schur complement on the platform.
    """
    for a in range(6):
        for b in range(6):
            schur[a, b] = Sp[a, b]
        y[a] = res_p[a]
    for leg in range(6):
        for a in range(12):
            for b in range(12):
                L[a, b] = Sl[a, b]
        # - G^T diag(D) G, block by block: DG = D_j G_jc once, then G_jc1^T DG_jc2
        for q in range(_PATTERN.shape[0]):
            j, c = _PATTERN[q, 0], _PATTERN[q, 1]
            for u in range(3):
                for b in range(3):
                    DG[q, u, b] = (D[leg, j, u, 0] * G[leg, 3 * j, 3 * c + b]
                                   + D[leg, j, u, 1] * G[leg, 3 * j + 1, 3 * c + b]
                                   + D[leg, j, u, 2] * G[leg, 3 * j + 2, 3 * c + b])
        for q1 in range(_PATTERN.shape[0]):
            j, c1 = _PATTERN[q1, 0], _PATTERN[q1, 1]
            for q2 in range(_PATTERN.shape[0]):
                if _PATTERN[q2, 0] != j:
                    continue
                c2 = _PATTERN[q2, 1]
                for a in range(3):
                    g0 = G[leg, 3 * j, 3 * c1 + a]
                    g1 = G[leg, 3 * j + 1, 3 * c1 + a]
                    g2 = G[leg, 3 * j + 2, 3 * c1 + a]
                    for b in range(3):
                        L[3 * c1 + a, 3 * c2 + b] -= g0 * DG[q2, 0, b] + g1 * DG[q2, 1, b] + g2 * DG[q2, 2, b]
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
        _lu(L, piv[leg])
        for a in range(12):
            X[leg, a, 0] = res_l[leg, a]
            for c in range(3):
                X[leg, a, 1 + c] = 1.0 if a == 9 + c else 0.0
        _lu_solve(L, piv[leg], X[leg], 4)
        # Schur complement: P - sum C L^-1 B, right-hand side rp - sum C L^-1 res
        for a in range(6):
            for b in range(6):
                s = 0.0
                for u in range(3):
                    t = 0.0
                    for v in range(3):
                        t += X[leg, 9 + u, 1 + v] * border[v, b]
                    s += lower[a, u] * t
                schur[a, b] -= s
            s = 0.0
            for u in range(3):
                s += lower[a, u] * X[leg, 9 + u, 0]
            y[a] -= s
        # L^-1 B = (L^-1 E) border, for the back substitution once the platform update is known
        for a in range(12):
            for b in range(6):
                s = 0.0
                for v in range(3):
                    s += X[leg, a, 1 + v] * border[v, b]
                X[leg, a, 4 + b] = s
    _lu(schur, ypiv)
    for a in range(6):
        dp[a] = y[a]
    _lu_solve(schur, ypiv, dp.reshape((6, 1)), 1)
    for leg in range(6):
        for a in range(12):
            s = X[leg, a, 0]
            for b in range(6):
                s -= X[leg, a, 4 + b] * dp[b]
            dl[leg, a] = s


@njit(cache=True, fastmath=_FAST)
def newton_step(G, J, Rr, omega, w, radius, Sl, Sp, params, law, impact,
                rb, rp, db, dpp, vb, vpp, ab, ap, bh2, gh, wf, tol_d, tol_v, max_iterations,
                f, gl, gp, delta, rate, done, count):
    """Joint-node accelerations ab (R, 6, 12) and platform accelerations ap (R, 6) of one step, in place.

    Solves Sl ab - rb - wf gl(x, v) = 0, Sp ap - rp - wf gp(x, v) = 0 per realisation with
    x = d + bh2 a, v = v_pred + gh a (the integrator's corrector), Newton with
    backtracking where a full step makes the residual worse (contact kinks).  Converged
    when the update the residual calls for (the last solve's gain times the residual)
    moves no joint by more than tol_d (m) and changes no velocity by more than tol_v
    (m/s).  Writes the contact forces f (R, 6, 3, 3), generalised forces gl, gp,
    penetrations and rates (R, 6, 4) [A radial, A axial, C, B] at the accepted iterate,
    the converged flags and the iteration counts.
    """
    R = ab.shape[0]
    e = np.empty((6, 3, 3))
    de = np.empty((6, 3, 3))
    De = np.empty((6, 3, 3, 3))
    Dv = np.empty((6, 3, 3, 3))
    D = np.empty((6, 3, 3, 3))
    tmp3 = np.empty(3)
    tmpD = np.empty((3, 3))
    tmpV = np.empty((3, 3))
    xb = np.empty((6, 12))
    ub = np.empty((6, 12))
    xp = np.empty(6)
    up = np.empty(6)
    res_l = np.empty((6, 12))
    res_p = np.empty(6)
    dl = np.empty((6, 12))
    dp = np.empty(6)
    base_l = np.empty((6, 12))
    base_p = np.empty(6)
    L = np.empty((12, 12))
    X = np.empty((6, 12, 10))
    piv = np.empty((6, 12), np.int64)
    schur = np.empty((6, 6))
    ypiv = np.empty(6, np.int64)
    y = np.empty(6)
    border = np.empty((3, 6))
    lower = np.empty((6, 3))
    DG = np.empty((_PATTERN.shape[0], 3, 3))
    DJ = np.empty((3, 6))
    DR = np.empty((3, 3))
    for r in range(R):
        a_l, a_p = ab[r], ap[r]
        ok = False
        n_it = 0
        last = np.inf
        gain = np.inf
        lam = 1.0
        for it in range(max_iterations + 1):
            for leg in range(6):
                for c in range(12):
                    xb[leg, c] = db[r, leg, c] + bh2 * a_l[leg, c]
                    ub[leg, c] = vb[r, leg, c] + gh * a_l[leg, c]
            for b in range(6):
                xp[b] = dpp[r, b] + bh2 * a_p[b]
                up[b] = vpp[r, b] + gh * a_p[b]
            _evaluate(G, J, w, omega, radius, params[r], law, impact[r], xb, xp, ub, up,
                      e, de, f[r], De, Dv, delta[r], rate[r], gl[r], gp[r], tmp3, tmpD, tmpV)
            norm2 = 0.0
            for leg in range(6):
                for a in range(12):
                    s = -rb[r, leg, a] - wf * gl[r, leg, a]
                    for b in range(12):
                        s += Sl[a, b] * a_l[leg, b]
                    res_l[leg, a] = s
                    norm2 += s * s
            for a in range(6):
                s = -rp[r, a] - wf * gp[r, a]
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
            _newton_update(G, J, Rr, Sl, Sp, D, res_l, res_p, dl, dp, L, X, piv, schur, ypiv, y,
                           border, lower, DG, DJ, DR)
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
        done[r] = ok
        count[r] = n_it
