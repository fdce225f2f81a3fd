"""Why the contact level integrates with generalized-alpha: its peaks and Newton iterations against Newmark.

For configs/smoke.toml (or --scene), realisations 0..n-1 of seed 0 at the contact level on fixed steps
(no refinement), Newmark's average acceleration and generalized-alpha (the scene's rho_inf) at each of
--steps, against Newmark at --reference: per quantity, the range over directions of the median (over
the realisations) signed relative difference of each realisation's max |error| (as ensemble files
store it: every internal step, after the scene's settle time); failed runs; Newton iterations per
internal step (mean over the realisations); seconds per realisation (measured one row after another,
so they move with the machine's load).  docs/guide.md quotes its numbers.

    python benchmarks/contact_integrators.py [-n 6] [--steps 1e-4 5e-4] [--reference 2.5e-5]
"""
import argparse
import os
import time
from pathlib import Path

import numpy as np

from pipeline.files.records import error_summaries
from pipeline.vocabulary import FINISHED, QUANTITIES
from rss6core import load_scene, simulate_batch

SCENE = Path(__file__).resolve().parents[1] / "configs" / "smoke.toml"
INTEGRATORS = ("newmark", "generalized-alpha")


def run(scene, integrator: str, dt: float, n: int) -> dict:
    """Realisations 0..n-1 on a fixed step ``dt`` s: their maxima (n, 3, 6), NaN where failed, the
    failures, Newton iterations per step and seconds per realisation."""
    start = time.perf_counter()
    results = simulate_batch(scene, "contact", integrator, dt, None, 0, range(n), 0.0, 0)
    wall = (time.perf_counter() - start) / n
    ok = [r.status == FINISHED for r in results]
    peaks = np.stack([error_summaries(r, scene.simulation.settle_time)[0] if good else np.full((3, 6), np.nan)
                      for r, good in zip(results, ok)])
    per_step = np.mean([r.iterations / max(r.steps, 1) for r, good in zip(results, ok) if good] or [np.nan])
    return {"peaks": peaks, "failed": n - sum(ok), "iterations_per_step": per_step, "seconds": wall}


def differences(peaks: np.ndarray, reference: np.ndarray) -> str:
    """Per quantity: min..max over directions of the median signed relative difference, in %."""
    if np.isnan(peaks).all():
        return "every run failed"
    med = 100 * np.nanmedian((peaks - reference) / reference, axis=0)       # (3, 6)
    return "  ".join(f"{q} {np.nanmin(m):+6.1f}..{np.nanmax(m):+6.1f}" for q, m in zip(QUANTITIES, med))


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("-n", type=int, default=6, help="realisations (default 6)")
    p.add_argument("--steps", type=float, nargs="+", default=[1e-4, 5e-4], help="fixed steps, s")
    p.add_argument("--reference", type=float, default=2.5e-5, help="Newmark's reference step, s")
    p.add_argument("--scene", default=str(SCENE), help="scene file (default configs/smoke.toml)")
    args = p.parse_args(argv)
    scene = load_scene(args.scene)
    print(f"scene {scene.name}, n = {args.n}, load average at the start {os.getloadavg()[0]:.2f}")
    ref = run(scene, "newmark", args.reference, args.n)
    print(f"reference: newmark {args.reference * 1e6:g} us, {ref['failed']} failed, "
          f"{ref['iterations_per_step']:.2f} Newton iterations per step, {ref['seconds']:.2f} s per realisation")
    print("median relative difference of the maxima against the reference, % (min..max over directions)")
    for dt in args.steps:
        for integrator in INTEGRATORS:
            row = run(scene, integrator, dt, args.n)
            print(f"{integrator:>17} {dt * 1e3:g} ms: {differences(row['peaks'], ref['peaks'])}  "
                  f"failed {row['failed']}/{args.n}, {row['iterations_per_step']:.2f} iterations per step, "
                  f"{row['seconds']:.2f} s per realisation")


if __name__ == "__main__":
    main()
