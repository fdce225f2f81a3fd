"""The contact level's initial state: the drawn offset, or the static contact equilibrium at t = 0.

``drawn``: every link rigidly offset by the realisation's eccentricities, no joint
touching (:func:`.contact_dynamics.initial_state`); the joints then fall onto
their walls in the first ~0.1 s, an impact no real robot starts with.
``equilibrium``: the state in which the contact level's own equations of motion
give zero acceleration at t = 0,
    K d - g(d, v0) = F(0) - C v0,
F(0) the t = 0 loads (gravity and the rigid inverse-dynamics loads of the ideal
motion, as the contact level applies them), v0 the drawn start's velocity (the
ideal-joint quasi-static deformation rate, zero at every joint), g the contact
forces.  At v0 every joint's penetration rate is zero, so the Lankarani-Nikravesh
law reduces to Hertz, k delta^n; friction is kept: the ideal motion already
slides every joint at t = 0 (the trajectory starts at full speed), so the
modified Coulomb force is at its kinetic value mu F_N and belongs to the balance.
Newton on the joint nodes (the links statically condensed onto them) starts from
the quasi-static ``reaction`` eccentricities, each joint pushed along its rigid
reaction force onto its wall and into it by the Hertz penetration (F/k)^(1/n) of
that force (a joint exactly at its wall has no contact stiffness).
"""
from __future__ import annotations

import dataclasses
from collections import namedtuple

import numpy as np

from .assembly import join, split
from .clearance import ClearanceDraw
from .contact_options import CONTACT_STARTS
from .contact_dynamics import (_Chunk, _Condensed, _evaluate, _full_contact, _generalized, _internal,
                               _joint_nodes, _solve_arrow, _tangent, StartState,
                               drawn_start, initial_state)
from .dynamics import inverse_dynamics
from .realised import ReferenceMotion
from .quasi_static import reaction_eccentricities
from .status import failure_message

__all__ = ["contact_initial_state", "equilibrium_state", "static_residual"]

# converged when no generalised force is out of balance by more than RESIDUAL_TOLERANCE times the
# largest t = 0 load: 1e-9 x ~20 N is 2e-8 N, an acceleration below 1e-7 m/s^2 on the 1.4 kg
# platform and a displacement below 1e-14 m at the joints' contact stiffness (> 1e6 N/m): far under
# anything the level reports, and ~100x above the round-off of K d (terms of ~1e4 N, 1e-16 relative)
RESIDUAL_TOLERANCE = 1e-9
MAX_ITERATIONS = 100   # friction makes ~30 common (docs/model.md, contact start)

def contact_initial_state(scene, jm, joints, reference=None) -> StartState:
    """The scene's ``contact_start`` ('drawn' or 'equilibrium') of a batch with joints ``joints``
    about the ``reference`` motion (:class:`.realised.ReferenceMotion`; default the scene's nominal
    one): what :func:`.contact_dynamics.simulate_contact` takes as ``initial``."""
    start = scene.simulation.contact_start
    if start not in CONTACT_STARTS:
        raise ValueError(f"contact start must be one of {', '.join(CONTACT_STARTS)}, not {start!r}")
    if start == "equilibrium":
        return equilibrium_state(scene, jm, joints, reference)
    return drawn_start(scene, jm, joints, reference)


def _penetrated(scene, joints, reference: ReferenceMotion | None = None):
    """The batch's joints with the reaction eccentricities at t = 0, each pushed into its wall by the
    Hertz penetration of its rigid reaction force: Newton's starting point."""
    motion = (reference or ReferenceMotion(scene)).at(np.array([0.0])).motion
    loads = inverse_dynamics(scene, motion)
    w = scene.geometry.w
    n = scene.contact.exponent
    fa = loads.force_A[0]
    axial = np.einsum("li,li->l", fa, w)
    radial = np.linalg.norm(fa - axial[:, None] * w, axis=-1)
    e = {"e_A": [], "e_C": [], "e_B": []}
    def deeper(size, force, k):
        return size + (np.abs(force) / k) ** (1.0 / n)

    for r in range(len(joints.radial)):
        draw = ClearanceDraw(deeper(joints.radial[r], radial, joints.k_A[r]),
                             deeper(joints.axial[r], axial, joints.k_A[r]),
                             deeper(joints.size_C[r], np.linalg.norm(loads.force_C[0], axis=-1), joints.k_C[r]),
                             deeper(joints.size_B[r], np.linalg.norm(loads.force_B[0], axis=-1), joints.k_B[r]),
                             joints.e_A[r], joints.e_C[r], joints.e_B[r])
        for key, value in zip(e, reaction_eccentricities(scene, motion, draw)):
            e[key].append(value[0])
    return dataclasses.replace(joints, **{k: np.stack(v) for k, v in e.items()})


def static_residual(scene, jm, joints, d, v, reference=None):
    """Force imbalance F(0) - C v - K d + g(d, v) (R, N) of the contact level at t = 0, N (or N m):
    M a(0) of the state (d, v); zero at the static equilibrium."""
    ch = _Chunk(scene, jm, np.array([0.0]), reference)
    impact = np.full(d.shape[:1] + (6, 4), scene.contact.impact_speed_floor)
    xb, xp = _joint_nodes(jm, d)
    vb, vp = _joint_nodes(jm, v)
    f = _evaluate(scene, ch, 0, joints, impact, xb, xp, vb, vp)[0]
    gl, gp = _generalized(ch, 0, f)
    rc, rr, _ = split(jm, d)
    g = join(*_full_contact(jm, gl, rc.shape, rr.shape), gp)
    return ch.F[0] - _internal(jm, ch.Mp[0], d, v) + g


_Static = namedtuple("_Static", "ch cond rb rp keep shapes vb vp impact tol")
_Static.__doc__ = """The static problem at t = 0: the chunk of t = 0, the links' stiffness condensed onto their
joint nodes and the condensed loads F(0) - C v0, what recovers the links' interiors, the joint
nodes' velocities, the (unused: zero rate) impact speeds and the force tolerance, N."""


def equilibrium_state(scene, jm, joints, reference=None) -> StartState:
    """The static contact equilibrium at t = 0 (module docstring), by damped Newton.  Without
    friction it converges in 2 iterations from the reaction start; the kinetic friction, which turns
    with the contact normal (a dependence the step kernel's Jacobian leaves out), makes it ~30,
    most of them halved steps, then quadratic (docs/performance.md)."""
    reference = reference or ReferenceMotion(scene)
    d0, v = initial_state(scene, jm, _penetrated(scene, joints, reference), reference=reference)
    ch = _Chunk(scene, jm, np.array([0.0]), reference)
    cond = _Condensed(jm, 0.0, 1.0)
    rc, rr, rp = split(jm, ch.F[0] - _internal(jm, ch.Mp[0], np.zeros_like(v), v))
    rb, keep = cond.condense(rc, rr)
    vb, vp = _joint_nodes(jm, v)
    problem = _Static(ch, cond, rb, rp, keep, (rc.shape, rr.shape), vb, vp,
                      np.full(v.shape[:1] + (6, 4), scene.contact.impact_speed_floor),
                      RESIDUAL_TOLERANCE * max(np.abs(ch.F[0]).max(), 1e-300))
    xb, xp, size, count = _newton(scene, joints, problem, *_joint_nodes(jm, d0))
    d = join(*cond.recover(xb, keep, *problem.shapes), xp)
    message = ["" if s <= problem.tol else failure_message(
        f"the static contact equilibrium did not converge in {MAX_ITERATIONS} Newton iterations "
        f"(force imbalance {s:.3g} N, tolerance {problem.tol:.3g} N)", 0.0, 0, 0.0) for s in size]
    return StartState(d, v, size, count, message)


def _newton(scene, joints, pb: _Static, xb, xp):
    """Damped Newton on the joint nodes xb (R, 6, 12) and platform xp (R, 6) of the static problem
    ``pb``: a step is halved where it does not reduce the squared imbalance (contact kinks).
    Returns xb, xp, the largest imbalance (R,), N, and the iterations taken (R,)."""
    def residual(xb, xp):
        f, De = _evaluate(scene, pb.ch, 0, joints, pb.impact, xb, xp, pb.vb, pb.vp)[:2]
        gl, gp = _generalized(pb.ch, 0, f)
        res_l, res_p = xb @ pb.cond.legs.T - pb.rb - gl, -pb.rp - gp
        size = np.maximum(np.abs(res_l).max((-1, -2)), np.abs(res_p).max(-1))
        return res_l, res_p, size, De, (res_l ** 2).sum((-1, -2)) + (res_p ** 2).sum(-1)

    res_l, res_p, size, De, merit = residual(xb, xp)
    count = np.zeros(len(xb), np.int64)
    for _ in range(MAX_ITERATIONS):
        todo = size > pb.tol
        if not todo.any():
            break
        dl, dp = _solve_arrow(*_tangent(pb.ch, 0, De, pb.cond.legs, np.zeros((6, 6))), res_l, res_p)
        lam = np.where(todo, 1.0, 0.0)
        for _ in range(30):
            trial = residual(xb - lam[:, None, None] * dl, xp - lam[:, None] * dp)
            worse = todo & ~(trial[4] < merit)
            if not worse.any():
                break
            lam = np.where(worse, 0.5 * lam, lam)
        else:
            trial = residual(xb - lam[:, None, None] * dl, xp - lam[:, None] * dp)
        xb, xp = xb - lam[:, None, None] * dl, xp - lam[:, None] * dp
        res_l, res_p, size, De, merit = trial
        count += todo
    return xb, xp, size, count
