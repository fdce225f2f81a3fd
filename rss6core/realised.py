"""The realised robot: one realisation's drawn geometry driven by the nominal controller (issue 38).

The controller knows only the drawing: it commands the nominal inverse kinematics alpha_cmd(t)
(:func:`.kinematics.rigid_motion` of the scene).  The realised robot's cranks turn to alpha_cmd +
its actuator offsets, and its platform takes the pose the realised closure gives (Newton's forward
kinematics, :func:`.kinematics.forward_kinematics`), with twist and its rate from the differentiated
closure (docs/model.md section 3b):
    G [v, omega] = (n . c_alpha) alpha',
    G [a, omega'] = (n . c_alpha) alpha'' + (n . c_alpha_alpha) alpha'^2 + |n'|^2 - n . (omega x (omega x r)),
G the rows [n_i, r_i x n_i], n_i = c_i - b_i.  Its error against the ideal pose is the geometric
(kinematic) error of the rigid level; the quasi-static level adds the clearance closure about it.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation

from .clearance import CLEARANCE_RADII
from .frozen import frozen_array
from .kinematics import RigidMotion, crank_points, forward_kinematics, leg_jacobian, platform_joints, rigid_motion
from .trajectory import PlatformMotion, euler_rate_matrix, euler_rate_matrix_dot, rotation

__all__ = ["GEOMETRY_KEYS", "realised_geometry", "realised_clearances", "realised_scene", "realised_motion",
           "motion_error", "linear_length_error", "Reference", "ReferenceMotion", "JointLaws", "realised_contact_laws"]

# each drawable [geometry] key and the Geometry field it sets
GEOMETRY_KEYS = {"geometry.crank_length_m": "crank_length", "geometry.rod_length_m": "rod_length",
                 "geometry.base_radius_m": "base_radius", "geometry.platform_radius_m": "platform_radius",
                 "geometry.base_angles_deg": "base_angles", "geometry.platform_angles_deg": "platform_angles",
                 "geometry.actuator_offsets_deg": "actuator_offsets"}


def realised_geometry(geometry, inputs):
    """The scene's ``geometry`` with the drawn values of ``inputs`` (an :class:`.uncertain.InputDraw`):
    per leg or joint (6,) where drawn so, (1,) for one shared draw; the nominal elsewhere."""
    changes = {field: frozen_array(inputs.realised(key)) for key, field in GEOMETRY_KEYS.items()
               if inputs.realised(key) is not None}
    return dataclasses.replace(geometry, **changes)


def realised_clearances(scene, inputs):
    """The scene with its drawn clearance sizes (each family's (6,) or shared (1,) values, m) as its
    [clearance] values: the clearance draw then takes them as the nominal sizes (no band: the
    parser refuses a band on a drawn family), so its eccentricities scale with them.  The scene
    itself when no size is drawn."""
    changes = {family.removesuffix("_m"): frozen_array(inputs.realised(f"clearance.{family}"))
               for family in CLEARANCE_RADII if inputs.realised(f"clearance.{family}") is not None}
    return dataclasses.replace(scene, clearance=dataclasses.replace(scene.clearance, **changes)) if changes else scene


def realised_scene(scene, inputs):
    """The scene of one realised robot: :func:`realised_geometry`, the links' Young's modulus and
    density (scalar, or per link (12,): cranks 1-6, rods 1-6), the platform's mass and principal
    moments.  The shear modulus follows the modulus (G E_real / E_nominal: Poisson's ratio kept)."""
    mat, plat = scene.material, scene.platform
    E, rho = inputs.realised("material.youngs_modulus_Pa"), inputs.realised("material.density_kg_m3")
    mass, inertia = inputs.realised("platform.mass_kg"), inputs.realised("platform.inertia_kg_m2")
    material = dataclasses.replace(
        mat, youngs_modulus=mat.youngs_modulus if E is None else _scalar_or_links(E),
        shear_modulus=mat.shear_modulus if E is None else _scalar_or_links(
            E * (mat.shear_modulus / mat.youngs_modulus)),
        density=mat.density if rho is None else _scalar_or_links(rho))
    platform = dataclasses.replace(plat, mass=plat.mass if mass is None else float(mass[0]),
                                   inertia=plat.inertia if inertia is None else frozen_array(inertia))
    return dataclasses.replace(scene, geometry=realised_geometry(scene.geometry, inputs), material=material,
                               platform=platform)


def _scalar_or_links(values):
    """One shared draw as a scalar (a scene's type), twelve per-link draws as a frozen (12,) array."""
    values = np.asarray(values, float)
    return float(values[0]) if values.size == 1 else frozen_array(values)


def scene_is_nominal(scene, realised) -> bool:
    """True when the realised scene's geometry, material and platform hold the nominal values exactly."""
    same = [np.array_equal(*np.broadcast_arrays(getattr(getattr(realised, part), f), getattr(getattr(scene, part), f)))
            for part, fields in (("material", ("youngs_modulus", "shear_modulus", "density")),
                                 ("platform", ("mass", "inertia"))) for f in fields]
    return all(same) and is_nominal(scene.geometry, realised.geometry)


def is_nominal(geometry, realised) -> bool:
    """True when the realised geometry holds the nominal values exactly (zero-width draws)."""
    return all(np.array_equal(*np.broadcast_arrays(getattr(realised, f), getattr(geometry, f)))
               for f in GEOMETRY_KEYS.values())


def _dot(x, y):
    return np.einsum("tli,tli->tl", x, y)


def realised_motion(geometry, nominal: RigidMotion) -> RigidMotion:
    """The realised robot's rigid motion under the nominal commands of ``nominal`` (same times)."""
    alpha = nominal.alpha + geometry.actuator_offsets
    alpha_dot, alpha_ddot = nominal.alpha_dot, nominal.alpha_ddot
    pose, _ = forward_kinematics(geometry, alpha, nominal.platform.pose)
    R = rotation(pose[:, 3:])
    b, r = platform_joints(geometry, pose[:, :3], R)
    c, dc, d2c = crank_points(geometry, alpha)
    n = c - b
    G = np.concatenate([n, np.cross(r, n)], -1)
    twist = np.linalg.solve(G, (_dot(n, dc) * alpha_dot)[..., None])[..., 0]
    v, omega = twist[:, :3], twist[:, 3:]
    w = omega[:, None, :]
    b_dot = v[:, None, :] + np.cross(w, r)
    c_dot = dc * alpha_dot[..., None]
    n_dot = c_dot - b_dot
    centripetal = np.cross(w, np.cross(w, r))
    rhs = (_dot(n, dc) * alpha_ddot + _dot(n, d2c) * alpha_dot ** 2 + _dot(n_dot, n_dot)
           - _dot(n, centripetal))
    rate = np.linalg.solve(G, rhs[..., None])[..., 0]
    a, omega_dot = rate[:, :3], rate[:, 3:]
    b_ddot = a[:, None, :] + np.cross(omega_dot[:, None, :], r) + centripetal
    c_ddot = dc * alpha_ddot[..., None] + d2c * (alpha_dot ** 2)[..., None]
    E = euler_rate_matrix(pose[:, 3:])
    euler_rate = np.linalg.solve(E, omega[..., None])[..., 0]
    euler_acc = np.linalg.solve(E, (omega_dot - np.einsum("tij,tj->ti", euler_rate_matrix_dot(
        pose[:, 3:], euler_rate), euler_rate))[..., None])[..., 0]
    platform = PlatformMotion(nominal.t, pose, np.concatenate([v, euler_rate], -1),
                              np.concatenate([a, euler_acc], -1), R, omega, omega_dot)
    return RigidMotion(platform, alpha, alpha_dot, alpha_ddot, c, c_dot, c_ddot, b, b_dot, b_ddot, r,
                       leg_jacobian(geometry, b, r, alpha))


def motion_error(real: RigidMotion, ideal: RigidMotion) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Realised minus ideal platform motion (T, 6) each: displacement [o - o*, rotation vector of
    R R*^T], velocity [v - v*, omega - omega*], acceleration [a - a*, omega' - omega'*] (SI)."""
    p, q = real.platform, ideal.platform
    turn = Rotation.from_matrix(np.einsum("tij,tkj->tik", p.R, q.R)).as_rotvec()
    return (np.concatenate([p.o - q.o, turn], -1), np.concatenate([p.v - q.v, p.omega - q.omega], -1),
            np.concatenate([p.a - q.a, p.omega_dot - q.omega_dot], -1))


def linear_length_error(geometry, ideal: RigidMotion, d_crank, d_rod) -> np.ndarray:
    """First-order pose error (T, 6) of crank and rod length deviations (6,) m: J_x dx = J_g dg with
    J_x = [n_i, r_i x n_i] and J_g = [n_i . (c_i - a_i) / L_ac, -L_cb] per leg (closure |c - b|^2 = L_cb^2)."""
    n = ideal.c - ideal.b
    G = np.concatenate([n, np.cross(ideal.r, n)], -1)
    rhs = (_dot(n, ideal.c - geometry.a) / geometry.crank_length * np.asarray(d_crank)
           - geometry.rod_length * np.asarray(d_rod))
    return np.linalg.solve(G, rhs[..., None])[..., 0]


@dataclasses.dataclass(frozen=True)
class Reference:
    """The rigid motion a dynamic level perturbs at some instants, and that motion's own error
    against the ideal pose (T, 3, 6) [displacement, velocity, acceleration] (zero for the nominal
    robot, the geometric error of a realised one): the level's error is its perturbation plus this."""
    motion: RigidMotion
    error: np.ndarray


@dataclasses.dataclass(frozen=True)
class ReferenceMotion:
    """Where the contact level linearises: the nominal robot's rigid motion (``geometry`` None), or a
    realised robot's under the nominal commands of ``scene`` (:func:`realised_motion`)."""
    scene: object
    geometry: object = None

    def at(self, t) -> Reference:
        """The :class:`Reference` at instants t (s)."""
        nominal = rigid_motion(self.scene, np.asarray(t, float))
        if self.geometry is None:
            return Reference(nominal, np.zeros((len(nominal.t), 3, 6)))
        real = realised_motion(self.geometry, nominal)
        return Reference(real, np.stack(motion_error(real, nominal), 1))


@dataclasses.dataclass(frozen=True)
class JointLaws:
    """Per joint of each leg (6, 3) [A, C, B]: friction coefficient mu_d (eq. 18) and restitution xi
    (eq. 17); A's axial faces take A's."""
    friction: np.ndarray
    restitution: np.ndarray


def realised_contact_laws(scene, inputs=None) -> JointLaws:
    """The :class:`JointLaws` of one realised robot: the drawn values ((18,) A1..A6, C1..C6, B1..B6,
    or one shared (1,)), the scene's [contact] values elsewhere (everywhere for ``inputs`` None)."""
    out = []
    for key, nominal in (("contact.friction_coefficient", scene.contact.friction_coefficient),
                         ("contact.restitution", scene.contact.restitution)):
        drawn = None if inputs is None else inputs.realised(key)
        values = np.full(18, float(nominal)) if drawn is None else np.broadcast_to(np.asarray(drawn, float), (18,))
        out.append(np.ascontiguousarray(values.reshape(3, 6).T))
    return JointLaws(*out)
