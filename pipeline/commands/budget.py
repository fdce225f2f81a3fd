"""rss6 budget: the largest common clearance scale factor for which requirement specs pass."""
from __future__ import annotations

from rss6core import MODELS

from ..ensemble.settings import resolve_cluster, resolve_level
from ..scenes.catalogue import find_scene
from .messages import interrupted, note_loaded_joints, warn_oversubscription
from .options import (add_confidence, add_model, add_parents, add_scene, add_seed, add_workers, output_stem,
                      positive_float, realisations)
from .requirements import known_windows, robot_measures


def add_parser(sub) -> None:
    p = sub.add_parser("budget", help="the largest common clearance scale factor for which requirement specs pass")
    add_scene(p, names_output=True)
    p.add_argument("--spec", action="append", required=True, metavar="SPEC",
                   help="an upper limit QUANTITY:DIRECTIONS <= VALUE UNIT@STATISTIC, as for "
                        "rss6 run --require, e.g. 'displacement:x,y,z<=0.1mm@q95' (repeatable; required, no "
                        "default)")
    add_model(p, "model level (default quasi-static: exact scaling from one ensemble; other levels: a "
                 "bisection of ensemble runs)", choices=MODELS, default="quasi-static")
    p.add_argument("-n", type=realisations, default=200,
                   help="realisations per ensemble (default 200; q95 has an interval from n = 59)")
    p.add_argument("-o", "--output", help="folder of the ensembles and the budget scene "
                                          "(default: budget_SCENE_MODEL); rerunning the same request resumes, another "
                                          "request is refused")
    add_parents(p)
    add_seed(p)
    add_confidence(p, "confidence of the one-sided bounds the specs are judged on, above 0.5", above=0.5)
    p.add_argument("--tolerance", type=positive_float, default=0.05,
                   help="sweep levels: relative width in the scale at which bisection stops (default 0.05)")
    add_workers(p, what="local dask workers")
    p.set_defaults(main=main)


def main(args) -> int:
    from ..analysis.spec import SpecError, parse_spec
    from ..files.outputs import check_output_folder, claimed_output_folder, text_identity
    from ..studies.budget import budget, format_budget
    from ..studies.trial import fresh_check_command
    try:
        specs = [parse_spec(t) for t in args.spec]
    except SpecError as exc:
        raise SpecError(str(exc).replace("--require", "--spec", 1)) from None
    cluster = resolve_cluster(args.workers)
    level = resolve_level(find_scene(args.config), args.config, model=args.model)
    known_windows(specs, level.scene, "--spec")
    robot_measures(specs, level.model, "--spec")
    folder = check_output_folder(args.output or f"budget_{output_stem(args.config)}_{level.model}", args.parents)
    request = {"scene": text_identity(level.scene.source_text), "--model": level.model, "--spec": args.spec,
               "-n": args.n, "--seed": args.seed, "--confidence": args.confidence, "--tolerance": args.tolerance}
    with claimed_output_folder(folder, "budget", request, ("*_budget.toml",)):
        warn_oversubscription(cluster.workers, None)
        try:
            b = budget(level.ensemble_spec(args.seed), specs, args.n, folder, args.confidence, cluster.workers,
                       args.tolerance)
        except KeyboardInterrupt:
            return interrupted(f"finished ensembles and chunks are kept in {folder}")
    fresh = fresh_check_command(b.scene_path, level.model, args.n, args.seed, args.spec, args.confidence)
    print(format_budget(b, level.scene.name, level.model, fresh))
    note_loaded_joints("budget", find_scene(str(b.scene_path)), level.model, specs,
                       f"the answer's robot (clearances x {b.scale:.4g})")
    return 0
