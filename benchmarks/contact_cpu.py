"""Benchmark: CPU time of the contact level's steps on configs/paper.toml, and what they count.

Run on demand: ``python benchmarks/contact_cpu.py [--realizations R] [--config TOML] [--json]``
(``--config``: another scene, for example configs/paper_manufacturing.toml, whose realised robots
each run as a batch of their own: "per batch" then sums their precomputes).
One batch of R realisations (seed 0) after a warm-up of one, timed with the process's CPU time
(``time.process_time``: on a shared machine wall times mean little), split into the compiled steps
(``CompiledStepper.advance``), the fine-grid precompute (``_Chunk``: its base-step instants up front,
and, where the code has it, the interior instants a refined step fills during the steps) and the rest;
with the batch's
accepted steps, refused attempts (each retried as two halves) and Newton updates per attempt.
For an A/B comparison run it alternately with two installs' interpreters (each imports its own
``rss6core``) and compare medians.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[var] = "1"  # before numpy is imported: one core, as an ensemble worker has

import numpy as np  # noqa: E402

from rss6core import contact_dynamics, load_scene  # noqa: E402
from rss6core.models import simulate_batch  # noqa: E402

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "paper.toml"


class _Meter:
    """CPU seconds spent in the wrapped methods, and the last batch the stepper handed over."""

    def __init__(self):
        self.cpu = {"steps": 0.0, "precompute": 0.0, "fill": 0.0}
        self.batches = []       # every batch the steppers hand over (a realised robot's scene: one each)

    def timed(self, key, method):
        def wrapper(*args, **kwargs):
            start = time.process_time()
            try:
                return method(*args, **kwargs)
            finally:
                self.cpu[key] += time.process_time() - start
        return wrapper

    def install(self):
        cls = contact_dynamics.CompiledStepper
        cls.advance = self.timed("steps", cls.advance)
        chunk = contact_dynamics._Chunk
        chunk.__init__ = self.timed("precompute", chunk.__init__)
        if hasattr(chunk, "fill"):      # instants filled during the steps (an install that has them)
            chunk.fill = self.timed("fill", chunk.fill)
        handover = contact_dynamics.ContactStepper.batch

        def keep(stepper):
            self.batches.append(handover(stepper))
            return self.batches[-1]
        contact_dynamics.ContactStepper.batch = keep


def measure(realizations: int, config=CONFIG) -> dict:
    scene = load_scene(config)
    meter = _Meter()
    meter.install()
    simulate_batch(scene, "contact", realizations=[0])          # warm-up: numba's cache, imports
    meter.cpu, meter.batches = dict.fromkeys(meter.cpu, 0.0), []
    start = time.process_time()
    simulate_batch(scene, "contact", realizations=range(realizations))
    total = time.process_time() - start
    steps, refined, iterations = (np.concatenate([getattr(b, f) for b in meter.batches])
                                  for f in ("steps", "refined", "iterations"))
    fill = meter.cpu.pop("fill")
    meter.cpu["steps"] -= fill
    meter.cpu["precompute"] += fill
    attempts = int(steps.sum() + refined.sum())
    return {"realizations": realizations, "cpu_s": total,
            "steps_cpu_s_per_realization": meter.cpu["steps"] / realizations,
            "precompute_cpu_s_per_batch": meter.cpu["precompute"],
            "other_cpu_s": total - meter.cpu["steps"] - meter.cpu["precompute"],
            "accepted_steps": steps.tolist(), "refused_attempts": refined.tolist(),
            "newton_updates": iterations.tolist(),
            "newton_updates_per_attempt": float(iterations.sum() / attempts),
            "status": sorted({s for b in meter.batches for s in b.status})}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realizations", type=int, default=8, metavar="R", help="batch size (default 8)")
    parser.add_argument("--config", type=Path, default=CONFIG, help="scene TOML (default configs/paper.toml)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args(argv)
    if args.realizations < 1:
        parser.error("--realizations must be at least 1")
    out = measure(args.realizations, args.config)
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"contact, {args.config.name}, {out['realizations']} realisations: {out['cpu_s']:.2f} s CPU; "
          f"steps {out['steps_cpu_s_per_realization']:.4f} s per realisation, precompute "
          f"{out['precompute_cpu_s_per_batch']:.2f} s per batch, other {out['other_cpu_s']:.2f} s; "
          f"{sum(out['accepted_steps'])} steps, {sum(out['refused_attempts'])} refused, "
          f"{out['newton_updates_per_attempt']:.3f} Newton updates per attempt")
    return 0


if __name__ == "__main__":
    sys.exit(main())
