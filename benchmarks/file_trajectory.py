"""The trajectory kind "file": eq. 35 of the paper scene sampled at 1 ms against the sinusoid itself (docs/model.md).

Run on demand: ``python benchmarks/file_trajectory.py [--seed S] [--step DT]`` (a few seconds).  It writes
eq. 35 (configs/paper.toml's [trajectory] values) every DT s to a CSV, runs the paper scene as ``kind = "file"``
on it and as the sinusoid with ``rss6core.simulate`` at the quasi-static and elastic levels on the same seed,
and prints per level and quantity the largest relative difference of the max and mean |error| over the six
directions, then the largest difference of the rigid actuator torques (``inverse_dynamics``) relative to
their largest magnitude.  tests/test_trajectory_kinds.py asks 1e-3 of both, on seed 7.
"""
from __future__ import annotations

import argparse
import pathlib
import tempfile

import numpy as np

from rss6core import inverse_dynamics, load_scene, rigid_motion, simulate

CONFIGS = pathlib.Path(__file__).resolve().parents[1] / "configs"
HEADER = "t_s,x_m,y_m,z_m,n1_deg,n2_deg,n3_deg"


def eq35_csv(path: pathlib.Path, dt: float, duration: float = 2.0) -> None:
    """The paper scene's eq. 35 (its [trajectory] values written out here) sampled every ``dt`` s."""
    t = np.arange(int(round(duration / dt)) + 1) * dt
    s = np.sin(2 * np.pi * 1.0 * t)[:, None]
    pose = np.array([0.0, 0.0, -0.387, 0, 0, 0]) + np.array([0.0, 0.050, 0.080, 20.0, 20.0, 0.0]) * s
    path.write_text("\n".join([HEADER, *(",".join(repr(float(v)) for v in (ti, *p)) for ti, p in zip(t, pose))])
                    + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--step", type=float, default=1e-3, help="the CSV's sample spacing, s (default 1 ms)")
    args = parser.parse_args()
    text = (CONFIGS / "paper.toml").read_text()
    start, end = text.index("[trajectory]"), text.index("[simulation]")
    with tempfile.TemporaryDirectory() as folder:
        eq35_csv(pathlib.Path(folder) / "eq35.csv", args.step)
        scene_file = pathlib.Path(folder) / "paper_file.toml"
        scene_file.write_text(text[:start] + '[trajectory]\nkind = "file"\npath = "eq35.csv"\n\n' + text[end:])
        by_file_scene = load_scene(scene_file)
    paper = load_scene(CONFIGS / "paper.toml")
    print(f"seed {args.seed}, samples every {args.step:g} s; largest relative difference over the six directions")
    for model in ("quasi-static", "elastic"):
        by_file, by_sine = simulate(by_file_scene, model, seed=args.seed), simulate(paper, model, seed=args.seed)
        for quantity in ("displacement", "velocity", "acceleration"):
            a, b = np.abs(getattr(by_file, quantity)), np.abs(getattr(by_sine, quantity))
            with np.errstate(all="ignore"):
                rel = [np.nanmax(np.abs(f(a) - f(b)) / np.abs(f(b))) for f in (lambda e: e.max(0),
                                                                              lambda e: e.mean(0))]
            print(f"{model:12} {quantity:12}  max {rel[0]:.1e}  mean {rel[1]:.1e}")
    torque = inverse_dynamics(by_file_scene, rigid_motion(by_file_scene)).torque
    ref = inverse_dynamics(paper, rigid_motion(paper)).torque
    print(f"rigid actuator torques: {np.abs(torque - ref).max() / np.abs(ref).max():.1e} of the largest")


if __name__ == "__main__":
    main()
