"""Scene summaries for ``rss6 check``: what a user checks before launching a run."""
from __future__ import annotations

import numpy as np

from rss6core.dynamics import inverse_dynamics
from rss6core.kinematics import rigid_motion
from rss6core.sections import crank_inertia, rod_inertia

__all__ = ["scene_summary", "format_summary"]


def scene_summary(scene) -> dict:
    """JSON-ready summary: crank angles, torques and link masses along the scene's trajectory."""
    motion = rigid_motion(scene)
    loads = inverse_dynamics(scene, motion)
    alpha = np.degrees(motion.alpha)
    return {
        "scene": scene.name,
        "source": scene.source_path,
        "duration_s": scene.trajectory.duration,
        "time_step_s": scene.time_step,
        "steps": len(scene.times) - 1,
        "home_crank_angles_deg": alpha[0].tolist(),
        "crank_angle_range_deg": np.stack([alpha.min(0), alpha.max(0)], -1).tolist(),
        "max_actuator_torque_Nm": np.abs(loads.torque).max(0).tolist(),
        "max_joint_force_N": {j: np.linalg.norm(f, axis=-1).max(0).tolist() for j, f in
                              (("A", loads.force_A), ("C", loads.force_C), ("B", loads.force_B))},
        "link_masses_kg": {"crank": crank_inertia(scene).mass, "rod": rod_inertia(scene).mass,
                           "platform": scene.platform.mass},
    }


def format_summary(s: dict) -> str:
    """Human-readable table of :func:`scene_summary` (degrees, N m, N, kg)."""
    legs = "".join(f"{i:>9d}" for i in range(1, 7))
    row = lambda name, vals, fmt="9.3f": f"{name:<24s}" + "".join(f"{v:{fmt}}" for v in vals)  # noqa: E731
    lines = [
        f"scene {s['scene']!r} ({s['source']}): valid",
        f"trajectory {s['duration_s']} s in {s['steps']} steps of {s['time_step_s']} s",
        f"link masses: crank {s['link_masses_kg']['crank']:.4f} kg, rod "
        f"{s['link_masses_kg']['rod']:.4f} kg, platform {s['link_masses_kg']['platform']:.4f} kg",
        f"{'leg':<24s}{legs}",
        row("home crank angle [deg]", s["home_crank_angles_deg"]),
        row("min crank angle [deg]", [r[0] for r in s["crank_angle_range_deg"]]),
        row("max crank angle [deg]", [r[1] for r in s["crank_angle_range_deg"]]),
        row("max |torque| [N m]", s["max_actuator_torque_Nm"]),
    ] + [row(f"max |F_{j}| [N]", v) for j, v in s["max_joint_force_N"].items()]
    return "\n".join(lines)
