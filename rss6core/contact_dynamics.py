"""Contact level (L4): clearance joints as contact pairs on top of the KED model, batched over realisations.

Small-displacement (perturbation) dynamics around the ideal motion, as in the
elastic level (:mod:`.assembly`), but the joints are no longer ideal: every
link is a free body held only by contact forces.
- crank i: nodes 0..n in its own frame; node 0 (the journal at A_i) may
  translate (its rotations stay clamped: the motor holds alpha_i, and the
  journal does not tilt in its bearing, as in the paper's sec. 2.3); with a
  ``motor_stiffness`` k_m (:func:`build_joint_model`) its rotation about the motor
  axis (crank-frame y) is a DOF too, held by a torsional spring k_m about the
  commanded angle plus the rigid robot's feed-forward torque;
- rod i: all nodes, both ends free (its own frame, torsion dropped as in L2);
- platform: rigid, 6 DOFs, base frame.
The relative displacements of the joint elements are the clearance state
(base frame): e_A = crank node 0 (the bearing is fixed), e_C = rod C end - crank
tip, e_B = rod B end - (u_0 + theta_0 x r_i).  While |e| stays inside the
clearance the joint is in free flight; beyond it the Lankarani-Nikravesh force
(eq. 17) and the modified Coulomb friction (eq. 18) act on the pair.  The
sliding velocity includes the ideal relative rotation of the joint elements,
(omega_ball - omega_socket) x R n, which dominates it; friction forces act at
the joint centres (their moment, at most mu R F_N, is left out, as in eq. 19).
The revolute's axial faces use the radial stiffness and no friction.

Every link's matrices are constant in its frame, so each step condenses the
links onto their joint nodes once for the whole batch; Newton iterations on the
contact forces then solve, per realisation, a block-arrow system of 12 joint DOFs
per leg bordered by the 6 platform DOFs.  Realisations are an array axis: the
per-step matrices, factorizations and rigid loads are shared by the batch; the
steps themselves run compiled (:mod:`.contact_kernel`), one realisation after
another, with the vectorised numpy stepper (:mod:`.contact_numpy`, built on the numpy
functions below) as their reference.  Both steppers keep one contract (:class:`ContactStepper`: it
owns the batch's state and status; ``advance`` says how far it got and why it stopped), and
:func:`simulate_contact` is a short driver over chunks of steps with either.
"""
from __future__ import annotations

import abc
import dataclasses
import functools
from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from .assembly import (LegLayout, build_elastic_model, frame_maps, join, link_frames, link_loads,
                       platform_point_map, scene_link_matrices, split, to_link_coordinates)
from .link_reduction import craig_bampton, reduce_pair
from .contact_kernel import (ChunkArrays, Frame, Joints, Law, Layout, Levels, Records, Settings, State, System,
                             Out, advance_chunk, kernel_compiling, make_scratch, make_work, newton_step)
from .contact_options import MAX_CONTACT_REFINEMENTS, TOL_DISPLACEMENT, TOL_VELOCITY
from .contact_laws import coulomb_friction, joint_stiffness, lankarani_nikravesh
from .dynamics import inverse_dynamics, platform_inertia_world, rod_angular_motion
from .elastic import quasi_static_state
from .results import PEAK_WINDOWS, ContactBatch, time_grid
from .integrators import Integrator, StepWeights, make_integrator
from .kinematics import crank_axes
from .quasi_static import closure_matrix
from .realised import JointLaws, ReferenceMotion, realised_contact_laws
from .status import DIVERGENCE_LIMIT, FAILED, FINISHED, contact_failure

__all__ = ["JointModel", "build_joint_model", "simulate_contact", "ContactStepper", "CompiledStepper",
           "Progress", "JointSolution", "StepSolution", "StartState", "drawn_start"]

MAX_ITERATIONS = 60
MOTOR_DOF = 3   # crank index of node 0's rotation about the motor axis, when a motor releases it


@dataclass(frozen=True)
class JointModel(LegLayout):
    """Constant link matrices of the contact level: every link free, joint nodes as boundaries."""
    elements: int
    crank_K: np.ndarray       # (6n+3): node 0 translations, then nodes 1..n (6n+4 with a motor: node 0 r_y 4th)
    crank_M: np.ndarray
    crank_boundary: np.ndarray  # crank indices of node 0 (3) and tip (3) translations
    rod_K: np.ndarray         # (5n+5) [own, C end, B end], as in the elastic model
    rod_M: np.ndarray
    platform_mass: float
    platform_inertia: np.ndarray
    mass_damping: float
    stiffness_damping: float
    elastic: object           # the ElasticModel it shares loads and rod layout with
    crank_basis: np.ndarray | None = None   # Craig-Bampton T (6n+3, m+9) of the crank: [node 0 (3), modes, tip (6)]
    motor_stiffness: float | None = None    # N m/rad, k_m of the crank's motor; None: node 0's rotations clamped

    @property
    def crank_dofs(self) -> int:
        return self.crank_K.shape[0]

    @property
    def crank_keep(self) -> np.ndarray:
        """The crank's full nodal indices (of 6(n+1)) that are its DOFs, in order."""
        return _crank_keep(self.elements, self.motor_stiffness is not None)

    @property
    def motor_dof(self) -> int | None:
        """The crank index of node 0's rotation about the motor axis (crank-frame y), or None (clamped)."""
        return None if self.motor_stiffness is None else MOTOR_DOF

    @property
    def rod_dofs(self) -> int:
        return self.rod_K.shape[0]


def _crank_keep(elements: int, motor: bool) -> np.ndarray:
    """Full nodal indices kept as crank DOFs: node 0's translations (and, with a motor, its rotation
    about the motor axis, index 4), then nodes 1..n."""
    return np.r_[0:3, [4] if motor else [], 6:6 * (elements + 1)].astype(np.int64)


def build_joint_model(scene, elements: int, motor_stiffness: float | None = None) -> JointModel:
    """Link matrices with free journals and free rod ends for ``elements`` elements per link.

    ``motor_stiffness`` k_m (N m/rad): the crank is driven through a compliant motor, node 0's
    rotation about the motor axis (crank-frame y = w_i) kept as a DOF grounded by k_m (the servo's
    position-loop stiffness about the commanded angle; the Rayleigh damping lambda_2 K applies to it
    too); the tilts stay clamped.  None: the scene's ``[actuator]`` (a prescribed drive: clamped, as in
    the paper)."""
    if motor_stiffness is None:
        motor_stiffness = scene.actuator.motor_stiffness
    em = build_elastic_model(scene, elements)
    if motor_stiffness is not None:
        if not motor_stiffness > 0.0:
            raise ValueError(f"motor stiffness must be > 0 N m/rad, got {motor_stiffness!r}")
        if em.crank_basis is not None:
            raise ValueError("a compliant motor (motor_stiffness) needs the full mesh: [beam] link_modes = 0")
    Kc, Mc = scene_link_matrices(scene, "crank", elements)
    keep = _crank_keep(elements, motor_stiffness is not None)
    n6, node0 = 6 * elements, len(keep) - 6 * elements
    boundary = np.r_[0:3, n6 + node0 - 6:n6 + node0 - 3]   # node 0 translations; node n translations
    K = Kc[..., keep[:, None], keep]
    if motor_stiffness is not None:
        K[..., MOTOR_DOF, MOTOR_DOF] += motor_stiffness
    jm = JointModel(elements, K, Mc[..., keep[:, None], keep], boundary,
                    em.rod_K, em.rod_M, em.platform_mass, em.platform_inertia, em.mass_damping,
                    em.stiffness_damping, em, motor_stiffness=motor_stiffness)
    return _reduced_crank(jm, em.crank_dofs - 6) if em.crank_basis is not None else jm


def _reduced_crank(jm: JointModel, modes: int) -> JointModel:
    """The Craig-Bampton crank of a reduced model: boundary = the journal's translations and the tip
    node, so its fixed-interface modes are the elastic level's (same interior, same bits) and its
    coordinates [node 0 (3), modes, tip node (6)] extend the elastic crank's as the full mesh's do."""
    n = jm.crank_dofs
    T = craig_bampton(jm.crank_K, jm.crank_M, np.r_[0:3, n - 6:n], modes)
    T = T[:, np.r_[modes:modes + 3, 0:modes, modes + 3:modes + 9]]
    K, M = reduce_pair(jm.crank_K, jm.crank_M, T)
    return dataclasses.replace(jm, crank_K=K, crank_M=M, crank_boundary=np.r_[0:3, modes + 3:modes + 6],
                               crank_basis=T)


class _Condensed:
    """Links condensed onto their joint nodes for the step matrix mass M + stiffness K (constant)."""

    def __init__(self, jm: JointModel, mass: float, stiffness: float):
        self.mass = mass
        parts = []
        for M, K, b in ((jm.crank_M, jm.crank_K, jm.crank_boundary),
                        (jm.rod_M, jm.rod_K, np.arange(jm.rod_dofs - 6, jm.rod_dofs))):
            E = mass * M + stiffness * K
            i = np.setdiff1d(np.arange(E.shape[0]), b)
            inv = np.linalg.inv(E[np.ix_(i, i)])
            P = inv @ E[np.ix_(i, b)]
            parts.append((i, b, inv, E[np.ix_(i, b)], P, E[np.ix_(b, b)] - E[np.ix_(b, i)] @ P))
        self.crank, self.rod = parts
        S = np.zeros((12, 12))
        S[:6, :6], S[6:, 6:] = self.crank[5], self.rod[5]
        self.legs = S   # (12, 12): crank node 0, crank tip, rod C end, rod B end (link frames)

    def maps(self):
        """Condensation as a matrix per link [crank, rod]: r (n,) -> [r_i inv, r_b - r_i P] (n, n_i + 6),
        and P (n_i, 6), with which :meth:`recover` makes x_i = y - x_b P^T."""
        out = []
        for i, b, inv, _, P, _ in (self.crank, self.rod):
            ni, n = len(i), len(i) + len(b)
            T = np.zeros((n, ni + 6))
            T[i, :ni], T[i, ni:], T[b, ni + np.arange(6)] = inv, -P, 1.0
            out.append((T, np.ascontiguousarray(P)))
        return out

    def condense(self, rc, rr):
        """Right-hand sides (..., 6, 12) on the joint nodes, and the interior parts for recovery."""
        out, keep = [], []
        for r, (i, b, inv, Eib, _, _) in ((rc, self.crank), (rr, self.rod)):
            y = r[..., i] @ inv                       # symmetric inverse: row form
            out.append(r[..., b] - y @ Eib)
            keep.append(y)
        return np.concatenate(out, -1), keep

    def recover(self, xb, keep, shape_c, shape_r):
        """Full link vectors from the joint-node solution xb (..., 6, 12)."""
        xs = []
        for y, xpart, (i, b, _, _, P, _), shape in ((keep[0], xb[..., :6], self.crank, shape_c),
                                                     (keep[1], xb[..., 6:], self.rod, shape_r)):
            x = np.empty(shape)
            x[..., i] = y - xpart @ P.T
            x[..., b] = xpart
            xs.append(x)
        return xs


@dataclass(frozen=True)
class _Joints:
    """Per-realisation contact data (leading axis R): clearance sizes, stiffnesses, initial draw,
    friction coefficients and restitutions per joint."""
    radial: np.ndarray   # (R, 6) m
    axial: np.ndarray
    size_C: np.ndarray
    size_B: np.ndarray
    k_A: np.ndarray      # (R, 6) N/m^1.5
    k_C: np.ndarray
    k_B: np.ndarray
    e_A: np.ndarray      # (R, 6, 3) initial eccentricities, base frame
    e_C: np.ndarray
    e_B: np.ndarray
    mu: np.ndarray       # (R, 6, 3) friction coefficient per joint [A, C, B] (eq. 18)
    restitution: np.ndarray  # (R, 6, 3) restitution per joint [A, C, B] (eq. 17)


def _joints(scene, draws, laws=None) -> _Joints:
    """The batch's joints from its clearance draws and its :class:`.realised.JointLaws` (one per
    draw; None: the scene's [contact] friction and restitution at every joint)."""
    laws = laws or [realised_contact_laws(scene)] * len(draws)
    stack = {f: np.stack([getattr(d, f) for d in draws]) for f in
             ("radial_size", "axial_size", "size_C", "size_B", "e_A", "e_C", "e_B")}
    for name, key in (("radial_size", "revolute_radial_m"), ("axial_size", "revolute_axial_m"),
                      ("size_C", "spherical_C_m"), ("size_B", "spherical_B_m")):
        if np.any(stack[name] <= 0.0):
            raise ValueError(f"the contact level needs positive clearances; [clearance] {key} is "
                             "zero (use the elastic level for ideal joints)")
    ct = scene.contact
    return _Joints(stack["radial_size"], stack["axial_size"], stack["size_C"], stack["size_B"],
                   joint_stiffness(scene, ct.journal_radius, stack["radial_size"]),
                   joint_stiffness(scene, ct.sphere_radius, stack["size_C"]),
                   joint_stiffness(scene, ct.sphere_radius, stack["size_B"]), stack["e_A"], stack["e_C"], stack["e_B"],
                   np.stack([law.friction for law in laws]), np.stack([law.restitution for law in laws]))


def _ball(e, de, size, stiffness, impact, law, omega, radius, mu=None, restitution=None, friction=True):
    """Force on the ball (journal) side of a ball-in-socket pair and its Jacobians (base frame).

    e, de (..., 3) relative displacement and velocity; mu and restitution (...) the pairs' (default:
    the scene's [contact] ``law``, which gives the exponent and friction velocities); returns force (..., 3),
    d force/d e and d force/d de (..., 3, 3), penetration, its rate and F_N (...).
    """
    rho = np.linalg.norm(e, axis=-1)
    safe = np.maximum(rho, 1e-300)
    n = e / safe[..., None]
    delta = rho - size
    rate = (n * de).sum(-1)
    mu = law.friction_coefficient if mu is None else mu
    restitution = law.restitution if restitution is None else restitution
    F, dF, dFr = lankarani_nikravesh(delta, rate, impact, stiffness, law.exponent, restitution)
    nn = n[..., :, None] * n[..., None, :]
    eye = np.eye(3)
    force = -F[..., None] * n
    De = -dF[..., None, None] * nn - (F / safe)[..., None, None] * (eye - nn)
    Dv = -dFr[..., None, None] * nn
    if friction and np.any(np.asarray(mu) > 0.0):
        Pn = eye - nn
        v = de + radius * np.cross(omega, n)
        slip = v - (n * v).sum(-1)[..., None] * n
        ft, jac, dft = coulomb_friction(F, slip, mu, law.stick_velocity, law.slip_velocity)
        force = force + ft
        De = De + dft[..., :, None] * (dF[..., None] * n)[..., None, :]
        Dv = Dv + jac @ Pn + dft[..., :, None] * (dFr[..., None] * n)[..., None, :]
    return force, De, Dv, delta, rate, F


def _contacts(e, de, w, joints: _Joints, impact, law, omega, radius):
    """All joints of a batch at once: A radial (journal in bearing), C and B (ball in socket), A axial.

    e, de (..., 6, 3, 3) relative displacements and velocities [A, C, B], base
    frame; omega (6, 3, 3) the ideal relative angular velocities; radius (3, 1)
    the journal and sphere radii.  Returns forces (..., 6, 3, 3), their
    Jacobians d/de and d/dde (..., 6, 3, 3, 3), and penetrations and their rates
    (..., 6, 4) ordered [A radial, A axial, C, B].
    """
    Pw = np.eye(3) - w[:, :, None] * w[:, None, :]
    eA = e[..., 0, :]
    radial = np.concatenate([(Pw @ eA[..., None])[..., None, :, 0], e[..., 1:, :]], -2)
    size = np.stack([joints.radial, joints.size_C, joints.size_B], -1)
    stiffness = np.stack([joints.k_A, joints.k_C, joints.k_B], -1)
    f, De, Dv, d, r, _ = _ball(radial, de, size, stiffness, impact[..., [0, 2, 3]], law, omega, radius,
                               joints.mu, joints.restitution)
    s = (w * eA).sum(-1)
    sign = np.where(s >= 0.0, 1.0, -1.0)
    na = sign[..., None] * w
    da = np.abs(s) - joints.axial
    ra = (na * de[..., 0, :]).sum(-1)
    Fa, dFa, dFra = lankarani_nikravesh(da, ra, impact[..., 1], joints.k_A, law.exponent,
                                        joints.restitution[..., 0])
    ww = w[:, :, None] * w[:, None, :]
    f[..., 0, :] -= Fa[..., None] * na
    De[..., 0, :, :] = De[..., 0, :, :] @ Pw - dFa[..., None, None] * ww
    Dv[..., 0, :, :] -= dFra[..., None, None] * ww
    order = [0, 3, 1, 2]   # [A radial, C, B, A axial] -> [A radial, A axial, C, B]
    return (f, De, Dv, np.concatenate([d, da[..., None]], -1)[..., order],
            np.concatenate([r, ra[..., None]], -1)[..., order])


class _Chunk:
    """Shared, per-instant data of a run of steps: joint maps, loads, ideal angular velocities
    (and the joint radii [journal, sphere, sphere] (3, 1), m, that the contact evaluation needs), about
    the ``reference`` motion (:class:`.realised.ReferenceMotion`; default: the scene's nominal one).

    ``t`` holds the chunk's instants on the finest grid, ``fine`` of them per base step.  Only the
    base steps' ends are computed at first; a base step's interior instants, which only a refined
    step reads, when :meth:`fill` asks for them (``filled`` per base step): each instant's values are
    the same bits either way, and most base steps are never refined."""

    def __init__(self, scene, jm: JointModel, t: np.ndarray, reference: ReferenceMotion | None = None,
                 fine: int = 1):
        self.t, self.fine, self.scene, self.jm = t, fine, scene, jm
        self.reference = reference or ReferenceMotion(scene)
        T = len(t)
        self.F = np.empty((T, jm.dofs))
        self.Mp, self.J = np.empty((T, 6, 6)), np.empty((T, 6, 3, 6))
        self.Rc, self.Rr, self.omega = (np.empty((T, 6, 3, 3)) for _ in range(3))
        self.offset = np.empty((T, 3, 6))
        self.filled = np.full(max((T - 1) // fine, 0), fine == 1)
        self._rows(np.arange(0, T, fine))
        law = scene.contact
        self.radius = np.array([[law.journal_radius], [law.sphere_radius], [law.sphere_radius]])

    def fill(self, steps) -> None:
        """Compute the interior instants of base steps ``steps`` (those not yet filled)."""
        steps = np.asarray(steps, np.int64)
        steps = steps[~self.filled[steps]]
        if len(steps):
            self._rows((steps[:, None] * self.fine + np.arange(1, self.fine)).ravel())
            self.filled[steps] = True

    def fill_all(self) -> None:
        self.fill(np.arange(len(self.filled)))

    def _rows(self, rows: np.ndarray) -> None:
        """The chunk's arrays at instants ``rows``."""
        jm, scene = self.jm, self.scene
        at = self.reference.at(self.t[rows])
        motion = at.motion
        Rc, Rr = link_frames(motion, scene.geometry)
        Ip = platform_inertia_world(jm.platform_inertia, motion.platform.R)
        self.Mp[rows] = _platform_mass(jm, Ip)
        fc, fr, fp = link_loads(jm.elastic, motion, scene, Rc, Rr, Ip)
        F = np.empty((len(rows), jm.dofs))               # join(crank, rod, platform), one copy less
        legs = F[:, :-6].reshape(len(rows), 6, jm.leg_dofs)   # a view: the legs' part of each row
        if jm.crank_basis is None:
            legs[..., :jm.crank_dofs], legs[..., jm.crank_dofs:] = fc[..., jm.crank_keep], fr
            if jm.motor_dof is not None:
                legs[..., jm.motor_dof] += self._feed_forward(motion)
        else:
            kept = np.concatenate([fc[..., :3], fc[..., 6:]], -1)      # node 0 translations, nodes 1..n
            legs[..., :jm.crank_dofs] = to_link_coordinates(jm.crank_basis, kept)
            legs[..., jm.crank_dofs:] = fr
        F[:, -6:] = fp
        self.F[rows] = F
        self.J[rows] = platform_point_map(motion.r)
        self.Rc[rows], self.Rr[rows] = Rc, Rr
        w_crank = motion.alpha_dot[..., None] * crank_axes(scene.geometry)[None]
        w_rod = rod_angular_motion(motion).omega
        self.omega[rows] = np.stack([w_crank, w_rod - w_crank, w_rod - motion.platform.omega[:, None, :]], -2)
        self.offset[rows] = at.error

    def _feed_forward(self, motion) -> np.ndarray:
        """The motor's feed-forward torque about crank-frame y (..., 6), N m: the rigid robot's actuator
        torque (:func:`.dynamics.inverse_dynamics`, conjugate to alpha_i about e_i = -w_i, hence the sign)."""
        geometry = self.reference.geometry
        scene = self.scene if geometry is None else dataclasses.replace(self.scene, geometry=geometry)
        return -inverse_dynamics(scene, motion).torque

    @functools.cached_property
    def G(self) -> np.ndarray:
        """Joint maps (T, 6, 9, 12): joint nodes -> [e_A, e_C, e_B], blocks Rc, -Rc, Rr, Rr (the numpy
        engine's; the compiled one reads Rc and Rr, so a compiled run never makes these 16 MB)."""
        G = np.zeros(self.Rc.shape[:2] + (9, 12))
        G[..., 0:3, 0:3], G[..., 3:6, 3:6], G[..., 3:6, 6:9], G[..., 6:9, 9:12] = self.Rc, -self.Rc, self.Rr, self.Rr
        return G

    def arrays(self) -> ChunkArrays:
        """What :func:`.contact_kernel.advance_chunk` reads of the chunk."""
        return ChunkArrays(F=self.F, Mp=self.Mp, Rc=self.Rc, J=self.J, Rr=self.Rr, omega=self.omega, t=self.t,
                           offset=self.offset, filled=self.filled)


def _platform_mass(jm: JointModel, Ip: np.ndarray) -> np.ndarray:
    M = np.zeros(Ip.shape[:-2] + (6, 6))
    M[..., :3, :3] = jm.platform_mass * np.eye(3)
    M[..., 3:, 3:] = Ip
    return M


def _internal(jm: JointModel, Mp, d, v) -> np.ndarray:
    """C v + K d (Rayleigh C = lambda_1 M + lambda_2 K), per link; the platform has mass only."""
    l1, l2 = jm.mass_damping, jm.stiffness_damping
    dc, dr, dp = split(jm, d)
    vc, vr, vp = split(jm, v)
    return join((l1 * vc) @ jm.crank_M + (dc + l2 * vc) @ jm.crank_K,
                 (l1 * vr) @ jm.rod_M + (dr + l2 * vr) @ jm.rod_K,
                 l1 * np.einsum("ij,...j->...i", Mp, vp))


def _mass(jm: JointModel, Mp, a) -> np.ndarray:
    ac, ar, ap = split(jm, a)
    return join(ac @ jm.crank_M, ar @ jm.rod_M, np.einsum("ij,...j->...i", Mp, ap))


def _joint_nodes(jm: JointModel, x) -> tuple[np.ndarray, np.ndarray]:
    """Joint-node vectors (..., 6, 12) [crank node 0, tip, rod C end, rod B end] and platform (..., 6)."""
    c, r, p = split(jm, x)
    return np.concatenate([c[..., jm.crank_boundary], r[..., -6:]], -1), p


def _relative(ch: _Chunk, k: int, xb, xp):
    """Relative displacements [e_A, e_C, e_B] (..., 6, 3, 3) of the joint elements, base frame."""
    e = (ch.G[k] @ xb[..., None]).reshape(xb.shape[:-1] + (3, 3))
    e[..., 2, :] -= (ch.J[k] @ xp[..., None, :, None])[..., 0]
    return e


class _Contacts:
    """Contact state carried between steps: impact speeds, contact flags, penetration rates."""

    def __init__(self, shape, floor: float):
        self.floor = floor
        self.stored = np.full(shape + (6, 4), floor)    # A radial, A axial, C, B
        self.in_contact = np.zeros(shape + (6, 4), bool)
        self.rate = np.zeros(shape + (6, 4))

    def impact(self, idx):
        """Impact speeds delta_dot_c1 for a step of realisations ``idx``: stored, or the approach
        speed of a new contact."""
        return np.where(self.in_contact[idx], self.stored[idx], np.maximum(self.rate[idx], self.floor))

    def update(self, idx, delta, rate, used):
        self.stored[idx] = np.where((delta > 0) & ~self.in_contact[idx], used, self.stored[idx])
        self.in_contact[idx], self.rate[idx] = delta > 0, rate


def _evaluate(scene, ch: _Chunk, k, joints, impact, xb, xp, vb, vp):
    return _contacts(_relative(ch, k, xb, xp), _relative(ch, k, vb, vp), scene.geometry.w, joints,
                     impact, scene.contact, ch.omega[k], ch.radius)


def _generalized(ch: _Chunk, k, f):
    """Contact forces on the joint nodes (..., 6, 12) (link frames) and on the platform (..., 6)."""
    loc = (np.swapaxes(ch.G[k], -1, -2) @ f.reshape(f.shape[:-2] + (9, 1)))[..., 0]
    return loc, -(np.swapaxes(ch.J[k], -1, -2) @ f[..., 2, :, None])[..., 0].sum(-2)


def _tangent(ch: _Chunk, k, D, Sl, Sp):
    """Newton matrix blocks: legs (..., 6, 12, 12), border (..., 6, 3, 6) on the rod B ends,
    its transpose partner (..., 6, 6, 3), and the platform block (..., 6, 6)."""
    full = np.zeros(D.shape[:-3] + (9, 9))
    for j in range(3):
        full[..., 3 * j:3 * j + 3, 3 * j:3 * j + 3] = D[..., j, :, :]
    L = Sl - np.swapaxes(ch.G[k], -1, -2) @ full @ ch.G[k]
    J, Rr = ch.J[k], ch.Rr[k]
    DB = D[..., 2, :, :]
    DBJ = DB @ J
    border = np.swapaxes(Rr, -1, -2) @ DBJ
    lower = np.swapaxes(J, -1, -2) @ DB @ Rr
    P = Sp - (np.swapaxes(J, -1, -2) @ DBJ).sum(-3)
    return L, border, lower, P


_B_COLUMNS = np.eye(12)[:, 9:12]


def _solve_arrow(L, border, lower, P, rl, rp):
    """Solve [L B; C P] [x; y] = [rl; rp], L block-diagonal over legs, B nonzero on the B-end rows only.

    B = E border with E the B-end columns of the identity, so L^-1 B = (L^-1 E) border:
    four right-hand sides per leg instead of seven.
    """
    rhs = np.concatenate([rl[..., None], np.broadcast_to(_B_COLUMNS, rl.shape + (3,))], -1)
    sol = np.linalg.solve(L, rhs)
    u, E = sol[..., 0], sol[..., 1:]
    schur = P - (lower @ E[..., 9:12, :] @ border).sum(-3)
    y = np.linalg.solve(schur, (rp - (lower @ u[..., 9:12, None])[..., 0].sum(-2))[..., None])[..., 0]
    return u - (E @ (border @ y[..., None, :, None]))[..., 0], y


def _lift(jm: JointModel, maps, x: np.ndarray) -> np.ndarray:
    """An elastic-level (ideal joint) state in the contact level's layout: joints closed."""
    c, f, p = split(jm.elastic, x)
    e_C = (maps.Q @ c[..., jm.elastic.tip, None])[..., 0]
    e_B = (maps.H @ p[..., None, :, None])[..., 0]
    crank = np.concatenate([np.zeros(c.shape[:-1] + (jm.crank_dofs - c.shape[-1],)), c], -1)
    return join(crank, np.concatenate([f, e_C, e_B], -1), p)


def initial_state(scene, jm: JointModel, joints: _Joints, t0: float = 0.0, reference: ReferenceMotion | None = None):
    """The elastic level's quasi-static state with every link rigidly offset by the drawn eccentricities.

    The links carry the quasi-static deformation of the ideal-joint robot (so
    that the level tends to the elastic one as the clearance vanishes) and sit
    at rest relative to it; crank i translates by e_A,i; the platform takes the
    linearised-closure error of the draw (so that no rod is stretched); each rod
    follows its two ends rigidly (static condensation of its end offsets
    reproduces a rigid motion).  Returns (d, v) (R, N), about the ``reference`` motion (default: the
    scene's nominal one).
    """
    reference = reference or ReferenceMotion(scene)
    motion = reference.at(np.array([t0])).motion
    crank_frames, rod_frames = link_frames(motion, scene.geometry)
    Rc, Rr = crank_frames[0], rod_frames[0]
    maps = frame_maps(jm.elastic, motion, crank_frames, rod_frames)[0]
    d_el, v_el, _ = quasi_static_state(scene, jm.elastic, t0, motion=lambda t: reference.at(t).motion)
    R = joints.e_A.shape[0]
    G, n = closure_matrix(motion)
    rhs = np.einsum("li,rli->rl", n[0], joints.e_A + joints.e_C - joints.e_B)
    xp = np.linalg.solve(G[0], rhs[..., None])[..., 0]
    crank = np.zeros((R, 6, jm.crank_dofs))
    local_A = np.einsum("lji,rlj->rli", Rc, joints.e_A)
    if jm.crank_basis is None:
        trans = np.flatnonzero(jm.crank_keep % 6 < 3)      # every node's translations
        crank[..., trans] = np.tile(local_A, jm.elements + 1)
    else:   # a rigid translation is a sum of constraint modes: the boundary's translations, no modes
        crank[..., jm.crank_boundary] = np.tile(local_A, 2)
    J = platform_point_map(motion.r[0])
    ends = np.concatenate([np.einsum("lji,rlj->rli", Rr, joints.e_A + joints.e_C),
                           np.einsum("lji,rlj->rli", Rr, np.einsum("lij,rj->rli", J, xp) + joints.e_B)],
                          -1)
    nf = jm.rod_dofs - 6
    Kff, Kfe = jm.rod_K[:nf, :nf], jm.rod_K[:nf, nf:]
    own = -ends @ np.linalg.solve(Kff, Kfe).T
    offset = join(crank, np.concatenate([own, ends], -1), xp)
    return offset + _lift(jm, maps, d_el), np.broadcast_to(_lift(jm, maps, v_el), offset.shape).copy()


StartState = namedtuple("StartState", "d v residual iterations message")
StartState.__doc__ = """An initial state of a contact batch: displacements and velocities (R, N) in the
contact level's layout, the largest force imbalance per realisation (N; not computed, NaN, for the
drawn start), the Newton iterations taken, and a failure message per realisation ('' where it holds)."""


def drawn_start(scene, jm: JointModel, joints: _Joints, reference: ReferenceMotion | None = None) -> StartState:
    """The drawn start (:func:`initial_state`) as a :class:`StartState`; refuses a scene that asks for
    another start, which :func:`.contact_start.contact_initial_state` makes."""
    if scene.simulation.contact_start != "drawn":
        raise ValueError(f"the scene's contact_start is {scene.simulation.contact_start!r}: pass "
                         "initial=rss6core.contact_start.contact_initial_state to simulate_contact")
    d, v = initial_state(scene, jm, joints, reference=reference)
    R = len(d)
    return StartState(d, v, np.full(R, np.nan), np.zeros(R, np.int64), [""] * R)


def simulate_contact(scene, draws, elements: int = 4, integrator: Integrator | None = None,
                     dt: float | None = None, output_step: float | None = None,
                     model: JointModel | None = None, chunk: int = 200,
                     divergence_limit: float = DIVERGENCE_LIMIT, settle: float | None = None,
                     stepper: type[ContactStepper] | None = None, tolerance: float | None = None,
                     refinements: int | None = None, initial=None, reference: ReferenceMotion | None = None,
                     laws: list[JointLaws] | None = None) -> ContactBatch:
    """Integrate the contact level for a batch of clearance draws (see :func:`_simulate_contact`).

    ``initial(scene, jm, joints, reference)`` makes the batch's :class:`StartState` (default
    :func:`drawn_start`; :func:`.contact_start.contact_initial_state` makes the scene's ``contact_start``).
    ``reference``: the rigid motion the batch perturbs (default: the scene's nominal one; a realised
    robot's under the nominal commands, whose geometric error the peaks then include; the histories
    are the perturbation alone).  ``laws``: each draw's friction and restitution per joint (default:
    the scene's).

    Overflow in a diverging realisation is detected and reported as its failure, not warned about.
    ``stepper`` runs the steps: :class:`CompiledStepper` (the default; numba, :mod:`.contact_kernel`) or
    :class:`.contact_numpy.NumpyStepper` (vectorised over the batch; about 10x slower, kept as the reference).
    """
    stepper = stepper or CompiledStepper
    if not (isinstance(stepper, type) and issubclass(stepper, ContactStepper)):
        raise ValueError(f"contact stepper must be a ContactStepper class (CompiledStepper, "
                         f"contact_numpy.NumpyStepper), not {stepper!r}")
    sim = scene.simulation
    tolerance = sim.contact_tolerance if tolerance is None else tolerance
    refinements = sim.contact_refinements if refinements is None else refinements
    if not tolerance >= 0.0:
        raise ValueError(f"contact error tolerance must be >= 0 m, got {tolerance!r}")
    if refinements not in range(MAX_CONTACT_REFINEMENTS + 1):
        raise ValueError(f"contact step refinements must be an integer in [0, {MAX_CONTACT_REFINEMENTS}], "
                         f"got {refinements!r}")
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        setup = dataclasses.replace(_setup(scene, draws, elements, integrator, dt, output_step, model,
                                           divergence_limit, settle, tolerance, refinements, laws),
                                    initial=initial or drawn_start, reference=reference or ReferenceMotion(scene))
        return _simulate_contact(setup, chunk, stepper)


@dataclass(frozen=True)
class _StepSize:
    """What one step length h needs: the condensed step matrix and the integrator's weights."""
    span: int              # fine-grid intervals per step
    cond: _Condensed
    coef_p: float          # weight of the platform mass in the step matrix
    weights: StepWeights   # predictor/corrector weights; weights.h the step, s
    error: float           # |beta - 1/6| h^2: Zienkiewicz-Xie local error per unit acceleration jump


@dataclass(frozen=True)
class _Setup:
    """An immutable description of one contact run: the model, the batch's joints, the step levels
    (0 the base step), the output grid and the limits."""
    scene: object
    jm: JointModel
    joints: _Joints
    integrator: Integrator
    sizes: tuple            # _StepSize per level
    t: np.ndarray           # base-step instants, s
    every: int              # base steps per output sample
    settle_at: float        # s: peaks from here on
    steady_at: float        # s: peaks of the steady window from here on, of the startup window before
    tolerance: float        # m, local error per step (0: refine only where Newton fails)
    limit: float            # m, divergence limit
    refinements: int
    initial: object = None  # (scene, jm, joints, reference) -> StartState: the batch's initial state
    reference: ReferenceMotion | None = None   # the rigid motion the batch perturbs

    @property
    def fine(self) -> int:
        return self.sizes[0].span

    @property
    def weighted(self) -> bool:
        return self.integrator.alpha_m != 0.0 or self.integrator.alpha_f != 0.0


def _setup(scene, draws, elements, integrator, dt, output_step, model, divergence_limit, settle,
           tolerance, refinements, laws=None) -> _Setup:
    sim = scene.simulation
    integrator = integrator or make_integrator(sim.contact_integrator, sim.newmark_beta,
                                               sim.newmark_gamma, sim.hht_alpha, sim.spectral_radius)
    jm = model or build_joint_model(scene, elements)
    h = sim.contact_time_step if dt is None else dt
    out = max(h, sim.time_step if output_step is None else output_step)
    every = int(round(out / h))
    if abs(every * h - out) > 1e-9 * out:
        raise ValueError(f"output step {out!r} s is not a multiple of the time step {h!r} s")
    lam1, lam2 = jm.mass_damping, jm.stiffness_damping
    sizes = []
    for level in range(refinements + 1):
        hl = h / 2 ** level
        cM, cC, cK = integrator.step_coefficients(hl)
        sizes.append(_StepSize(2 ** refinements >> level, _Condensed(jm, cM + cC * lam1, cC * lam2 + cK),
                               cM + cC * lam1, integrator.weights(hl),
                               abs(integrator.beta - 1.0 / 6.0) * hl * hl))
    settle_at = (sim.settle_time if settle is None else settle) - 1e-9 * h
    return _Setup(scene, jm, _joints(scene, draws, laws), integrator, tuple(sizes),
                  time_grid(scene.trajectory.duration, h), every, settle_at,
                  sim.steady_after - 1e-9 * h, float(tolerance),
                  float(divergence_limit), int(refinements))


class _Workspace:
    """The batch's state between steps (every array has the realisation axis first) and its records.

    d, v, a: displacements, velocities, accelerations (R, N); for the alpha-weighted integrators
    also M a and the force balance F + g - (C v + K d) at the last instant (R, N;
    :func:`.contact_kernel.balance_next`); a_past, h_past the accepted accelerations before a and
    their steps, for Newton's first iterate; coarsest the step-size memory (R,;
    :func:`.contact_kernel.coarsest_next`).
    """

    def __init__(self, R, N, n_out, floor):
        self.d = self.v = self.a = self.Ma = self.balance = None
        self.contacts = _Contacts((R,), floor)
        self.hist = np.full((3, R, n_out, 6), np.nan)
        self.peak = np.zeros((R, len(PEAK_WINDOWS), 3, 6))
        self.cpeak = np.zeros((R, 18))
        self.alive = np.ones(R, bool)
        self.status, self.message = [FINISHED] * R, [""] * R
        self.steps, self.iters = np.zeros(R, np.int64), np.zeros(R, np.int64)
        self.refined = np.zeros(R, np.int64)
        self.fail = np.zeros(R, np.int64)          # :mod:`.status` failure code
        self.fail_t, self.fail_h, self.fail_size = np.zeros(R), np.zeros(R), np.zeros(R)   # s, s, m
        self.a_past = np.zeros((R, 2, N))      # Newton's predictor: the two accelerations before a,
        self.h_past = np.zeros((R, 2))         # the steps between them (s; 0: not yet known)
        self.coarsest = np.zeros(R, np.int64)  # the coarsest level each realisation's next step may take

    def failed(self, r, code, t, h, size, limit):
        """Mark realisation r failed (``code`` from :mod:`.status`) in its next step, ending at t (s),
        of length h (s); size (m) its largest displacement."""
        self.alive[r] = False
        self.fail[r], self.fail_t[r], self.fail_h[r], self.fail_size[r] = code, t, h, size
        self.status[r] = FAILED
        self.message[r] = contact_failure(code, t, self.steps[r] + 1, h, size, limit, MAX_ITERATIONS)

    def history(self, k):
        """Keep the platform's error at output instant k for the realisations still alive."""
        live = self.alive
        self.hist[:, live, k] = np.stack([self.d[live, -6:], self.v[live, -6:], self.a[live, -6:]])

    def peaks(self, idx, window, d, v, a, f, offset):
        """Peaks of |platform error| (plus the reference's own ``offset`` (3, 6), as the compiled
        kernel's) in ``window`` (index into PEAK_WINDOWS) and of |contact force| of realisations idx
        updated with a step."""
        p = np.stack([d[..., -6:], v[..., -6:], a[..., -6:]], 1) + offset     # (R, 3, 6)
        self.peak[idx, window] = np.maximum(self.peak[idx, window], np.abs(p))
        mags = np.swapaxes(np.linalg.norm(f, axis=-1), -1, -2).reshape(len(idx), 18)
        self.cpeak[idx] = np.maximum(self.cpeak[idx], mags)

    def batch(self, t) -> ContactBatch:
        return ContactBatch(t, self.hist[0], self.hist[1], self.hist[2], self.peak, self.cpeak,
                            self.status, self.message, self.steps, self.iters, self.refined)


StepSolution = namedtuple("StepSolution", "a f g converged iterations delta rate impact")
StepSolution.__doc__ = """What Newton finds for a step of realisations (:meth:`ContactStepper._newton`, leading axis
R): accelerations a (R, N), contact forces f (R, 6, 3, 3) N, generalised contact forces g (R, N),
converged flags and iteration counts (R,), penetrations (m) and their rates (m/s) (R, 6, 4) ordered
[A radial, A axial, C, B], and the impact speeds used (m/s) (R, 6, 4)."""
JointSolution = namedtuple("JointSolution", "ab ap f gl gp converged iterations delta rate")
JointSolution.__doc__ = """Newton's result on the joint nodes (:meth:`ContactStepper._solve`): accelerations of the
joint nodes (R, 6, 12) and platform (R, 6), contact forces f (R, 6, 3, 3) N, generalised contact forces
on the joint nodes gl (R, 6, 12) and the platform gp (R, 6), converged flags and iteration counts (R,),
penetrations (m) and their rates (m/s) (R, 6, 4)."""
Progress = namedtuple("Progress", "t alive reason")
Progress.__doc__ = """How far :meth:`ContactStepper.advance` got: the time (s) the live realisations
reached (or the last failure's, when none is left), how many are alive, and why it stopped
(:data:`CHUNK_DONE` or :data:`ALL_FAILED`)."""
CHUNK_DONE, ALL_FAILED = "chunk done", "all failed"


class ContactStepper(abc.ABC):
    """The stepper contract of the contact level (in the spirit of SciPy's ``OdeSolver``): one object
    owns the batch's state and status; :meth:`start` sets the initial accelerations, :meth:`advance`
    carries every live realisation through a chunk of base steps and says how far it got and why it
    stopped, :meth:`batch` hands the results over.  :class:`.contact_numpy.NumpyStepper` is the readable
    reference, :class:`CompiledStepper` runs the same steps compiled (:mod:`.contact_kernel`)."""

    def __init__(self, setup: _Setup):
        self.setup = setup
        self.ws = _Workspace(len(setup.joints.radial), setup.jm.dofs, len(setup.t[::setup.every]),
                             setup.scene.contact.impact_speed_floor)

    def start(self):
        """The initial state (the setup's ``initial``) and its accelerations at t = 0, output sample 0."""
        su, ws = self.setup, self.ws
        ch = _Chunk(su.scene, su.jm, su.t[:1], su.reference)
        first = su.initial(su.scene, su.jm, su.joints, su.reference)
        ws.d, ws.v = first.d, first.v
        for r in np.flatnonzero([bool(m) for m in first.message]):
            ws.alive[r], ws.status[r], ws.message[r] = False, FAILED, first.message[r]
        everyone = np.arange(len(ws.d))
        rest = _internal(su.jm, ch.Mp[0], ws.d, ws.v)
        first = self._newton(everyone, ch, 0, _Condensed(su.jm, 1.0, 0.0), 1.0, ch.F[0] - rest, ws.d, ws.v,
                             np.zeros_like(ws.d), 0.0, 0.0, 1.0)
        ws.a = first.a
        ws.contacts.update(everyone, first.delta, first.rate, first.impact)
        ws.Ma, ws.balance = _mass(su.jm, ch.Mp[0], ws.a), ch.F[0] + first.g - rest
        if 0.0 >= su.settle_at:
            ws.peaks(everyone, int(0.0 >= su.steady_at), ws.d, ws.v, ws.a, first.f, ch.offset[0])
        ws.history(0)

    @abc.abstractmethod
    def advance(self, ch: _Chunk, first: int, n_base: int) -> Progress:
        """Base steps first .. first + n_base - 1 on the chunk ``ch`` (its instants on the finest grid,
        from the start of step ``first``)."""

    def batch(self) -> ContactBatch:
        return self.ws.batch(self.setup.t[::self.setup.every])

    def _progress(self, ch: _Chunk) -> Progress:
        alive = int(self.ws.alive.sum())
        if alive:
            return Progress(float(ch.t[-1]), alive, CHUNK_DONE)
        return Progress(float(self.ws.fail_t.max()), 0, ALL_FAILED)

    def _newton(self, idx, ch, j, cond, coef_p, rhs, dp, vp, a_guess, bh2, gh, wf) -> StepSolution:
        """Accelerations for a step of realisations ``idx`` at chunk instant j, with what comes with
        them (:class:`StepSolution`)."""
        jm = self.setup.jm
        rc, rr, rp = split(jm, rhs)
        rb, keep = cond.condense(rc, rr)
        db, dpp = _joint_nodes(jm, dp)
        vb, vpp = _joint_nodes(jm, vp)
        ab, ap = _joint_nodes(jm, a_guess)
        impact = self.ws.contacts.impact(idx)
        sy = System(Sl=cond.legs, Sp=coef_p * ch.Mp[j], impact=impact, rb=rb, rp=np.ascontiguousarray(rp),
                    db=db, dpp=np.ascontiguousarray(dpp), vb=vb, vpp=np.ascontiguousarray(vpp))
        sol = self._solve(idx, ch, j, sy, ab, ap.copy(), bh2, gh, wf)
        ac, ar = cond.recover(sol.ab, keep, rc.shape, rr.shape)
        gc, gr = _full_contact(jm, sol.gl, rc.shape, rr.shape)
        return StepSolution(a=join(ac, ar, sol.ap), f=sol.f, g=join(gc, gr, sol.gp), converged=sol.converged,
                            iterations=sol.iterations, delta=sol.delta, rate=sol.rate, impact=impact)

    @abc.abstractmethod
    def _solve(self, idx, ch, j, sy: System, ab, ap, bh2, gh, wf) -> JointSolution:
        """Newton on the joint nodes for realisations ``idx`` at chunk instant j (see
        :func:`.contact_kernel.newton_one`), from the first iterate ab, ap."""


FILL_STEPS = 8   # base steps whose interior instants a refined step's pause fills at once (impacts cluster)


class CompiledStepper(ContactStepper):
    """The same steps compiled (:func:`.contact_kernel.advance_chunk`), one realisation after another."""

    def __init__(self, setup: _Setup):
        super().__init__(setup)
        su, jm, it = setup, setup.jm, setup.integrator
        stack = [sz.cond.maps() for sz in su.sizes]
        per_level = {q: np.array([getattr(sz.weights, q) for sz in su.sizes])
                     for q in (f.name for f in dataclasses.fields(StepWeights))}
        self.levels = Levels(span=np.array([sz.span for sz in su.sizes], np.int64),
                             coef_p=np.array([sz.coef_p for sz in su.sizes]),
                             error=np.array([sz.error for sz in su.sizes]),
                             legs=np.stack([sz.cond.legs for sz in su.sizes]),
                             crank_T=np.stack([m[0][0] for m in stack]), crank_P=np.stack([m[0][1] for m in stack]),
                             rod_T=np.stack([m[1][0] for m in stack]), rod_P=np.stack([m[1][1] for m in stack]),
                             **per_level)
        self.layout = Layout(crank_dofs=int(jm.crank_dofs), crank_MK=np.concatenate([jm.crank_M, jm.crank_K]),
                             rod_MK=np.concatenate([jm.rod_M, jm.rod_K]), crank_M=np.ascontiguousarray(jm.crank_M),
                             rod_M=np.ascontiguousarray(jm.rod_M),
                             crank_boundary=jm.crank_boundary.astype(np.int64),
                             crank_interior=su.sizes[0].cond.crank[0].astype(np.int64))
        self.settings = Settings(mass_damping=float(jm.mass_damping), stiffness_damping=float(jm.stiffness_damping),
                                 alpha_m=float(it.alpha_m), alpha_f=float(it.alpha_f),
                                 settle_at=float(su.settle_at), steady_at=float(su.steady_at),
                                 impact_floor=float(su.scene.contact.impact_speed_floor), tolerance=su.tolerance,
                                 divergence_limit=su.limit, tol_d=float(TOL_DISPLACEMENT),
                                 tol_v=float(TOL_VELOCITY), max_iterations=int(MAX_ITERATIONS),
                                 refinements=su.refinements)
        self.scratch = make_scratch()
        self.work = None

    def _joints_of(self, idx) -> Joints:
        j, law, su = self.setup.joints, self.setup.scene.contact, self.setup
        return Joints(size=np.ascontiguousarray(np.stack([j.radial, j.size_C, j.size_B], -1)[idx]),
                      axial=np.ascontiguousarray(j.axial[idx]),
                      stiffness=np.ascontiguousarray(np.stack([j.k_A, j.k_C, j.k_B], -1)[idx]),
                      mu=np.ascontiguousarray(j.mu[idx], dtype=float),
                      restitution=np.ascontiguousarray(j.restitution[idx], dtype=float),
                      w=np.ascontiguousarray(su.scene.geometry.w, dtype=float),
                      radius=np.array([law.journal_radius, law.sphere_radius, law.sphere_radius], float),
                      law=Law(exponent=float(law.exponent), v0=float(law.stick_velocity),
                              v1=float(law.slip_velocity)))

    def _solve(self, idx, ch, j, sy, ab, ap, bh2, gh, wf):
        R = ab.shape[0]
        out = Out(f=np.empty((R, 6, 3, 3)), gl=np.empty((R, 6, 12)), gp=np.empty((R, 6)),
                  delta=np.empty((R, 6, 4)), rate=np.empty((R, 6, 4)))
        done, count = np.zeros(R, np.bool_), np.zeros(R, np.int64)
        with kernel_compiling():
            newton_step(Frame(Rc=ch.Rc[j], J=ch.J[j], Rr=ch.Rr[j], omega=ch.omega[j]), self._joints_of(idx), sy, ab,
                        ap, float(bh2), float(gh), float(wf), self.settings, out, done, count, self.scratch)
        return JointSolution(ab=ab, ap=ap, f=out.f, gl=out.gl, gp=out.gp, converged=done, iterations=count,
                             delta=out.delta, rate=out.rate)

    def advance(self, ch: _Chunk, first: int, n_base: int) -> Progress:
        ws, lv = self.ws, self.levels
        if self.work is None:
            N, nc = ws.d.shape[1], self.layout.crank_dofs
            self.work = make_work(N, nc, (N - 6) // 6 - nc, lv.crank_T.shape[2] - 6, lv.rod_T.shape[2] - 6)
        before = ws.alive.copy()
        state = State(d=ws.d, v=ws.v, a=ws.a, Ma=ws.Ma, balance=ws.balance, stored=ws.contacts.stored,
                      in_contact=ws.contacts.in_contact, crate=ws.contacts.rate, a_past=ws.a_past,
                      h_past=ws.h_past, coarsest=ws.coarsest)
        records = Records(peak=ws.peak, cpeak=ws.cpeak, hist=ws.hist, alive=ws.alive, fail=ws.fail,
                          fail_t=ws.fail_t, fail_h=ws.fail_h, fail_size=ws.fail_size, steps=ws.steps,
                          iters=ws.iters, refined=ws.refined)
        live, arrays, joints = np.flatnonzero(ws.alive), ch.arrays(), self._joints_of(slice(None))
        begin, pause = np.zeros(len(ws.alive), np.int64), np.full(2, -1, np.int64)
        while True:
            with kernel_compiling():
                advance_chunk(live, first, n_base, self.setup.every, lv, self.layout, self.settings, arrays,
                              joints, state, records, self.work, self.scratch, begin, pause)
            if pause[0] < 0:
                break
            r, step = int(pause[0]), int(pause[1])     # r needs step's interior instants: fill a few steps
            ch.fill(np.arange(step, min(step + FILL_STEPS, n_base)))
            live, begin[:], begin[r] = live[np.searchsorted(live, r):], 0, step
        for r in np.flatnonzero(before & ~ws.alive):
            ws.failed(r, ws.fail[r], ws.fail_t[r], ws.fail_h[r], ws.fail_size[r], self.setup.limit)
        return self._progress(ch)


def _simulate_contact(setup: _Setup, chunk: int, stepper) -> ContactBatch:
    """Integrate the contact level for a batch of clearance draws (one realisation each).

    ``dt`` is the base step and ``integrator`` the method (default: the scene's
    contact time step and contact integrator).  With ``refinements`` > 0 a step
    is retried as two half steps, down to dt / 2**refinements, where Newton fails
    or the Zienkiewicz-Xie estimate |beta - 1/6| h^2 |delta a| of the local error
    of a joint's relative displacement exceeds ``tolerance`` m (0: only where Newton
    fails): impacts are resolved where they happen, each realisation on its own.
    Histories are kept every ``output_step`` (default: the scene's time step);
    peaks are taken over every internal step from ``settle`` s on (default: the
    scene's settle time, the start-up transient left out).  A realisation whose Newton
    iteration fails at the finest step or whose state diverges is marked failed; the others go on.
    """
    stepper = stepper(setup)
    stepper.start()
    t, fine, h = setup.t, setup.fine, setup.sizes[0].weights.h
    for s0 in range(1, len(t), chunk):
        s1 = min(s0 + chunk, len(t))
        # the chunk's instants on the finest grid, from the start of its first step
        ch = _Chunk(setup.scene, setup.jm, ((s0 - 1) * fine + np.arange((s1 - s0) * fine + 1)) * (h / fine),
                    setup.reference, fine)
        if stepper.advance(ch, s0, s1 - s0).reason == ALL_FAILED:
            break
    return stepper.batch()


def _full_contact(jm: JointModel, gl, shape_c, shape_r):
    """Generalised contact forces on the joint nodes spread into full link vectors."""
    gc, gr = np.zeros(shape_c), np.zeros(shape_r)
    gc[..., jm.crank_boundary] = gl[..., :6]
    gr[..., -6:] = gl[..., 6:]
    return gc, gr
