"""What ``rss6 allocate`` writes: the class table, costs and verification verdicts as text, a CF
netCDF Dataset and plain JSON."""
from __future__ import annotations

import numpy as np
import xarray as xr

from ..analysis.gate import format_verdicts, overall, verdicts_json
from ..files.schema import _provenance, command_line
from .allocation import Allocation
from ..vocabulary import CONFIDENCE, counted
from .fits import COST_LAW
from .trial import SELECTION_NOTE, fresh_check_command as fresh_check

__all__ = ["format_allocation", "allocation_dataset", "allocation_json", "COST_NOTE", "SELECTION_NOTE",
           "fresh_check_command"]

COST_NOTE = (f"relative units per joint: ISO 286 fit cost C(T_hole) + C(T_shaft), C(T) = {COST_LAW.a:g} + "
             f"{COST_LAW.b:g} ({COST_LAW.reference * 1e6:g} um / T)^{COST_LAW.k:g} (reciprocal-power law, "
             "Chase et al. 1990), unless --costs gives them")


def _saving(a: Allocation) -> str:
    if a.uniform_cost is None:
        return ("no single class for every family meets the specs" if a.method.startswith("exact") else
                "the cheapest uniform class that meets the specs was not found within the ensemble budget")
    name = a.uniform[0].name
    return (f"cheapest uniform class {name}: cost {a.uniform_cost:.4g}; allocation saves "
            f"{a.uniform_cost - a.cost:.4g} ({100 * (1 - a.cost / a.uniform_cost):.1f} %)")


def _rows(a: Allocation) -> list[str]:
    """The table's row labels: the joints (A1 revolute_radial, ...) or the families."""
    return [f"{j} {c.family}" for j, c in zip(a.joints, a.classes)] if a.joints else [c.family for c in a.classes]


def format_allocation(a: Allocation, scene_name: str, model: str, n: int, cost_note: str,
                      fresh_check: str | None = None) -> str:
    """The answer as lines: the class table, total against uniform, the verification's verdicts, what
    they can say (:data:`SELECTION_NOTE`) and ``fresh_check``, the command that judges fresh draws."""
    width = 21 if a.joints else 18
    lines = [f"fit allocation: scene {scene_name}, {model} level, n = {n} realisations, "
             f"{counted(a.combinations, 'class combination')} judged ({a.method})",
             f"costs: {cost_note}",
             f"{'joint' if a.joints else 'family':{width}}{'class':10}{'radial band (um)':>20}{'cost/joint':>12}"
             f"{'joints':>8}"]
    for label, c in zip(_rows(a), a.classes):
        band = f"{c.low * 1e6:.4g}-{c.high * 1e6:.4g}"
        lines.append(f"{label:{width}}{c.name:10}{band:>20}{c.cost:12.4g}{1 if a.joints else 6:8d}")
    lines.append(f"total cost {a.cost:.4g}; {_saving(a)}")
    lines.append(_predicted_line(a, n))
    lines.append(f"scene at the answer: {a.scene_path or 'none (per-joint bands; a scene has one band a family)'}")
    lines.append(f"verification ensemble {a.ensemble_path}: {overall(list(a.verdicts))}")
    lines.append(format_verdicts(list(a.verdicts)))
    lines.append(SELECTION_NOTE.format(what="verification") + (f"; a fresh check: {fresh_check}" if fresh_check else
                                   "; per-joint bands fit no scene, so rss6 run cannot recheck them"))
    return "\n".join(lines)


def _predicted_line(a: Allocation, n: int) -> str:
    """What the search judged each spec by at the answer, in the spec's own unit: the one-sided upper bound of
    its statistic, or for a pf spec the (k+1)-th largest maximum, which must meet the limit for at most the k
    exceedances its pf bound allows at n."""
    from ..analysis.spec import PF, parse_spec
    how = "predicted by the linear scaling" if "linear scaling" in a.method else "measured"
    said = []
    for text, value in a.predicted.items():
        spec = parse_spec(text)
        shown = f"{value / spec.factor:.4g} {spec.unit}"
        said.append(f"{text}: {shown}" if spec.statistic != PF else
                    f"{text}: the (k+1)-th largest maximum of n = {n}, {shown} (k: the exceedances pf allows)")
    return f"at the answer ({how}), the statistic's upper bound: " + "; ".join(said)


def fresh_check_command(a: Allocation, model: str, n: int, seed: int, specs: list[str],
                        confidence: float = CONFIDENCE) -> str | None:
    """The `rss6 run` of the answer's scene on the next seed (:func:`.trial.fresh_check_command`), or
    None for per-joint bands (no scene holds them)."""
    return None if a.scene_path is None else fresh_check(a.scene_path, model, n, seed, specs, confidence)


def allocation_dataset(a: Allocation, scene, model: str, integrator: str, dt: float, elements: int,
                       options: str, cost_note: str) -> xr.Dataset:
    """The allocation as a CF Dataset: per family its class, band (m) and cost; per verdict the
    verification's outcome and bounds; totals in the global attributes."""
    v = list(a.verdicts)
    upper = [np.nan if x.upper is None else x.upper for x in v]
    row = "joint" if a.joints else "family"
    extra = ({"joint_family": ("joint", [c.family for c in a.classes], {"long_name": "joint family"})}
             if a.joints else {})
    ds = xr.Dataset(
        {"fit_class": (row, [c.name for c in a.classes], {"long_name": "ISO 286 fit class chosen"}),
         "band_low": (row, [c.low for c in a.classes], {"long_name": "smallest radial clearance of the class",
                                                        "units": "m"}),
         "band_high": (row, [c.high for c in a.classes], {"long_name": "largest radial clearance of the class",
                                                          "units": "m"}),
         "cost_per_joint": (row, [c.cost for c in a.classes], {"long_name": f"cost per joint ({cost_note})",
                                                               "units": "1"}),
         **extra,
         "verdict_spec": ("verdict", [x.spec for x in v], {"long_name": "requirement spec"}),
         "verdict_direction": ("verdict", [x.direction for x in v], {"long_name": "direction judged"}),
         "verdict_outcome": ("verdict", [x.outcome for x in v], {"long_name": "verification verdict"}),
         "verdict_upper": ("verdict", upper, {"long_name": "one-sided upper bound of the statistic (SI: m, rad "
                                                           "and their rates)", "units": "1"}),
         "verdict_limit": ("verdict", [x.limit for x in v], {"long_name": "limit of the spec (SI)", "units": "1"})},
        coords={row: list(a.joints) if a.joints else [c.family for c in a.classes]})
    title = f"least-cost fit class per {'joint' if a.joints else 'joint family'} meeting the requirement specs"
    ds.attrs.update(_provenance(scene, title, model=model, integrator=integrator, dt=dt, elements=elements,
                                history=command_line("allocate", scene, model=model, integrator=integrator, dt=dt,
                                                     elements=elements, options=options)))
    ds.attrs.update(total_cost=a.cost, uniform_class=a.uniform[0].name if a.uniform else "none",
                    uniform_cost=np.nan if a.uniform_cost is None else a.uniform_cost,
                    combinations_judged=a.combinations, search_method=a.method, verification=overall(v),
                    verification_file=a.ensemble_path.name)
    return ds


def _si_units(predicted: dict) -> dict:
    """Each spec's SI unit (m, rad and their rates), that of its predicted value."""
    from ..analysis.spec import parse_spec, si_unit
    return {text: si_unit(spec.quantity, spec.directions[0]) for text, spec in ((t, parse_spec(t)) for t in predicted)}


def allocation_json(a: Allocation) -> dict:
    """The allocation as plain data (SI)."""
    joints = a.joints or (None,) * len(a.classes)
    return {"classes": [{"family": c.family, "class": c.name, "band_low_m": c.low, "band_high_m": c.high,
                         "cost_per_joint": c.cost, "joints": 1 if j else 6} | ({"joint": j} if j else {})
                        for j, c in zip(joints, a.classes)],
            "total_cost": a.cost, "uniform_class": a.uniform[0].name if a.uniform else None,
            "uniform_cost": a.uniform_cost, "combinations_judged": a.combinations, "method": a.method,
            "predicted_upper": a.predicted, "predicted_upper_si_unit": _si_units(a.predicted),
            "verification": overall(list(a.verdicts)),
            "verification_file": str(a.ensemble_path), "verification_draws": "the search's own (optimistic)",
            "scene": a.scene_path and str(a.scene_path),
            "verdicts": verdicts_json(list(a.verdicts))}
