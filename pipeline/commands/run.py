"""rss6 run: a Monte Carlo ensemble of clearance realisations, resumable, with its statistics,
--require verdicts and --until stopping rule."""
from __future__ import annotations

import sys

from rss6core import model_level, models_with

from ..analysis.summary import run_default_level
from ..ensemble.settings import resolve_cluster, resolve_level, resolve_replicates
from ..scenes.catalogue import find_scene
from ..vocabulary import QUANTITIES, STORES, OptionError, UserError
from .messages import (import_meanwhile, interrupted, loaded_joints_meanwhile, scheduler_lost,
                       warn_oversubscription)
from .options import (LEVELS_HELP, add_level_settings, add_model, add_parents, add_require, add_scene, add_scheduler,
                      add_seed, add_workers, int_at_least, output_stem, positive_int, realisations)
from .requirements import annotator, known_windows, requirements, robot_measures


def add_parser(sub) -> None:
    from ..ensemble.run import MAX_AUTO_CHUNK, MAX_AUTO_CHUNK_BY_MODEL
    p = sub.add_parser("run", help="run a Monte Carlo ensemble of clearance realisations")
    add_scene(p, names_output=True)
    p.add_argument("-n", type=realisations, default=32, help="realisations (default 32)")
    p.add_argument("-o", "--output", help="ensemble netCDF file (default: SCENE_MODEL.nc); its "
                   "folder must exist unless --parents is given. Rerunning the same command "
                   "resumes from the parts stored in OUTPUT.parts")
    add_parents(p)
    add_seed(p)
    add_model(p, "model level (default: the scene's if it has clearances; a scene whose level has none "
                 f"asks for --model). {LEVELS_HELP}")
    add_level_settings(p)
    add_workers(p)
    add_scheduler(p)
    larger = ", ".join(f"{n} for {m}" for m, n in MAX_AUTO_CHUNK_BY_MODEL.items())
    p.add_argument("--chunk", type=positive_int,
                   help="realisations per task (default: n cut into a multiple of the workers "
                        f"nearly equal chunks of at most {MAX_AUTO_CHUNK}, {larger}; each task integrates "
                        "its realisations as one batch)")
    p.add_argument("--store", choices=STORES, default="summary",
                   help="summary: per-realisation maxima and means; full: also time histories "
                        "(default: summary)")
    add_require(p)
    p.add_argument("--until", action="append", metavar="TARGET",
                   help="add realisations until a confidence interval is this narrow, e.g. "
                        "'displacement:x,y,z@q95<=5%%' (half-width relative to the estimate) or "
                        "'displacement:z@mean<=0.001mm' (absolute), 95 %% confidence; checked at "
                        "fixed n (x1.25 from the statistic's minimum n; qmc: doubling), up to -n "
                        "as the cap; exit 1 if the cap comes first (repeatable; default: none)")
    p.add_argument("--sampler", choices=("mc", "qmc"), default="mc",
                   help="mc: independent random draws; qmc: randomised quasi-Monte Carlo, "
                        "scrambled Sobol' points in --replicates independent scramblings, "
                        "-n a multiple of them; intervals from the replicates (default: mc)")
    p.add_argument("--replicates", type=int_at_least(2), metavar="R",
                   help="with --sampler qmc: independent scramblings (default 8)")
    p.set_defaults(main=main)


def _refuse_clearance_free_default(args, level) -> None:
    """An ensemble of a level without clearances is N identical runs: only on explicit request."""
    if args.model is None and run_default_level(level.scene) is None:
        raise OptionError(f"scene {level.scene.name!r}: its model {level.model!r} has no clearances, so every "
                          f"realisation would be the same; pass --model with a clearance level "
                          f"({', '.join(models_with('draws_clearances'))}), or --model {level.model} to run "
                          "it anyway")


def main(args) -> int:
    from ..analysis.until import check_cap, parse_targets
    from ..ensemble.cluster import SchedulerUnavailable
    from ..ensemble.run import parts_dir
    from ..files.outputs import check_output_path
    specs, verdicts = requirements(args), []
    targets = parse_targets(args.until)
    known_windows(specs + targets)
    cluster = resolve_cluster(args.workers, args.scheduler, args.worker_timeout)
    level = level_settings(args)
    known_windows(specs + targets, level.scene)
    robot_measures(specs, level.model)
    _refuse_clearance_free_default(args, level)
    replicates = resolve_replicates(args.sampler, args.replicates, args.n, level)
    check_cap(targets, args.n, replicates)
    output = check_output_path(args.output or f"{output_stem(args.config)}_{level.model}.nc", args.parents)
    warn_oversubscription(cluster.workers, cluster.scheduler)
    import_meanwhile("distributed", "pipeline.analysis.gate")   # gate imports stats (scipy.stats)
    spec = level.ensemble_spec(args.seed, args.store, replicates)
    kept = f"finished chunks are kept in {parts_dir(output)}"
    note = loaded_joints_meanwhile("run", level.scene, level.model, specs)   # what the statistics leave out
    try:
        outcome, until = _compute(args, spec, targets, output, cluster, annotator(specs, verdicts))
    except SchedulerUnavailable as exc:
        return scheduler_lost("run", exc, kept, parts_dir(output).exists())
    except KeyboardInterrupt:
        return interrupted(kept if parts_dir(output).exists() else None)
    return _report(args, level, outcome, until, output, specs, verdicts, note)


def level_settings(args):
    """The run's level resolved against its scene (:func:`.settings.resolve_level`)."""
    return resolve_level(find_scene(args.config), args.config, model=args.model, integrator=args.integrator,
                         dt=args.dt, elements=args.elements, start=args.start)


def ensemble_spec_of(argv: list[str]):
    """The ensemble that ``rss6 run`` with ``argv`` (the words after ``run``) computes, resolved as
    :func:`main` resolves it (its level and seed; the fork server's head start, :mod:`.prepare_ahead`)."""
    import argparse
    parser = argparse.ArgumentParser(prog="rss6")
    add_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["run", *argv])
    return level_settings(args).ensemble_spec(args.seed, args.store)


def _compute(args, spec, targets: list, output, cluster, annotate):
    """The ensemble (and the --until outcome, None without targets)."""
    from ..ensemble.run import ensemble
    if targets:
        from ..analysis.until import run_until
        until = run_until(spec, targets, args.n, output, workers=cluster.workers, scheduler=cluster.scheduler,
                          chunk=args.chunk, annotate=annotate, worker_timeout=cluster.worker_timeout)
        return until.ensemble, until
    outcome = ensemble(spec, args.n, output, workers=cluster.workers, scheduler=cluster.scheduler,
                       chunk=args.chunk, annotate=annotate, worker_timeout=cluster.worker_timeout)
    return outcome, None


def _report(args, level, outcome, until, output, specs: list, verdicts: list, note) -> int:
    """Print what was written, the statistics, the verdicts and ``note`` (what they leave out); the exit
    code."""
    from ..analysis.gate import exit_code, verdicts_with_note
    from ..analysis.resolution import resolution_attrs
    from ..analysis.stats import ensemble_stats, format_stats
    from ..analysis.summary import every_realisation_failed, failure_reasons
    ds = outcome.dataset
    print(_outcome_line(outcome, output, args.n if until is None else until.n, level.model))
    none_finished = every_realisation_failed(ds, output)
    if none_finished:
        raise UserError(none_finished)
    for line in failure_reasons(ds):
        print(line, file=sys.stderr)
    dynamic = model_level(level.model).contact_joints   # its velocity and acceleration measure the robot
    shown = {"quantity": list(QUANTITIES) if dynamic else ["displacement"],
             "window": ["whole", "steady"] if dynamic else ["whole"]}
    sds = ensemble_stats(ds, window=None)
    sds = sds.sel({k: v for k, v in shown.items() if k in sds.dims})
    print(format_stats(sds.assign_attrs(resolution_attrs(sds, ds))))
    if not dynamic:
        print(f"(displacement only; rss6 stats {output} shows velocity and acceleration too)")
    code = 0 if until is None else _until_verdict(until, args.n)
    if specs:
        print(verdicts_with_note(verdicts, ds))
    note()
    if not specs:
        return code
    return code or exit_code(verdicts, args.undecided)   # an --until cap reached first stays 1


def _outcome_line(outcome, output, n: int, model: str) -> str:
    """What the run did to ``output``: written, extended, or nothing to do (and why)."""
    ds, total = outcome.dataset, outcome.dataset.sizes["realization"]
    failed = int(ds.attrs["n_failed"])
    if not outcome.written:
        extra = (f"; -n {n} is fewer than the {total} stored, the file is kept as it is "
                 "(use another -o for a smaller ensemble)" if total > n else "")
        return f"nothing to do: {output} already holds {total} realisations of the {model} level{extra}"
    kept = f", {outcome.stored_before} of them stored before" if outcome.stored_before else ""
    return f"wrote {output}: {total} realisations of the {model} level ({failed} failed{kept})"


def _until_verdict(until, cap: int) -> int:
    """Print whether the --until targets were met; 1 if the cap was reached first."""
    if until.met:
        print(f"--until: every target met at n = {until.n}")
        return 0
    missing = sorted({w.target for w in until.widths if not w.met})
    print(f"rss6: --until not met at n = {until.n} (cap -n {cap}): {'; '.join(missing)}; raise -n "
          "and rerun the same command to continue", file=sys.stderr)
    return 1
