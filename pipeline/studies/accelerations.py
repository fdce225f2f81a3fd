"""Steady-window acceleration maxima of the contact level against mesh, beam theory and step.

Issue 21, "accelerations you can defend": the same realisations (same seed) of the contact level
are run for each variant (elements per link; Euler-Bernoulli, or Timoshenko beams with rotary
inertia and consistent or lumped mass; the scene's contact step or half of it) and each
realisation's max |acceleration error| is taken per direction over the scene's steady window
(t >= ``[simulation] steady_after_s``, the boundary every ensemble file uses) on the output
histories.  The friction-excited ~100 Hz bursts are measured as the max over each burst window (BURSTS) of the
acceleration minus its running mean over BURST_PERIOD (which removes the slow trajectory-rate
part).  One command reruns it::

    python -m pipeline.studies.accelerations paper -n 6 -o docs/study   # minutes (docs/accelerations.md)

and writes DIR/acceleration_maxima.csv (every realisation) and DIR/acceleration_maxima.md (medians,
spread, the convergence verdict).
"""
from __future__ import annotations

import argparse
import csv
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rss6core import BeamTheory, SceneError, default_time_step, simulate_batch

from ..vocabulary import DIRECTIONS, FINISHED

__all__ = ["BURSTS", "Variant", "default_variants", "window_maxima", "measure",
           "converged", "study", "markdown", "main"]

BURSTS = ((0.9, 1.1), (1.9, 2.0))      # s, windows of the ~100 Hz friction-excited bursts
BURST_PERIOD = 0.01                    # s, one period of the ~100 Hz bursts
CONVERGED = 0.05                       # relative change between the two finest settings
EULER_BERNOULLI = BeamTheory()
TIMOSHENKO = BeamTheory("timoshenko", True)
LUMPED = BeamTheory("timoshenko", True, "lumped")   # the independent reference's formulation


@dataclass(frozen=True)
class Variant:
    """Elements per link, beam theory, and the factor on the scene's contact step (its adaptive
    tolerance and refinement count unchanged, so the smallest step scales with it too)."""
    elements: int
    beam: BeamTheory
    step_factor: float = 1.0

    @property
    def label(self) -> str:
        return f"{self.elements} el, {self.beam.label}, step x{self.step_factor:g}"


def default_variants(meshes=(1, 2, 4, 8, 16, 32)) -> list[Variant]:
    """Every beam model on every mesh at the scene's step; Euler-Bernoulli and Timoshenko with
    consistent mass at half the step on the two finest meshes."""
    out = [Variant(m, b) for b in (EULER_BERNOULLI, TIMOSHENKO, LUMPED) for m in meshes]
    return out + [Variant(m, b, 0.5) for b in (EULER_BERNOULLI, TIMOSHENKO) for m in sorted(meshes)[-2:]]


def window_maxima(t: np.ndarray, history: np.ndarray, start: float, end: float = np.inf) -> np.ndarray:
    """max |history| over start <= t <= end, per column (history (..., T, 6)); SI units as given."""
    inside = (t >= start - 1e-12) & (t <= end + 1e-12)
    return np.abs(history[..., inside, :]).max(axis=-2)


def high_pass(t: np.ndarray, history: np.ndarray, period: float = BURST_PERIOD) -> np.ndarray:
    """history (..., T, 6) minus its centred running mean over ``period`` (s, odd sample count),
    edges by the mean of the samples present; keeps content at 1 / period and above."""
    half = max(1, int(round(period / (t[1] - t[0]) / 2)))
    kernel = np.ones(2 * half + 1)
    counts = np.convolve(np.ones(len(t)), kernel, "same")
    mean = np.apply_along_axis(lambda x: np.convolve(x, kernel, "same") / counts, -2, history)
    return history - mean


def measure(scene, variant: Variant, n: int, seed: int = 0) -> dict:
    """Realisations 0..n-1 of the contact level in ``variant``: steady-window maxima (n, 6) of
    |acceleration error| and burst-window maxima (n, len(BURSTS), 6) of its high-passed part
    (:func:`high_pass`) (m/s^2, rad/s^2), seconds per
    realisation, failures (their maxima are NaN)."""
    import dataclasses
    sc = dataclasses.replace(scene, beam=variant.beam)
    start = time.perf_counter()
    results = simulate_batch(sc, "contact", None, default_time_step(scene, "contact") * variant.step_factor,
                             variant.elements, seed, range(n))
    wall = (time.perf_counter() - start) / n
    acc = np.stack([r.acceleration for r in results])
    bad = np.array([r.status != FINISHED for r in results])
    t = results[0].t
    steady = window_maxima(t, acc, scene.simulation.steady_after)
    fast = high_pass(t, acc)
    bursts = np.stack([window_maxima(t, fast, a, b) for a, b in BURSTS], 1)
    steady[bad], bursts[bad] = np.nan, np.nan
    return {"steady": steady, "bursts": bursts, "seconds_per_realization": wall, "failed": int(bad.sum()),
            "steady_after": scene.simulation.steady_after}


def converged(coarse: np.ndarray, fine: np.ndarray, tolerance: float = CONVERGED) -> np.ndarray:
    """Per direction: |median(fine) / median(coarse) - 1| <= tolerance (maxima (n, 6))."""
    return np.abs(np.nanmedian(fine, 0) / np.nanmedian(coarse, 0) - 1) <= tolerance


def study(scene, n: int, seed: int = 0, variants=None, log=print) -> dict:
    """Every variant's measurement, keyed by variant, in order."""
    runs = {}
    for v in variants or default_variants():
        runs[v] = measure(scene, v, n, seed)
        log(f"  {v.label}: {runs[v]['seconds_per_realization']:.3g} s per realisation, "
            f"ry steady median {np.nanmedian(runs[v]['steady'][:, 4]):.4g} rad/s^2"
            + (f", {runs[v]['failed']} failed" if runs[v]["failed"] else ""))
    return runs


def _cell(values: np.ndarray) -> str:
    """median [min - max] over realisations, 3 significant digits."""
    return f"{np.nanmedian(values):.3g} [{np.nanmin(values):.3g}-{np.nanmax(values):.3g}]"


def _verdict(runs: dict) -> list[str]:
    """Convergence between the two finest meshes per theory, and the model-form band at the finest."""
    lines, finest = [], {}
    for beam in dict.fromkeys(v.beam for v in runs):
        meshes = sorted(v.elements for v in runs if v.beam == beam and v.step_factor == 1.0)
        if len(meshes) < 2:
            continue
        a, b = (runs[Variant(m, beam)]["steady"] for m in meshes[-2:])
        finest[beam] = b
        ok = converged(a, b)
        change = np.nanmedian(b, 0) / np.nanmedian(a, 0) - 1
        lines.append(f"- {beam.label}, {meshes[-2]} -> {meshes[-1]} elements: median change "
                     + ", ".join(f"{d} {100 * c:+.1f} %" for d, c in zip(DIRECTIONS, change))
                     + (" - converged (within 5 %) in every direction" if ok.all() else
                        f" - not converged in {', '.join(np.array(DIRECTIONS)[~ok])}"))
    if len(finest) >= 2:
        med = np.stack([np.nanmedian(x, 0) for x in finest.values()])
        band = med.max(0) / med.min(0) - 1
        lines.append("- model-form band (beam models at the finest mesh, max/min of the medians - 1): "
                     + ", ".join(f"{d} {100 * c:.1f} %" for d, c in zip(DIRECTIONS, band)))
    return lines


def markdown(runs: dict, scene_name: str, n: int, seed: int, command: str = "") -> str:
    """The study's table (steady-window maxima, ry burst maxima, cost) and verdict, as markdown, headed by the
    ``command`` that measured it."""
    head = ("| setting | " + " | ".join(f"{d} steady" for d in DIRECTIONS)
            + " | ry burst t~1 s | ry burst t~2 s | s/realisation |")
    rows = [head, "|" + "---|" * (len(DIRECTIONS) + 4)]
    for v, r in runs.items():
        rows.append(f"| {v.label} | " + " | ".join(_cell(r["steady"][:, k]) for k in range(6))
                    + f" | {_cell(r['bursts'][:, 0, 4])} | {_cell(r['bursts'][:, 1, 4])}"
                    + f" | {r['seconds_per_realization']:.3g} |")
    steady_after = next(iter(runs.values()))["steady_after"]
    intro = ((f"`{command}`: " if command else "")
             + f"Scene {scene_name}, contact level, realisations 0-{n - 1} of seed {seed}; max |acceleration "
             f"error| over the steady window t >= {steady_after:g} s on the output grid (x, y, z in m/s^2; "
             f"rx, ry, rz in "
             f"rad/s^2), median [min-max] over the realisations; bursts: max |ry - its {1e3 * BURST_PERIOD:g} ms "
             f"running mean| over " + " and ".join(f"{a:g}-{b:g} s" for a, b in BURSTS) + ".")
    return "\n".join([intro, "", *rows, "", *_verdict(runs)]) + "\n"


def write(runs: dict, outdir, scene_name: str, n: int, seed: int, command: str = "") -> Path:
    """DIR/acceleration_maxima.csv (one row per variant and realisation) and DIR/acceleration_maxima.md."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "acceleration_maxima.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["elements_per_link", "beam_theory", "step_factor", "realization"]
                   + [f"steady_max_{d}" for d in DIRECTIONS]
                   + [f"burst{k + 1}_max_{d}" for k in range(len(BURSTS)) for d in DIRECTIONS]
                   + ["seconds_per_realization"])
        for v, r in runs.items():
            for i in range(len(r["steady"])):
                w.writerow([v.elements, v.beam.label, f"{v.step_factor:g}", i]
                           + [f"{x:.6g}" for x in r["steady"][i]]
                           + [f"{x:.6g}" for x in r["bursts"][i].reshape(-1)]
                           + [f"{r['seconds_per_realization']:.4g}"])
    path = out / "acceleration_maxima.md"
    path.write_text(markdown(runs, scene_name, n, seed, command))
    return path


def main(argv=None) -> int:
    """``python -m pipeline.studies.accelerations SCENE -n N -o DIR [--meshes 1 2 4 8 16 32]``."""
    from ..scenes.catalogue import find_scene
    p = argparse.ArgumentParser(prog="python -m pipeline.studies.accelerations", description=__doc__.split("\n")[0])
    p.add_argument("scene", help="scene name or TOML file")
    p.add_argument("-n", type=int, default=6, help="realisations per variant (same seed for all)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--meshes", type=int, nargs="+", default=[1, 2, 4, 8, 16, 32], help="elements per link")
    p.add_argument("-o", "--output", default="acceleration_study", help="output folder")
    args = p.parse_args(argv)
    if args.n < 1 or min(args.meshes) < 1:
        p.error("-n and --meshes must be at least 1")
    try:
        scene = find_scene(args.scene)
    except SceneError as exc:
        print(f"python -m pipeline.studies.accelerations: {exc}", file=sys.stderr)
        return 2
    print(f"acceleration study: {scene.name}, {args.n} realisations per variant (seed {args.seed})")
    runs = study(scene, args.n, args.seed, default_variants(tuple(args.meshes)))
    command = " ".join(["python -m pipeline.studies.accelerations", *map(shlex.quote, argv or sys.argv[1:])])
    path = write(runs, args.output, scene.name, args.n, args.seed, command)
    print(path.read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
