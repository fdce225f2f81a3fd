"""Contact laws of the clearance joints (paper sec. 4): Hertz stiffness, Lankarani-Nikravesh, friction.

All functions are vectorised over any leading axes (joints, realisations) and
return the derivatives an implicit integrator's Newton iteration needs.
"""
from __future__ import annotations

import numpy as np

__all__ = ["poisson_ratio", "hertz_stiffness", "lankarani_nikravesh", "friction_factor",
           "coulomb_friction"]


def poisson_ratio(youngs_modulus: float, shear_modulus: float) -> float:
    """nu = E / (2 G) - 1 of an isotropic material (docs/model.md section 2)."""
    return youngs_modulus / (2.0 * shear_modulus) - 1.0


def hertz_stiffness(radius_inner, radius_outer, E_inner: float, nu_inner: float,
                    E_outer: float, nu_outer: float):
    """K_N of eq. 17 (N/m^1.5) for a ball or journal (radius_inner, m) in a socket or bearing (radius_outer).

    K_N = 4 / (3 (sigma_in + sigma_out)) sqrt(R_in R_out / (R_out - R_in)), sigma = (1 - nu^2)/E:
    Hertz's law for internal (conformal) contact of two spheres.  Eq. 17 uses the
    same law for the journal in its bearing (cylinder in cylinder), as is common
    in the clearance-joint literature; we follow the paper.  A zero clearance
    (R_out = R_in) gives an infinite stiffness.
    """
    r_in, r_out = np.asarray(radius_inner, float), np.asarray(radius_outer, float)
    if np.any(r_out < r_in):
        raise ValueError("hertz_stiffness: the outer (socket, bearing) radius must not be smaller "
                         "than the inner (ball, journal) radius")
    sigma = (1.0 - nu_inner ** 2) / E_inner + (1.0 - nu_outer ** 2) / E_outer
    with np.errstate(divide="ignore"):
        return 4.0 / (3.0 * sigma) * np.sqrt(r_in * r_out / (r_out - r_in))


def joint_stiffness(scene, radius, size):
    """The scene's K_N of eq. 17 (N/m^1.5) for balls or journals of ``radius`` (m) in clearances of
    ``size`` (m; arrays broadcast): :func:`hertz_stiffness` of two bodies of the scene's material, times its
    ``[contact] stiffness_scale``; the one contact stiffness of every level."""
    mat = scene.material
    nu, E = poisson_ratio(mat.youngs_modulus, mat.shear_modulus), mat.youngs_modulus
    return scene.contact.stiffness_scale * hertz_stiffness(radius, radius + size, E, nu, E, nu)


def lankarani_nikravesh(delta, delta_dot, impact_speed, stiffness, exponent: float,
                        restitution: float):
    """Normal force F_N (N) of eq. 17 and its derivatives dF/d(delta), dF/d(delta_dot).

    F_N = K delta^n [1 + 3 (1 - xi^2)/4 * delta_dot / delta_dot_c1] for penetration
    delta > 0 (m), zero otherwise; delta_dot (m/s) is the penetration rate and
    delta_dot_c1 the rate at the start of this impact.  The force never pulls
    (F_N >= 0): the damping term cannot make a separating contact adhesive.
    """
    delta = np.asarray(delta, float)
    pen = np.maximum(delta, 0.0)
    with np.errstate(invalid="ignore"):   # a zero clearance's infinite K times zero penetration: masked below
        spring = stiffness * pen ** exponent
        d_spring = exponent * stiffness * pen ** (exponent - 1.0)
    c = 0.75 * (1.0 - restitution ** 2) / impact_speed
    factor = 1.0 + c * delta_dot
    force = spring * factor
    active = (delta > 0.0) & (force > 0.0)
    zero = np.zeros_like(force)
    return (np.where(active, force, zero), np.where(active, d_spring * factor, zero),
            np.where(active, spring * c, zero))


def friction_factor(speed, stick_velocity: float, slip_velocity: float):
    """Dynamic correction c_d of eq. 18 (0 below v0, linear, 1 above v1) and dc_d/d|v_t| (s/m)."""
    speed = np.asarray(speed, float)
    ramp = (speed - stick_velocity) / (slip_velocity - stick_velocity)
    inside = (speed >= stick_velocity) & (speed <= slip_velocity)
    return (np.clip(ramp, 0.0, 1.0),
            np.where(inside, 1.0 / (slip_velocity - stick_velocity), 0.0))


def coulomb_friction(normal_force, slip, mu, stick_velocity: float, slip_velocity: float):
    """Friction force F_t = -mu c_d F_N v_t / |v_t| (eq. 18, direction normalised), N.

    ``slip`` (..., 3) is the tangential sliding velocity v_t (m/s), ``mu`` a scalar or one per
    pair (...).  Returns F_t
    (..., 3), dF_t/dv_t (..., 3, 3) and dF_t/dF_N (..., 3).
    """
    speed = np.linalg.norm(slip, axis=-1)
    cd, dcd = friction_factor(speed, stick_velocity, slip_velocity)
    safe = np.maximum(speed, 1e-300)
    t = slip / safe[..., None]
    scale = -mu * np.asarray(normal_force)
    force = (scale * cd)[..., None] * t
    tt = t[..., :, None] * t[..., None, :]
    eye = np.eye(3)
    jac = scale[..., None, None] * ((cd / safe)[..., None, None] * (eye - tt) + dcd[..., None, None] * tt)
    return force, jac, -(np.asarray(mu) * cd)[..., None] * t
