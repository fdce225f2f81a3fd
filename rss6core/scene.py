"""Immutable scene description of a 6-RSS robot, read from a TOML file.

A scene holds everything a run needs to know and nothing it computes: geometry,
link sections, material, platform, gravity, trajectory (eq. 35 or another kind of
:mod:`.trajectory_kinds`), time step,
damping, clearances and contact laws.  All values are SI inside; the TOML keys
carry their units in their names.  Loading checks every key strictly (unknown,
missing, wrong type, non-physical value) and raises :class:`SceneError` naming
the key, then checks that the trajectory stays inside the workspace.
"""
from __future__ import annotations

import difflib
import json
import math
import tomllib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from .beam import BEAM_THEORIES, MASS_MODELS, BeamTheory
from .clearance import CLEARANCE_RADII, RELATIVE_BAND_REACH, SizeBand
from .contact_options import CONTACT_STARTS, MAX_CONTACT_REFINEMENTS
from .frozen import frozen_array
from .integrators import INTEGRATORS
from .kinematics import WorkspaceError, check_workspace
from .link_reduction import max_link_modes
from .levels import MODELS
from .pose_csv import file_trajectory, with_pose_samples
from .results import check_step_count, whole_steps
from .sections import RectangleSection, TubeSection
from .uncertain import UncertainInputError, UncertainInputs, parse_uncertain
from .trajectory_kinds import TRAJECTORY_KINDS, SampledPoses, Sinusoid, TrajectoryError, ViaPoints, via_points

MAX_ELEMENTS_PER_LINK = 64   # beam elements per crank and per rod

__all__ = [
    "SceneError", "Scene", "Geometry", "Material", "Platform", "Trajectory", "Simulation", "Sampling", "Damping",
    "Clearances", "ContactLaw", "Tolerances", "Actuator", "DRIVES",
    "load_scene", "parse_scene", "toml_spelling",
]


class SceneError(ValueError):
    """A scene file that cannot describe a physical robot; the message names the key."""


def _per_leg(value) -> np.ndarray:
    """A scalar or per-leg (6,) value as a column (1 or 6, 1) multiplying (6, 3) leg vectors: a scalar
    gives the same bits as the scalar product."""
    return np.asarray(value, float)[..., None]


def _rot_z(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    z, o = np.zeros_like(angle), np.ones_like(angle)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1),
                     np.stack([z, z, o], -1)], -2)


@dataclass(frozen=True)
class Geometry:
    """Joint layout (eq. 2-3): base joints a_i, platform joints p_i (platform frame), links.

    A scene's lengths and radii are scalars; a realised robot (rss6core/realised.py) may hold them
    per leg or joint as (6,) arrays (every formula broadcasts over the legs). The joint vectors and
    rotations below are computed once per geometry (read-only arrays; a draw reads them once per realisation)."""
    base_radius: float             # R1, m (or per joint)
    base_angles: np.ndarray        # theta_i = u_i, rad
    platform_radius: float         # R2, m (or per joint)
    platform_angles: np.ndarray    # beta_i, rad
    crank_length: float            # L_ac, m (or per leg)
    rod_length: float              # L_cb, m (or per leg)
    actuator_offsets: np.ndarray = field(default_factory=lambda: frozen_array(np.zeros(6)))  # rad, true - commanded

    @cached_property
    def a(self) -> np.ndarray:
        """Base joint centres a_i = R1 [cos theta_i, sin theta_i, 0] (6, 3), m."""
        th = self.base_angles
        return frozen_array(_per_leg(self.base_radius) * np.stack([np.cos(th), np.sin(th), 0 * th], -1))

    @cached_property
    def p(self) -> np.ndarray:
        """Platform joint centres in the platform frame n_i* (6, 3), m."""
        be = self.platform_angles
        return frozen_array(_per_leg(self.platform_radius) * np.stack([np.cos(be), np.sin(be), 0 * be], -1))

    @cached_property
    def k(self) -> np.ndarray:
        """Leg mounting rotations k_i = Rz(u_i) (6, 3, 3), eq. 2."""
        return frozen_array(_rot_z(self.base_angles))

    @cached_property
    def w(self) -> np.ndarray:
        """Revolute axes w_i = [-sin u_i, cos u_i, 0] (6, 3)."""
        return frozen_array(self.k[:, :, 1])


@dataclass(frozen=True)
class Material:
    density: float          # kg/m^3
    youngs_modulus: float   # Pa
    shear_modulus: float    # Pa

    @property
    def poisson_ratio(self) -> float:
        """nu = E / (2 G) - 1 (isotropic)."""
        return self.youngs_modulus / (2.0 * self.shear_modulus) - 1.0


@dataclass(frozen=True)
class Platform:
    mass: float             # kg
    inertia: np.ndarray     # principal moments about o_p in platform axes, kg m^2


Trajectory = Sinusoid   # the default kind, eq. 35 (its former name)


@dataclass(frozen=True)
class Damping:
    """Rayleigh damping C = mass_coefficient M + stiffness_coefficient K."""
    mass_coefficient: float       # 1/s
    stiffness_coefficient: float  # s


@dataclass(frozen=True)
class Clearances:
    """Maximum clearances (Table 2), m."""
    revolute_radial: float
    revolute_axial: float
    spherical_C: float
    spherical_B: float


@dataclass(frozen=True)
class ContactLaw:
    """Joint contact geometry and the laws of eq. 17-18."""
    journal_radius: float         # m
    sphere_radius: float          # m
    restitution: float            # xi
    exponent: float               # n
    friction_coefficient: float   # mu_d
    stick_velocity: float         # v0, m/s
    slip_velocity: float          # v1, m/s
    impact_speed_floor: float = 1e-3  # m/s, lower bound of delta_dot_c1 in eq. 17 (resting contact)
    stiffness_scale: float = 1.0      # factor on eq. 17's Hertz stiffness K (sensitivity, stability)


@dataclass(frozen=True)
class Simulation:
    """Model level, integrator and mesh a run uses unless the command line overrides them."""
    time_step: float          # s
    model: str
    integrator: str
    elements_per_link: int
    newmark_beta: float
    newmark_gamma: float
    hht_alpha: float
    spectral_radius: float    # generalized-alpha rho_inf
    quasi_static_eccentricity: str  # 'drawn' or 'reaction' (at the boundary, along the L0 force)
    contact_time_step: float = 1e-4  # s, internal step of the contact level (L4)
    contact_integrator: str = "generalized-alpha"  # its integrator: damps unresolved contact chatter
    settle_time: float = 0.0  # s, start-up transient left out of the error summaries (maxima, means)
    steady_after: float = 0.0  # s, boundary t_s of the analysis windows startup [0, t_s), steady [t_s, T]
    contact_tolerance: float = 0.0   # m, local error bound of the adaptive contact step (0: none)
    contact_refinements: int = 0     # halvings of contact_time_step the adaptive step may take
    contact_start: str = "drawn"     # contact level's initial state: 'drawn' offset or 'equilibrium'


DRIVES = ("prescribed", "servo")   # [actuator] drive


@dataclass(frozen=True)
class Actuator:
    """How each motor drives its crank at the contact level: ``prescribed`` (the crank's angle at its
    journal is the commanded one, as in the paper's sec. 2.3) or ``servo`` (a position loop of stiffness
    ``servo_stiffness`` about the commanded angle, the rigid robot's torque fed forward; docs/model.md)."""
    drive: str = "prescribed"
    servo_stiffness: float = 0.0   # N m/rad, positive with a servo drive

    @property
    def motor_stiffness(self) -> float | None:
        """k_m of the contact level's crank on its motor (N m/rad), None for a prescribed crank."""
        return self.servo_stiffness if self.drive == "servo" else None


@dataclass(frozen=True)
class Sampling:
    """Clearance sampling laws (docs/model.md section 4); means and stds as fractions of the size."""
    radial_mean: float
    radial_std: float
    axial_mean: float
    axial_std: float
    direction: str            # 'uniform' on the sphere, or the paper's eta-angle law
    size_tolerance: float     # relative std of the clearance sizes (0: exact sizes)


@dataclass(frozen=True)
class Tolerances:
    """Per joint family the size band of [tolerance.<family>], or None (nominal or size_tolerance)."""
    revolute_radial: SizeBand | None = None
    revolute_axial: SizeBand | None = None
    spherical_C: SizeBand | None = None
    spherical_B: SizeBand | None = None


@dataclass(frozen=True)
class Scene:
    """Everything one run of rss6 needs to know, immutable."""
    name: str
    geometry: Geometry
    crank_section: RectangleSection
    rod_section: TubeSection
    material: Material
    platform: Platform
    gravity: float                # m/s^2 along -Z
    trajectory: Sinusoid | ViaPoints | SampledPoses   # [trajectory] kind
    simulation: Simulation
    damping: Damping
    clearance: Clearances
    sampling: Sampling
    contact: ContactLaw
    beam: BeamTheory = BeamTheory()   # [beam]: the links' beam theory (default Euler-Bernoulli)
    actuator: Actuator = Actuator()   # [actuator]: how the motors drive the cranks (contact level)
    tolerance: Tolerances = Tolerances()
    uncertain: UncertainInputs = UncertainInputs()   # [uncertain.*], [correlation.*] (rss6core/uncertain.py)
    source_text: str = field(default="", repr=False, compare=False)
    source_path: str = field(default="", repr=False, compare=False)

    @property
    def times(self) -> np.ndarray:
        """Output time grid t_k = k dt on [0, duration], s."""
        n = int(round(self.trajectory.duration / self.time_step))
        return np.arange(n + 1) * self.time_step

    @property
    def time_step(self) -> float:
        return self.simulation.time_step

    @property
    def gravity_vector(self) -> np.ndarray:
        return np.array([0.0, 0.0, -self.gravity])


# --- the schema ------------------------------------------------------------

@dataclass(frozen=True)
class _Key:
    kind: type                  # float, int, str or bool
    length: int | None = None   # array length, None for a scalar
    check: str | None = None    # 'positive', 'nonnegative', 'unit' (0, 1]
    default: object = None      # value when the key is absent; None: the key is required
    choices: tuple = ()         # allowed strings
    bounds: tuple = ()          # (lo, hi) closed interval for numbers


_POS, _NONNEG = "positive", "nonnegative"
_UNSET = float("nan")   # a key whose default depends on other keys
STEADY_AFTER = 0.75     # s: default window boundary, measured on paper's contact level (docs/model.md)


def _steady_after(value: float, duration: float, duration_key: str) -> float:
    """The window boundary t_s (s): the key's value, checked to lie in [0, duration), or by default
    STEADY_AFTER, at most half the duration (a short scene keeps a start-up and a steady window)."""
    if np.isnan(value):
        return min(STEADY_AFTER, duration / 2)
    if value >= duration:
        raise SceneError(f"[simulation] steady_after_s: must be shorter than {duration_key} "
                         f"= {duration!r}, got {value!r}")
    return value


def _check_startup_samples(settle: float, steady_after: float, dt: float) -> None:
    """SceneError if a start-up window [settle, steady_after) is asked for (settle < steady_after) but holds
    no sample k dt of the output grid (its maxima would be NaN in every finished realisation); the same
    comparisons as the pipeline's window masks. steady_after <= settle asks for no start-up window."""
    if steady_after <= settle:
        return
    first = max(0, int(np.ceil((settle - 1e-12) / dt)) - 1)
    if not any(settle - 1e-12 <= k * dt < steady_after - 1e-12 for k in range(first, first + 3)):
        raise SceneError(f"[simulation] steady_after_s: the start-up window [settle_time_s, steady_after_s) = "
                         f"[{settle!r}, {steady_after!r}) s holds no output sample (time_step_s = {dt!r} s); put "
                         "steady_after_s a step or more after settle_time_s, or at most settle_time_s for none")


def _check_not_the_end_sample_alone(sim: dict, duration: float, dt: float) -> None:
    """SceneError if the whole or steady window, [settle_time_s, T] or [steady_after_s, T], would hold the end
    sample T alone (s): its maximum would be that sample's, an end-sample artefact, and its mean the same."""
    for key in ("settle_time_s", "steady_after_s"):
        if sim[key] > duration - dt + 1e-12:
            window = "whole" if key == "settle_time_s" else "steady"
            raise SceneError(f"[simulation] {key}: the {window} window [{sim[key]!r}, {duration!r}] s holds only the "
                             f"end sample (time_step_s = {dt!r} s); put {key} at least a step before the end")


_SCHEMA: dict = {
    "name": _Key(str),
    "geometry": {
        "base_radius_m": _Key(float, check=_POS),
        "base_angles_deg": _Key(float, 6),
        "platform_radius_m": _Key(float, check=_POS),
        "platform_angles_deg": _Key(float, 6),
        "crank_length_m": _Key(float, check=_POS),
        "rod_length_m": _Key(float, check=_POS),
        "actuator_offsets_deg": _Key(float, 6, default=(0.0,) * 6),   # the cranks' true - commanded angle
    },
    "crank_section": {"axial_width_m": _Key(float, check=_POS),
                      "height_m": _Key(float, check=_POS)},
    "rod_section": {"outer_diameter_m": _Key(float, check=_POS),
                    "inner_diameter_m": _Key(float, check=_NONNEG)},
    "material": {"density_kg_m3": _Key(float, check=_POS),
                 "youngs_modulus_Pa": _Key(float, check=_POS),
                 "shear_modulus_Pa": _Key(float, check=_POS)},
    "platform": {"mass_kg": _Key(float, check=_POS),
                 "inertia_kg_m2": _Key(float, 3, check=_POS)},
    "environment": {"gravity_m_s2": _Key(float, check=_NONNEG)},
    "simulation": {
        "time_step_s": _Key(float, check=_POS),
        "model": _Key(str, default="elastic", choices=MODELS),
        "integrator": _Key(str, default="newmark", choices=INTEGRATORS),
        "elements_per_link": _Key(int, default=4, bounds=(1, MAX_ELEMENTS_PER_LINK)),
        "newmark_beta": _Key(float, default=0.25, bounds=(0.0, 0.5)),
        "newmark_gamma": _Key(float, default=0.5, bounds=(0.0, 1.0)),
        "hht_alpha": _Key(float, default=0.05, bounds=(0.0, 1.0 / 3.0)),
        "spectral_radius": _Key(float, default=0.8, bounds=(0.0, 1.0)),
        "quasi_static_eccentricity": _Key(str, default="drawn", choices=("drawn", "reaction")),
        "contact_time_step_s": _Key(float, default=1e-4, check=_POS),
        "contact_integrator": _Key(str, default="generalized-alpha", choices=INTEGRATORS),
        "settle_time_s": _Key(float, default=0.0, check=_NONNEG),
        "steady_after_s": _Key(float, default=_UNSET, check=_NONNEG),
        "contact_tolerance_m": _Key(float, default=0.0, check=_NONNEG),
        "contact_refinements": _Key(int, default=0, bounds=(0, MAX_CONTACT_REFINEMENTS)),
        "contact_start": _Key(str, default="drawn", choices=CONTACT_STARTS),
    },
    "sampling": {  # docs/model.md section 4; mean and std as fractions of the clearance size
        "radial_mean": _Key(float, default=0.5, bounds=(0.0, 1.0)),
        "radial_std": _Key(float, default=0.25, check=_NONNEG),
        "axial_mean": _Key(float, default=0.0, bounds=(-1.0, 1.0)),
        "axial_std": _Key(float, default=0.5, check=_NONNEG),
        "direction": _Key(str, default="uniform", choices=("uniform", "paper")),
        "size_tolerance": _Key(float, default=0.0, bounds=(0.0, 0.5)),
    },
    "beam": {"theory": _Key(str, default="euler-bernoulli", choices=BEAM_THEORIES),
             "rotary_inertia": _Key(bool, default=False),
             "mass": _Key(str, default="consistent", choices=MASS_MODELS),
             "link_modes": _Key(int, default=0, check=_NONNEG)},   # Craig-Bampton modes per link, 0: full mesh
    "actuator": {"drive": _Key(str, default="prescribed", choices=DRIVES),
                 "servo_stiffness_N_m_per_rad": _Key(float, default=0.0, check=_NONNEG)},
    "damping": {"mass_coefficient_per_s": _Key(float, check=_NONNEG),
                "stiffness_coefficient_s": _Key(float, check=_NONNEG)},
    "clearance": {"revolute_radial_m": _Key(float, check=_NONNEG),
                  "revolute_axial_m": _Key(float, check=_NONNEG),
                  "spherical_C_m": _Key(float, check=_NONNEG),
                  "spherical_B_m": _Key(float, check=_NONNEG)},
    "contact": {"journal_radius_m": _Key(float, check=_POS),
                "sphere_radius_m": _Key(float, check=_POS),
                "restitution": _Key(float, check="unit"),
                "exponent": _Key(float, check=_POS),
                "friction_coefficient": _Key(float, check=_NONNEG),
                "stick_velocity_m_s": _Key(float, check=_POS),
                "slip_velocity_m_s": _Key(float, check=_POS),
                "impact_speed_floor_m_s": _Key(float, default=1e-3, check=_POS),
                "stiffness_scale": _Key(float, default=1.0, check=_POS)},
}


_SINUSOID = {   # [trajectory] of kind "sinusoid" (eq. 35); the other kinds read their own tables
    "kind": _Key(str, default="sinusoid", choices=TRAJECTORY_KINDS),
    "frequency_Hz": _Key(float, check=_NONNEG),
    "position_offset_m": _Key(float, 3),
    "position_amplitude_m": _Key(float, 3),
    "angle_offset_deg": _Key(float, 3),
    "angle_amplitude_deg": _Key(float, 3),
    "duration_s": _Key(float, check=_POS),
}


def _trajectory(table) -> Sinusoid | ViaPoints | SampledPoses:
    """The [trajectory] table as its kind (default "sinusoid", eq. 35)."""
    if table is None:
        raise SceneError("missing key trajectory")
    if not isinstance(table, dict):
        raise SceneError("[trajectory] must be a table")
    kind = _scalar(table.get("kind", "sinusoid"), _SINUSOID["kind"], ("trajectory", "kind"))
    if kind == "points":
        return via_points(table)
    if kind == "file":
        return file_trajectory(table)
    tr = _read_table(table, _SINUSOID, ("trajectory",))
    deg = np.radians
    return Sinusoid(tr["frequency_Hz"], frozen_array(tr["position_offset_m"] + list(deg(tr["angle_offset_deg"]))),
                    frozen_array(tr["position_amplitude_m"] + list(deg(tr["angle_amplitude_deg"]))), tr["duration_s"])


_BAND = {"law": _Key(str, choices=("normal", "uniform")), "low_m": _Key(float, check=_NONNEG),
         "high_m": _Key(float, check=_NONNEG), "std_m": _Key(float, default=0.0, check=_NONNEG)}


def _tolerances(table, clearance: dict, size_tolerance: float, contact: dict) -> Tolerances:
    """The [tolerance] section: per family a size band around the [clearance] nominal size, below
    the joint's radius as the nominal size is (:func:`_below_radius`)."""
    if not isinstance(table, dict):
        raise SceneError("[tolerance] must be a table")
    if table and size_tolerance > 0:
        raise SceneError("[tolerance]: give either [tolerance] bands or [sampling] size_tolerance, not both")
    if size_tolerance > 0:
        _relative_band_below_radius(clearance, contact)
    bands = {}
    for family, raw in table.items():
        if family not in Tolerances.__dataclass_fields__:
            near = difflib.get_close_matches(family, list(Tolerances.__dataclass_fields__), n=1)
            raise SceneError(f"unknown key [tolerance] {family}" + (f" (did you mean {near[0]!r}?)" if near else ""))
        if not isinstance(raw, dict):
            raise SceneError(f"[tolerance.{family}] must be a table")
        b = _read_table(raw, _BAND, ("tolerance", family))
        where, nominal = f"[tolerance.{family}]", clearance[f"{family}_m"]
        if not b["low_m"] < b["high_m"]:
            raise SceneError(f"{where} low_m: must be smaller than high_m, got {b['low_m']!r} >= {b['high_m']!r}")
        if b["law"] == "normal" and not b["low_m"] <= nominal <= b["high_m"]:
            raise SceneError(f"{where} low_m, high_m: must enclose the [clearance] {family}_m = {nominal!r}")
        _below_radius(f"{where} high_m", b["high_m"], CLEARANCE_RADII[f"{family}_m"], contact)
        if (b["law"] == "normal") != (b["std_m"] > 0):
            raise SceneError(f"{where} std_m: must be positive for law 'normal' and absent for 'uniform'")
        bands[family] = SizeBand(b["law"], b["low_m"], b["high_m"], b["std_m"])
    return Tolerances(**bands)


def _where(path: tuple[str, ...]) -> str:
    return f"[{'.'.join(path[:-1])}] {path[-1]}" if len(path) > 1 else path[0]


def toml_spelling(value) -> str:
    """A value as the TOML file spells it, with its kind where Python's spelling would differ."""
    if isinstance(value, bool):
        return f"{str(value).lower()} (a boolean)"
    if isinstance(value, str):
        return f"{json.dumps(value)} (a string)"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "[" + ", ".join(toml_spelling(v).split(" (")[0] for v in value) + "]"
    return repr(value)


def _scalar(value, spec: _Key, path) -> float | int | str | bool:
    if spec.kind is bool:
        if not isinstance(value, bool):
            raise SceneError(f"{_where(path)}: expected true or false, got {toml_spelling(value)}")
        return value
    if spec.kind is str:
        if not isinstance(value, str):
            raise SceneError(f"{_where(path)}: expected a string, got {toml_spelling(value)}")
        if spec.choices and value not in spec.choices:
            raise SceneError(f"{_where(path)}: {value!r} is not one of {', '.join(spec.choices)}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{_where(path)}: expected a number, got {toml_spelling(value)}")
    if spec.kind is int and not isinstance(value, int):
        raise SceneError(f"{_where(path)}: expected an integer, got {toml_spelling(value)}")
    if not math.isfinite(value):
        raise SceneError(f"{_where(path)}: must be finite, got {value!r}")
    bad = {_POS: value <= 0, _NONNEG: value < 0, "unit": not 0 < value <= 1}.get(spec.check, False)
    if bad:
        rule = {_POS: "positive", _NONNEG: "non-negative", "unit": "in (0, 1]"}[spec.check]
        raise SceneError(f"{_where(path)}: must be {rule}, got {value!r}")
    if spec.bounds and not spec.bounds[0] <= value <= spec.bounds[1]:
        raise SceneError(f"{_where(path)}: must lie in [{spec.bounds[0]:g}, {spec.bounds[1]:g}], "
                         f"got {value!r}")
    return spec.kind(value)


def _read_key(value, spec: _Key, path):
    if spec.length is None:
        return _scalar(value, spec, path)
    if not isinstance(value, list) or len(value) != spec.length:
        raise SceneError(f"{_where(path)}: expected a list of {spec.length} numbers, got {toml_spelling(value)}")
    return [_scalar(v, spec, path) for v in value]


def _read_table(table: dict, schema: dict, path: tuple[str, ...] = ()) -> dict:
    """Check ``table`` against ``schema``: no unknown, no missing keys, right types and signs."""
    for key in table:
        if key not in schema:
            near = difflib.get_close_matches(key, list(schema), n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise SceneError(f"unknown key {_where(path + (key,))}{hint}")
    out = {}
    for key, spec in schema.items():
        if key not in table:
            if isinstance(spec, _Key) and spec.default is not None:
                out[key] = spec.default
                continue
            if isinstance(spec, dict) and all(isinstance(v, _Key) and v.default is not None
                                              for v in spec.values()):
                out[key] = _read_table({}, spec, path + (key,))  # an optional table
                continue
            raise SceneError(f"missing key {_where(path + (key,))}")
        value = table[key]
        if isinstance(spec, dict):
            if not isinstance(value, dict):
                raise SceneError(f"[{'.'.join(path + (key,))}] must be a table")
            out[key] = _read_table(value, spec, path + (key,))
        else:
            out[key] = _read_key(value, spec, path + (key,))
    return out


def _check_actuator(actuator: dict, link_modes: int) -> None:
    """[actuator]: a servo drive has a positive stiffness, a prescribed one none, and a servo needs the
    full mesh (the journal's rotation is not a boundary DOF of the Craig-Bampton crank)."""
    stiffness = actuator["servo_stiffness_N_m_per_rad"]
    if actuator["drive"] == "servo" and stiffness == 0.0:
        raise SceneError("[actuator] servo_stiffness_N_m_per_rad: a servo drive needs a positive stiffness "
                         "(N m/rad, the position loop's), got 0.0")
    if actuator["drive"] == "prescribed" and stiffness > 0.0:
        raise SceneError("[actuator] servo_stiffness_N_m_per_rad: only with drive = 'servo' (a prescribed "
                         f"crank holds the commanded angle exactly), got {stiffness!r}")
    if actuator["drive"] == "servo" and link_modes:
        raise SceneError(f"[actuator] drive: 'servo' needs the full mesh, [beam] link_modes = 0 (got {link_modes})")


MAX_SIZE_M = 20.0   # a [geometry] length above this is a unit slip (a flight simulator's legs are a few metres)
# (table, key, lowest, highest, the slip a value outside suggests): beyond any link material (polymers to
# tungsten carbide, foams excluded) or a robot's environment (up to 10 g)
MAGNITUDES = (("material", "youngs_modulus_Pa", 1e8, 2e12, "a modulus in GPa or MPa written in Pa?"),
              ("material", "shear_modulus_Pa", 3e7, 1e12, "a modulus in GPa or MPa written in Pa?"),
              ("material", "density_kg_m3", 100.0, 25000.0, "a density in g/cm^3 written in kg/m^3?"),
              ("environment", "gravity_m_s2", 0.0, 100.0, "an acceleration in mm/s^2 written in m/s^2?"))


def _below_radius(where: str, size: float, radius: str, contact: dict) -> None:
    """A clearance is a small gap between pin and bore: a ``size`` (m) not below the joint's [contact]
    ``radius`` is refused (typically a value in mm written in an _m key)."""
    if size >= contact[radius]:
        raise SceneError(f"{where}: {size!r} m is not below [contact] {radius} = {contact[radius]!r} m "
                         "(a clearance in mm written in metres?)")


def _relative_band_below_radius(clearance: dict, contact: dict) -> None:
    """[sampling] size_tolerance draws each size up to RELATIVE_BAND_REACH x its nominal
    (:func:`.clearance.size_band`): that bound must stay below the joint's radius too."""
    for key, radius in CLEARANCE_RADII.items():
        high = RELATIVE_BAND_REACH * clearance[key]
        if high >= contact[radius]:
            raise SceneError(f"[sampling] size_tolerance: sizes are drawn up to {RELATIVE_BAND_REACH:g} x "
                             f"[clearance] {key} ({clearance[key]!r} m) = {high!r} m, not below [contact] "
                             f"{radius} = {contact[radius]!r} m")


def _check_clearances(clearance: dict, contact: dict) -> None:
    """Every [clearance] size below its joint's radius (:func:`_below_radius`)."""
    for key, radius in CLEARANCE_RADII.items():
        _below_radius(f"[clearance] {key}", clearance[key], radius, contact)


def _check_link_modes(modes: int, elements: int) -> None:
    """[beam] link_modes: at most the interior DOFs of the scene's mesh (:func:`.link_reduction.max_link_modes`)."""
    if modes > max_link_modes(elements):
        raise SceneError(f"[beam] link_modes: {modes} is more than the {max_link_modes(elements)} interior DOFs "
                         f"a link of [simulation] elements_per_link = {elements} has (0: the full mesh)")


def _build(v: dict, text: str, source: str) -> Scene:
    """The checked Scene of the parsed tables ``v`` (the consistency checks no single key can make)."""
    _check_magnitudes(v)
    _check_sections(v)
    _check_geometry(v["geometry"], v["contact"])
    _check_link_modes(v["beam"]["link_modes"], v["simulation"]["elements_per_link"])
    _check_actuator(v["actuator"], v["beam"]["link_modes"])
    _check_clearances(v["clearance"], v["contact"])
    _check_timing(v["simulation"], v["trajectory"])
    return _scene(v, text, source)


def _rod(section: dict) -> TubeSection:
    return TubeSection(section["outer_diameter_m"], section["inner_diameter_m"])


def _material(material: dict) -> Material:
    return Material(material["density_kg_m3"], material["youngs_modulus_Pa"], material["shear_modulus_Pa"])


def _check_magnitudes(v: dict) -> None:
    """SceneError for a material or gravity outside MAGNITUDES: a unit slip, on which the runs diverge."""
    for table, key, low, high, slip in MAGNITUDES:
        if not low <= v[table][key] <= high:
            raise SceneError(f"[{table}] {key}: {v[table][key]!r} lies outside [{low:g}, {high:g}], beyond any "
                             f"6-RSS robot's links and environment ({slip})")


def _check_sections(v: dict) -> None:
    """SceneError for a rod tube without a wall, a material's impossible Poisson ratio, platform moments no body
    has, or lumped mass without the rotary inertia it carries."""
    rod, mat = _rod(v["rod_section"]), _material(v["material"])
    if rod.inner_diameter >= rod.outer_diameter:
        raise SceneError("[rod_section] inner_diameter_m: must be smaller than outer_diameter_m, "
                         f"got {rod.inner_diameter!r} >= {rod.outer_diameter!r}")
    if not -1.0 < mat.poisson_ratio <= 0.5:
        raise SceneError(f"[material] shear_modulus_Pa: implies Poisson ratio E/(2G)-1 = "
                         f"{mat.poisson_ratio:.3f}, outside (-1, 0.5]")
    _rigid_body_moments(v["platform"]["inertia_kg_m2"], "[platform] inertia_kg_m2")
    if v["beam"]["mass"] == "lumped" and not v["beam"]["rotary_inertia"]:
        raise SceneError("[beam] mass: 'lumped' puts the sections' rotary inertia on the nodes' "
                         "rotations; set [beam] rotary_inertia = true")


def _check_geometry(g: dict, ct: dict) -> None:
    """SceneError for a size no 6-RSS robot has, nominal actuator offsets, or a friction ramp that ends
    before it starts."""
    for key in ("base_radius_m", "platform_radius_m", "crank_length_m", "rod_length_m"):
        if g[key] > MAX_SIZE_M:
            raise SceneError(f"[geometry] {key}: {g[key]!r} m is above {MAX_SIZE_M:g} m, no 6-RSS robot's size "
                             "(a length in mm written in metres?)")
    if any(g["actuator_offsets_deg"]):
        raise SceneError("[geometry] actuator_offsets_deg: the nominal offsets are 0 (the controller's zero); "
                         "draw them in an [uncertain.NAME] table")
    if ct["stick_velocity_m_s"] >= ct["slip_velocity_m_s"]:
        raise SceneError("[contact] stick_velocity_m_s: must be smaller than slip_velocity_m_s")


def _check_timing(sim: dict, tr) -> None:
    """SceneError unless the steps divide the trajectory's duration and the contact step the output step,
    and the windows hold samples; fills in the default steady_after_s (s)."""
    dt, duration, where = sim["time_step_s"], tr.duration, tr.duration_key
    try:
        check_step_count(duration, dt)
    except ValueError as exc:
        raise SceneError(f"[simulation] time_step_s: {exc} ({where})") from None
    if sim["settle_time_s"] >= duration:
        raise SceneError(f"[simulation] settle_time_s: must be shorter than {where} "
                         f"= {duration!r}, got {sim['settle_time_s']!r}")
    sim["steady_after_s"] = _steady_after(sim["steady_after_s"], duration, where)
    _check_startup_samples(sim["settle_time_s"], sim["steady_after_s"], dt)
    _check_not_the_end_sample_alone(sim, duration, dt)
    try:
        whole_steps(dt, sim["contact_time_step_s"], at_least=1)
    except ValueError:
        raise SceneError(f"[simulation] contact_time_step_s: must divide time_step_s = {dt!r} "
                         "into whole steps") from None


def _scene(v: dict, text: str, source: str) -> Scene:
    """The Scene of the checked tables ``v`` (SI; angles from degrees to radians)."""
    g, ct = v["geometry"], v["contact"]
    deg = np.radians
    return Scene(
        name=v["name"],
        geometry=Geometry(g["base_radius_m"], frozen_array(deg(g["base_angles_deg"])),
                          g["platform_radius_m"], frozen_array(deg(g["platform_angles_deg"])),
                          g["crank_length_m"], g["rod_length_m"], frozen_array(deg(g["actuator_offsets_deg"]))),
        crank_section=RectangleSection(v["crank_section"]["axial_width_m"],
                                       v["crank_section"]["height_m"]),
        rod_section=_rod(v["rod_section"]),
        material=_material(v["material"]),
        platform=Platform(v["platform"]["mass_kg"], frozen_array(v["platform"]["inertia_kg_m2"])),
        gravity=v["environment"]["gravity_m_s2"],
        trajectory=v["trajectory"],
        simulation=Simulation(**{k.removesuffix("_s").removesuffix("_m"): val
                                 for k, val in v["simulation"].items()}),
        damping=Damping(v["damping"]["mass_coefficient_per_s"],
                        v["damping"]["stiffness_coefficient_s"]),
        clearance=Clearances(**{k: v["clearance"][f"{k}_m"] for k in
                                ("revolute_radial", "revolute_axial", "spherical_C", "spherical_B")}),
        sampling=Sampling(**v["sampling"]),
        contact=ContactLaw(ct["journal_radius_m"], ct["sphere_radius_m"], ct["restitution"],
                           ct["exponent"], ct["friction_coefficient"], ct["stick_velocity_m_s"],
                           ct["slip_velocity_m_s"], ct["impact_speed_floor_m_s"],
                           ct["stiffness_scale"]),
        beam=BeamTheory(v["beam"]["theory"], v["beam"]["rotary_inertia"], v["beam"]["mass"], v["beam"]["link_modes"]),
        actuator=Actuator(v["actuator"]["drive"], v["actuator"]["servo_stiffness_N_m_per_rad"]),
        tolerance=_tolerances(v.get("tolerance", {}), v["clearance"], v["sampling"]["size_tolerance"], ct),
        uncertain=_uncertain(v),
        source_text=text, source_path=source)


def _uncertain(v: dict) -> UncertainInputs:
    """The [uncertain.*] and [correlation.*] tables (rss6core/uncertain.py), checked against the nominal keys."""
    try:
        inputs = parse_uncertain(v.get("uncertain", {}), v.get("correlation", {}), v)
    except UncertainInputError as exc:
        raise SceneError(str(exc)) from None
    _check_drawn_magnitudes(inputs)
    _check_drawn_inertia(inputs)
    return inputs


def _rigid_body_moments(moments, where: str) -> None:
    """SceneError unless principal moments (kg m^2) are those of a body: each at most the sum of the
    other two (I1 + I2 >= I3, as every mass distribution gives; equality for a flat plate)."""
    m = np.sort(np.asarray(moments, float))
    if m[0] + m[1] < m[2] * (1 - 1e-12):
        raise SceneError(f"{where}: principal moments {', '.join(f'{x:.6g}' for x in moments)} kg m^2 are no "
                         f"body's: the largest ({m[2]:.6g}) exceeds the sum of the other two ({m[0] + m[1]:.6g})")


def _check_drawn_inertia(inputs: UncertainInputs) -> None:
    """SceneError for an uncertain platform inertia whose law can draw moments no body has (a shared
    deviation added to all three can break I1 + I2 >= I3; a factor cannot)."""
    for item in inputs.inputs:
        if item.parameter == "platform.inertia_kg_m2":
            for d in item.draws([0.0, 1.0]):
                moments = item.realised(np.full(item.count, d))
                if np.all(np.isfinite(moments)):
                    _rigid_body_moments(moments, f"[uncertain.{item.name}] {item.parameter}: law {item.law!r} "
                                                 "can draw")


def _check_drawn_magnitudes(inputs: UncertainInputs) -> None:
    """SceneError for an uncertain material whose law can draw a value outside MAGNITUDES (a unit slip
    in its parameters, or a spread no robot has): such realised robots would diverge at their first step."""
    bounds = {f"{table}.{key}": (low, high, slip) for table, key, low, high, slip in MAGNITUDES}
    for item in inputs.inputs:
        if item.parameter in bounds:
            (low, high, slip), (lo, hi) = bounds[item.parameter], item.extremes()
            if lo < low or hi > high:
                raise SceneError(f"[uncertain.{item.name}] {item.parameter}: law {item.law!r} can draw values in "
                                 f"[{lo:.6g}, {hi:.6g}] {item.units}, outside [{low:g}, {high:g}], beyond any "
                                 f"6-RSS robot's links ({slip})")


def parse_scene(text: str, source: str = "<string>") -> Scene:
    """Build a scene from TOML text and check its trajectory stays in the workspace."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{source}: not valid TOML: {exc}") from None
    try:
        extra = {k: raw.pop(k, {}) for k in ("tolerance", "uncertain", "correlation")}
        extra["trajectory"] = _trajectory(raw.pop("trajectory", None))
        scene = _build(_read_table(raw, _SCHEMA) | extra, text, source)
        check_workspace(scene)
    except (SceneError, WorkspaceError, TrajectoryError) as exc:
        raise SceneError(f"{source}: {exc}") from None
    return scene


def _binary_kind(path) -> str:
    """What a binary file given as a scene looks like: a netCDF file (an rss6 output?) or nothing said."""
    with open(path, "rb") as f:
        head = f.read(8)
    return " (a netCDF file: an rss6 output?)" if head.startswith((b"\x89HDF", b"CDF")) else ""


def load_scene(path: str | Path) -> Scene:
    """Load and check a scene from a TOML file; SceneError naming the file if it cannot be read.
    A ``kind = "file"`` trajectory's samples are read here and carried in the scene text (:mod:`.pose_csv`).

    Shipped scenes are found by name in ``pipeline.scenes.catalogue``, not here: the core reads files only.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(f"{path}: no such scene file") from None
    except UnicodeDecodeError:
        raise SceneError(f"{path}: not a scene file but binary{_binary_kind(path)}; a CONFIG is a scene TOML "
                         "file or a shipped scene's name") from None
    except OSError as exc:
        raise SceneError(f"{path}: cannot read the scene file: {exc}") from None
    try:   # a kind = "file" trajectory's CSV, relative to the scene file, into the scene text
        text = with_pose_samples(text, Path(path).parent)
    except TrajectoryError as exc:
        raise SceneError(f"{path}: {exc}") from None
    return parse_scene(text, str(path))
