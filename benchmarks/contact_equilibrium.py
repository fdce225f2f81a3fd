"""The contact level's equilibrium start against the drawn start and the quasi-static reaction level.

Run on demand: ``python benchmarks/contact_equilibrium.py [--realizations N] [CONFIG ...]`` (default
configs/paper.toml and configs/smoke.toml, realisations 0-3 of seed 0; about 5 s with the contact kernel in
numba's cache, a few minutes more to compile it).  Per scene it prints (docs/model.md section 3, "L4 initial
state"):

- the force imbalance at t = 0 (max over the generalised forces, N or N m) of the drawn and the equilibrium
  start (rss6core.contact_start.static_residual) and the equilibrium's Newton iterations, with and without
  friction;
- the largest |acceleration error| over the first 50 ms of the output grid, per direction (m/s^2, rad/s^2),
  of both starts (the compiled kernel), and the equilibrium's over the drawn's (max over the directions);
- per direction, the t = 0 platform error less the ideal-joint elastic sag of the equilibrium start against
  the quasi-static ``reaction`` level at t = 0 (|eq - reaction| / |reaction|, max over the realisations),
  without friction, with friction, and without friction against the reaction eccentricities pushed into their
  walls by the Hertz penetration (the linearised closure, as tests/test_contact_start.py);
- the equilibrium's t = 0 platform error (sag included) with and without friction, the reaction level's
  t = 0 error (mm, rad), and each direction of the reaction level's error over its |z| (m and rad over m).

Rerunning the same command gives the same numbers (fixed seed).
"""
from __future__ import annotations

import argparse
import dataclasses
import pathlib

import numpy as np

from rss6core import draw_clearances, load_scene
from rss6core.contact_dynamics import CompiledStepper, _joints, build_joint_model, simulate_contact
from rss6core.contact_start import _penetrated, contact_initial_state, equilibrium_state, static_residual
from rss6core.elastic import quasi_static_state
from rss6core.kinematics import rigid_motion
from rss6core.quasi_static import closure_matrix, quasi_static_error

CONFIGS = pathlib.Path(__file__).resolve().parents[1] / "configs"
DIRECTIONS = ("x", "y", "z", "rx", "ry", "rz")
SCALE = np.array([1e3, 1e3, 1e3, 1.0, 1.0, 1.0])   # m -> mm, rad as rad


def _row(label: str, values, fmt: str = "10.3g") -> None:
    print(f"  {label:52}" + "".join(f"{v:{fmt}}" for v in values))


def _frictionless(scene):
    return dataclasses.replace(scene, contact=dataclasses.replace(scene.contact, friction_coefficient=0.0))


def _with_start(scene, start):
    return dataclasses.replace(scene, simulation=dataclasses.replace(scene.simulation, contact_start=start))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="*", default=[str(CONFIGS / "paper.toml"), str(CONFIGS / "smoke.toml")])
    parser.add_argument("--realizations", type=int, default=4, help="realisations 0..N-1 of seed 0 (default 4)")
    args = parser.parse_args()
    for path in args.configs:
        base = load_scene(path)
        draws = [draw_clearances(base, 0, r) for r in range(args.realizations)]
        print(f"{path}, realisations 0-{args.realizations - 1} of seed 0")
        print(f"  {'':52}" + "".join(f"{d:>10}" for d in DIRECTIONS))
        motion = rigid_motion(base, np.array([0.0, 1e-3, 2e-3]))
        reaction = np.array([quasi_static_error(base, motion, d, "reaction")[0][0] for d in draws])
        G, n = closure_matrix(rigid_motion(base, np.array([0.0])))
        for friction in (False, True):
            scene = base if friction else _frictionless(base)
            jm = build_joint_model(scene, scene.simulation.elements_per_link)
            joints = _joints(scene, draws)
            st = equilibrium_state(scene, jm, joints)
            drawn = contact_initial_state(scene, jm, joints)
            imb = np.abs(static_residual(scene, jm, joints, st.d, st.v)).max()
            imb_drawn = np.abs(static_residual(scene, jm, joints, drawn.d, drawn.v)).max()
            print(f"  friction {friction}: force imbalance at t = 0: drawn {imb_drawn:.3g} N, equilibrium "
                  f"{imb:.2g} N after {st.iterations.max()} Newton iterations")
            sag = quasi_static_state(scene, jm.elastic, 0.0)[0][-6:]
            eq = st.d[:, -6:] - sag
            _row(f"equilibrium at t = 0, max |error| (mm, rad), friction {friction}", np.abs(st.d[:, -6:]).max(0)
                 * SCALE)
            _row(f"|eq - reaction| / |reaction|, friction {friction}",
                 (np.abs(eq - reaction) / np.abs(reaction)).max(0), "10.2%")
            if not friction:
                deep = _penetrated(scene, joints)
                closure = np.array([np.linalg.solve(G[0], np.einsum("li,li->l", n[0], deep.e_A[k] + deep.e_C[k]
                                                                    - deep.e_B[k])) for k in range(len(draws))])
                _row("|eq - penetrated closure| / |closure|", (np.abs(eq - closure) / np.abs(closure)).max(0),
                     "10.2%")
                _row("|penetrated closure - reaction| / |reaction|",
                     (np.abs(closure - reaction) / np.abs(reaction)).max(0), "10.2%")
        _row("reaction level at t = 0, max |error| (mm, rad)", np.abs(reaction).max(0) * SCALE)
        _row("reaction level at t = 0, |error| / |z| (max)", (np.abs(reaction) / np.abs(reaction[:, 2:3])).max(0))
        first = {}
        for start in ("drawn", "equilibrium"):
            batch = simulate_contact(_with_start(base, start), draws, base.simulation.elements_per_link,
                                     stepper=CompiledStepper, initial=contact_initial_state)
            first[start] = np.abs(batch.acceleration[:, batch.t <= 0.05 + 1e-12]).max(1)   # (R, 6)
            _row(f"max |acceleration error|, t <= 50 ms, {start}", first[start].max(0))
        _row("per realisation: drawn, max over directions", first["drawn"].max(1))
        _row("per realisation: equilibrium / drawn", first["equilibrium"].max(1) / first["drawn"].max(1), "10.2%")


if __name__ == "__main__":
    main()
