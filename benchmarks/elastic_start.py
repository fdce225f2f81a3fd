"""The elastic level's initial state: the quasi-static state consistent with eq. 32 against d = K^-1 F, v = a = 0.

Run on demand: ``python benchmarks/elastic_start.py [CONFIG]`` (default configs/paper.toml; a few seconds).  It
runs the scene's elastic level (its step and mesh, Newmark average acceleration as the paper scene's;
rss6core.elastic.simulate_elastic) from both
initial states and prints, per direction, the largest |acceleration error| over the first output steps (the
output at t = 0 and up to 10 ms) and over the whole run: what the naive start's stiff-mode ringing adds
(docs/guide.md, "Initial state").
"""
from __future__ import annotations

import argparse
import pathlib

import numpy as np

from rss6core import load_scene
from rss6core.assembly import build_elastic_model
from rss6core.elastic import _quasi_static_path, simulate_elastic

CONFIGS = pathlib.Path(__file__).resolve().parents[1] / "configs"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default=str(CONFIGS / "paper.toml"))
    args = parser.parse_args()
    scene = load_scene(args.config)
    sim = scene.simulation
    model = build_elastic_model(scene, sim.elements_per_link)
    d0 = _quasi_static_path(scene, model, np.array([0.0]), None).d[0]
    runs = {"quasi-static state (rss6)": None, "d = K^-1 F, v = a = 0": (d0, np.zeros_like(d0), np.zeros_like(d0))}
    print(f"{'initial state':28} {'window':14}" + "".join(f"{d:>10}" for d in ("x", "y", "z", "rx", "ry", "rz"))
          + "   (m/s^2, rad/s^2)")
    for name, initial in runs.items():
        r = simulate_elastic(scene, sim.elements_per_link, None, sim.time_step, model=model, initial=initial)
        a = np.abs(r.acceleration)
        for label, rows in (("t = 0", r.t == 0.0), ("t <= 10 ms", r.t <= 0.010), ("whole run", r.t >= 0.0)):
            print(f"{name:28} {label:14}" + "".join(f"{v:10.3g}" for v in a[rows].max(0)))


if __name__ == "__main__":
    main()
