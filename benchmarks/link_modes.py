"""Craig-Bampton reduced links ([beam] link_modes): cost against accuracy per mesh and number of modes.

For configs/paper.toml (or --scene), the contact level with the scene's adaptive step on meshes of 4, 8
and 16 elements per link, each on the full mesh and reduced to 2, 4 and 8 modes per link: seconds per
realisation (n realisations in one batch, seed 0) and the largest relative error per quantity
(displacement, velocity, acceleration; mean and 95 % quantile of the realisations' maxima, as
`rss6 tradeoff` measures them) against `rss6 tradeoff`'s reference setting and against the same mesh
unreduced; then the robot's lowest and highest natural frequency and the central-difference limit
2/omega_max per number of modes (4 elements).  The rows are measured one after another, so their
seconds move with the machine's load (printed).

    python benchmarks/link_modes.py [-n 4] [--scene configs/paper.toml]
"""
import argparse
import dataclasses
import os
from pathlib import Path

import numpy as np

from pipeline.studies.setting import Setting, _adaptive, measure, relative_errors
from pipeline.studies.tradeoff import default_settings
from rss6core import default_integrator, default_time_step, load_scene, natural_frequencies

SCENE = Path(__file__).resolve().parents[1] / "configs" / "paper.toml"
MESHES, MODES = (4, 8, 16), (None, 2, 4, 8)


def _worst(errors: np.ndarray) -> str:
    """Largest relative error per quantity (3, 6, 2) in %."""
    return " ".join(f"{100 * np.nanmax(errors[q]):7.3f}" for q in range(3))


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("-n", type=int, default=4, help="realisations per row (default 4)")
    p.add_argument("--scene", default=str(SCENE), help="scene file (default configs/paper.toml)")
    args = p.parse_args(argv)
    scene = load_scene(args.scene)
    print(f"scene {scene.name}, n = {args.n}, load average at the start {os.getloadavg()[0]:.2f}")
    _, reference = default_settings(scene)
    ref = measure(scene, reference, args.n)
    print(f"reference {reference.label}: {ref['seconds_per_realization']:.3f} s per realisation")
    tol, levels = _adaptive(scene)
    base = Setting("contact", default_integrator(scene, "contact"), default_time_step(scene, "contact"), 4,
                   tolerance=tol, refinements=levels)
    print(f"{'setting':100s} {'s/real':>7s}   vs reference: disp    vel    acc   | vs full mesh: disp    vel    acc")
    for elements in MESHES:
        full = None
        for modes in MODES:
            s = dataclasses.replace(base, elements=elements, link_modes=modes)
            run = measure(scene, s, args.n)
            against_ref = relative_errors(run["statistics"], ref["statistics"])
            line = f"{s.label:100s} {run['seconds_per_realization']:7.3f}   {_worst(against_ref)}"
            if modes is None:
                full = run
            else:
                line += f"   | {_worst(relative_errors(run['statistics'], full['statistics']))}"
            print(line + (f"  ({run['failed']} failed)" if run["failed"] else ""), flush=True)
    for modes in (0, 2, 4, 8):
        w = natural_frequencies(dataclasses.replace(scene, beam=dataclasses.replace(scene.beam, link_modes=modes)), 4)
        print(f"4 elements, link_modes = {modes}: {len(w)} DOFs, lowest {w[0] / (2 * np.pi):.2f} Hz, highest "
              f"{w[-1] / (2 * np.pi):.4g} Hz, 2/omega_max = {2 / w[-1] * 1e6:.3g} us")
    print(f"load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
