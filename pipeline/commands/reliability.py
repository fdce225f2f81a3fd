"""rss6 reliability: the probability that a level's maximum |error| exceeds a limit, by subset
simulation or plain Monte Carlo, with every evaluation in a netCDF file."""
from __future__ import annotations

import json
import math
import sys
import time

from ..ensemble.settings import resolve_cluster, resolve_level
from ..scenes.catalogue import find_scene
from ..vocabulary import OptionError, window_words
from .messages import interrupted, loaded_joints_meanwhile
from .options import (add_confidence, add_json, add_model, add_parents, add_scene, add_seed, add_workers, evaluations,
                      fraction, output_stem)
from .requirements import known_windows


def add_parser(sub) -> None:
    from ..studies.reliability import METHODS
    p = sub.add_parser("reliability", help="probability that the maximum |error| exceeds a limit (subset "
                                           "simulation or Monte Carlo), with its interval")
    add_scene(p)
    add_model(p, "model level (default quasi-static; contact costs about 0.4 s per evaluation on the paper "
                 "scene)", default="quasi-static")
    p.add_argument("--event", required=True, metavar="EVENT",
                   help="QUANTITY:DIRECTIONS>VALUE UNIT[/WINDOW], e.g. 'displacement:z>0.1mm' or "
                        "'displacement:x,y,z>0.1mm/steady': a realisation's maximum |error| over the window "
                        "(default whole) exceeds the limit, in any of the directions given")
    p.add_argument("--method", choices=METHODS, default="subset",
                   help="subset: subset simulation (Au & Beck 2001, adaptive conditional sampling); mc: plain "
                        "Monte Carlo with an exact Clopper-Pearson interval (default subset)")
    p.add_argument("-n", type=evaluations, help="subset: evaluations per level N, a multiple of 1 / p0 "
                                                 "(default 1000); mc: realisations (default 20000)")
    p.add_argument("--cov", type=fraction, metavar="C",
                   help="a CoV target in (0, 1): mc adds realisations (blocks of 1000), subset doubles N (a fresh "
                        "run each time), until the estimated CoV is at most C or --budget would be exceeded "
                        "(exit 0 either way; status 'budget' if not met) (default: none: a run of size -n)")
    p.add_argument("--budget", type=evaluations, metavar="E",
                   help="with --cov: evaluations at most, over all runs (default 50000 subset, 200000 mc); a subset "
                        "run starts only if its most evaluations, N + 16 (1 - p0) N, fit in what is left")
    p.add_argument("-p0", "--p0", type=float, default=0.1,
                   help="subset: conditional probability of each level, in (0, 0.5] (default 0.1)")
    add_seed(p)
    add_confidence(p, "confidence of the interval")
    p.add_argument("-o", "--output", help="netCDF file of every evaluation (default: SCENE_MODEL_reliability.nc)")
    add_parents(p)
    add_json(p, "print one JSON object: pf, lower, upper, confidence, cov, evaluations, method, ...")
    add_workers(p, what="local dask workers for large batches (1: in this process)")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run from OUTPUT.checkpoint.nc (the same command otherwise): the "
                        "result is that of an uninterrupted run; without it, a checkpoint left there is refused")
    p.add_argument("--plot", metavar="PNG", help="also write a figure: the levels' thresholds against the limit, "
                                                 "and the inputs' shift among the failing evaluations (default: none)")
    p.set_defaults(main=main)


def _settings(args):
    """Every option checked before any work: the event, p0 and N, the level's random inputs."""
    from ..analysis.exceedance import parse_event
    from ..analysis.subset import SubsetSettings
    from ..studies.reliability import DEFAULT_BUDGET, check_subset_budget, input_dimension
    event = parse_event(args.event)
    if args.method == "subset":
        try:
            settings = SubsetSettings(args.n or 1000, args.p0, args.seed, args.confidence)
        except ValueError as exc:
            raise OptionError(f"-n/--p0: {exc}") from None
        if args.cov is not None:
            check_subset_budget(settings, args.budget or DEFAULT_BUDGET["subset"])
    elif args.p0 != 0.1:
        raise OptionError("--p0: applies with --method subset only")
    if args.budget and args.cov is None:
        raise OptionError("--budget: applies with --cov only")
    if args.method == "mc" and args.cov is not None and args.n:
        raise OptionError("-n: with --method mc --cov the realisations are added until the CoV target; cap them "
                          "with --budget")
    level = resolve_level(find_scene(args.config), args.config, model=args.model)
    known_windows([event], level.scene, "--event")
    input_dimension(level.scene, level.model, args.config)   # ReliabilityError: no random inputs
    return event, level


def main(args) -> int:
    from ..files.outputs import OutputLock, check_new_output
    from ..files.writing import write_netcdf
    from ..studies.reliability import reliability, reliability_dataset
    from ..studies.reliability_checkpoint import Checkpoint, checkpoint_path
    event, level = _settings(args)
    cluster = resolve_cluster(args.workers)
    output = check_new_output(args.output or f"{output_stem(args.config)}_{level.model}_reliability.nc",
                              "rss6 reliability", args.parents)
    figure = check_new_output(args.plot, "rss6 reliability", args.parents, "--plot") if args.plot else None
    spec = level.ensemble_spec(args.seed)
    options = f"--event '{event.text}' --method {args.method}" + (f" -n {args.n}" if args.n else "") + \
        (f" --p0 {args.p0:g}" if args.method == "subset" else "") + f" --seed {args.seed}" + \
        (f" --cov {args.cov:g}" if args.cov else "") + (f" --budget {args.budget}" if args.budget else "")
    start = time.perf_counter()
    note = loaded_joints_meanwhile("reliability", level.scene, level.model, [event])
    with OutputLock(output):
        found = checkpoint_path(output).exists()
        checkpoint = Checkpoint(checkpoint_path(output), {**spec.attrs(), "options": options}, args.resume)
        if args.resume and not found:
            print(f"rss6 reliability: note: --resume found no checkpoint at {checkpoint.path}: the run starts "
                  "from its first batch", file=sys.stderr)
        try:
            est = reliability(spec, event, args.method, args.n, args.p0, args.confidence, cluster.workers,
                              checkpoint, args.cov, args.budget)
        except KeyboardInterrupt:
            kept = f"the evaluations so far are kept in {checkpoint.path}"
            return interrupted(kept if checkpoint.batches else None, "rerun the same command with --resume to continue")
        write_netcdf(reliability_dataset(est, event, spec, time.perf_counter() - start, options), output)
        checkpoint.remove()
    if not math.isfinite(est.pf):     # stalled, or no convergence within the levels: no estimate to report
        print(f"rss6 reliability: error: no estimate of P({event.text}) ({est.status}: {est.message}); the "
              f"{est.level.size} evaluations are in {output}; a larger -n or another --p0 may get one",
              file=sys.stderr)
        return 2
    _report(args, est, event, level, output, figure, note)
    note()
    return 0


def _report(args, est, event, level, output, figure, note) -> None:
    """Print the estimate and what fails (text or JSON); write the figure if asked."""
    from ..analysis.failure_domain import failure_domain_json, format_failure_domain
    from ..studies.reliability import what_fails
    fd, physical = what_fails(est, event, level.scene, level.model)
    if figure is not None:
        from ..analysis.reliability_plots import plot_reliability
        plot_reliability(est, event, fd, figure, f"rss6 reliability: P({event.text}) = {est.pf:.3g}, scene "
                                                 f"{level.scene.name}, {level.model} level, {output.name}")
    if args.json:
        out = _strict(est.summary()) | {"failure_domain": failure_domain_json(fd, physical) if fd else None}
        out |= note.json()
        print(json.dumps(out, indent=2))
        return
    print(_text(est, event, output))
    print(format_failure_domain(fd, physical) if fd else "what fails: no evaluation exceeded the limit")
    if figure is not None:
        print(f"wrote {figure}")


def _strict(summary: dict) -> dict:
    """NaN and infinities as null (strict JSON)."""
    from ..analysis.stats import json_number
    return {k: json_number(v) if isinstance(v, float) else v for k, v in summary.items()}


def _text(est, event, output) -> str:
    """The estimate in a few lines."""
    from ..analysis.exceedance import union_words
    levels = ", ".join(f"{e}" for e in est.evaluations_per_level)
    interval = (f"{100 * est.confidence:g} % interval [{est.lower:.4g}, {est.upper:.4g}] ({est.interval})"
                if math.isfinite(est.lower) else f"no {100 * est.confidence:g} % interval: {est.interval}")
    event_line = f"P({event.text}){union_words(event.directions)} over the {window_words(event.window)}"
    cov = f"CoV {est.cov:.3g}" if math.isfinite(est.cov) else "no CoV (none at a probability of 0 or 1)"
    return (f"wrote {output}\n{event_line} = {est.pf:.4g} by {est.method}, {cov}; {interval}\n"
            f"{est.level.size} evaluations (per level: {levels}); {est.message}")
