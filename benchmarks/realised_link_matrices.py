"""What the contact level's realised robots leave out: link matrices at the nominal link lengths.

The contact kernel holds one crank and one rod matrix for all legs, so a realised robot's contact
run takes its link matrices at the nominal lengths (its realised material), while its motion,
frames, joint positions and loads are the realised ones (docs/model.md section 4b).  The elastic
level can hold per-leg matrices, so it measures what that costs: for realisations of
configs/paper_manufacturing.toml, the steady-window difference between the elastic run with
per-leg (exact) and nominal-length matrices, relative to the elastic part and to the total error
(elastic + geometric), per quantity and direction.

    python benchmarks/realised_link_matrices.py [-n 3]
"""
import argparse
import dataclasses
from pathlib import Path

import numpy as np

from rss6core.assembly import build_elastic_model
from rss6core.elastic import simulate_elastic
from rss6core.kinematics import rigid_motion
from rss6core.models import prepare_level, stored_inputs
from rss6core.realised import motion_error, realised_motion, realised_scene
from rss6core.scene import load_scene

SCENE = Path(__file__).resolve().parents[1] / "configs" / "paper_manufacturing.toml"


def compare(scene, level, r):
    """Largest steady |exact - nominal-length| over max |elastic| and over max |total| (3, 6) each."""
    real = realised_scene(scene, stored_inputs(scene, 0, r))
    motion = lambda t: realised_motion(real.geometry, rigid_motion(scene, t))   # noqa: E731
    exact = simulate_elastic(real, level.elements, level.integrator, level.dt, motion=motion)
    nominal = dataclasses.replace(real.geometry, crank_length=scene.geometry.crank_length,
                                  rod_length=scene.geometry.rod_length)
    approx = simulate_elastic(real, level.elements, level.integrator, level.dt, motion=motion,
                              model=build_elastic_model(dataclasses.replace(real, geometry=nominal), level.elements))
    ideal = rigid_motion(scene, exact.t)
    geometric = motion_error(realised_motion(real.geometry, ideal), ideal)
    steady = exact.t >= scene.simulation.steady_after
    of_elastic, of_total = [], []
    for q, f in enumerate(("displacement", "velocity", "acceleration")):
        e, a = getattr(exact, f)[steady], getattr(approx, f)[steady]
        diff = np.abs(e - a).max(0)
        of_elastic.append(diff / np.abs(e).max(0))
        of_total.append(diff / np.abs(e + geometric[q][steady]).max(0))
    return np.array(of_elastic), np.array(of_total)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=3, help="realisations (seed 0)")
    args = parser.parse_args()
    scene = load_scene(SCENE)
    level = prepare_level(scene, "elastic")
    worst_e, worst_t = np.zeros((3, 6)), np.zeros((3, 6))
    for r in range(args.n):
        e, t = compare(scene, level, r)
        worst_e, worst_t = np.maximum(worst_e, e), np.maximum(worst_t, t)
    np.set_printoptions(formatter={"float": "{:.1e}".format})
    print(f"{args.n} realisations of {SCENE.name}, steady window, x y z rx ry rz")
    for q, name in enumerate(("displacement", "velocity", "acceleration")):
        print(f"{name:13s} of the elastic part {worst_e[q]}  of the total error {worst_t[q]}")
    print(f"largest: {worst_e.max():.2e} of the elastic part, {worst_t.max():.2e} of the total error")


if __name__ == "__main__":
    main()
