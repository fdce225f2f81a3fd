"""The workspace along a scene's trajectory for ``rss6 check``: every pose reachable, each crank's angle
range, how far each leg is from its crank-rod singularity and how well the platform Jacobian is
conditioned, each with the time where it is worst (rss6core.workspace_quality)."""
from __future__ import annotations

import numpy as np

from rss6core import workspace_quality

__all__ = ["workspace_summary", "format_workspace", "NEAR_SINGULAR"]

# a leg's transmission index below this (the crank-rod angle within about 6 deg of its singularity) gets a
# warning: crank rates and torques grow as its inverse, and the elastic levels may not converge there
NEAR_SINGULAR = 0.1


def workspace_summary(scene) -> dict:
    """JSON-ready workspace report on the scene's time grid (s, degrees, dimensionless indices).

    A pose out of reach never gets here: the scene parser refuses it (one line naming leg and time)."""
    q = workspace_quality(scene)
    t, alpha = q.t, np.degrees(q.alpha)
    reach, trans = q.reach.max(0), q.transmission.min(0)
    worst = int(np.argmax(q.condition))
    return {"workspace": {
        "trajectory_kind": scene.trajectory.kind,
        "poses": len(t),
        "reachable": True,
        "crank_angle_range_time_s": np.stack([t[alpha.argmin(0)], t[alpha.argmax(0)]], -1).tolist(),
        "max_reach_ratio": reach.tolist(),     # |K/rho| <= 1: the joint b_i within the leg's reach
        "max_reach_ratio_time_s": t[q.reach.argmax(0)].tolist(),
        "min_transmission_index": trans.tolist(),   # |n . dc/dalpha| / (L_ac L_cb): 0 at a singularity
        "min_transmission_index_time_s": t[q.transmission.argmin(0)].tolist(),
        "max_condition_number": float(q.condition[worst]),
        "max_condition_number_time_s": float(t[worst]),
    }}


def format_workspace(s: dict) -> list[str]:
    """Lines of :func:`workspace_summary` for ``rss6 check``'s text: one row per quantity and leg, and
    the row of the times (s) where each leg's value is worst."""
    w = s["workspace"]   # crank angle ranges: the summary's crank_angle_range_deg
    row = lambda name, vals, fmt="9.3f": f"{name:<24s}" + "".join(f"{v:{fmt}}" for v in vals)  # noqa: E731
    return [
        f"workspace along the trajectory ({w['trajectory_kind']}, {w['poses']} poses): every pose reachable",
        f"{'leg':<24s}" + "".join(f"{i:>9d}" for i in range(1, 7)),
        row("max |K/rho| (<= 1)", w["max_reach_ratio"]),
        row("  at t [s]", w["max_reach_ratio_time_s"]),
        row("min transmission index", w["min_transmission_index"]),
        row("  at t [s]", w["min_transmission_index_time_s"]),
        row("min crank angle at t [s]", [r[0] for r in w["crank_angle_range_time_s"]]),
        row("max crank angle at t [s]", [r[1] for r in w["crank_angle_range_time_s"]]),
        f"platform Jacobian: max condition number {w['max_condition_number']:.3f} "
        f"at t = {w['max_condition_number_time_s']:.3f} s",
    ] + _near_singular(w)


def _near_singular(w: dict) -> list[str]:
    """A warning line where a leg's transmission index falls below NEAR_SINGULAR, else none."""
    worst = int(np.argmin(w["min_transmission_index"]))
    index = w["min_transmission_index"][worst]
    if index >= NEAR_SINGULAR:
        return []
    return [f"warning: leg {worst + 1} comes within {np.degrees(np.arcsin(index)):.2g} deg of its crank-rod "
            f"singularity (transmission index {index:.3g} < {NEAR_SINGULAR:g}) at t = "
            f"{w['min_transmission_index_time_s'][worst]:.3f} s: crank rates and torques grow as 1 / index there, "
            "and the elastic, paper and contact levels may not converge; move the trajectory away from it"]
