"""The contact level's start on the paper scene: how the drawn start differs between realisations and how long
its start-up lasts, against the equilibrium start (docs/model.md L4 initial state, docs/guide.md).

Run on demand: ``python benchmarks/contact_start_spread.py [-n N] [--window S]`` (default 8 realisations of
seed 0, window 0.3 s; about a minute once the contact kernel is compiled).  For each start (``drawn``,
``equilibrium``) it runs realisations 0..N-1 of configs/paper.toml at the contact level and prints, per
quantity and direction, the spread of the realisations' maximum |error| over the first S seconds,
(largest - smallest) / largest.  Then how long the drawn start's start-up lasts against the equilibrium
start of the same realisation (the motion every realisation settles onto when the clearance sizes are fixed),
as the range over the realisations of the last output time at which
- its acceleration error exceeds 1000, 100 or 10 times the equilibrium run's largest |acceleration error|
  after S, in any direction (the impacts of the joints' fall onto their walls);
- its z displacement error (the sag on the loaded walls, the largest direction) differs from the equilibrium
  run's by more than 10, 5 or 1 % of the latter's largest |value| (the joints settling onto their walls).
"""
from __future__ import annotations

import argparse
import pathlib

import numpy as np

from rss6core import parse_scene
from rss6core.models import simulate_batch

CONFIGS = pathlib.Path(__file__).resolve().parents[1] / "configs"
QUANTITIES = ("displacement", "velocity", "acceleration")
DIRECTIONS = ("x", "y", "z", "rx", "ry", "rz")


def scene_with_start(start: str):
    text = (CONFIGS / "paper.toml").read_text()
    return parse_scene(text.replace("[simulation]\n", f'[simulation]\ncontact_start = "{start}"\n', 1), "paper")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=8, help="realisations 0..N-1 of seed 0 (default 8)")
    parser.add_argument("--window", type=float, default=0.3, help="the start-up window, s (default 0.3)")
    args = parser.parse_args()
    runs = {start: simulate_batch(scene_with_start(start), "contact", seed=0, realizations=range(args.n))
            for start in ("drawn", "equilibrium")}
    print(f"spread of the max |error| over t < {args.window:g} s across {args.n} realisations, "
          "(largest - smallest) / largest, %:")
    print(f"{'start':12} {'quantity':13}" + "".join(f"{d:>8}" for d in DIRECTIONS))
    for start, results in runs.items():
        assert all(r.status == "finished" for r in results), [r.message for r in results]
        early = results[0].t < args.window
        for quantity in QUANTITIES:
            peaks = np.array([np.abs(getattr(r, quantity)[early]).max(0) for r in results])
            spread = 100 * (peaks.max(0) - peaks.min(0)) / peaks.max(0)
            print(f"{start:12} {quantity:13}" + "".join(f"{s:8.2g}" for s in spread))
    drawn, equilibrium = ({q: np.array([getattr(r, q) for r in runs[start]]) for q in ("displacement", "acceleration")}
                          for start in ("drawn", "equilibrium"))
    t = runs["drawn"][0].t

    def last(mask: np.ndarray) -> str:
        """Range over the realisations (axis 0) of the last time ``mask`` (R, T) holds, ms."""
        ends = [1e3 * t[np.flatnonzero(m)[-1]] if m.any() else 0.0 for m in mask]
        return f"{min(ends):.0f}-{max(ends):.0f} ms"

    calm = np.abs(equilibrium["acceleration"][:, t >= args.window]).max(1)            # (R, 6)
    for factor in (1000, 100, 10):
        loud = (np.abs(drawn["acceleration"]) > factor * calm[:, None, :]).any(2)
        print(f"drawn start: acceleration error above {factor:4d}x the equilibrium start's after "
              f"{args.window:g} s until {last(loud)}")
    z = DIRECTIONS.index("z")
    sag = np.abs(equilibrium["displacement"][:, :, z]).max(1)                              # (R,)
    for share in (0.10, 0.05, 0.01):
        off = np.abs(drawn["displacement"][:, :, z] - equilibrium["displacement"][:, :, z]) > share * sag[:, None]
        print(f"drawn start: z displacement error off the equilibrium start's by more than {100 * share:2.0f} % "
              f"of its sag until {last(off)}")

if __name__ == "__main__":
    main()
