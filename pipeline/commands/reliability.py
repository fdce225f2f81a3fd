"""rss6 reliability: the probability that a level's maximum |error| exceeds a limit, by subset
simulation or plain Monte Carlo, with every evaluation in a netCDF file."""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

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
    add_scene(p, names_output=True)
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
                   help="with --cov: evaluations at most, over all runs (default 20000 subset, 200000 mc); a subset "
                        "run takes at most the levels, (1 - p0) N evaluations each after N, that fit in what is left")
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
    from ..files.outputs import OutputLock, answered_request
    event, level = _settings(args)
    cluster = resolve_cluster(args.workers)
    request = _request(args, event, level)
    output = Path(args.output or f"{output_stem(args.config)}_{level.model}_reliability.nc")
    answered = answered_request(output, "reliability", request, args.parents)
    figure = _figure(args, answered)
    note = loaded_joints_meanwhile("reliability", level.scene, level.model, [event])
    with OutputLock(output):
        est = _held(output) if answered else _compute(args, event, level, cluster, output, request)
    if est is None:
        return 130
    if not math.isfinite(est.pf):     # stalled, or no convergence within the levels: no estimate to report
        print(f"rss6 reliability: error: {_no_estimate(est, event, level, output)}", file=sys.stderr)
        return 2
    try:
        _report(args, est, event, level, output, figure, note, wrote=not answered)
    except KeyboardInterrupt:
        return interrupted(f"the answer is in {output}", "rerun the same command to print it and write the figure")
    note()
    return 0


def _no_estimate(est, event, level, output) -> str:
    """Why a run gave no estimate, with the largest response it reached against the limit (far below it, the
    event may be impossible and no -n helps) and advice that works: the same command only reprints this."""
    from ..studies.reliability import largest_response
    top = largest_response(est, event)
    reached = (f"the largest response of its {est.level.size} evaluations is {top / event.factor:.4g} {event.unit} "
               f"against the limit {event.limit / event.factor:g} {event.unit}")
    kept = f"they are in {output} (the same command reprints this without recomputing)"
    if top <= event.limit:
        return (f"no estimate of P({event.text}) ({est.status}: {est.message}); {reached}: the event may be "
                f"impossible for scene {level.scene.name} at the {level.model} level (P 0 to within these "
                f"evaluations; a larger -n is unlikely to reach it); {kept}; ask for a lower limit with another -o")
    return (f"no estimate of P({event.text}) ({est.status}: {est.message}); {reached}; {kept}; a larger -n or "
            "another --p0, with another -o, may get one")


def _request(args, event, level) -> dict:
    """What a reliability file answers (pipeline.files.outputs.answered_request): the scene's sha256, the level's
    numerics and every option that changes the estimate."""
    from ..files.outputs import text_identity
    return {"scene": text_identity(level.scene.source_text), "--model": level.model, "--integrator": level.integrator,
            "--dt": level.dt, "--elements": level.elements, "--event": event.text, "--method": args.method,
            "-n": args.n, "--p0": args.p0, "--seed": args.seed, "--confidence": args.confidence, "--cov": args.cov,
            "--budget": args.budget}


def _figure(args, answered: bool):
    """The --plot file checked before any work (None: none asked, or one already drawn from the file that
    answers this request, which a rerun keeps)."""
    from ..files.outputs import check_new_output
    if not args.plot or (answered and Path(args.plot).exists()):
        return None
    return check_new_output(args.plot, "rss6 reliability", args.parents, "--plot")


def _held(output):
    """The estimate an earlier run of the same request wrote to ``output`` (files.outputs.reuse_answer)."""
    from ..files.outputs import reuse_answer
    from ..files.reading import load_netcdf
    from ..studies.reliability import estimate_from_dataset
    from ..studies.reliability_checkpoint import checkpoint_path
    return reuse_answer(output, "reliability", lambda path: estimate_from_dataset(load_netcdf(path)),
                        checkpoint_path(output))


def _compute(args, event, level, cluster, output, request):
    """Run the estimate (resuming a checkpoint with --resume) and write ``output`` with ``request``; None after
    Ctrl-C (said on stderr)."""
    from ..files.outputs import REQUEST_ATTR
    from ..files.writing import write_netcdf
    from ..studies.reliability import reliability, reliability_dataset
    from ..studies.reliability_checkpoint import Checkpoint, checkpoint_path
    spec = level.ensemble_spec(args.seed)
    options = f"--event '{event.text}' --method {args.method}" + (f" -n {args.n}" if args.n else "") + \
        (f" --p0 {args.p0:g}" if args.method == "subset" else "") + f" --seed {args.seed}" + \
        (f" --cov {args.cov:g}" if args.cov else "") + (f" --budget {args.budget}" if args.budget else "")
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
        interrupted(kept if checkpoint.batches else None, "rerun the same command with --resume to continue")
        return None
    ds = reliability_dataset(est, event, spec, options)
    write_netcdf(ds.assign_attrs({REQUEST_ATTR: json.dumps(request, sort_keys=True)}), output)
    checkpoint.remove()
    return est


def _report(args, est, event, level, output, figure, note, wrote: bool = True) -> None:
    """Print the estimate and what fails (text or JSON); write the figure if asked. ``wrote``: whether this run
    wrote ``output`` (else it answers from the file of an earlier run)."""
    from ..analysis.failure_domain import failure_domain_json, format_failure_domain
    from ..studies.reliability import coverage_note, what_fails
    fd, physical = what_fails(est, event, level.scene, level.model)
    if figure is not None:
        from ..analysis.reliability_plots import plot_reliability
        plot_reliability(est, event, fd, figure, f"rss6 reliability: P({event.text}) = {est.pf:.3g}, scene "
                                                 f"{level.scene.name}, {level.model} level, {output.name}")
    if args.json:
        from ..analysis.spec import si_unit
        out = _strict(est.summary()) | {"si_unit": si_unit(event.quantity, event.directions[0]),
                                        "coverage_note": coverage_note(est),
                                        "failure_domain": failure_domain_json(fd, physical) if fd else None}
        out |= note.json()
        print(json.dumps(out, indent=2))
        return
    print(_text(est, event, output, wrote))
    print(format_failure_domain(fd, physical) if fd else "what fails: no evaluation exceeded the limit")
    if figure is not None:
        print(f"wrote {figure}")


def _strict(summary: dict) -> dict:
    """NaN and infinities as null (strict JSON)."""
    from ..analysis.stats import json_number
    return {k: json_number(v) if isinstance(v, float) else v for k, v in summary.items()}


def _text(est, event, output, wrote: bool = True) -> str:
    """The estimate in a few lines (the first: the file written, or read back)."""
    from ..analysis.exceedance import union_words
    from ..studies.reliability import coverage_note
    levels = ", ".join(f"{e}" for e in est.evaluations_per_level)
    interval = (f"{100 * est.confidence:g} % interval [{est.lower:.4g}, {est.upper:.4g}] ({est.interval})"
                if math.isfinite(est.lower) else f"no {100 * est.confidence:g} % interval: {est.interval}")
    event_line = f"P({event.text}){union_words(event.directions)} over the {window_words(event.window)}"
    cov = f"CoV {est.cov:.3g}" if math.isfinite(est.cov) else "no CoV (none at a probability of 0 or 1)"
    note = coverage_note(est)
    return (f"{'wrote' if wrote else 'read back'} {output}\n"
            f"{event_line} = {est.pf:.4g} by {est.method}, {cov}; {interval}\n"
            f"{est.level.size} evaluations (per level: {levels}); {est.message}" + (f"\nnote: {note}" if note else ""))
