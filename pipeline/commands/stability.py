"""rss6 stability: time-step sweeps of each integrator, stable, inaccurate or failed."""
from __future__ import annotations

from ..scenes.catalogue import find_scene
from ..vocabulary import OptionError
from .options import add_study_arguments, positive_float, study_request


def add_parser(sub) -> None:
    p = sub.add_parser("stability", help="time-step sweeps: stable, inaccurate or failed")
    add_study_arguments(p, "stability", 2, "change vs the finest step that counts as inaccurate")
    p.add_argument("--horizon", type=positive_float, default=0.2,
                   help="simulated time of the contact sweeps, s (default 0.2)")
    p.set_defaults(main=main)


def main(args) -> int:
    from ..files.outputs import check_output_folder, claimed_output_folder
    from ..studies.stability import stability, summary_lines, write_stability
    scene = find_scene(args.config)
    if args.horizon > scene.trajectory.duration:
        raise OptionError(f"--horizon {args.horizon:g}: longer than the scene's trajectory "
                          f"({scene.trajectory.duration:g} s); give at most that")
    check_output_folder(args.output, args.parents)
    with claimed_output_folder(args.output, "stability", study_request(scene, args, **{"--horizon": args.horizon}),
                               ("stability.nc", "stability.csv")):
        print(f"rss6 stability: {scene.name}, tolerance {100 * args.tolerance:g} %")
        ds = stability(scene, args.tolerance, args.n, args.seed, args.horizon)
        write_stability(ds, args.output)
    print(f"wrote {args.output}/stability.csv, stability.nc, stability.png")
    for line in summary_lines(ds):
        print(line)
    print(f"central-difference 2/omega_max: {ds.attrs['central_difference_limit_s']:.3g} s")
    return 0
