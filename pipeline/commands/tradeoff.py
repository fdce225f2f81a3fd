"""rss6 tradeoff: cost and error of every model level, integrator, step and mesh, and the cheapest
setting within a tolerance of the reference."""
from __future__ import annotations

from ..scenes.catalogue import find_scene
from .options import add_study_arguments, study_request


def add_parser(sub) -> None:
    p = sub.add_parser("tradeoff", help="cost and error of every model level, integrator, step and mesh")
    add_study_arguments(p, "tradeoff", 8, "relative error allowed on every statistic")
    p.set_defaults(main=main)


def main(args) -> int:
    from ..files.outputs import check_output_folder, claimed_output_folder
    from ..studies.tradeoff import tradeoff, write_tradeoff
    scene = find_scene(args.config)
    check_output_folder(args.output, args.parents)
    with claimed_output_folder(args.output, "tradeoff", study_request(scene, args), ("tradeoff.nc", "tradeoff.csv")):
        print(f"rss6 tradeoff: {scene.name}, {args.n} realisations per setting (seed {args.seed})")
        ds = tradeoff(scene, args.n, args.seed)
    change = float(ds["reference_change"].max())
    print(f"reference {ds.attrs['reference']}: its step halved and mesh doubled change the statistics by at "
          f"most {100 * change:.2f} %" + ("" if change < 0.01 else " (not converged to 1 %)"))
    rec = write_tradeoff(ds, args.output, args.tolerance)
    print(f"wrote {args.output}/tradeoff.csv, tradeoff.nc, tradeoff.png")
    if rec["setting"] is None:
        print(f"no setting is within {100 * args.tolerance:g} % of the reference (closest: "
              f"{100 * rec['best_error']:.1f} %); use the reference")
    else:
        print(f"cheapest within {100 * args.tolerance:g} %: {rec['setting']} (max error "
              f"{100 * rec['max_relative_error']:.2f} %, {rec['seconds_per_realization']:.3g} s per "
              f"realisation, {rec['speedup_vs_reference']:.1f}x cheaper than the reference)")
    return 0
