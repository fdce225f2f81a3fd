"""Kineto-elastodynamic (KED) assembly of the 6-RSS robot: a block-arrow system per time step.

Elastic displacements are superposed on the ideal rigid motion (paper sec. 5):
M(t) U'' + C(t) U' + K(t) U = F(t) (eq. 32), with the matrices taken at the rigid
configuration of each instant and F the rigid-body inertia and gravity loads.

Each link's DOFs live in its own frame, where its matrices are constant:
- crank i (frame: x along A->C, y = w_i, z = x cross y), clamped at A_i (the
  motor holds alpha_i): nodes 1..n, 6 DOFs each;
- rod i (frame: x along C->B): its end translations are not DOFs of their own:
  at C they equal the crank tip's (spherical joint: forces pass, moments do
  not, so end rotations are free), at B they follow the platform, eq. 27,
  u_B = u_0 + theta_0 x r_i.  Rod torsion is dropped: for a straight beam it is
  uncoupled from bending and axial motion and nothing loads it (spherical ends,
  rigid rod angular acceleration normal to the rod), so this removes the rods'
  zero spin mode and changes no other response;
- platform: rigid, 6 DOFs (translation of o_p and small rotation), base frame.
With ``[beam] link_modes = m > 0`` each link's DOFs are its Craig-Bampton coordinates instead
(:mod:`.link_reduction`): m fixed-interface modes, then the boundary DOFs (crank: the tip node;
rod: its C and B end translations) kept exact and last, so every slice below holds.
Only the small maps from crank tip and platform to the rod ends (and the
platform inertia) vary in time: the link matrices are constant, so a step
matrix is condensed once onto the crank tips and rod ends and factorised per
instant as 3 DOFs per leg bordered by the 6 platform DOFs (:class:`StepSolver`).
Eq. 26's frame-motion terms (2 B^T M B' U', B^T M B'' U) are not in the
matrices; :func:`frame_coupling_forces` measures what they would add.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .beam import link_matrices
from .link_reduction import craig_bampton, link_modes, max_link_modes, reduce_pair
from .dynamics import euler_moment, platform_inertia_world, rod_angular_motion
from .kinematics import RigidMotion, crank_axes
from .sections import section_properties, shear_correction_factor

__all__ = ["LegLayout", "ElasticModel", "build_elastic_model", "scene_link_matrices", "EndMaps", "end_maps",
           "link_frames", "frame_maps", "split", "join", "apply", "apply_pair", "internal_force", "StepSolver",
           "dense_matrices", "system_at", "rigid_loads", "link_loads", "platform_point_map",
           "frame_coupling_forces", "frame_inertia_load", "to_link_coordinates", "to_nodal"]


def _skew(v: np.ndarray) -> np.ndarray:
    z = np.zeros_like(v[..., 0])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


class LegLayout:
    """System vector layout shared by the KED levels: six legs [crank, rod], then 6 platform DOFs.

    Subclasses say how many DOFs a crank and a rod carry (``crank_dofs``, ``rod_dofs``).
    """

    @property
    def leg_dofs(self) -> int:
        """DOFs of one leg: crank plus rod."""
        return self.crank_dofs + self.rod_dofs

    @property
    def dofs(self) -> int:
        """Total DOFs: six legs plus the platform."""
        return 6 * self.leg_dofs + 6


@dataclass(frozen=True)
class ElasticModel(LegLayout):
    """Constant (frame-independent) part of the KED model of one scene and mesh.

    Leg vector: crank nodes 1..n (6 n, crank frame), then the rod's own DOFs
    (5 n - 1, rod frame).  Rod matrices are ordered [own DOFs, C end (3), B end (3)].
    A Craig-Bampton model (``[beam] link_modes`` = m > 0) holds each link in the coordinates of its
    basis (:mod:`.link_reduction`): crank [m modes, tip node (6)], rod [m modes, C end, B end];
    ``crank_basis`` (6n, m + 6) and ``rod_basis`` (5n+5, m + 6) map them to the nodal DOFs above
    (None: the full mesh, nodal DOFs).
    """
    elements: int
    crank_K: np.ndarray       # (6n, 6n) crank nodes 1..n; each link matrix (6, ...) per leg if they differ
    crank_M: np.ndarray
    crank_M_full: np.ndarray  # (6(n+1), 6(n+1)) with the clamped node, for loads
    rod_K: np.ndarray         # (5n+5, 5n+5) [own, C end, B end]
    rod_M: np.ndarray
    rod_M_full: np.ndarray    # (6(n+1), 6(n+1)) natural node order, for loads
    rod_order: np.ndarray     # rod full-vector indices of [own, C end, B end]
    platform_mass: float
    platform_inertia: np.ndarray  # (3,) principal, platform frame
    mass_damping: float       # Rayleigh lambda_1, 1/s
    stiffness_damping: float  # Rayleigh lambda_2, s
    crank_basis: np.ndarray | None = None   # Craig-Bampton T of the crank, or per leg (6, ...)
    rod_basis: np.ndarray | None = None     # ... of the rod [own, C end, B end]

    @property
    def crank_dofs(self) -> int:
        return self.crank_K.shape[-1]

    @property
    def rod_dofs(self) -> int:
        """The rod's own DOFs (ends excluded)."""
        return self.rod_K.shape[-1] - 6

    @property
    def tip(self) -> slice:
        """Crank tip (C_i) translations within the crank part of a leg vector."""
        return slice(self.crank_dofs - 6, self.crank_dofs - 3)


def _rows(x: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Row vectors times a link matrix: x (..., 6, m) @ M, with M shared by the legs (m, m') or one per
    leg (6, m, m') (a realised robot's, :func:`scene_link_matrices`)."""
    return x @ M if M.ndim == 2 else (x[..., None, :] @ M)[..., 0, :]


def _per_link(value, link: str) -> np.ndarray:
    """A material value as the ``link``'s: a scene's scalar, or the crank or rod part of a realised
    robot's per-link (12,) values (cranks 1-6, rods 1-6)."""
    value = np.asarray(value, float)
    return value if value.size != 12 else value[:6] if link == "crank" else value[6:]


def scene_link_matrices(scene, link: str, elements: int) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness and mass (6 (n+1) square, link frame) of the scene's ``link`` ('crank' or 'rod')
    in ``elements`` elements, with the scene's beam theory ([beam] table).  A realised robot whose
    length or material differs per leg or link gets one pair per leg (6, 6 (n+1), 6 (n+1))."""
    section, length = {"crank": (scene.crank_section, scene.geometry.crank_length),
                       "rod": (scene.rod_section, scene.geometry.rod_length)}[link]
    mat, beam = scene.material, scene.beam
    values = [np.asarray(v, float) for v in (mat.youngs_modulus, mat.shear_modulus, mat.density, length)]
    if all(v.ndim == 0 for v in values):
        k = (shear_correction_factor(section, mat.poisson_ratio) if beam.theory == "timoshenko"
             else None)
        return link_matrices(section_properties(section), mat.youngs_modulus, mat.shear_modulus,
                             mat.density, length, elements, k, beam.rotary_inertia, beam.mass)
    E, G, rho = (np.broadcast_to(_per_link(v, link), (6,)) for v in values[:3])
    lengths = np.broadcast_to(values[3], (6,))
    pairs = [link_matrices(section_properties(section), E[i], G[i], rho[i], lengths[i], elements,
                           shear_correction_factor(section, E[i] / (2.0 * G[i]) - 1.0)
                           if beam.theory == "timoshenko" else None, beam.rotary_inertia, beam.mass)
             for i in range(6)]
    return np.stack([K for K, _ in pairs]), np.stack([M for _, M in pairs])


def build_elastic_model(scene, elements: int) -> ElasticModel:
    """Link matrices and DOF layout for ``elements`` beam elements per link; with the scene's
    ``[beam] link_modes`` > 0 each link reduced to that many Craig-Bampton modes."""
    Kc, Mc = scene_link_matrices(scene, "crank", elements)
    Kr, Mr = scene_link_matrices(scene, "rod", elements)
    n6 = 6 * elements
    ends = np.r_[0:3, n6:n6 + 3]
    torsion = np.arange(3, n6 + 6, 6)
    order = np.r_[np.setdiff1d(np.arange(n6 + 6), np.r_[ends, torsion]), ends]
    model = ElasticModel(elements, Kc[..., 6:, 6:], Mc[..., 6:, 6:], Mc, Kr[..., order[:, None], order],
                         Mr[..., order[:, None], order], Mr, order, scene.platform.mass,
                         np.array(scene.platform.inertia), scene.damping.mass_coefficient,
                         scene.damping.stiffness_coefficient)
    return _reduced(model, scene.beam.link_modes) if scene.beam.link_modes else model


def _reduced(model: ElasticModel, modes: int) -> ElasticModel:
    """The Craig-Bampton model of ``model`` with ``modes`` fixed-interface modes per link (all of a link's
    interior if it has fewer); the boundary DOFs (the crank's tip node, the rod's end translations) are
    the last six of each."""
    if modes > max_link_modes(model.elements):
        raise ValueError(f"[beam] link_modes: {modes} is more than the {max_link_modes(model.elements)} interior "
                         f"DOFs of a link of {model.elements} elements")
    tip, ends = np.arange(model.crank_dofs - 6, model.crank_dofs), np.arange(model.rod_dofs, model.rod_dofs + 6)
    Tc = craig_bampton(model.crank_K, model.crank_M, tip, link_modes(modes, model.crank_dofs, tip))
    Tr = craig_bampton(model.rod_K, model.rod_M, ends, link_modes(modes, model.rod_dofs + 6, ends))
    (Kc, Mc), (Kr, Mr) = reduce_pair(model.crank_K, model.crank_M, Tc), reduce_pair(model.rod_K, model.rod_M, Tr)
    return dataclasses.replace(model, crank_K=Kc, crank_M=Mc, rod_K=Kr, rod_M=Mr, crank_basis=Tc, rod_basis=Tr)


def to_link_coordinates(basis: np.ndarray | None, f: np.ndarray) -> np.ndarray:
    """Nodal loads f (..., 6, n) as generalised loads T^T f on a link's reduced coordinates (eq. CB2);
    f itself for a full-mesh link (``basis`` None)."""
    return f if basis is None else _rows(f, basis)


def to_nodal(basis: np.ndarray | None, x: np.ndarray) -> np.ndarray:
    """A link's reduced coordinates x (..., 6, k) as nodal DOFs T x (eq. CB1); x for a full mesh."""
    return x if basis is None else _rows(x, np.swapaxes(basis, -1, -2))


@dataclass(frozen=True)
class EndMaps:
    """Time-varying part of the system at a batch of instants (leading axis T).

    Q = R_r^T R_c maps the crank tip (crank frame) to the rod's C end (rod frame);
    H = R_r^T [I, -[r_i]x] maps the platform DOFs to the rod's B end (eq. 27);
    platform_inertia is R I_p R^T about o_p.
    """
    Q: np.ndarray                 # (T, 6, 3, 3)
    H: np.ndarray                 # (T, 6, 3, 6)
    platform_inertia: np.ndarray  # (T, 3, 3)

    def __getitem__(self, k) -> "EndMaps":
        return EndMaps(self.Q[k], self.H[k], self.platform_inertia[k])


def link_frames(motion: RigidMotion, geometry) -> tuple[np.ndarray, np.ndarray]:
    """Crank and rod frames (T, 6, 3, 3), columns = local x, y, z in base coordinates."""
    w = np.broadcast_to(geometry.w, motion.c.shape)
    xc = (motion.c - geometry.a) / np.asarray(geometry.crank_length, float)[..., None]
    crank = np.stack([xc, w, np.cross(xc, w)], -1)
    xr = (motion.b - motion.c) / np.asarray(geometry.rod_length, float)[..., None]
    yr = w - np.einsum("tli,tli->tl", w, xr)[..., None] * xr
    yr /= np.linalg.norm(yr, axis=-1, keepdims=True)
    return crank, np.stack([xr, yr, np.cross(xr, yr)], -1)


def platform_point_map(r: np.ndarray) -> np.ndarray:
    """[I, -[r]x] (..., 3, 6): displacement u + theta x r of a platform point at r (eq. 27)."""
    return np.concatenate([np.broadcast_to(np.eye(3), r.shape + (3,)), -_skew(r)], -1)


def frame_maps(model: ElasticModel, motion: RigidMotion, crank: np.ndarray, rod: np.ndarray) -> EndMaps:
    """The end maps of ``motion`` from link frames already computed (see :func:`link_frames`)."""
    Q = np.einsum("tlji,tljk->tlik", rod, crank)
    H = np.einsum("tlji,tljk->tlik", rod, platform_point_map(motion.r))
    return EndMaps(Q, H, platform_inertia_world(model.platform_inertia, motion.platform.R))


def end_maps(model: ElasticModel, motion: RigidMotion, geometry) -> EndMaps:
    """The time-varying maps of the system at every instant of ``motion``."""
    return frame_maps(model, motion, *link_frames(motion, geometry))


def split(model: LegLayout, x: np.ndarray):
    """System vector (..., N) -> crank (..., 6, n_c), rod (..., 6, n_r), platform (..., 6) views."""
    legs = x[..., :-6].reshape(x.shape[:-1] + (6, model.leg_dofs))
    return legs[..., :model.crank_dofs], legs[..., model.crank_dofs:], x[..., -6:]


def join(crank: np.ndarray, rod: np.ndarray, platform: np.ndarray) -> np.ndarray:
    legs = np.concatenate([crank, rod], -1)
    return np.concatenate([legs.reshape(legs.shape[:-2] + (-1,)), platform], -1)


def _local(model: ElasticModel, maps: EndMaps, x: np.ndarray):
    """Crank (..., 6, 6n) and rod [own, C end, B end] (..., 6, 5n+5) local vectors of x."""
    c, f, p = split(model, x)
    e_C = (maps.Q @ c[..., model.tip, None])[..., 0]
    e_B = (maps.H @ p[..., None, :, None])[..., 0]
    return c, np.concatenate([f, e_C, e_B], -1), p


def apply_pair(model: ElasticModel, maps: EndMaps, x_mass: np.ndarray,
               x_stiff: np.ndarray) -> np.ndarray:
    """M x_mass + K x_stiff at one instant (``maps`` for that instant); x (..., N)."""
    cm, rm, pm = _local(model, maps, x_mass)
    ck, rk, _ = _local(model, maps, x_stiff)
    yc = _rows(cm, model.crank_M) + _rows(ck, model.crank_K)
    yr = _rows(rm, model.rod_M) + _rows(rk, model.rod_K)
    nf = model.rod_dofs
    yc[..., model.tip] += (yr[..., None, nf:nf + 3] @ maps.Q)[..., 0, :]
    yp = np.einsum("...lj,ljk->...k", yr[..., nf + 3:], maps.H)
    yp[..., :3] += model.platform_mass * pm[..., :3]
    yp[..., 3:] += pm[..., 3:] @ maps.platform_inertia
    return join(yc, yr[..., :nf], yp)


def apply(model: ElasticModel, maps: EndMaps, x: np.ndarray, mass: float,
          stiffness: float) -> np.ndarray:
    """(mass M + stiffness K) x at one instant."""
    return apply_pair(model, maps, mass * x, stiffness * x)


def internal_force(model: ElasticModel, maps: EndMaps, d: np.ndarray, v: np.ndarray) -> np.ndarray:
    """C v + K d with Rayleigh C = lambda_1 M + lambda_2 K, at one instant."""
    return apply_pair(model, maps, model.mass_damping * v, d + model.stiffness_damping * v)


class StepSolver:
    """Solves (mass M + stiffness K) x = r at a batch of instants by static condensation.

    The crank interior and the rod's own DOFs have constant matrices, so they are
    condensed once onto the crank tips and the rod ends; per instant only a
    block-arrow system of 3 DOFs per leg plus the 6 platform DOFs is factorised.
    """

    def __init__(self, model: ElasticModel, maps: EndMaps, mass: float, stiffness: float):
        self.model, self.maps = model, maps
        Ec = mass * model.crank_M + stiffness * model.crank_K
        Er = mass * model.rod_M + stiffness * model.rod_K
        t = np.arange(model.crank_dofs)[model.tip]
        i = np.setdiff1d(np.arange(model.crank_dofs), t)
        self._ci, self._ct = i, t
        self._Ec_ii_inv = np.linalg.inv(Ec[..., i[:, None], i])
        self._Ec_it = Ec[..., i[:, None], t]
        self._Ec_ti = np.swapaxes(self._Ec_it, -1, -2)
        Sc = Ec[..., t[:, None], t] - self._Ec_ti @ self._Ec_ii_inv @ self._Ec_it
        nf = model.rod_dofs
        self._Er_ff_inv = np.linalg.inv(Er[..., :nf, :nf])
        self._Er_fe = Er[..., :nf, nf:]
        self._Er_ef = np.swapaxes(self._Er_fe, -1, -2)
        Sr = Er[..., nf:, nf:] - self._Er_ef @ self._Er_ff_inv @ self._Er_fe
        Q, H = maps.Q, maps.H
        QT = np.swapaxes(Q, -1, -2)
        legs = Sc + QT @ Sr[..., :3, :3] @ Q                  # (T, 6, 3, 3)
        self._border = QT @ Sr[..., :3, 3:] @ H                # (T, 6, 3, 6)
        plat = np.einsum("tlji,jk,tlkm->tim" if Sr.ndim == 2 else "tlji,ljk,tlkm->tim", H, Sr[..., 3:, 3:], H)
        plat[..., :3, :3] += mass * model.platform_mass * np.eye(3)
        plat[..., 3:, 3:] += mass * maps.platform_inertia
        self._legs_inv = np.linalg.inv(legs)
        self._W = self._legs_inv @ self._border
        self._schur_inv = np.linalg.inv(plat - np.einsum("tlji,tljk->tik", self._border, self._W))

    def solve(self, k: int, r: np.ndarray) -> np.ndarray:
        """x at instant k of the batch; r (..., N)."""
        m = self.model
        rc, rf, rp = split(m, r)
        y_ci = _rows(rc[..., self._ci], self._Ec_ii_inv)     # symmetric inverses: row form
        y_f = _rows(rf, self._Er_ff_inv)
        g = _rows(y_f, self._Er_fe)                          # (..., 6, 6) rod-end loads of the own DOFs
        Q, H = self.maps.Q[k], self.maps.H[k]
        r_tip = rc[..., self._ct] - _rows(y_ci, self._Ec_it) - (g[..., None, :3] @ Q)[..., 0, :]
        r_p = rp - np.einsum("...lj,ljk->...k", g[..., 3:], H)
        u = (self._legs_inv[k] @ r_tip[..., None])[..., 0]
        r_p = r_p - np.einsum("lji,...lj->...i", self._border[k], u)
        x_p = (self._schur_inv[k] @ r_p[..., None])[..., 0]
        x_tip = u - (self._W[k] @ x_p[..., None, :, None])[..., 0]
        x_ci = y_ci - _rows(_rows(x_tip, self._Ec_ti), self._Ec_ii_inv)
        e = np.concatenate([(Q @ x_tip[..., None])[..., 0], (H @ x_p[..., None, :, None])[..., 0]], -1)
        x_f = y_f - _rows(_rows(e, self._Er_ef), self._Er_ff_inv)
        xc = np.empty(rc.shape)
        xc[..., self._ci], xc[..., self._ct] = x_ci, x_tip
        return join(xc, x_f, x_p)


def dense_matrices(model: ElasticModel, maps: EndMaps) -> tuple[np.ndarray, np.ndarray]:
    """Full M and K (N, N) at one instant, for modal analysis and tests."""
    eye = np.eye(model.dofs)
    return apply(model, maps, eye, 1.0, 0.0), apply(model, maps, eye, 0.0, 1.0)


def _affine_nodal_loads(frames, lin0, lin1, ang, M_full: np.ndarray) -> np.ndarray:
    """Nodal loads (T, 6, 6(n+1)) = field @ M_full of the link-local field whose node k (at s_k = k/n
    along the link) has linear part R^T (lin0 + s_k lin1) and angular part R^T ang (lin0, lin1, ang
    (T, 6, 3), base frame; R = frames).

    The field is linear in the nine local components [R^T lin0, R^T lin1, R^T ang], so the
    product is taken as (6, 9) @ (9, 6(n+1)) per instant with the constant map folded into M_full:
    a third of the flops of the nodal field's product and no (T, 6, 6(n+1)) field in memory.
    One BLAS product per instant, not one (T 6, 9) product: BLAS sums a row differently with
    its place among the rows and their number (its edge kernels, which depend on the CPU and
    OPENBLAS_CORETYPE), so an instant's loads would depend on how many instants are computed
    together, and a contact run's chunks, of 2^refinements more instants with a finer step, must
    give the fixed run's bits (tests/test_contact.py, adaptive step limits).
    """
    nodes = M_full.shape[-1] // 6
    B = np.zeros((9, 6 * nodes))                  # [lin0, lin1, ang] -> nodal field
    for k, s_k in enumerate(np.linspace(0.0, 1.0, nodes)):
        B[0:3, 6 * k:6 * k + 3] = np.eye(3)
        B[3:6, 6 * k:6 * k + 3] = s_k * np.eye(3)
        B[6:9, 6 * k + 3:6 * k + 6] = np.eye(3)
    local = np.stack([lin0, lin1, ang], -2) @ frames          # rows v^T R = (R^T v)^T: (T, 6, 3, 3)
    T = local.shape[0]
    return _rows(local.reshape(T, 6, 9), B @ M_full).reshape(T, 6, 6 * nodes)


def system_at(model: ElasticModel, motion: RigidMotion, scene) -> tuple[EndMaps, np.ndarray]:
    """End maps and rigid loads at every instant of ``motion``, sharing one set of link frames."""
    crank, rod = link_frames(motion, scene.geometry)
    maps = frame_maps(model, motion, crank, rod)
    return maps, _loads(model, motion, scene, crank, rod, maps)


def rigid_loads(model: ElasticModel, motion: RigidMotion, scene) -> np.ndarray:
    """Rigid-body inertia and gravity loads F = M (g - a_rigid) on the system DOFs (T, N), N."""
    return system_at(model, motion, scene)[1]


def _loads(model, motion, scene, crank, rod, maps) -> np.ndarray:
    f_crank, f_rod, f_platform = link_loads(model, motion, scene, crank, rod, maps.platform_inertia)
    F = _to_independent(model, maps, to_link_coordinates(model.crank_basis, f_crank[..., 6:]), f_rod)
    F[:, -6:] += f_platform
    return F


def link_loads(model: ElasticModel, motion: RigidMotion, scene, crank: np.ndarray, rod: np.ndarray,
               platform_inertia: np.ndarray):
    """Rigid-body inertia and gravity loads M (g - a_rigid) per link, in link frames, N.

    Returns the crank's (T, 6, 6(n+1)) on all its nodes (the clamped one first),
    the rod's (T, 6, 5n+5) in the order [own, C end, B end] (on its reduced coordinates for a
    Craig-Bampton model), and the platform's (T, 6).
    """
    geo, g = scene.geometry, scene.gravity_vector
    e = crank_axes(geo)[None]
    arm = motion.c - geo.a
    # crank nodes at s L_ac turn about the fixed axis e: a = s (alpha'' e x arm - alpha'^2 arm)
    tip = motion.alpha_ddot[..., None] * np.cross(e, arm) - (motion.alpha_dot ** 2)[..., None] * arm
    f_crank = _affine_nodal_loads(crank, np.broadcast_to(g, tip.shape), -tip,
                                  -motion.alpha_ddot[..., None] * e, model.crank_M_full)
    # rod: rigid acceleration is linear along the rod, c'' + s (b'' - c'')
    f_rod = _affine_nodal_loads(rod, g - motion.c_ddot, motion.c_ddot - motion.b_ddot,
                                -rod_angular_motion(motion).alpha, model.rod_M_full)
    pm = motion.platform
    f_platform = np.concatenate([model.platform_mass * (g - pm.a),
                                 -euler_moment(platform_inertia, pm.omega, pm.omega_dot)], -1)
    return f_crank, to_link_coordinates(model.rod_basis, f_rod[..., model.rod_order]), f_platform


def _to_independent(model: ElasticModel, maps: EndMaps, f_crank: np.ndarray,
                    f_rod: np.ndarray) -> np.ndarray:
    """Map link-local nodal forces (crank nodes 1..n; rod [own, C, B]) to the system DOFs."""
    nf = model.rod_dofs
    f_crank = f_crank.copy()
    f_crank[..., model.tip] += (f_rod[..., None, nf:nf + 3] @ maps.Q)[..., 0, :]
    platform = np.einsum("...lj,...ljk->...k", f_rod[..., nf + 3:], maps.H)
    return join(f_crank, f_rod[..., :nf], platform)


def frame_inertia_load(M: np.ndarray, q: np.ndarray, q_dot: np.ndarray, Om: np.ndarray,
                       Om_dot: np.ndarray) -> np.ndarray:
    """-M (2 Omega~ q' + (Omega~' + Omega~^2) q) (..., 6(n+1)), N: the frame-motion inertia of a link's
    elastic motion, as a load (eq. 26's 2 B^T M B' U' + B^T M B'' U in the link frame).

    q, q_dot (..., 6(n+1)): the link's full nodal displacements (m, rad) and rates in its own axes; Om,
    Om_dot (..., 3, 3): R^T R' (1/s), the frame's angular velocity in its axes as a skew matrix, and its
    rate (1/s^2); M (6(n+1), 6(n+1)): the link's full mass.  Each node's translations and rotations
    are turned alike, as three-vectors."""
    q3, qd3 = q.reshape(q.shape[:-1] + (-1, 3)), q_dot.reshape(q.shape[:-1] + (-1, 3))
    acc = (2 * np.einsum("...ij,...kj->...ki", Om, qd3)
           + np.einsum("...ij,...kj->...ki", Om_dot + Om @ Om, q3))
    return -acc.reshape(q.shape) @ M


def frame_coupling_forces(model: ElasticModel, motion: RigidMotion, scene,
                          d: np.ndarray) -> np.ndarray:
    """Generalised forces (T, N) of eq. 26's frame-motion terms along a computed response d (T, N).

    In a link frame turning at Omega (local axes) the elastic motion q has the
    extra inertia M (2 Omega~ q' + (Omega~' + Omega~^2) q), the local form of
    2 B^T M B' U' + B^T M B'' U; returned with a minus sign, as a load.  Rates
    are central differences of the history, so the rod ends' time-varying maps
    are differentiated too.
    """
    t = motion.t
    crank, rod = link_frames(motion, scene.geometry)
    maps = frame_maps(model, motion, crank, rod)
    c, f, p = split(model, d)
    rod_ends = np.concatenate([(maps.Q @ c[..., model.tip, None])[..., 0],
                               (maps.H @ p[:, None, :, None])[..., 0]], -1)
    crank_full = np.concatenate([np.zeros(c.shape[:2] + (6,)), to_nodal(model.crank_basis, c)], -1)
    rod_full = np.zeros(f.shape[:2] + (6 * model.elements + 6,))
    rod_full[..., model.rod_order] = to_nodal(model.rod_basis, np.concatenate([f, rod_ends], -1))

    def extra(M, q, frames):
        Om = np.einsum("tlji,tljk->tlik", frames, np.gradient(frames, t, axis=0))
        return frame_inertia_load(M, q, np.gradient(q, t, axis=0), Om, np.gradient(Om, t, axis=0))

    f_crank = extra(model.crank_M_full, crank_full, crank)[..., 6:]
    f_rod = extra(model.rod_M_full, rod_full, rod)[..., model.rod_order]
    return _to_independent(model, maps, to_link_coordinates(model.crank_basis, f_crank),
                           to_link_coordinates(model.rod_basis, f_rod))
