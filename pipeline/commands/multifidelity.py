"""rss6 multifidelity: means of a dear level with a cheap level on more realisations as control variate."""
from __future__ import annotations

import json
import sys

from rss6core import MODELS, models_with

from ..ensemble.settings import resolve_cluster, resolve_level
from ..scenes.catalogue import find_scene
from ..vocabulary import QUANTITIES, OptionError
from .messages import interrupted, scheduler_lost, warn_oversubscription
from .options import (add_confidence, add_json, add_parents, add_scene, add_scheduler, add_seed, add_window_choice,
                      MAX_REALISATIONS, add_workers, fraction, int_at_least, positive_float, realisations)


def add_parser(sub) -> None:
    p = sub.add_parser("multifidelity", help="means of a dear level with a cheap level on more "
                       "realisations as control variate (multi-fidelity Monte Carlo)")
    add_scene(p)
    p.add_argument("--high", choices=MODELS, default="contact",
                   help="the dear level, run on realisations 0..N-1 (default: contact)")
    p.add_argument("--low", choices=MODELS, default="quasi-static",
                   help="the cheap level, run on realisations 0..M-1 (default: quasi-static)")
    p.add_argument("-n", type=int_at_least(3, MAX_REALISATIONS, " per ensemble"), default=64,
                   help="high-level realisations N, 3 or more (default 64); no interval below N = 32 (at 95 %%; at "
                        "99 %% below 64, as the plain mean)")
    p.add_argument("--low-n", type=realisations, default=1024,
                   help="low-level realisations M, at least N (default 1024)")
    p.add_argument("-o", "--output", required=True,
                   help="multi-fidelity netCDF file F.nc; the two ensembles are ordinary rss6 run "
                        "files beside it, F.high.nc and F.low.nc, resumed like any other")
    add_parents(p)
    add_seed(p)
    add_confidence(p, "confidence of the two-sided intervals, in (0, 1)")
    p.add_argument("--cost-ratio", type=positive_float, metavar="C",
                   help="cost of one high realisation over one low one (e.g. from rss6 tradeoff); "
                        "adds the cost-optimal M/N and the cost against plain MC (default: none)")
    p.add_argument("--width", type=fraction, metavar="REL",
                   help="with --cost-ratio: also the realisations plain MC and multi-fidelity need "
                        "for a half-width of REL times the mean, e.g. 0.02 (default: none)")
    add_window_choice(p, "means")
    add_workers(p)
    add_scheduler(p, worker_timeout=False)
    add_json(p)
    p.set_defaults(main=main)


def _check_levels(args) -> None:
    if args.high == args.low:
        raise OptionError(f"--low {args.low}: must differ from --high (the same level is no control variate)")
    for option, level in (("--high", args.high), ("--low", args.low)):
        if level not in models_with("draws_clearances"):
            raise OptionError(f"{option} {level}: this level has no clearances, so all its realisations "
                              f"are the same; choose one of {', '.join(models_with('draws_clearances'))}")
    if args.low_n < args.n:
        raise OptionError(f"--low-n {args.low_n}: must be at least -n ({args.n}); the first -n low "
                          "realisations are the pairs")
    if args.width is not None and args.cost_ratio is None:
        raise OptionError("--width: needs --cost-ratio (the cost of a high realisation over a low one)")


def main(args) -> int:
    from ..analysis.stats import level_notes
    from ..files.records import check_window
    from ..files.writing import write_netcdf
    from ..studies.multifidelity import (REQUEST_ATTR, check_multifidelity_output, format_multifidelity, level_paths,
                                         multifidelity_dataset, result_notes, to_json)
    _check_levels(args)
    cluster = resolve_cluster(args.workers, args.scheduler)
    scene = find_scene(args.config)
    try:
        check_window(scene, args.window)
    except ValueError as exc:
        raise OptionError(str(exc)) from None
    request = _request(args, scene)
    output = check_multifidelity_output(args.output, request, args.parents)
    warn_oversubscription(cluster.workers, cluster.scheduler)
    from ..ensemble.cluster import SchedulerUnavailable
    from ..ensemble.run import parts_dir
    files, data = level_paths(output), []
    for level, n, path in ((args.high, args.n, files[0]), (args.low, args.low_n, files[1])):
        kept = f"finished chunks are kept in {parts_dir(path)}"
        try:
            data.append(_level_ensemble(args, scene, level, n, path, cluster))
        except SchedulerUnavailable as exc:
            return scheduler_lost("multifidelity", exc, kept)
        except KeyboardInterrupt:
            return interrupted(kept)
    try:
        mds = multifidelity_dataset(*data, args.confidence, files, args.cost_ratio, args.width, args.window).load()
        # what of the dear level's maxima does not measure the robot (the paper level's step, a drawn start's impacts)
        notes = level_notes(data[0].attrs, set(QUANTITIES), {args.window})
    except ValueError as exc:   # too few finished pairs
        print(f"rss6 multifidelity: error: {files[0]}: {exc}", file=sys.stderr)
        return 1
    finally:
        for level_data in data:
            level_data.close()
    table_notes = notes + result_notes(mds)   # the level's, then the intervals' and the costly rows' (the table's)
    write_netcdf(mds.assign_attrs({REQUEST_ATTR: json.dumps(request, sort_keys=True),
                                   "table_notes": "\n".join(table_notes)}), output)
    if args.json:
        print(json.dumps(to_json(mds) | {"table_notes": table_notes}, indent=2, allow_nan=False))
    else:
        print(f"wrote {output} (also the means of mean_abs_error; --json prints both)")
        print(format_multifidelity(mds) + "".join(f"\nnote: {line}" for line in notes))
    return 0


def _request(args, scene) -> dict:
    """What the multi-fidelity file answers (:func:`check_multifidelity_output`)."""
    from ..files.outputs import text_identity
    return {"scene": text_identity(scene.source_text), "--high": args.high, "--low": args.low, "-n": args.n,
            "--low-n": args.low_n, "--seed": args.seed, "--confidence": args.confidence, "--window": args.window,
            "--cost-ratio": args.cost_ratio, "--width": args.width}


def _level_ensemble(args, scene, level: str, n: int, path, cluster):
    """The first ``n`` realisations of ``level``, run or resumed in ``path``."""
    from ..ensemble.run import ensemble
    print(f"rss6 multifidelity: {level} level, {n} realisations in {path}", file=sys.stderr)
    spec = resolve_level(scene, args.config, model=level).ensemble_spec(args.seed)
    out = ensemble(spec, n, path, workers=cluster.workers, scheduler=cluster.scheduler, progress=not args.json)
    return out.dataset.sel(realization=out.dataset["realization"].values < n)
