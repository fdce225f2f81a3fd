"""The contact level's numpy stepper: the steps vectorised over the batch with numpy, the readable
reference the compiled stepper (:class:`.contact_dynamics.CompiledStepper`, :mod:`.contact_kernel`)
is compared with.  About 10x slower; run it with ``simulate_contact(..., stepper=NumpyStepper)``.

Per realisation it takes the steps the compiled kernel takes: the predictor, the alpha-weighted
right-hand side, Newton on the joint nodes (:func:`_newton_numpy`, first from the extrapolated
accelerations, again from the last ones where that fails), the corrector, and the adaptive step's
accept-or-halve decision (:meth:`NumpyStepper._step`'s recursion).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from . import contact_dynamics as dynamics   # Newton's limits, read there when a step runs (tests lower them)
from .contact_dynamics import (ContactStepper, JointSolution, Progress, StepSolution, _Chunk, _evaluate,
                               _generalized, _internal, _joint_nodes, _Joints, _mass, _relative, _solve_arrow,
                               _StepSize, _tangent)
from .contact_kernel import System, balance_next, coarsest_next
from .integrators import correct, predict
from .status import DIVERGED, NEWTON_FAILED

__all__ = ["NumpyStepper"]


def _newton_numpy(scene, ch: _Chunk, j, joints: _Joints, sy: System, ab, ap, bh2, gh, wf) -> JointSolution:
    """One step's Newton iteration on the joint nodes (see :func:`.contact_kernel.newton_one`),
    vectorised over the batch with numpy: the compiled kernel's reference."""
    R = ab.shape[0]
    done = np.zeros(R, bool)
    count = np.zeros(R, np.int64)
    last = np.full(R, np.inf)           # residual norm at the last accepted iterate
    gain = np.full(R, np.inf)           # |update| / |residual| of the last Newton solve
    lam = np.ones(R)                    # step length of the last update
    base_l, base_p = ab, ap
    step_l, step_p = np.zeros_like(ab), np.zeros_like(ap)
    for it in range(dynamics.MAX_ITERATIONS + 1):
        xb, ub = correct(sy.db, sy.vb, ab, bh2, gh)
        xp, up = correct(sy.dpp, sy.vpp, ap, bh2, gh)
        f, De, Dv, delta, rate = _evaluate(scene, ch, j, joints, sy.impact, xb, xp, ub, up)
        gl, gp = _generalized(ch, j, f)
        res_l = ab @ sy.Sl.T - sy.rb - wf * gl
        res_p = (sy.Sp @ ap[..., None])[..., 0] - sy.rp - wf * gp
        norm = np.sqrt((res_l ** 2).sum((-1, -2)) + (res_p ** 2).sum(-1))
        # converged when the update this residual calls for (the last solve's gain times
        # it) moves no joint by more than the tolerances: the iterate just evaluated is kept
        est = gain * norm
        if it:   # the first iterate has no gain yet
            done |= (bh2 * est <= dynamics.TOL_DISPLACEMENT) & (gh * est <= dynamics.TOL_VELOCITY)
        done |= norm == 0.0
        if done.all() or it == dynamics.MAX_ITERATIONS:
            break
        # backtrack where the full Newton step made the residual worse (contact kinks)
        worse = ~done & (norm > last) & (lam > 1.0 / 256.0)
        if worse.any():
            lam = np.where(worse, 0.5 * lam, lam)
            ab = np.where(worse[:, None, None], base_l - lam[:, None, None] * step_l, ab)
            ap = np.where(worse[:, None], base_p - lam[:, None] * step_p, ap)
            count += worse
            continue
        last = np.where(done, last, norm)
        D = wf * (bh2 * De + gh * Dv)
        L, border, lower, P = _tangent(ch, j, D, sy.Sl, sy.Sp)
        dl, dpl = _solve_arrow(L, border, lower, P, res_l, res_p)
        # converged realisations keep their iterate: a result never depends on its batch
        dl, dpl = np.where(done[:, None, None], 0.0, dl), np.where(done[:, None], 0.0, dpl)
        size = np.abs(np.concatenate([dl.reshape(R, -1), dpl], -1)).max(-1)
        gain = np.where(done, gain, size / np.maximum(norm, 1e-300))
        base_l, base_p, step_l, step_p, lam = ab, ap, dl, dpl, np.ones(R)
        ab, ap = ab - dl, ap - dpl
        count += ~done
    return JointSolution(ab=ab, ap=ap, f=f, gl=gl, gp=gp, converged=done, iterations=count, delta=delta,
                         rate=rate)


class NumpyStepper(ContactStepper):
    """The steps vectorised over the batch with numpy: the compiled stepper's reference."""

    def _solve(self, idx, ch, j, sy, ab, ap, bh2, gh, wf) -> JointSolution:
        return _newton_numpy(self.setup.scene, ch, j, _subset(self.setup.joints, idx), sy, ab, ap, bh2, gh, wf)

    def advance(self, ch: _Chunk, first: int, n_base: int) -> Progress:
        su, ws = self.setup, self.ws
        ch.fill_all()
        for j in range(n_base):
            live = np.flatnonzero(ws.alive)
            if not len(live):
                break
            self._step(live, ch, j * su.fine, 0)
            if (first + j) % su.every == 0:
                ws.history((first + j) // su.every)
        return self._progress(ch)

    def _step(self, idx, ch, k0, level):
        """Step realisations ``idx`` from fine instant k0 of the chunk by sizes[level], halving where
        the attempt is refused or where the step-size memory asks for a finer step; their state moves
        to k0 + sizes[level].span."""
        ws = self.ws
        finer = ws.coarsest[idx] > level
        now = idx[~finer]
        retry = np.concatenate([idx[finer], self._attempt(now, ch, k0, level) if len(now) else now])
        if len(retry):
            half = self.setup.sizes[level].span // 2
            self._step(retry, ch, k0, level + 1)
            retry = retry[ws.alive[retry]]
            if len(retry):
                self._step(retry, ch, k0 + half, level + 1)

    def _attempt(self, idx, ch, k0, level):
        """One attempt of realisations ``idx`` at sizes[level] from fine instant k0: keep the accepted
        ones (and their step-size memory), fail the unsound ones at the finest level; returns the
        refused ones."""
        su, ws = self.setup, self.ws
        sz = su.sizes[level]
        k1 = k0 + sz.span
        sol, d_new, v_new = self._candidate(idx, ch, k0, k1, sz)
        ok = sol.converged
        sound = ok & np.isfinite(d_new).all(-1) & (np.abs(d_new).max(-1) < su.limit)
        estimate = np.zeros(len(idx))
        if su.tolerance > 0.0:
            jb, jp = _joint_nodes(su.jm, sol.a - ws.a[idx])
            estimate = sz.error * np.linalg.norm(_relative(ch, k1, jb, jp), axis=-1).max((-1, -2))
        accept = np.ones(len(idx), bool)
        if level < su.refinements:
            accept = sound & (estimate <= su.tolerance)
        for i in np.flatnonzero(accept & ~sound):
            ws.failed(idx[i], DIVERGED if ok[i] else NEWTON_FAILED, ch.t[k1], sz.weights.h,
                      np.abs(d_new[i]).max(), su.limit)
        keep = accept & sound
        if keep.any():
            self._keep(idx[keep], ch, k1, sz.weights.h, sol.a[keep], d_new[keep], v_new[keep], sol.f[keep],
                       sol.delta[keep], sol.rate[keep], sol.impact[keep])
            for r, e in zip(idx[keep], estimate[keep]):
                ws.coarsest[r] = coarsest_next(level, e, su.tolerance)
        ws.refined[idx[~accept]] += 1
        return idx[~accept]

    def _candidate(self, idx, ch, k0, k1, sz: _StepSize) -> tuple[StepSolution, np.ndarray, np.ndarray]:
        """Predictor, alpha-weighted right-hand side, Newton and corrector of one step attempt: Newton's
        :class:`.contact_dynamics.StepSolution` and the corrected displacements and velocities (R, N)."""
        su, ws = self.setup, self.ws
        d, v, a = ws.d[idx], ws.v[idx], ws.a[idx]
        w = sz.weights
        dp, vp = predict(d, v, a, w.h, w.d_pred, w.v_pred)
        af, am = su.integrator.alpha_f, su.integrator.alpha_m
        r = (1.0 - af) * (self._step_loads(idx, ch, k1, w.h) - _internal(su.jm, ch.Mp[k1], dp, vp))
        if su.weighted:
            r += af * ws.balance[idx] - am * ws.Ma[idx]
        guess = _extrapolated(w.h, a, ws.a_past[idx], ws.h_past[idx])
        sol = self._newton(idx, ch, k1, sz.cond, sz.coef_p, r, dp, vp, guess, w.d_corr, w.v_corr, 1.0 - af)
        ws.iters[idx] += sol.iterations
        again = ~sol.converged & (ws.h_past[idx, 0] > 0.0)   # retry from a where Newton failed from the guess
        if again.any():
            retry = self._newton(idx[again], ch, k1, sz.cond, sz.coef_p, r[again], dp[again], vp[again],
                                 a[again], w.d_corr, w.v_corr, 1.0 - af)
            ws.iters[idx[again]] += retry.iterations
            for name in StepSolution._fields:
                getattr(sol, name)[again] = getattr(retry, name)
        d_new, v_new = correct(dp, vp, sol.a, w.d_corr, w.v_corr)
        return sol, d_new, v_new

    def _step_loads(self, idx, ch, k1, h):
        """The applied loads (R or 1, N) of an attempt of h (s) to fine instant k1: the chunk's rigid-body
        loads; a subclass may add its own (benchmarks/acceleration_candidates.py)."""
        return ch.F[k1]

    def _keep(self, kept, ch, k1, h, a, d, v, f, delta, rate, used):
        """Make an accepted step of h (s) to fine instant k1 the state of realisations ``kept``."""
        su, ws = self.setup, self.ws
        ws.a_past[kept, 1], ws.a_past[kept, 0] = ws.a_past[kept, 0], ws.a[kept]
        ws.h_past[kept, 1], ws.h_past[kept, 0] = ws.h_past[kept, 0], h
        ws.d[kept], ws.v[kept], ws.a[kept] = d, v, a
        ws.contacts.update(kept, delta, rate, used)
        ws.steps[kept] += 1
        if su.weighted:
            ma = _mass(su.jm, ch.Mp[k1], a)
            it = su.integrator
            ws.balance[kept] = balance_next(ma, ws.Ma[kept], ws.balance[kept], it.alpha_m, it.alpha_f)
            ws.Ma[kept] = ma
        if ch.t[k1] >= su.settle_at:
            ws.peaks(kept, int(ch.t[k1] >= su.steady_at), d, v, a, f, ch.offset[k1])


def _extrapolated(h, a, a_past, h_past):
    """Newton's first iterate for a step of h (s): the accelerations a (R, N) extrapolated by the
    polynomial through them and a_past (R, 2, N), h_past (R, 2) s apart (0: not yet known), of
    degree 2, 1 or 0 as far as known (the compiled twin: :func:`.contact_kernel._predict`)."""
    h1, h2 = h_past[:, 0], h_past[:, 1]
    w = np.zeros((len(a), 3))
    w[:, 0] = 1.0
    lin, quad = (h1 > 0.0) & (h2 <= 0.0), h2 > 0.0
    w[lin, 0], w[lin, 1] = 1.0 + h / h1[lin], -h / h1[lin]
    h1, h2 = h1[quad], h2[quad]      # Lagrange weights at t + h of the nodes t, t - h1, t - h1 - h2
    w[quad] = np.stack([(h + h1) * (h + h1 + h2) / (h1 * (h1 + h2)), -h * (h + h1 + h2) / (h1 * h2),
                        h * (h + h1) / (h2 * (h1 + h2))], -1)
    return w[:, 0, None] * a + w[:, 1, None] * a_past[:, 0] + w[:, 2, None] * a_past[:, 1]


def _subset(joints: _Joints, idx) -> _Joints:
    """The joints of realisations ``idx``."""
    return _Joints(**{f.name: getattr(joints, f.name)[idx] for f in dataclasses.fields(joints)})
