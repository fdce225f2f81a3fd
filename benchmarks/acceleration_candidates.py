"""Issue 43's candidate causes, each as a switch on issue 43's case (docs/accelerations.md).

The case: configs/paper.toml with settle_time_s = 0.3, contact level, realisation 0 of seed 0,
drawn start; maxima of |acceleration error| over t >= 0.3 s on the 1 ms output grid (m/s^2,
rad/s^2), with the displacement maxima (mm) and mean |velocity error| beside them.

The switches run on the numpy stepper (rss6core/contact_numpy.py, the compiled kernel's
reference), as a measurement, not yet a formulation of the product:

- ``moments``: the spherical joints' friction moments.  rss6 applies the friction force at the
  joint centre; at the contact point, R n from the centre of the element whose angular velocity
  enters the sliding velocity with a plus sign, it also applies R n x f_t to that element and
  -R n x f_t to the other (the moment conjugate to the relative rotation in the friction's power,
  f_t . (de + R omega x n) = f_t . de + omega . (R n x f_t)).  C: rod end (bending rotations;
  rss6 drops rod torsion, so the moment's axial part is lost) and crank tip; B: rod end and
  platform.  Lagged: each step takes the last accepted step's forces and normals.
- ``rates``: the sliding velocity with the joint nodes' elastic rotation rates added to the
  ideal relative rotation (last accepted velocities).
- ``C`` / ``B``: the moments at one joint family only.
- ``spin-inertia``: each rod's spin about its own axis (rss6 drops rod torsion and with it the
  spin), advanced by backward Euler under the axial friction moments of its two spherical joints
  (:func:`spin_step`) and added to the sliding velocity at C and B; ``spin`` the same without the
  rod's polar inertia (the rates at which the two moments balance); ``spin-moments``,
  ``spin-inertia-moments`` with the friction moments; ``all``: spin with inertia, moments, rates.

``frame``, ``stiffening``, ``nonlinear`` (candidate 1, the small-displacement linearisation): the terms a
geometrically nonlinear (co-rotational, to second order) link formulation adds to the linear KED, on cranks and
rods, lagged from the last accepted step's displacements and velocities like the others.  ``frame``: the
frame-motion inertia of the elastic motion, -M (2 Omega~ q' + (Omega~' + Omega~^2) q) in each link frame
(:func:`rss6core.assembly.frame_inertia_load`; Omega from the link frames by central differences,
:func:`frame_rates`).  ``stiffening``: -K_G(N) q, each element's consistent geometric stiffness
(:func:`rss6core.beam.geometric_stiffness`) under its axial force N = EA du / l from its current axial strain
(:func:`axial_forces`); the centrifugal axial force of the link's rotation is already in N, since the rigid-body
loads (centrifugal ones included) stretch the links' elastic axial DOFs.  ``nonlinear``: both.  ``chord`` and
``bending`` split ``stiffening`` into the axial force turned with each element's chord rotation
(:func:`chord_load`, +-N phi on its end nodes) and the rest (the bending stiffening proper).  Checks:
``nonlinear-zero`` (scale 0, must print plain's numbers), ``nonlinear-1e-3`` and ``nonlinear-0.1`` (the loads
scaled).  Verified on the rotating cantilever (tests/test_rotating_beam.py).

``--contact FIELD=VALUE`` changes one of the scene's contact-law parameters (the compiled kernel's
``plain`` run measures the law's own sensitivity).

``motor=K`` (candidate 3): the compiled kernel on the contact level whose cranks are driven through a
compliant motor of stiffness K N m/rad (:func:`rss6core.contact_dynamics.build_joint_model`'s
``motor_stiffness``: node 0's rotation about the motor axis a DOF on a torsional spring K, plus the rigid
robot's feed-forward torque); its row also prints the rigid crank's frequency on that spring,
sqrt(K / J_A) / 2 pi.  ``--numpy`` runs it on the numpy stepper instead (the kernel's check).
``motor-friction=K`` (numpy stepper): the same motor with the actuated joint's friction moment about
the motor axis, w . (R n x f_t) (:func:`journal_friction_torque`; R the journal radius, n the radial
normal, f_t the friction on the journal), applied lagged to the released rotation, which the clamped
crank's rotation absorbs.

    python benchmarks/acceleration_candidates.py [--half-step] [--realization K] [--contact FIELD=VALUE]
        [--scale] [SWITCH ...]

SWITCH in: plain (the compiled kernel), zero (the moments at scale 0: must print plain's numbers),
moments, rates, both, C, B, spin, spin-moments, spin-inertia, spin-inertia-moments, all, frame, stiffening,
nonlinear, chord, bending, nonlinear-zero, nonlinear-1e-3, nonlinear-0.1, spin-inertia-moments-nonlinear,
all-nonlinear (``all`` and ``spin-inertia-moments`` with ``nonlinear``), motor=K, motor-friction=K.  Each numpy
run takes 20-220 s on the shared 2-core machine (about twice that with --half-step).
"""
import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from rss6core.assembly import frame_inertia_load, join, link_frames, split
from rss6core.beam import geometric_stiffness
from rss6core.clearance import draw_clearances
from rss6core.contact_dynamics import _joint_nodes, _relative, build_joint_model, simulate_contact
from rss6core.contact_numpy import NumpyStepper
from rss6core.kinematics import rigid_motion
from rss6core.models import prepare_level
from rss6core.scene import load_scene
from rss6core.sections import crank_inertia, crank_on_motor_frequency, section_properties

SCENE = Path(__file__).resolve().parents[1] / "configs" / "paper.toml"
SETTLE = 0.3   # s, issue 43's window start
FRAME_STEP = 1e-4   # s, the central differences of the link frames' rates (error ~ (4 rad/s FRAME_STEP)^2)


def _to_local(R, m):
    """R^T m per leg: base-frame vectors m (..., 6, 3) into the link frames R (6, 3, 3)."""
    return np.einsum("lab,...la->...lb", R, m)


def _spin_inertia(scene) -> float:
    """A rod's moment of inertia about its own axis, rho J_p L (kg m^2)."""
    rod = scene.rod_section
    return scene.material.density * np.pi / 32 * (rod.outer_diameter ** 4 - rod.inner_diameter ** 4) \
        * scene.geometry.rod_length


def friction(contact, normal, force, de, omega, radius):
    """Modified Coulomb friction (eq. 18) (..., 3) on the + element of a pair in contact with normal
    force ``force`` (...) N along -``normal``, relative velocity de (m/s) and relative rotation omega
    (rad/s), sliding at R n (``radius`` R, m); ``contact`` the scene's [contact] laws."""
    v = de + radius * np.cross(omega, normal)
    v = v - (v * normal).sum(-1, keepdims=True) * normal
    speed = np.linalg.norm(v, axis=-1, keepdims=True)
    ramp = np.clip((speed - contact.stick_velocity) / (contact.slip_velocity - contact.stick_velocity), 0.0, 1.0)
    return -contact.friction_coefficient * force[..., None] * ramp * v / np.maximum(speed, 1e-300)


def friction_moment(radius, normal, force):
    """R n x f_t (..., 3) N m: the moment about its centre of a pair force ``force`` (..., 3) N acting on
    the + element at its contact point R n (``radius`` R, m; ``normal`` n unit); only the tangential
    (friction) part has one.  With the relative rotation omega it carries the friction's power:
    f_t . (de + R omega x n) = f_t . de + omega . (R n x f_t)."""
    tangential = force - (force * normal).sum(-1, keepdims=True) * normal
    return radius * np.cross(normal, tangential)


def journal_friction_torque(radius, normal, force, axis):
    """w . (R n x f) (...) N m: the moment about the motor ``axis`` w (..., 3) of the actuated joint's
    force ``force`` (..., 3) N on the journal, at its contact point R n (``radius`` R, m; ``normal`` n,
    the radial normal, unit, normal to w).  Only the friction has one: the radial normal force is
    along n and the axial faces' force along w, both with no moment about w."""
    return (friction_moment(radius, normal, force) * axis).sum(-1)


def spin_step(contact, last, h, inertia, normal, force, de, omega, axis, radius):
    """The rods' spin rates (6,) rad/s after a step of h (s) from ``last``: J (s - last) / h = the axial
    friction moments a . (R n x f) of each rod's two spherical joints (backward Euler; ``inertia`` J
    = 0: the rates at which the moments balance), f = :func:`friction` with the rod turning at s about
    its ``axis`` (6, 3) on top of the ideal relative rotations ``omega`` (6, 2, 3); ``normal``,
    ``de`` (6, 2, 3) and ``force`` (6, 2) of joints C and B.  Bisection: the moments fall as s grows.
    A rod touching neither socket keeps its rate."""
    def residual(s):
        f = friction(contact, normal, force, de, omega + s[:, None, None] * axis[:, None], radius)
        return (np.cross(radius * normal, f) * axis[:, None]).sum((-1, -2)) - inertia * (s - last) / h

    low, high = last - 1e3, last + 1e3
    for _ in range(60):
        mid = 0.5 * (low + high)
        up = residual(mid) > 0.0
        low, high = np.where(up, mid, low), np.where(up, high, mid)
    return np.where((force <= 0).all(-1), last, 0.5 * (low + high))


def frame_rates(reference, geometry, t):
    """Om = R^T R' (1/s) and its rate Om' = R'^T R' + R^T R'' (1/s^2), (2, 6, 3, 3) each, crank then rod, of the
    link frames (:func:`rss6core.assembly.link_frames`) of ``reference``'s motion at t (s): central
    differences over FRAME_STEP."""
    R_minus, R, R_plus = (np.stack(link_frames(reference.at(np.array([t + s])).motion, geometry))[:, 0]
                          for s in (-FRAME_STEP, 0.0, FRAME_STEP))
    rate = (R_plus - R_minus) / (2 * FRAME_STEP)
    curvature = (R_plus - 2 * R + R_minus) / FRAME_STEP ** 2
    T = np.swapaxes
    return T(R, -1, -2) @ rate, T(rate, -1, -2) @ rate + T(R, -1, -2) @ curvature


def axial_forces(q, axial_stiffness, length):
    """N = EA (u_{e+1} - u_e) / l (..., n) N of each element from a link's full nodal vector q (..., 6(n+1))
    (local axes; tension > 0); ``axial_stiffness`` EA (N), ``length`` the element's l (m)."""
    return axial_stiffness * np.diff(q[..., 0::6], axis=-1) / length


def link_axial_forces(scene, elements: int, q):
    """Per link kind (0 crank, 1 rod, as :meth:`Switched._links_full` stacks q): its index, section
    properties, element length l (m) and elements' axial forces N (..., n) N (:func:`axial_forces`)."""
    for link, (section, length) in enumerate(((scene.crank_section, scene.geometry.crank_length),
                                              (scene.rod_section, scene.geometry.rod_length))):
        props, l = section_properties(section), length / elements
        yield link, props, l, axial_forces(q[link], scene.material.youngs_modulus * props.area, l)


def geometric_load(q, N, length, props):
    """-K_G(N) q (..., 6(n+1)): each element's geometric stiffness (:func:`rss6core.beam.geometric_stiffness`,
    elements of ``length`` l, m) under its axial force N (..., n) N on a link's full nodal vector q, as a load
    (N, N m)."""
    g = geometric_stiffness(props, length)
    out = np.zeros(q.shape)
    for e in range(N.shape[-1]):
        out[..., 6 * e:6 * e + 12] -= N[..., e, None] * (q[..., 6 * e:6 * e + 12] @ g)
    return out


def chord_load(q, N, length):
    """The part of -K_G(N) q (:func:`geometric_load`) that an element's rigid chord rotation phi = (v2 - v1) / l
    gives (..., 6(n+1)): +N phi on its first node's transverse translation, -N phi on its second, in both
    bending planes (the axial force turned with the chord, to first order; the rest is the bending stiffening)."""
    out = np.zeros(q.shape)
    for transverse in (1, 2):
        force = N * np.diff(q[..., transverse::6], axis=-1) / length
        out[..., transverse:-6:6] += force
        out[..., 6 + transverse::6] -= force
    return out


class Switched(NumpyStepper):
    """The numpy stepper with issue 43's lagged switches (class attributes, set by :func:`stepper`)."""
    moments, rates, spin, inertia, scale, joints, journal = False, False, False, False, 1.0, (1, 2), False
    frame, stiffening, geometric_scale, part = False, False, 1.0, "all"

    def _links_full(self, x):
        """Crank and rod full nodal vectors (R, 6, 6(n+1)), link frames, of system vectors x (R, N)."""
        jm = self.setup.jm
        c, r, _ = split(jm, x)
        full = np.zeros((2,) + r.shape[:-1] + (6 * jm.elements + 6,))
        full[0][..., jm.crank_keep] = c
        full[1][..., jm.elastic.rod_order] = r
        return full

    def _geometric(self, idx, ch, k1):
        """Generalised forces (R, N) of the geometrically nonlinear terms switched on (``frame``: the frame-motion
        inertia of the elastic motion, :func:`rss6core.assembly.frame_inertia_load`; ``stiffening``: -K_G(N) q,
        :func:`geometric_load`), on cranks and rods, from the last accepted state."""
        jm, ws, scene = self.setup.jm, self.ws, self.setup.scene
        out = np.zeros((len(idx), ws.d.shape[-1]))
        if not (self.frame or self.stiffening):
            return out
        if jm.crank_basis is not None:
            raise ValueError("the geometric switches address nodal DOFs: run them on the full mesh")
        q, q_dot = self._links_full(ws.d[idx]), self._links_full(ws.v[idx])
        em, load = jm.elastic, np.zeros(q.shape)
        if self.frame:
            cache = ch.__dict__.setdefault("frame_rates", {})
            if k1 not in cache:
                cache[k1] = frame_rates(ch.reference, scene.geometry, ch.t[k1])
            Om, Om_dot = cache[k1]
            for link, M in enumerate((em.crank_M_full, em.rod_M_full)):
                load[link] += frame_inertia_load(M, q[link], q_dot[link], Om[link], Om_dot[link])
        if self.stiffening:
            for link, props, l, N in link_axial_forces(scene, jm.elements, q):
                if self.part == "chord":
                    load[link] += chord_load(q[link], N, l)
                    continue
                load[link] += geometric_load(q[link], N, l, props)
                if self.part == "bending":
                    load[link] -= chord_load(q[link], N, l)
        load *= self.geometric_scale
        return join(load[0][..., jm.crank_keep], load[1][..., em.rod_order], out[..., -6:])

    def _journal_friction(self, idx, ch, k1):
        """Generalised forces (R, N) of the actuated joints' friction moments about the motor axes on the
        released crank rotations (:func:`journal_friction_torque`), at the last accepted state."""
        jm, ws = self.setup.jm, self.ws
        out = np.zeros((len(idx), ws.d.shape[-1]))
        if not self.journal or not hasattr(ws, "f_last"):
            return out
        if jm.motor_dof is None:
            raise ValueError("the journal friction switch needs a crank on a motor (motor_stiffness)")
        w = self.setup.scene.geometry.w                                   # (6, 3) crank-frame y, base frame
        e = _relative(ch, k1, *_joint_nodes(jm, ws.d[idx]))[:, :, 0]        # (R, 6, 3) e_A
        radial = e - (e * w).sum(-1, keepdims=True) * w
        normal = radial / np.maximum(np.linalg.norm(radial, axis=-1, keepdims=True), 1e-300)
        radius = float(np.asarray(ch.radius).reshape(-1)[0])
        split(jm, out)[0][..., jm.motor_dof] = journal_friction_torque(radius, normal, ws.f_last[idx][:, :, 0], w)
        return out

    def _rod_spin(self, idx, ch, k1, h):
        """The rods' spin rates (6,) over a step of h (s) from the last accepted state (:func:`spin_step`;
        normal forces, normals and relative velocities lagged)."""
        jm, ws, scene = self.setup.jm, self.ws, self.setup.scene
        if len(idx) != 1:
            raise ValueError("the spin switch runs one realisation at a time")
        last = getattr(ws, "spin_last", np.zeros(6))
        if not hasattr(ws, "f_last"):
            ws.spin_try = last
            return last
        e = _relative(ch, k1, *_joint_nodes(jm, ws.d[idx[0]]))[:, 1:]
        de = _relative(ch, k1, *_joint_nodes(jm, ws.v[idx[0]]))[:, 1:]
        normal = e / np.maximum(np.linalg.norm(e, axis=-1, keepdims=True), 1e-300)
        force = np.maximum(-(ws.f_last[idx[0]][:, 1:] * normal).sum(-1), 0.0)     # (6, 2) C, B
        ws.spin_try = spin_step(scene.contact, last, h, _spin_inertia(scene) if self.inertia else 0.0, normal,
                                force, de, ch.omega_ideal[k1][:, 1:], ch.Rr[k1][:, :, 0],
                                float(np.asarray(ch.radius).reshape(-1)[1]))
        return ws.spin_try

    def _friction_moments(self, idx, ch, k1):
        """Generalised forces (R, N) of the friction moments at the last accepted state."""
        jm, ws = self.setup.jm, self.ws
        out = np.zeros((len(idx), ws.d.shape[-1]))
        if not self.moments or not hasattr(ws, "f_last"):
            return out
        e = _relative(ch, k1, *_joint_nodes(jm, ws.d[idx]))
        c, r, p = split(jm, out)
        n, radius, tip = jm.elements, np.asarray(ch.radius).reshape(-1), jm.crank_boundary[-1] + 1
        for j in self.joints:
            normal = e[:, :, j] / np.maximum(np.linalg.norm(e[:, :, j], axis=-1, keepdims=True), 1e-300)
            m = self.scale * friction_moment(radius[j], normal, ws.f_last[idx][:, :, j])
            rod = _to_local(ch.Rr[k1], m)[..., 1:3]          # bending rotations only
            if j == 1:
                r[..., 0:2] += rod
                c[..., tip:tip + 3] -= _to_local(ch.Rc[k1], m)       # the tip node's rotations
            else:
                r[..., 5 * n - 3:5 * n - 1] += rod
                p[..., 3:] -= m.sum(1)
        return join(c, r, p)

    def _sliding_rotation(self, idx, ch, k1, h):
        """ch.omega[k1]: the ideal relative rotations plus, as switched on, the joint nodes' elastic
        rotation rates and the rods' spin."""
        if len(idx) != 1:
            raise ValueError("the rates and spin switches run one realisation at a time")
        if not hasattr(ch, "omega_ideal"):
            ch.omega_ideal = ch.omega.copy()
        ch.omega[k1] = ch.omega_ideal[k1]
        if self.rates:
            c, r, p = split(self.setup.jm, self.ws.v[idx[0]])
            n, Rc, Rr = self.setup.jm.elements, ch.Rc[k1], ch.Rr[k1]
            t0 = self.setup.jm.crank_boundary[-1] + 1
            tip = np.einsum("lab,lb->la", Rc, c[:, t0:t0 + 3])
            ch.omega[k1, :, 1] += np.einsum("lab,lb->la", Rr[:, :, 1:3], r[:, 0:2]) - tip
            ch.omega[k1, :, 2] += np.einsum("lab,lb->la", Rr[:, :, 1:3], r[:, 5 * n - 3:5 * n - 1]) - p[None, 3:]
        if self.spin:
            spin = self._rod_spin(idx, ch, k1, h)[:, None] * ch.Rr[k1][:, :, 0]
            ch.omega[k1, :, 1] += spin
            ch.omega[k1, :, 2] += spin

    def _step_loads(self, idx, ch, k1, h):
        """The rigid-body loads plus the friction moments; first, as switched on, the sliding velocity's
        rotations of this attempt (:meth:`_sliding_rotation`), which its Newton iteration then reads."""
        if self.rates or self.spin:
            self._sliding_rotation(idx, ch, k1, h)
        return (ch.F[k1] + self._friction_moments(idx, ch, k1) + self._journal_friction(idx, ch, k1)
                + self._geometric(idx, ch, k1))

    def _keep(self, kept, ch, k1, h, a, d, v, f, delta, rate, used):
        super()._keep(kept, ch, k1, h, a, d, v, f, delta, rate, used)
        if not hasattr(self.ws, "f_last"):
            self.ws.f_last = np.zeros((len(self.ws.d),) + f.shape[1:])
        self.ws.f_last[kept] = f
        if self.spin:
            self.ws.spin_last = self.ws.spin_try


SWITCHES = {"plain": None, "zero": dict(moments=True, scale=0.0), "moments": dict(moments=True),
            "rates": dict(rates=True), "both": dict(moments=True, rates=True),
            "C": dict(moments=True, joints=(1,)), "B": dict(moments=True, joints=(2,)),
            "spin": dict(spin=True), "spin-moments": dict(spin=True, moments=True),
            "spin-inertia": dict(spin=True, inertia=True),
            "spin-inertia-moments": dict(spin=True, inertia=True, moments=True),
            "all": dict(spin=True, inertia=True, moments=True, rates=True),
            "frame": dict(frame=True), "stiffening": dict(stiffening=True),
            "nonlinear": dict(frame=True, stiffening=True),
            "nonlinear-zero": dict(frame=True, stiffening=True, geometric_scale=0.0),
            "nonlinear-1e-3": dict(frame=True, stiffening=True, geometric_scale=1e-3),
            "nonlinear-0.1": dict(frame=True, stiffening=True, geometric_scale=0.1),
            "chord": dict(stiffening=True, part="chord"), "bending": dict(stiffening=True, part="bending"),
            "spin-inertia-moments-nonlinear": dict(spin=True, inertia=True, moments=True, frame=True, stiffening=True),
            "all-nonlinear": dict(spin=True, inertia=True, moments=True, rates=True, frame=True, stiffening=True)}


def stepper(name):
    """The stepper class of switch ``name`` (None: the compiled kernel)."""
    return None if SWITCHES[name] is None else type(name, (Switched,), SWITCHES[name])


def motor_stiffness(name):
    """K (N m/rad) of switch ``motor=K``, or None for any other switch."""
    head, _, value = name.partition("=")
    if head not in ("motor", "motor-friction"):
        return None
    try:
        k = float(value)
    except ValueError:
        raise ValueError(f"switch {name!r}: {head}=K needs a stiffness K in N m/rad, e.g. {head}=1e4") from None
    if not k > 0.0:
        raise ValueError(f"switch {name!r}: the motor stiffness must be > 0 N m/rad")
    return k


def run(scene, name, realization=0, numpy=False):
    """The case under switch ``name`` (``numpy``: a motor=K switch on the numpy stepper): maxima and means
    over t >= SETTLE, and the wall time."""
    if scene.beam.link_modes:
        raise ValueError("the switches address nodal DOFs: run them on the full mesh ([beam] link_modes = 0)")
    level = prepare_level(scene, "contact")
    k_m = motor_stiffness(name)
    model = None if k_m is None else build_joint_model(scene, level.elements, motor_stiffness=k_m)
    steps = (NumpyStepper if numpy else None) if k_m is not None else stepper(name)
    if name.startswith("motor-friction="):
        steps = type("motor-friction", (Switched,), dict(journal=True))
    start = time.perf_counter()
    b = simulate_contact(scene, [draw_clearances(scene, 0, realization)], level.elements, level.integrator,
                         level.dt, model=model, stepper=steps)
    inside = b.t >= SETTLE - 1e-12
    return dict(acceleration=np.abs(b.acceleration[0, inside]).max(0),
                displacement=np.abs(b.displacement[0, inside]).max(0),
                velocity=np.abs(b.velocity[0, inside]).mean(0),
                status=b.status[0], wall=time.perf_counter() - start)


def linearisation_scale(scene):
    """Candidate 1's size on the case: the rods' largest joint force over their Euler load, and the
    largest crank rate over the links' first bending frequencies, squared (closed-form beams)."""
    level = prepare_level(scene, "contact")
    b = simulate_contact(scene, [draw_clearances(scene, 0, 0)], level.elements, level.integrator, level.dt)
    mat, rod, crank = scene.material, scene.rod_section, scene.crank_section
    E, rho, L = mat.youngs_modulus, mat.density, scene.geometry.rod_length
    inertia = np.pi / 64 * (rod.outer_diameter ** 4 - rod.inner_diameter ** 4)
    area = np.pi / 4 * (rod.outer_diameter ** 2 - rod.inner_diameter ** 2)
    euler = np.pi ** 2 * E * inertia / L ** 2                         # N, pinned-pinned
    rod_f1 = np.pi / (2 * L ** 2) * np.sqrt(E * inertia / (rho * area))   # Hz, pinned-pinned
    Lc, h = scene.geometry.crank_length, crank.height
    crank_f1 = 1.875 ** 2 / (2 * np.pi) * np.sqrt(E * h ** 2 / 12 / (rho * Lc ** 4))   # Hz, clamped-free
    rate = np.abs(rigid_motion(scene).alpha_dot).max()
    print(f"largest C or B joint force {b.contact_peak[0, 6:].max():.3g} N = {b.contact_peak[0, 6:].max() / euler:.2g} "
          f"of the rod's Euler load {euler:.4g} N; largest crank rate {rate:.3g} rad/s; (rate / 2 pi f1)^2: "
          f"rod {(rate / (2 * np.pi * rod_f1)) ** 2:.2g} (f1 {rod_f1:.4g} Hz), crank "
          f"{(rate / (2 * np.pi * crank_f1)) ** 2:.2g} (f1 {crank_f1:.4g} Hz)")


class _Sizes(Switched):
    """The numpy stepper recording candidate 1's sizes at every attempt (loads not applied): per link kind
    [crank, rod], the largest |N| (N), |element chord rotation| (rad) and |-K_G(N) q| (N, N m)."""
    sizes = None

    def _geometric(self, idx, ch, k1):
        jm, scene, q = self.setup.jm, self.setup.scene, self._links_full(self.ws.d[idx])
        for link, props, l, N in link_axial_forces(scene, jm.elements, q):
            chord = np.abs(np.diff(q[link][..., 1::6], axis=-1)) + np.abs(np.diff(q[link][..., 2::6], axis=-1))
            now = [np.abs(N).max(), chord.max() / l, np.abs(geometric_load(q[link], N, l, props)).max()]
            self.sizes[link] = np.maximum(self.sizes[link], now)
        return np.zeros((len(idx), self.ws.d.shape[-1]))


def geometric_sizes(scene):
    """Print candidate 1's sizes on the case (:class:`_Sizes`, the plain run's states)."""
    level = prepare_level(scene, "contact")
    _Sizes.sizes = np.zeros((2, 3))
    simulate_contact(scene, [draw_clearances(scene, 0, 0)], level.elements, level.integrator, level.dt,
                     stepper=_Sizes)
    for name, (N, chord, load) in zip(("crank", "rod"), _Sizes.sizes):
        print(f"{name}: largest axial force {N:.3g} N, element chord rotation <= {chord:.2g} rad (|v| + |w| "
              f"differences / l), largest |K_G(N) q| {load:.2g} N or N m")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("switches", nargs="*", help=f"any of {', '.join(SWITCHES)} (default: all)")
    p.add_argument("--half-step", action="store_true", help="half the scene's contact step")
    p.add_argument("--contact", action="append", default=[], metavar="FIELD=VALUE",
                   help="a [contact] law field (rss6core ContactLaw name, e.g. slip_velocity=1e-3), repeatable")
    p.add_argument("--realization", type=int, default=0, help="realisation of seed 0 (default 0, the case's)")
    p.add_argument("--scale", action="store_true", help="print candidate 1's size (linearisation) first")
    p.add_argument("--numpy", action="store_true", help="run the motor=K switches on the numpy stepper")
    args = p.parse_args(argv)
    unknown = sorted(n for n in set(args.switches) - set(SWITCHES) if not n.startswith(("motor=", "motor-friction=")))
    if unknown:
        p.error(f"unknown switch {unknown[0]!r}; choose from {', '.join(SWITCHES)}, motor=K, motor-friction=K")
    try:
        [motor_stiffness(n) for n in args.switches]
    except ValueError as error:
        p.error(str(error))
    scene = load_scene(SCENE)
    sim = dataclasses.replace(scene.simulation, settle_time=SETTLE,
                              contact_time_step=scene.simulation.contact_time_step * (0.5 if args.half_step else 1))
    law = {}
    for item in args.contact:
        field, _, value = item.partition("=")
        if field not in {f.name for f in dataclasses.fields(scene.contact)}:
            p.error(f"--contact {item}: no [contact] law field {field!r}")
        law[field] = float(value)
    scene = dataclasses.replace(scene, simulation=sim, contact=dataclasses.replace(scene.contact, **law))
    laws = "".join(", " + c for c in args.contact)
    print(f"issue 43's case, contact step {sim.contact_time_step:g} s{laws}; max |acceleration| x y z m/s^2, "
          f"rx ry rz rad/s^2 | max |displacement| x y z mm | mean |velocity| x y z mm/s, rx ry rz mrad/s")
    if args.scale:
        linearisation_scale(scene)
        geometric_sizes(scene)
    J_A = crank_inertia(scene).inertia[1]
    if any(motor_stiffness(n) for n in args.switches):
        print(f"crank J_A {J_A:.4g} kg m^2; a position loop of 50-200 Hz on it: k_m = (2 pi f)^2 J_A = "
              f"{(2 * np.pi * 50) ** 2 * J_A:.3g}-{(2 * np.pi * 200) ** 2 * J_A:.3g} N m/rad")
    for name in args.switches or list(SWITCHES):
        r, k_m = run(scene, name, args.realization, args.numpy), motor_stiffness(name)
        print(f"{name:8s} " + " ".join(f"{x:.4g}" for x in r["acceleration"])
              + " | " + " ".join(f"{1e3 * x:.4g}" for x in r["displacement"][:3])
              + " | " + " ".join(f"{1e3 * x:.3g}" for x in r["velocity"])
              + ("" if k_m is None else f" | sqrt(k_m / J_A) / 2 pi = {crank_on_motor_frequency(scene, k_m):.4g} Hz")
              + f" | {r['status']}, {r['wall']:.0f} s", flush=True)


if __name__ == "__main__":
    main()
