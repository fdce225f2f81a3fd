"""Uncertain scene parameters: the ``[uncertain.NAME]`` tables, their laws and their draws.

A table names one existing scene key (``parameter = "table.key"``), how many draws it takes
(``each``: one shared draw, or one per leg, joint or link, :data:`UNCERTAIN_KEYS`) and a law of the
deviation from the nominal value (docs/model.md section 4b).  Every law is a scipy.stats
distribution sampled through its inverse CDF (ppf), so a realisation's inputs are a function of a
vector of uniforms: a seeded stream of their own (:func:`input_rng`, never the clearance stream), or
a quasi-Monte Carlo point's last coordinates (:func:`inputs_from_uniforms`).  An optional Gaussian
copula (``[correlation.NAME]``) correlates inputs with as many draws each.

Unbounded laws (normal, lognormal) are truncated at their :data:`TAIL` and 1 - :data:`TAIL`
quantiles: the scene check refuses a law whose truncated range holds an impossible value, and a draw
never leaves that range.  Parsing raises :class:`UncertainInputError`; the scene reader turns it into
a SceneError naming the file.
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.special import ndtr, ndtri

from .clearance import CLEARANCE_RADII

__all__ = ["UncertainInputError", "UncertainKey", "UNCERTAIN_KEYS", "LAWS", "TAIL", "INPUT_STREAM",
           "UncertainInput", "Correlation", "UncertainInputs", "InputDraw", "parse_uncertain", "input_rng",
           "inputs_from_uniforms", "draw_inputs"]

TAIL = 1e-9           # unbounded laws are cut at their TAIL and 1 - TAIL quantiles
INPUT_STREAM = 38     # spawn key of the inputs' stream: SeedSequence([seed, r], spawn_key=(38,))


class UncertainInputError(ValueError):
    """A bad [uncertain.NAME] or [correlation.NAME] table; the message names the table and key."""


@dataclass(frozen=True)
class UncertainKey:
    """A scene key that may be drawn: its TOML unit suffix, file units, SI scale, the ``each`` it
    takes (and how many draws each gives) and the values it can physically hold."""
    suffix: str        # unit suffix of the TOML key and of the law parameters ("" dimensionless)
    units: str         # UDUNITS string of the SI value
    scale: float       # SI value per TOML value (pi/180 for degrees)
    each: tuple        # ((each, draws), ...)
    possible: str      # 'any', 'positive', 'nonnegative' or 'unit' (0, 1]


_DEG = math.pi / 180.0
_LEG, _JOINT = (("one", 1), ("leg", 6)), (("one", 1), ("joint", 6))
_LINK, _CONTACT = (("one", 1), ("link", 12)), (("one", 1), ("joint", 18))
UNCERTAIN_KEYS = {
    "geometry.crank_length_m": UncertainKey("m", "m", 1.0, _LEG, "positive"),
    "geometry.rod_length_m": UncertainKey("m", "m", 1.0, _LEG, "positive"),
    "geometry.base_radius_m": UncertainKey("m", "m", 1.0, _JOINT, "positive"),
    "geometry.platform_radius_m": UncertainKey("m", "m", 1.0, _JOINT, "positive"),
    "geometry.base_angles_deg": UncertainKey("deg", "rad", _DEG, _JOINT, "any"),
    "geometry.platform_angles_deg": UncertainKey("deg", "rad", _DEG, _JOINT, "any"),
    "geometry.actuator_offsets_deg": UncertainKey("deg", "rad", _DEG, _LEG, "any"),
    "material.youngs_modulus_Pa": UncertainKey("Pa", "Pa", 1.0, _LINK, "positive"),
    "material.density_kg_m3": UncertainKey("kg_m3", "kg m-3", 1.0, _LINK, "positive"),
    "platform.mass_kg": UncertainKey("kg", "kg", 1.0, (("one", 1),), "positive"),
    "platform.inertia_kg_m2": UncertainKey("kg_m2", "kg m2", 1.0, (("one", 1),), "positive"),
    "contact.friction_coefficient": UncertainKey("", "1", 1.0, _CONTACT, "nonnegative"),
    "contact.restitution": UncertainKey("", "1", 1.0, _CONTACT, "unit"),
    **{f"clearance.{family}": UncertainKey("m", "m", 1.0, _JOINT, "clearance") for family in CLEARANCE_RADII},
}

# per law: required parameters, optional ones with defaults (in the key's unit; lognormal's are
# dimensionless, a factor on the nominal value)
LAWS = {
    "normal": (("std",), {"mean": 0.0}),
    "truncated-normal": (("std", "low", "high"), {"mean": 0.0}),
    "lognormal": (("sigma",), {"median": 1.0}),
    "uniform": (("low", "high"), {}),
    "triangular": (("low", "mode", "high"), {}),
}
_TABLE_KEYS = ("parameter", "each", "law")


@dataclass(frozen=True)
class UncertainInput:
    """One [uncertain.NAME] table, checked: the key, how many draws, the law and its parameters
    (in the key's TOML unit, as written; :meth:`deviation` turns uniforms into SI values)."""
    name: str
    parameter: str        # "table.key"
    each: str             # one | leg | joint | link
    count: int            # draws per realisation
    law: str
    parameters: tuple     # ((name, value), ...) without the unit suffix
    nominal: tuple        # the key's nominal SI value(s): 1, 3 or 6 components

    @property
    def key(self) -> UncertainKey:
        return UNCERTAIN_KEYS[self.parameter]

    @property
    def units(self) -> str:
        return self.key.units

    def labels(self) -> tuple[str, ...]:
        """One label per draw: NAME, NAME[leg i], NAME[joint i] (base or platform joint i), NAME[A1] ..
        NAME[B6] (the clearance joints), NAME[crank i] / NAME[rod i] (the links)."""
        if self.count == 1:
            return (self.name,)
        if self.each == "link":
            return tuple(f"{self.name}[{link} {i}]" for link in ("crank", "rod") for i in range(1, 7))
        if self.count == 18:
            return tuple(f"{self.name}[{j}{i}]" for j in "ACB" for i in range(1, 7))
        return tuple(f"{self.name}[{self.each} {i}]" for i in range(1, 7))

    def law_text(self) -> str:
        """The law as one line, its parameters with the key's unit suffix (file attributes, rss6 check)."""
        names = dict(self.parameters)
        suffix = "" if self.law == "lognormal" or not self.key.suffix else "_" + self.key.suffix
        kind = "factor" if self.law == "lognormal" else "deviation"
        return f"{self.law} {kind} (" + ", ".join(f"{k}{suffix}={v!r}" for k, v in names.items()) + ")"

    @cached_property
    def distribution(self):
        """The scipy.stats law of the deviation (TOML unit) or, for lognormal, of the factor; None
        for a point law (std or sigma 0). scipy.stats is imported here, at the first law, not by
        every process that imports rss6core (docs/performance.md section 31)."""
        from scipy import stats
        p = dict(self.parameters)
        if self.law == "normal":
            return stats.norm(p["mean"], p["std"]) if p["std"] > 0 else None
        if self.law == "truncated-normal":
            a, b = (p["low"] - p["mean"]) / p["std"], (p["high"] - p["mean"]) / p["std"]
            return stats.truncnorm(a, b, loc=p["mean"], scale=p["std"])
        if self.law == "lognormal":
            return stats.lognorm(p["sigma"], scale=p["median"]) if p["sigma"] > 0 else None
        if self.law == "uniform":
            return stats.uniform(p["low"], p["high"] - p["low"])
        return stats.triang((p["mode"] - p["low"]) / (p["high"] - p["low"]), p["low"], p["high"] - p["low"])

    def quantiles(self, u) -> np.ndarray:
        """The deviation (TOML unit), or the lognormal factor, at probabilities ``u``; unbounded
        laws cut at their TAIL quantiles."""
        u = np.asarray(u, float)
        dist = self.distribution
        if dist is None:   # a point law: std or sigma zero
            p = dict(self.parameters)
            return np.full(u.shape, p["median"] if self.law == "lognormal" else p["mean"])
        if self.law in ("normal", "lognormal"):
            u = np.clip(u, TAIL, 1.0 - TAIL)
        return dist.ppf(u)

    @property
    def draw_units(self) -> str:
        """Units of a draw: the key's SI unit for a deviation, "1" for a lognormal factor."""
        return "1" if self.law == "lognormal" else self.key.units

    def draws(self, u) -> np.ndarray:
        """The ``count`` draws from as many uniforms: SI deviations, or lognormal factors."""
        q = self.quantiles(u)
        return q if self.law == "lognormal" else q * self.key.scale

    def realised(self, draws) -> np.ndarray:
        """The key's SI values given the draws: nominal + deviation, or nominal x factor; one value
        per draw, or the key's components with one shared draw."""
        nominal, draws = np.asarray(self.nominal), np.asarray(draws, float)
        size = max(nominal.size, draws.size)
        nominal, draws = np.broadcast_to(nominal, (size,)), np.broadcast_to(draws, (size,))
        return nominal * draws if self.law == "lognormal" else nominal + draws

    def extremes(self) -> tuple[float, float]:
        """The smallest and largest SI value a draw can give the key (over its components)."""
        ends = [self.realised(np.full(self.count, d)) for d in self.draws([0.0, 1.0])]
        return float(min(e.min() for e in ends)), float(max(e.max() for e in ends))


@dataclass(frozen=True)
class Correlation:
    """One [correlation.NAME] table: a Gaussian copula over inputs with as many draws each."""
    name: str
    inputs: tuple         # input names, in the matrix's order
    matrix: tuple         # rows of the correlation matrix


@dataclass(frozen=True)
class UncertainInputs:
    """A scene's uncertain inputs in table order and their correlations; empty for most scenes."""
    inputs: tuple = ()
    correlations: tuple = ()

    @property
    def dimension(self) -> int:
        """Uniforms one realisation's inputs take (one per draw)."""
        return sum(i.count for i in self.inputs)

    def __bool__(self) -> bool:
        return bool(self.inputs)

    def labels(self) -> tuple[str, ...]:
        """Every draw's label, in a realisation's order (:meth:`UncertainInput.labels`)."""
        return tuple(label for i in self.inputs for label in i.labels())

    def columns(self, attribute) -> tuple:
        """``attribute(input)`` repeated for each of the input's draws, in a realisation's order."""
        return tuple(attribute(i) for i in self.inputs for _ in range(i.count))

    def offsets(self) -> dict:
        """Each input's first position in a realisation's uniforms (table order)."""
        out, at = {}, 0
        for i in self.inputs:
            out[i.name] = at
            at += i.count
        return out


# --- parsing -----------------------------------------------------------------

def _number(where: str, key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise UncertainInputError(f"{where} {key}: expected a finite number, got {value!r}")
    return float(value)


def _nominal(values: dict, parameter: str, key: UncertainKey) -> tuple:
    """The checked scene's nominal SI value(s) of the key."""
    table, name = parameter.split(".", 1)
    return tuple(float(x) for x in np.atleast_1d(np.asarray(values[table][name], float)) * key.scale)


def _law_parameters(where: str, raw: dict, law: str, key: UncertainKey) -> tuple:
    """The law's parameters without unit suffix, checked: none missing, unknown or in another unit."""
    required, optional = LAWS[law]
    suffix = "" if law == "lognormal" or not key.suffix else "_" + key.suffix
    names = {base + suffix: base for base in required + tuple(optional)}
    for given in raw:
        if given in _TABLE_KEYS or given in names:
            continue
        base = next((b for b in names.values() if given == b or given.startswith(b + "_")), None)
        if base is not None:
            why = "a factor, dimensionless" if law == "lognormal" else f"in the key's unit, {key.suffix or 'none'}"
            raise UncertainInputError(f"{where} {given}: law parameters are {why}: write {base + suffix}")
        near = difflib.get_close_matches(given, list(names) + list(_TABLE_KEYS), n=1)
        hint = f" (did you mean {near[0]!r}?)" if near else ""
        raise UncertainInputError(f"{where} {given}: not a parameter of law {law!r} "
                                  f"(it takes {', '.join(names)}){hint}")
    out = {}
    for full, base in names.items():
        if full in raw:
            out[base] = _number(where, full, raw[full])
        elif base in optional:
            out[base] = optional[base]
        else:
            raise UncertainInputError(f"{where} {full}: missing (law {law!r} takes {', '.join(names)})")
    return tuple(out.items())


def _check_law(where: str, law: str, p: dict, suffix: str) -> None:
    """Parameters a law cannot take: a negative spread, low >= high, a mode outside [low, high]."""
    s = "" if law == "lognormal" or not suffix else "_" + suffix
    for spread in ("std", "sigma"):
        if spread in p and (p[spread] < 0 or (law == "truncated-normal" and p[spread] <= 0)):
            rule = "positive" if law == "truncated-normal" else "non-negative"
            raise UncertainInputError(f"{where} {spread}{s}: must be {rule}, got {p[spread]!r}")
    if "low" in p and not p["low"] < p["high"]:
        raise UncertainInputError(f"{where} low{s}: must be smaller than high{s}, got {p['low']!r} >= {p['high']!r}")
    if "mode" in p and not p["low"] <= p["mode"] <= p["high"]:
        raise UncertainInputError(f"{where} mode{s}: must lie in [low{s}, high{s}], got {p['mode']!r}")
    if "median" in p and p["median"] <= 0:
        raise UncertainInputError(f"{where} median: a factor, must be positive, got {p['median']!r}")


_RULES = {"positive": (lambda lo, hi: lo > 0, "positive"),
          "nonnegative": (lambda lo, hi: lo >= 0, "non-negative"),
          "unit": (lambda lo, hi: lo > 0 and hi <= 1, "in (0, 1]"),
          "clearance": (lambda lo, hi: lo >= 0, "non-negative"),   # and below the joint's radius: _check_clearance
          "any": (lambda lo, hi: True, "")}


def _check_possible(where: str, item: UncertainInput) -> None:
    """Refuse a law that can draw an impossible value (its TAIL quantiles for unbounded laws)."""
    ok, rule = _RULES[item.key.possible]
    lo, hi = item.extremes()
    if not ok(lo, hi):
        ends = "its 1e-9 and 1-1e-9 quantiles" if item.law in ("normal", "lognormal") else "its bounds"
        raise UncertainInputError(f"{where} {item.parameter}: law {item.law!r} can draw values in "
                                  f"[{lo:.6g}, {hi:.6g}] {item.units} ({ends}), which must be {rule}")


def _check_clearance(where: str, item: UncertainInput, values: dict) -> None:
    """A drawn clearance size: below its joint's [contact] radius at every value the law can draw, and
    its family's size drawn by this table alone (no [tolerance.<family>] band, no [sampling]
    size_tolerance: those are the older form of the same draw)."""
    key = item.parameter.split(".", 1)[1]
    family, radius = key.removesuffix("_m"), CLEARANCE_RADII[key]
    if family in values.get("tolerance", {}) or values["sampling"]["size_tolerance"] > 0:
        other = f"[tolerance.{family}]" if family in values.get("tolerance", {}) else "[sampling] size_tolerance"
        raise UncertainInputError(f"{where} parameter: {item.parameter} is drawn by {other} already; give one of them")
    lo, hi = item.extremes()
    if hi >= values["contact"][radius]:
        raise UncertainInputError(f"{where} {item.parameter}: law {item.law!r} can draw sizes up to {hi:.6g} m, "
                                  f"not below [contact] {radius} = {values['contact'][radius]!r} m")


def _input(name: str, raw, values: dict, taken: dict) -> UncertainInput:
    where = f"[uncertain.{name}]"
    if not isinstance(raw, dict):
        raise UncertainInputError(f"{where} must be a table")
    for key in ("parameter", "law"):
        if not isinstance(raw.get(key), str):
            raise UncertainInputError(f"{where} {key}: missing or not a string")
    parameter, law = raw["parameter"], raw["law"]
    if parameter not in UNCERTAIN_KEYS:
        near = difflib.get_close_matches(parameter, list(UNCERTAIN_KEYS), n=1)
        hint = f" (did you mean {near[0]!r}?)" if near else ""
        raise UncertainInputError(f"{where} parameter: {parameter!r} is not a scene key that can be drawn{hint}")
    if parameter in taken:
        raise UncertainInputError(f"{where} parameter: {parameter} is already drawn by [uncertain.{taken[parameter]}]")
    if law not in LAWS:
        raise UncertainInputError(f"{where} law: {law!r} is not one of {', '.join(LAWS)}")
    key = UNCERTAIN_KEYS[parameter]
    each = raw.get("each", "one")
    if each not in dict(key.each):
        raise UncertainInputError(f"{where} each: {each!r} is not one of {', '.join(dict(key.each))} for {parameter}")
    if law == "lognormal" and key.possible == "any":
        raise UncertainInputError(f"{where} law: 'lognormal' is a factor on a positive value; {parameter} "
                                  "can be zero or negative, give a deviation law")
    params = _law_parameters(where, raw, law, key)
    _check_law(where, law, dict(params), key.suffix)
    count = dict(key.each)[each]
    item = UncertainInput(name, parameter, each, count, law, params, _nominal(values, parameter, key))
    _check_possible(where, item)
    if key.possible == "clearance":
        _check_clearance(where, item, values)
    return item


def _correlation(name: str, raw, inputs: dict, taken: dict) -> Correlation:
    """One [correlation.NAME]: inputs = [...] (two or more, same draw count), matrix = symmetric
    unit-diagonal positive-definite rows."""
    where = f"[correlation.{name}]"
    if not isinstance(raw, dict) or set(raw) != {"inputs", "matrix"}:
        raise UncertainInputError(f"{where} must be a table of exactly inputs = [names] and matrix = [[rows]]")
    names = raw["inputs"]
    if not isinstance(names, list) or len(names) < 2 or len(set(names)) != len(names):
        raise UncertainInputError(f"{where} inputs: expected a list of two or more distinct input names")
    for n in names:
        if n not in inputs:
            raise UncertainInputError(f"{where} inputs: {n!r} is no [uncertain.{n}] table")
        if n in taken:
            raise UncertainInputError(f"{where} inputs: {n!r} is already in [correlation.{taken[n]}]")
        if inputs[n].count != inputs[names[0]].count:
            raise UncertainInputError(f"{where} inputs: {n!r} has {inputs[n].count} draws, {names[0]!r} "
                                      f"{inputs[names[0]].count}; a copula pairs inputs with as many draws")
    try:
        m = np.array(raw["matrix"], dtype=float)
    except (TypeError, ValueError):
        raise UncertainInputError(f"{where} matrix: expected {len(names)} rows of {len(names)} numbers") from None
    if m.shape != (len(names),) * 2 or not np.all(np.isfinite(m)):
        raise UncertainInputError(f"{where} matrix: expected {len(names)} rows of {len(names)} numbers")
    if not np.array_equal(m, m.T) or not np.all(np.diag(m) == 1.0):
        raise UncertainInputError(f"{where} matrix: must be symmetric with ones on the diagonal")
    try:
        np.linalg.cholesky(m)
    except np.linalg.LinAlgError:
        raise UncertainInputError(f"{where} matrix: must be positive definite") from None
    return Correlation(name, tuple(names), tuple(tuple(row) for row in m.tolist()))


def parse_uncertain(tables, correlations, values: dict) -> UncertainInputs:
    """The checked [uncertain.*] and [correlation.*] tables of a scene whose other keys ``values``
    (table -> key -> TOML value) were checked already."""
    for kind, raw in (("uncertain", tables), ("correlation", correlations)):
        if not isinstance(raw, dict):
            raise UncertainInputError(f"[{kind}] must hold tables [{kind}.NAME]")
    taken, inputs = {}, {}
    for name, raw in tables.items():
        inputs[name] = _input(name, raw, values, taken)
        taken[inputs[name].parameter] = name
    grouped, out = {}, []
    for name, raw in correlations.items():
        out.append(_correlation(name, raw, inputs, grouped))
        grouped.update({n: name for n in out[-1].inputs})
    return UncertainInputs(tuple(inputs.values()), tuple(out))


# --- draws -------------------------------------------------------------------

@dataclass(frozen=True)
class InputDraw:
    """One realisation's drawn inputs, in table order: SI deviations (lognormal: factors)."""
    inputs: UncertainInputs
    values: np.ndarray    # (dimension,) the inputs' draws one after another

    def of(self, name: str) -> np.ndarray:
        """The draws (count,) of input ``name``."""
        at = self.inputs.offsets()[name]
        return self.values[at:at + {i.name: i.count for i in self.inputs.inputs}[name]]

    def realised(self, parameter: str) -> np.ndarray | None:
        """The SI value(s) of scene key ``parameter`` ("table.key") in this realisation, or None
        if it is not drawn."""
        item = next((i for i in self.inputs.inputs if i.parameter == parameter), None)
        return None if item is None else item.realised(self.of(item.name))


def input_rng(seed: int, realization: int) -> np.random.Generator:
    """The inputs' stream of realisation ``realization``: a spawned child of the clearance stream's
    SeedSequence([seed, r]), which never yields that stream's numbers."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(realization)],
                                                        spawn_key=(INPUT_STREAM,)))


def _copula(inputs: UncertainInputs, u: np.ndarray) -> np.ndarray:
    """The uniforms with each correlation's Gaussian copula applied: z = Phi^-1(u) of the grouped
    inputs' draws k, z' = L z (L the matrix's Cholesky factor), u' = Phi(z')."""
    if not inputs.correlations:
        return u
    u, at = u.copy(), inputs.offsets()
    count = {i.name: i.count for i in inputs.inputs}
    for c in inputs.correlations:
        rows = np.array([np.arange(at[n], at[n] + count[n]) for n in c.inputs])
        z = ndtri(np.clip(u[rows], TAIL, 1.0 - TAIL))
        u[rows] = ndtr(np.linalg.cholesky(np.array(c.matrix)) @ z)
    return u


def inputs_from_uniforms(inputs: UncertainInputs, u) -> InputDraw:
    """A realisation's inputs from ``inputs.dimension`` uniforms in [0, 1) (table order)."""
    u = np.asarray(u, float).ravel()
    if u.size != inputs.dimension:
        raise ValueError(f"the uncertain inputs take {inputs.dimension} uniforms, got {u.size}")
    u = _copula(inputs, u)
    parts, at = [], 0
    for item in inputs.inputs:
        parts.append(item.draws(u[at:at + item.count]))
        at += item.count
    return InputDraw(inputs, np.concatenate(parts) if parts else np.zeros(0))


def draw_inputs(scene, seed: int, realization: int, uniforms=None, offset: int = 0) -> InputDraw:
    """Realisation ``realization``'s inputs: from :func:`input_rng`, or from the last
    ``dimension`` of the ``offset + dimension`` uniforms ``uniforms(realization, n)`` returns
    (a QMC point whose first ``offset`` coordinates the clearance draw takes)."""
    inputs = scene.uncertain
    if uniforms is None:
        u = input_rng(seed, realization).uniform(size=inputs.dimension)
    else:
        u = np.asarray(uniforms(realization, offset + inputs.dimension), float)[offset:]
    return inputs_from_uniforms(inputs, u)
