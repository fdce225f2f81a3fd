"""rss6 map: the workspace error map of the quasi-static level, worst case and q95 per pose and direction."""
from __future__ import annotations

import argparse

from rss6core import MODELS

from ..scenes.catalogue import find_scene
from ..vocabulary import OptionError
from .options import add_parents, add_scene, add_seed, int_at_least

_AXES = {"x": "m", "y": "m", "z": "m", "n1": "deg", "n2": "deg", "n3": "deg"}   # --grid's axes and units


MAX_GRID_POINTS = 1000   # per axis: a million poses at most


def grid_axis(text: str):
    """An argparse type: AXIS:LO:HI:N (x, y, z in m; n1, n2, n3 in deg; LO < HI; N >= 2), in SI."""
    import numpy as np

    from ..studies.workspace_map import GridAxis
    parts = text.split(":")
    if len(parts) != 4 or parts[0] not in _AXES:
        raise argparse.ArgumentTypeError(f"expected AXIS:LO:HI:N with AXIS one of {', '.join(_AXES)}, got {text!r}")
    try:
        low, high, count = float(parts[1]), float(parts[2]), int(parts[3])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers LO, HI and an integer N in {text!r}") from None
    if not (np.isfinite(low) and np.isfinite(high) and low < high) or not 2 <= count <= MAX_GRID_POINTS:
        raise argparse.ArgumentTypeError(f"{text!r}: needs LO < HI and 2 <= N <= {MAX_GRID_POINTS}")
    factor = 1.0 if _AXES[parts[0]] == "m" else np.pi / 180.0
    return GridAxis(parts[0], low * factor, high * factor, count)


def add_parser(sub) -> None:
    from ..studies.workspace_map import DEFAULT_COUNT, DEFAULT_DRAWS, MAP_MODELS, MAX_DRAWS
    p = sub.add_parser("map", help="worst-case and q95 pose error over a grid of poses (quasi-static level)")
    add_scene(p)
    p.add_argument("--model", choices=MODELS, default=MAP_MODELS[0],
                   help=f"model level; only {', '.join(MAP_MODELS)} defines the map (default {MAP_MODELS[0]})")
    p.add_argument("--grid", type=grid_axis, action="append", metavar="AXIS:LO:HI:N",
                   help="a grid axis: x, y, z (m) or n1, n2, n3 (deg) from LO to HI in N points; give two "
                        "(default: the trajectory's two position axes of largest range, padded, "
                        f"{DEFAULT_COUNT} points each, the rest at the trajectory's mean pose)")
    p.add_argument("-n", type=int_at_least(1, MAX_DRAWS, " (the map holds 64 poses x N draws of errors at once)"),
                   default=DEFAULT_DRAWS,
                   help=f"clearance realisations for the q95 and max (default {DEFAULT_DRAWS})")
    add_seed(p)
    p.add_argument("-o", "--output", default="workspace_map", help="output folder (default: workspace_map)")
    add_parents(p)
    p.set_defaults(main=main)


def _check(args) -> None:
    from ..studies.workspace_map import MAP_MODELS
    if args.model not in MAP_MODELS:
        raise OptionError(f"--model {args.model}: the workspace map is defined for the {', '.join(MAP_MODELS)} "
                          "level only (its error at a static pose is linear in the eccentricities, so its "
                          "worst case has a closed form)")
    if args.grid is not None and (len(args.grid) != 2 or args.grid[0].axis == args.grid[1].axis):
        raise OptionError(f"--grid: give two different axes, got {' '.join(g.option() for g in args.grid)}")


def _check_scene(scene, source: str) -> None:
    """OptionError for a scene with [uncertain.*] inputs: the map's worst case is a closed form over the
    clearance sets of one geometry (the nominal), which a realised robot's drawn geometry would leave."""
    if scene.uncertain:
        raise OptionError(f"{source}: [uncertain.{scene.uncertain.inputs[0].name}]: the workspace map is the "
                          "nominal geometry's clearance error and cannot take [uncertain.*] inputs; map the scene "
                          "without its [uncertain.*] tables")


def main(args) -> int:
    from ..files.outputs import check_output_folder, claimed_output_folder, text_identity
    from ..studies.workspace_map import map_table, workspace_map, write_map
    _check(args)
    scene = find_scene(args.config)
    _check_scene(scene, args.config)
    check_output_folder(args.output, args.parents)
    request = {"scene": text_identity(scene.source_text), "--model": args.model, "-n": args.n, "--seed": args.seed,
               "--grid": [g.option() for g in args.grid] if args.grid else None}
    with claimed_output_folder(args.output, "map", request, ("workspace_map.nc",)):
        print(f"rss6 map: scene {scene.name}, {args.model} level, {args.n} drawn realisations (seed {args.seed})",
              flush=True)
        ds = workspace_map(scene, tuple(args.grid) if args.grid else None, args.n, args.seed, args.model)
        if not ds["reachable"].values.any():
            grid = " ".join(f"--grid {g.option()}" for g in args.grid) if args.grid else "the default grid"
            raise OptionError(f"{grid}: the robot reaches none of its {ds['reachable'].size} poses; choose a "
                              "grid inside the workspace (rss6 check prints the trajectory's)")
        print(f"grid: {ds.attrs['grid']}; worst case with {ds.attrs['clearance_sizes']}")
        print(map_table(ds))
        paths = write_map(ds, args.output)
    print(f"wrote {paths[0]} and {len(paths) - 1} heat maps ({paths[1].name} ...)")
    return 0
