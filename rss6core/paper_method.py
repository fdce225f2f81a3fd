"""The seed paper's clearance method (L3): clearance vectors redrawn every time step on top of L2.

Faithful to the paper (sec. 2-5), with each step's draw from the realisation's own stream:
- eccentricities e_A, e_C, e_B are drawn afresh at every time step (eq. 5, 7, 9);
- virtual lengths (eq. 33): the crank's distance from bearing centre to socket C
  grows by dl_ac = x_c . e_A, the rod's socket-to-socket distance by
  dl_cb = x_r . (e_C - e_B) (x_c, x_r unit link axes);
- their kinematic error is the platform error that keeps every leg closed with
  the changed lengths, from the linearised closure (as in L1, with only the
  components along the link axes): n_i . (dp + dtheta x r_i) = (n_i . x_c) dl_ac - dl_cb;
- the contact force of eq. 17-19 uses the penetration e - delta of eq. 6, 8, 10.
The platform error is the elastic error of eq. 32 plus the kinematic error;
velocity and acceleration of the kinematic part are its time derivatives on the
step grid (central differences), as the method defines no other.  The same central
differences hold at t = 0 and t = T: the draw has CENTRAL_PAD extra steps beyond
each end, from their own seeded stream (one-sided differences there weighed the
white noise differently and put 40-60 % of the velocity and 70-80 % of the
acceleration maxima on the first or last sample).

Where the method is ill-posed (measured in the tests and the README):
- the drawn eccentricities lie inside the clearance by construction (|e| <= delta),
  so the penetration of eq. 6-10 is never positive and the LN and friction forces
  of eq. 17-19 are identically zero; and a joint force pair applied to the two
  elements of an ideal joint cancels in the assembled eq. 32 anyway;
- a fresh draw every step is white noise: the kinematic velocity error grows
  like 1/dt and the acceleration error like 1/dt^2 as the step is refined, so
  those statistics measure the time step, not the robot;
- the length-dependent matrices of eq. 34 (rho(t) = M_l / (l_c A)) change
  stiffness by at most 3 dl/l (0.35 % for 0.25 mm on the 216 mm crank), which
  moves the elastic error by well under a micrometre; they are not rebuilt.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .assembly import link_frames
from .clearance import (SIZE_UNIFORMS, ClearanceDraw, clearances_from_uniforms, draw_clearances,
                        eccentricities_inside, realization_rng, uniform_dimension)
from .contact_laws import joint_stiffness, lankarani_nikravesh
from .kinematics import rigid_motion
from .quasi_static import CENTRAL_PAD, closure_matrix, padded_grid, time_derivatives
from .results import SimulationResult
from .status import FINISHED, Outcome, check_history

__all__ = ["PaperClosure", "paper_contact_forces", "paper_draw", "paper_result", "output_step", "END_TAG"]

END_TAG = 7340033   # third SeedSequence word of the stream of the steps drawn beyond the ends


class PaperClosure:
    """Link axes and the linearised leg closure along the ideal motion at times t (s) and CENTRAL_PAD
    steps beyond each end, shared by every realisation's draws; ``motion`` (t -> RigidMotion): another
    rigid motion (a realised robot's under the nominal commands, rss6core/realised.py)."""

    def __init__(self, scene, t: np.ndarray, motion=None):
        grid = padded_grid(t, CENTRAL_PAD)
        motion = rigid_motion(scene, grid) if motion is None else motion(grid)
        crank, rod = link_frames(motion, scene.geometry)
        self.x_c, self.x_r = crank[..., 0], rod[..., 0]   # unit link axes (T + 2 pad, 6, 3)
        self.G, n = closure_matrix(motion)
        self.n_dot_xc = np.einsum("tli,tli->tl", n, self.x_c)
        self.t = motion.t
        # the closure as one linear map per step (T + 2 pad, 6, 36) of [e_A, e_C - e_B] (36,):
        # G^-1 [(n . x_c) x_c, -x_r] (eq. 33 and the closure), shared by every draw instead of a
        # solve per draw; it equals the solve to round-off (G is well conditioned, about 30)
        g_inv = np.linalg.inv(self.G)
        along_crank = g_inv[..., None] * (self.n_dot_xc[:, None, :, None] * self.x_c[:, None])
        along_rod = -g_inv[..., None] * self.x_r[:, None]
        self.closure_map = np.concatenate([along_crank.reshape(len(self.t), 6, 18),
                                           along_rod.reshape(len(self.t), 6, 18)], -1)

    def virtual_lengths(self, draw) -> tuple[np.ndarray, np.ndarray]:
        """Crank and rod virtual lengths dl_ac, dl_cb (T + 2 pad, 6), m (eq. 33) for a
        :func:`paper_draw` (T + 2 pad, 6, 3)."""
        return (np.einsum("tli,tli->tl", self.x_c, draw.e_A),
                np.einsum("tli,tli->tl", self.x_r, draw.e_C - draw.e_B))

    def error(self, draw):
        """Platform error (T, 6) of the virtual lengths, and its first and second time derivatives,
        the same central differences at every output step (the pads cut off)."""
        steps = len(self.t)
        offsets = np.concatenate([draw.e_A.reshape(steps, 18), (draw.e_C - draw.e_B).reshape(steps, 18)], -1)
        return time_derivatives(np.einsum("tij,tj->ti", self.closure_map, offsets), self.t, CENTRAL_PAD)


def paper_contact_forces(scene, draw, dt: float, restitution=None) -> np.ndarray:
    """Normal contact force magnitudes (T, 18) N of eq. 17 for a :func:`paper_draw`, joints A, C, B.

    The penetration rate is the central difference of |e| between steps (the pads make it central
    at the ends too); the initial contact speed is the joint's first positive rate (the scene's
    floor otherwise).  ``restitution``: one per joint (18,) A1..A6, C1..C6, B1..B6 (default the
    scene's).
    """
    w = scene.geometry.w
    size = np.concatenate([draw.radial_size, draw.size_C, draw.size_B])
    if _inside(draw, w, size):
        return np.zeros((len(draw.e_A) - 2 * CENTRAL_PAD, len(size)))
    e_r = draw.e_A - np.einsum("tli,li->tl", draw.e_A, w)[..., None] * w
    ct = scene.contact
    rho = np.concatenate([np.linalg.norm(e_r, axis=-1), np.linalg.norm(draw.e_C, axis=-1),
                          np.linalg.norm(draw.e_B, axis=-1)], -1)
    radius = np.repeat([ct.journal_radius, ct.sphere_radius, ct.sphere_radius], 6)
    K = joint_stiffness(scene, radius, size)
    rate = np.gradient(rho, dt, axis=0)[CENTRAL_PAD:-CENTRAL_PAD]
    rho = rho[CENTRAL_PAD:-CENTRAL_PAD]
    impact = np.maximum(np.max(rate, axis=0), ct.impact_speed_floor)
    xi = ct.restitution if restitution is None else restitution
    return lankarani_nikravesh(rho - size, rate, impact, K, ct.exponent, xi)[0]


INSIDE_MARGIN = 1.0 - 1e-9   # |e|^2 below this times size^2: no penetration despite rounding


def _inside(draw, w, size) -> bool:
    """Whether every output step's eccentricity of a :func:`paper_draw` (the revolute's radial part
    off its axis w (6, 3)) lies clearly inside its clearance ``size`` (18,) m: then no force can
    act (eq. 17), and the force history is zero.  A cheap test (squared lengths, one compiled pass,
    :func:`.clearance.eccentricities_inside`) with a margin that rounding cannot cross."""
    return eccentricities_inside(draw, w, size, INSIDE_MARGIN, CENTRAL_PAD, len(draw.e_A) - CENTRAL_PAD)


def paper_draw(scene, seed: int, realization: int, steps: int, uniforms=None) -> ClearanceDraw:
    """The realisation's per-step draw: sizes once, eccentricities at the ``steps`` output steps and
    at CENTRAL_PAD steps beyond each end (leading axis steps + 2 CENTRAL_PAD, in time order).

    The output steps draw from the realisation's stream (or ``uniforms``, as in
    :func:`.clearance.draw_clearances`) exactly as without pads; the pads from their own stream
    SeedSequence([seed, realization, END_TAG]) with the same sizes (the first SIZE_UNIFORMS
    uniforms set them), so neither chunking nor workers change them.
    """
    padded = {e: np.empty((steps + 2 * CENTRAL_PAD, 6, 3)) for e in ("e_A", "e_C", "e_B")}
    inside = {e: a[CENTRAL_PAD:CENTRAL_PAD + steps] for e, a in padded.items()}   # drawn in place
    if uniforms is None:
        inner = draw_clearances(scene, seed, realization, steps=steps, out=inside)
        size_uniforms = realization_rng(seed, realization).uniform(size=SIZE_UNIFORMS)
    else:
        u = uniforms(realization, uniform_dimension(steps, scene))
        inner, size_uniforms = clearances_from_uniforms(scene, u, steps, inside), u[:SIZE_UNIFORMS]
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(realization), END_TAG]))
    fresh = rng.uniform(size=uniform_dimension(2 * CENTRAL_PAD) - SIZE_UNIFORMS)
    ends = clearances_from_uniforms(scene, np.concatenate([size_uniforms, fresh]), 2 * CENTRAL_PAD)
    for e, a in padded.items():
        a[:CENTRAL_PAD], a[CENTRAL_PAD + steps:] = getattr(ends, e)[:CENTRAL_PAD], getattr(ends, e)[CENTRAL_PAD:]
    return dataclasses.replace(inner, **padded)


def output_step(draw: ClearanceDraw, step: int = 0) -> ClearanceDraw:
    """A :func:`paper_draw`'s sizes with output step ``step``'s eccentricities, copied: a view would
    keep every step's draw (0.9 MB per realisation at 2001 steps) alive with the result."""
    k = CENTRAL_PAD + step
    return dataclasses.replace(draw, e_A=draw.e_A[k].copy(), e_C=draw.e_C[k].copy(), e_B=draw.e_B[k].copy())


def paper_result(elastic: SimulationResult, closure: PaperClosure, draw, force, stored_draw):
    """The elastic run plus the draw's kinematic error: failed where the elastic run failed, or where
    the sum is not finite or beyond the divergence limit; ``force`` (T, 18) N, ``stored_draw`` the
    draw an ensemble file records."""
    d, v, a = closure.error(draw)
    d, v, a = elastic.displacement + d, elastic.velocity + v, elastic.acceleration + a
    outcome = Outcome(elastic.status, elastic.message, elastic.steps)
    if outcome.status == FINISHED:
        outcome = check_history(d, elastic.t, "paper-level displacement error")
    return SimulationResult(elastic.t, d, v, a, outcome.status, outcome.message, outcome.steps,
                            contact_force_peak=force.max(0), draw=stored_draw)
