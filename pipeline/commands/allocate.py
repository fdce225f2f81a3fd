"""rss6 allocate: the least-cost ISO 286 fit class per joint family such that every spec holds."""
from __future__ import annotations

import json

from rss6core import MODELS, model_level

from ..ensemble.settings import resolve_cluster, resolve_level
from ..scenes.catalogue import find_scene
from ..studies.fits import DEFAULT_FITS
from ..vocabulary import OptionError
from .messages import interrupted, loaded_joints_meanwhile, warn_oversubscription
from .options import (add_confidence, add_json, add_model, add_parents, add_scene, add_seed, add_workers, output_stem,
                      positive_int, realisations)
from .requirements import known_windows, robot_measures


def add_parser(sub) -> None:
    p = sub.add_parser("allocate", help="the least-cost fit class per joint family for which requirement specs "
                                        "pass, checked by an ensemble")
    add_scene(p, names_output=True)
    p.add_argument("--spec", action="append", required=True, metavar="SPEC",
                   help="an upper limit QUANTITY:DIRECTIONS <= VALUE UNIT@STATISTIC, as for rss6 budget, e.g. "
                        "'displacement:x,y,z<=0.1mm@q95' (repeatable; required)")
    p.add_argument("--per-joint", action="store_true",
                   help="a class per joint (A1-A6, C1-C6, B1-B6) rather than per family; quasi-static level only "
                        "(exhaustive up to 4096 combinations, else greedy from the per-family optimum)")
    add_model(p, "model level (default quasi-static: exhaustive search by its exact linear scaling; paper, "
                 "contact: a greedy search of ensembles, at most --max-ensembles)", choices=MODELS,
              default="quasi-static")
    p.add_argument("--max-ensembles", type=positive_int, default=12,
                   help="paper and contact levels: most ensembles the greedy search runs (default 12)")
    p.add_argument("--classes", default=",".join(DEFAULT_FITS), metavar="FITS",
                   help="comma list of ISO 286 hole-basis clearance fits offered to the revolute radial and "
                        f"spherical C, B families at their joint diameters (default {','.join(DEFAULT_FITS)})")
    p.add_argument("--costs", metavar="TOML", help="costs per joint: [<family>] \"<fit>\" = cost for each "
                                                   "family and fit (default: the reciprocal-power cost law), and "
                                                   "named classes [classes.<family>.<name>] low_m, high_m, cost")
    p.add_argument("-n", type=realisations, default=200,
                   help="realisations of the search and of the verification ensemble (default 200)")
    p.add_argument("-o", "--output", help="folder of the allocation file, scene and verification ensemble "
                                          "(default: allocate_SCENE_MODEL, with --per-joint "
                                          "allocate_SCENE_MODEL_per-joint); rerunning the same request resumes "
                                          "the ensemble, another request is refused")
    add_parents(p)
    add_seed(p)
    add_confidence(p, "confidence of the one-sided bounds the specs are judged on, above 0.5", above=0.5)
    add_json(p)
    add_workers(p, what="local dask workers of the verification ensemble")
    p.set_defaults(main=main)


def _specs(texts):
    from ..analysis.spec import SpecError, parse_spec
    try:
        return [parse_spec(t) for t in texts]
    except SpecError as exc:
        raise SpecError(str(exc).replace("--require", "--spec", 1)) from None


def _request(args, level, fits: list[str]) -> dict:
    """What the allocation folder's answer depends on (:func:`claimed_output_folder`)."""
    from ..files.outputs import sha256, text_identity
    return {"scene": text_identity(level.scene.source_text), "--model": level.model, "--spec": args.spec,
            "--per-joint": args.per_joint, "--classes": fits, "-n": args.n, "--seed": args.seed,
            "--confidence": args.confidence, "--max-ensembles": args.max_ensembles,
            "--costs": sha256(args.costs) if args.costs else None}


def main(args) -> int:
    from ..analysis.gate import EXIT_CODES, overall
    from ..files.outputs import check_output_folder, claimed_output_folder
    from ..files.writing import write_netcdf
    from ..studies.allocation import allocate, check_request, class_options
    from ..studies.allocation_greedy import greedy_allocate
    from ..studies.allocation_joints import allocate_per_joint
    from ..studies.allocation_output import (COST_NOTE, allocation_dataset, allocation_json, format_allocation,
                                             fresh_check_command)
    specs = _specs(args.spec)
    cluster = resolve_cluster(args.workers)
    level = resolve_level(find_scene(args.config), args.config, model=args.model)
    known_windows(specs, level.scene, "--spec")
    robot_measures(specs, level.model, "--spec")
    if args.per_joint and not model_level(level.model).linear_in_clearances:
        raise OptionError(f"--per-joint: at the {', '.join(m for m in MODELS if model_level(m).linear_in_clearances)} "
                          f"level only (exact linear scaling); at the {level.model} level each per-joint step "
                          "would need its own ensemble, and a scene has one size band a family")
    fits = [f.strip() for f in args.classes.split(",") if f.strip()]
    if not fits:
        raise OptionError(f"--classes {args.classes!r}: names no fit; give ISO 286 fits, e.g. H7/g6,H9/e9")
    options = class_options(level.scene, fits, args.costs)
    check_request(level.ensemble_spec(args.seed), specs, args.n, args.confidence)
    default = f"allocate_{output_stem(args.config)}_{level.model}" + ("_per-joint" if args.per_joint else "")
    folder = check_output_folder(args.output or default, args.parents)
    answers = ("allocation.nc", "*_allocated.toml")
    with claimed_output_folder(folder, "allocate", _request(args, level, fits), answers):
        warn_oversubscription(cluster.workers, None)
        try:
            spec = level.ensemble_spec(args.seed)
            if args.per_joint:
                a = allocate_per_joint(spec, specs, args.n, folder, args.confidence, options)
            elif model_level(level.model).linear_in_clearances:
                a = allocate(spec, specs, args.n, folder, args.confidence, options, cluster.workers)
            else:
                a = greedy_allocate(spec, specs, args.n, folder, args.confidence, options, cluster.workers,
                                    args.max_ensembles)
        except KeyboardInterrupt:
            return interrupted(f"finished chunks of the verification ensemble are kept in {folder}")
    note = f"per joint from {args.costs}" if args.costs else COST_NOTE
    opts = ("--per-joint " if args.per_joint else "") + f"-n {args.n} --seed {args.seed} --confidence " \
        f"{args.confidence} --classes {args.classes} " + " ".join(
        f"--spec '{s}'" for s in args.spec)
    ds = allocation_dataset(a, level.scene, level.model, level.integrator, level.dt, level.elements, opts, note)
    write_netcdf(ds, folder / "allocation.nc")
    fresh = fresh_check_command(a, level.model, args.n, args.seed, args.spec, args.confidence)
    if a.scene_path is not None:   # what the answer's robot does under its loads
        loaded = loaded_joints_meanwhile("allocate", find_scene(str(a.scene_path)), level.model, specs,
                                         "the answer's robot at its fits' middle sizes")
    else:
        loaded = loaded_joints_meanwhile("allocate", level.scene, level.model, specs, "the nominal robot at the "
                                         "scene's sizes (a per-joint answer has no scene of its own)")
    if args.json:
        print(json.dumps(allocation_json(a) | {"file": str(folder / "allocation.nc"), "fresh_check": fresh}
                         | loaded.json(), indent=2, allow_nan=False))
    else:
        print(format_allocation(a, level.scene.name, level.model, args.n, note, fresh))
        print(f"allocation file: {folder / 'allocation.nc'}")
    loaded()
    return EXIT_CODES[overall(list(a.verdicts))]
