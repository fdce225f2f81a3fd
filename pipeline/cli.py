"""The ``rss6`` command line: parse, build the work, print or write the result.

User mistakes (a bad scene file, a bad option) end with exit code 2 and one
line naming what is wrong; no traceback.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace

import numpy as np

from rss6core import CONTACT_STARTS, INTEGRATORS, MODELS, SceneError, __version__

from .scenes.catalogue import find_scene, scene_names
from .analysis.summary import contact_peaks, error_summary, format_errors, format_summary, scene_summary
from .vocabulary import CONFIDENCE, FINISHED


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text}")
    return value


def _scheduler_address(text: str) -> str:
    """A dask.distributed scheduler address (tcp://host:port or host:port), checked before any work."""
    from distributed.comm.addressing import parse_address, parse_host_port
    try:
        parse_host_port(parse_address(text)[1])
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r} is no scheduler address ({exc}); e.g. "
                                         "tcp://10.0.0.5:8786") from None
    return text


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"must lie strictly between 0 and 1, got {text}")
    return value


def _int_at_least(minimum: int):
    """An argparse type: an integer of at least ``minimum``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be {minimum} or more, got {text}")
        return value
    return parse


_positive_int = _int_at_least(1)
_nonnegative_int = _int_at_least(0)


def _check(args) -> int:
    summary = scene_summary(find_scene(args.config))
    print(json.dumps(summary, indent=2) if args.json else format_summary(summary))
    return 0


def _settings(args, scene) -> tuple[str, str, float, int]:
    """Model, integrator, time step and mesh: the command line's, else the scene's; the step is
    checked here, before any work, against the scene's duration."""
    from rss6core import default_integrator, default_time_step, time_grid
    sim = scene.simulation
    model = args.model or sim.model
    if getattr(args, "start", None) is not None and model != "contact":
        raise SceneError(f"--start {args.start}: sets the contact level's initial state; this run is "
                         f"the {model} level")
    dt = args.dt or default_time_step(scene, model)
    try:
        time_grid(scene.trajectory.duration, dt)
    except ValueError as exc:
        source = "--dt" if args.dt else f"{scene.source_path}: time step"
        raise SceneError(f"{source}: {exc}") from None
    return (model, args.integrator or default_integrator(scene, model), dt,
            args.elements or sim.elements_per_link)


def _with_start(args, scene):
    """The scene with the command line's --start as its [simulation] contact_start (recorded in the
    scene text, so an ensemble's workers and its file see it)."""
    if args.start is None or args.start == scene.simulation.contact_start:
        return scene
    from rss6core import parse_scene

    from .scenes.variant import scene_variant
    text = scene_variant(scene.source_text, {"simulation": {"contact_start": args.start}},
                         scene.source_path, add=True)
    return parse_scene(text, scene.source_path)


def _refuse_clearance_free_default(args, scene, model: str) -> None:
    """An ensemble of a level without clearances is N identical runs: only on explicit request."""
    from .analysis.summary import CLEARANCE_LEVELS, run_default_level
    if args.model is None and run_default_level(scene) is None:
        raise SceneError(f"scene {scene.name!r}: its model {model!r} has no clearances, so every "
                         f"realisation would be the same; pass --model with a clearance level "
                         f"({', '.join(CLEARANCE_LEVELS)}), or --model {model} to run it anyway")


def _simulate(args) -> int:
    import time

    from rss6core import simulate

    from .files.store import run_dataset, write_netcdf
    from .files.outputs import check_new_output
    scene = _with_start(args, find_scene(args.config))
    model, integrator, dt, elements = _settings(args, scene)
    if args.output:
        check_new_output(args.output, "rss6 simulate", args.parents)
    _note_compiling(model)
    start = time.perf_counter()
    try:
        result = simulate(scene, model, integrator, dt, elements, args.seed, args.realization)
    except ValueError as exc:  # a time step that does not divide the duration, ...
        raise SceneError(f"{args.config}: {exc}") from None
    wall = time.perf_counter() - start
    ds = run_dataset(scene, result, model=model, integrator=integrator, dt=dt, elements=elements,
                     wall_time=wall, seed=args.seed, realization=args.realization)
    if args.output:
        write_netcdf(ds, args.output)
    summary = error_summary(ds)
    if result.contact_force_peak is not None:
        summary["max_contact_force_N"] = contact_peaks(result.contact_force_peak)
    if args.json:
        print(json.dumps({**summary, "wall_time_s": wall, "status": result.status,
                          "message": result.message, "model": model, "integrator": integrator,
                          "time_step_s": dt, "elements_per_link": elements}, indent=2))
    else:
        print(f"scene {scene.name!r}, model {model}, {integrator}, dt = {dt:g} s, "
              f"{elements} elements per link: {result.status} in {wall:.2f} s")
        print(format_errors(summary))
        if "max_contact_force_N" in summary:
            print("max contact force (N): " + ", ".join(
                f"{k} {v:.4g}" for k, v in summary["max_contact_force_N"].items())
                + (" (the paper's method keeps every joint inside its clearance, so eq. 17 gives none)"
                   if model == "paper" and not any(summary["max_contact_force_N"].values()) else ""))
    if result.status != FINISHED:
        print(f"rss6: run failed: {result.message}", file=sys.stderr)
        return 1
    return 0


def _note_compiling(model: str) -> None:
    """One line on stderr when this process is about to compile ``model``'s kernels."""
    from rss6core import kernels_to_compile
    cold = kernels_to_compile(model)
    if cold:
        from .ensemble.progress import compile_note
        print(f"rss6 simulate: {compile_note(cold)}", file=sys.stderr, flush=True)


def _warm(args) -> int:
    """Compile the kernels every level uses into numba's cache, and say which and how long."""
    import time

    from rss6core import MODELS, compile_kernels, kernel_cache_folder, level_kernels
    start = time.perf_counter()
    compiled = compile_kernels(find_scene("smoke"))
    wall = time.perf_counter() - start
    where = f"numba's cache ({kernel_cache_folder()})"
    if not compiled:
        kernels = [k for model in MODELS for k in level_kernels(model)]
        print(f"rss6 warm: nothing to compile: {', '.join(kernels)} (the contact level's; the other "
              f"levels have none) are in {where}; checked in {wall:.1f} s")
        return 0
    print("rss6 warm: compiled " + ", ".join(f"{k} ({s:.0f} s)" for k, s in compiled.items())
          + f" into {where} in {wall:.0f} s")
    return 0


def _run(args) -> int:
    from .files.outputs import check_output_path
    from .ensemble.cluster import SchedulerUnavailable
    from .ensemble.run import EnsembleSpec, ensemble, parts_dir
    from .analysis.summary import failure_reasons
    specs, verdicts = _requirements(args), []
    targets = _until_targets(args)
    _known_windows(specs + targets)
    scene = _with_start(args, find_scene(args.config))
    model, integrator, dt, elements = _settings(args, scene)
    _refuse_clearance_free_default(args, scene, model)
    replicates = _replicates(args, scene, model, dt)
    _check_until_cap(targets, args.n, replicates)
    output = check_output_path(args.output or f"{scene.name}_{model}.nc", args.parents)
    _warn_oversubscription(args.workers, args.scheduler)
    _import_meanwhile("distributed", "pipeline.analysis.gate")   # gate imports stats (scipy.stats)
    spec = EnsembleSpec(scene.source_text, str(args.config), model, integrator, dt, elements,
                        args.seed, args.store, qmc_replicates=replicates)
    until = None
    kept = f"finished chunks are kept in {parts_dir(output)}"
    try:
        if targets:
            from .analysis.until import run_until
            until = run_until(spec, targets, args.n, output, workers=args.workers,
                              scheduler=args.scheduler, chunk=args.chunk,
                              annotate=_annotate(specs, verdicts), worker_timeout=args.worker_timeout)
            outcome = until.ensemble
        else:
            outcome = ensemble(spec, args.n, output, workers=args.workers, scheduler=args.scheduler,
                               chunk=args.chunk, annotate=_annotate(specs, verdicts),
                               worker_timeout=args.worker_timeout)
    except SchedulerUnavailable as exc:
        print(f"rss6: error: {exc}" + (f"; {_continue(kept)}" if parts_dir(output).exists() else ""),
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return _interrupted(kept)
    from .analysis.stats import ensemble_stats, format_stats
    from .analysis.gate import exit_code, format_verdicts
    ds = outcome.dataset
    print(_outcome_line(outcome, output, args.n if until is None else until.n, model))
    reasons = failure_reasons(ds)
    for line in reasons:
        print(line, file=sys.stderr)
    if reasons and ds.attrs["n_failed"] == ds.sizes["realization"]:
        print("rss6: every realisation failed; no statistics", file=sys.stderr)
        return 1
    from .vocabulary import QUANTITIES
    contact = model == "contact"   # its velocity and acceleration measure the robot; start-up impacts
    shown = {"quantity": list(QUANTITIES) if contact else ["displacement"],
             "window": ["whole", "steady"] if contact else ["whole"]}
    sds = ensemble_stats(ds, window=None)
    print(format_stats(sds.sel({k: v for k, v in shown.items() if k in sds.dims})))
    if model != "contact":
        print(f"(displacement only; rss6 stats {output} shows velocity and acceleration too)")
    code = 0 if until is None else _until_verdict(until, args.n)
    if not specs:
        return code
    print(format_verdicts(verdicts))
    return code or exit_code(verdicts, args.undecided)   # an --until cap reached first stays 1


def _known_windows(specs: list) -> None:
    """A --require or --until naming a window the files do not have is a one-line error before any work."""
    from .vocabulary import WINDOWS
    for s in specs:
        if s.window is not None and s.window not in WINDOWS:
            raise SceneError(f"{s.text!r}: unknown window {s.window!r}; choose one of "
                             f"{', '.join(WINDOWS)}")


def _until_targets(args) -> list:
    """The --until targets, parsed before any work; a malformed one is a one-line error."""
    from .analysis.until import UntilError, parse_targets
    try:
        return parse_targets(args.until)
    except UntilError as exc:
        raise SceneError(str(exc)) from None


def _check_until_cap(targets: list, cap: int, replicates: int | None) -> None:
    """A --until target no n up to -n can meet is a one-line error before any work."""
    from .analysis.until import UntilError, check_cap
    try:
        check_cap(targets, cap, replicates)
    except UntilError as exc:
        raise SceneError(str(exc)) from None


def _replicates(args, scene, model: str, dt: float) -> int | None:
    """R for --sampler qmc (None for mc), checked before any work against -n and the level."""
    from rss6core import time_grid, uniform_dimension

    from .ensemble.sampler import DEFAULT_REPLICATES, check_qmc
    from .analysis.summary import CLEARANCE_LEVELS
    if args.sampler == "mc":
        if args.replicates is not None:
            raise SceneError("--replicates applies to --sampler qmc only")
        return None
    if model not in CLEARANCE_LEVELS:
        raise SceneError(f"--sampler qmc: the {model} level draws no clearances")
    replicates = DEFAULT_REPLICATES if args.replicates is None else args.replicates
    steps = len(time_grid(scene.trajectory.duration, dt)) if model == "paper" else None
    try:
        check_qmc(args.n, replicates, uniform_dimension(steps))
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    return replicates


def _until_verdict(until, cap: int) -> int:
    """Print whether the --until targets were met; 1 if the cap was reached first."""
    if until.met:
        print(f"--until: every target met at n = {until.n}")
        return 0
    missing = sorted({w.target for w in until.widths if not w.met})
    print(f"rss6: --until not met at n = {until.n} (cap -n {cap}): {'; '.join(missing)}; raise -n "
          "and rerun the same command to continue", file=sys.stderr)
    return 1


def _import_meanwhile(*modules: str) -> None:
    """Import ``modules`` (needed only once the realisations are computed) in a thread, in order,
    while this one starts the workers and waits for them: the statistics' scipy.stats alone took
    0.6-0.9 s of a 10 s run when imported first. An import that fails there is retried, and then
    reported, where the module is used."""
    import importlib
    import threading

    def load() -> None:
        for name in modules:
            try:
                importlib.import_module(name)
            except Exception:   # noqa: BLE001 (the caller's own import reports it)
                return
    threading.Thread(target=load, name="rss6-imports", daemon=True).start()


def _annotate(specs: list, verdicts: list):
    """The hook that judges the finished ensemble and puts the verdicts in its attributes; the
    verdicts are also appended to ``verdicts`` for the caller."""
    if not specs:
        return None

    def annotate(ds) -> dict:
        verdicts[:] = _judge(ds, specs)
        return _verdict_attrs(verdicts)
    return annotate


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


def _continue(kept: str) -> str:
    """What a stopped command kept (e.g. "finished chunks are kept in X.parts") and that the same
    command continues from it: one wording for Ctrl-C and a lost scheduler alike."""
    return f"{kept}; rerun the same command to continue"


def _interrupted(kept: str | None) -> int:
    """Exit code 130 after Ctrl-C, with one line: :func:`_continue` of what is kept, or, for a
    command that does not resume (``kept`` None), that nothing was written."""
    what = _continue(kept) if kept else "nothing written (this command does not resume)"
    print(f"rss6: interrupted; {what}", file=sys.stderr)
    return 130


def _warn_oversubscription(workers: int, scheduler: str | None) -> None:
    import os
    cores = os.cpu_count() or 1
    if not scheduler and workers > cores:
        print(f"rss6: warning: --workers {workers} exceeds the {cores} cores of this machine; the "
              "workers will share them and the run will not be faster", file=sys.stderr)


def _tracked(paths: list) -> list[str]:
    """Those of ``paths`` (files or folders) that hold files git tracks; none outside a repository."""
    import subprocess
    from pathlib import Path
    tracked = []
    for path in map(Path, paths):
        folder = path if path.is_dir() else path.parent
        if not path.exists():
            continue
        try:
            out = subprocess.run(["git", "ls-files", "--", path.name if path.is_file() else "."],
                                 cwd=folder, capture_output=True, text=True, timeout=20)
        except (OSError, subprocess.TimeoutExpired):
            continue
        tracked += [str(folder / f) for f in out.stdout.split()] if out.returncode == 0 else []
    return tracked


def _report(args) -> int:
    from pathlib import Path

    from .studies.report import ReportPlan, write_report
    from .ensemble.cluster import SchedulerUnavailable
    out = Path(args.output)
    tracked = [] if args.overwrite_tracked else _tracked([out / "results.md", out / "results"])
    if tracked:
        raise SceneError(f"{args.output}: would overwrite {tracked[0]}, which git tracks "
                         f"({len(tracked)} tracked files); choose another -o or pass "
                         "--overwrite-tracked")
    plan = ReportPlan(args.n, args.family_n, args.workers, args.scheduler, args.seed,
                      args.worker_timeout)
    kept = f"finished ensembles and chunks are kept in {args.data or out / 'results-data'}"
    try:
        path = write_report(args.configs, args.output, plan, args.data)
    except SchedulerUnavailable as exc:
        print(f"rss6: error: {exc}; {_continue(kept)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return _interrupted(kept)
    print(f"wrote {path}")
    return 0


def _selection(sds, args):
    """The statistics of the quantity and direction asked for; SceneError names an unknown one."""
    for dim in ("quantity", "direction"):
        given = getattr(args, dim)
        allowed = [str(v) for v in sds[dim].values]
        if given is not None and given not in allowed:
            raise SceneError(f"--{dim}: unknown {dim} {given!r}; choose one of {', '.join(allowed)}")
        if given is not None:
            sds = sds.sel({dim: [given]})
    return sds


def _requirements(args) -> list:
    """The --require specs, parsed before any work; a malformed one is a one-line error."""
    from .analysis.spec import SpecError, parse_specs
    if args.undecided is not None and not args.require:
        raise SceneError(f"--undecided {args.undecided}: applies with --require only")
    try:
        return parse_specs(args.require)
    except SpecError as exc:
        raise SceneError(str(exc)) from None


def _judge(ds, specs: list, confidence: float = CONFIDENCE) -> list:
    """Verdicts of the specs on an ensemble (or single-run) Dataset; a window the file lacks is a
    one-line error."""
    from .analysis.gate import judge_all
    try:
        return judge_all(specs, ds, confidence)
    except ValueError as exc:
        raise SceneError(str(exc)) from None


def _stats(args) -> int:
    from .files.check import open_results
    from .analysis.gate import check_confidence, exit_code, format_verdicts, verdicts_json
    from .analysis.stats import ensemble_stats, format_stats, to_json
    from .files.outputs import check_new_output
    from .files.store import write_netcdf
    specs = _requirements(args)
    _known_windows(specs)
    if specs:
        try:
            check_confidence(args.confidence)
        except ValueError as exc:
            raise SceneError(f"--{exc} (with --require)") from None
    if args.output:
        check_new_output(args.output, "rss6 stats", args.parents)
    ds = open_results(args.file)
    full = ensemble_stats(ds, args.confidence, window=None)
    if args.window is not None:
        full, specs = _window_of(full, args.window), [replace(s, window=s.window or args.window)
                                                      for s in specs]
    verdicts = _judge(ds, specs, args.confidence)
    sds = _selection(full, args)
    if args.output:
        write_netcdf(sds.assign_attrs(_verdict_attrs(verdicts)) if specs else sds, args.output)
    if args.json:
        out = to_json(sds) | ({"requirements": verdicts_json(verdicts)} if specs else {})
        print(json.dumps(out, indent=2, allow_nan=False))
    else:
        print(format_stats(sds))
        if specs:
            print(format_verdicts(verdicts))
    return exit_code(verdicts, args.undecided) if specs else 0


def _window_of(sds, window: str):
    """The statistics of analysis window ``window`` only (dimension kept); SceneError names an unknown
    one, or a file without windows."""
    from .analysis.stats import windows_of
    if window not in windows_of(sds):
        raise SceneError(f"--window: unknown window {window!r}; the file has "
                         f"{', '.join(windows_of(sds)) or 'no analysis windows'}")
    return sds.sel(window=[window])


def _verdict_attrs(verdicts: list) -> dict:
    """File attributes of the verdicts: the overall one and each as strict JSON (SI values)."""
    from .analysis.gate import overall, verdicts_json
    return {"requirements_verdict": overall(verdicts),
            "requirements": json.dumps(verdicts_json(verdicts), allow_nan=False)}


def _require_arguments(p) -> None:
    p.add_argument("--require", action="append", metavar="SPEC",
                   help="a requirement QUANTITY:DIRECTIONS OP VALUE UNIT@STATISTIC[/WINDOW], e.g. "
                        "'displacement:x,y<=0.05mm@q95' or '...@q95/steady' (window whole, startup or "
                        "steady; default whole) (repeatable): fails when the statistic's one-sided "
                        "95 %% bound (rss6 stats: --confidence) on the limit's side violates the limit, "
                        "passes when the other one-sided bound meets it, else undecided; exit 0 if all "
                        "pass, 1 if any fails, 3 if none fails but some are undecided (default: none)")
    p.add_argument("--undecided", choices=("fail", "pass"),
                   help="count undecided requirements as failed (exit 1) or passed (exit 0) "
                        "(default: neither, exit 3)")


def _plot(args) -> int:
    from .files.check import open_results
    from .analysis.plots import plot_ensemble, plot_run
    from .files.outputs import check_output_folder
    from .files.store import EnsembleFileError
    check_output_folder(args.output, args.parents)
    ds = open_results(args.file)
    if "realization" not in ds.dims:                      # rss6 simulate -o: one run's histories
        if str(ds.attrs.get("status", FINISHED)) != FINISHED:
            raise EnsembleFileError(f"{args.file}: nothing to plot, the run failed "
                                    f"({ds.attrs.get('status_message', 'no reason recorded')})")
        paths = plot_run(ds, args.output)
    else:
        if not (ds["status"].values.astype(str) == FINISHED).any():
            message = str(ds["status_message"].values.astype(str)[0])
            raise EnsembleFileError(f"{args.file}: nothing to plot, all {ds.sizes['realization']} "
                                    f"realisations failed (first reason: {message})")
        paths = plot_ensemble(ds, args.output)
        if "error" not in ds:
            print("no time histories in the file (run with --store full): envelope plots skipped",
                  file=sys.stderr)
    for p in paths:
        print(p)
    return 0


def _level_spec(args, scene, level: str):
    """The ensemble spec of one level of ``rss6 multifidelity``: the scene's settings for it."""
    from .ensemble.run import EnsembleSpec
    model, integrator, dt, elements = _settings(
        argparse.Namespace(model=level, integrator=None, dt=None, elements=None), scene)
    return EnsembleSpec(scene.source_text, str(args.config), model, integrator, dt, elements,
                        args.seed, "summary")


def _multifidelity(args) -> int:
    from .studies.multifidelity import (check_multifidelity_output, format_multifidelity, level_paths,
                                        multifidelity_dataset, to_json)
    from .ensemble.cluster import SchedulerUnavailable
    from .ensemble.run import ensemble, parts_dir
    from .files.store import check_window, write_netcdf
    from .analysis.summary import CLEARANCE_LEVELS
    if args.high == args.low:
        raise SceneError(f"--low {args.low}: must differ from --high (the same level is no control "
                         "variate)")
    for option, level in (("--high", args.high), ("--low", args.low)):
        if level not in CLEARANCE_LEVELS:
            raise SceneError(f"{option} {level}: this level has no clearances, so all its realisations "
                             f"are the same; choose one of {', '.join(CLEARANCE_LEVELS)}")
    if args.low_n < args.n:
        raise SceneError(f"--low-n {args.low_n}: must be at least -n ({args.n}); the first -n low "
                         "realisations are the pairs")
    if args.width is not None and args.cost_ratio is None:
        raise SceneError("--width: needs --cost-ratio (the cost of a high realisation over a low one)")
    scene = find_scene(args.config)
    try:
        check_window(scene, args.window)
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    output = check_multifidelity_output(args.output, args.parents)
    _warn_oversubscription(args.workers, args.scheduler)
    files = level_paths(output)
    data = []
    for level, n, path in ((args.high, args.n, files[0]), (args.low, args.low_n, files[1])):
        print(f"rss6 multifidelity: {level} level, {n} realisations in {path}", file=sys.stderr)
        kept = f"finished chunks are kept in {parts_dir(path)}"
        try:
            out = ensemble(_level_spec(args, scene, level), n, path, workers=args.workers,
                           scheduler=args.scheduler, progress=not args.json)
        except SchedulerUnavailable as exc:
            print(f"rss6: error: {exc}; {_continue(kept)}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            return _interrupted(kept)
        data.append(out.dataset.sel(realization=out.dataset["realization"].values < n))
    try:
        mds = multifidelity_dataset(*data, args.confidence, files, args.cost_ratio, args.width,
                                    args.window)
    except ValueError as exc:   # too few finished pairs
        print(f"rss6: error: {files[0]}: {exc}", file=sys.stderr)
        return 1
    write_netcdf(mds, output)
    if args.json:
        print(json.dumps(to_json(mds), indent=2, allow_nan=False))
    else:
        print(f"wrote {output} (also the means of mean_abs_error; --json prints both)")
        print(format_multifidelity(mds))
    return 0


def _multifidelity_parser(sub) -> None:
    from .vocabulary import WINDOWS
    mf = sub.add_parser("multifidelity", help="means of a dear level with a cheap level on more "
                        "realisations as control variate (multi-fidelity Monte Carlo)")
    mf.add_argument("config", nargs="?", default="paper",
                    help="scene TOML file or embedded scene name (default: paper)")
    mf.add_argument("--high", choices=MODELS, default="contact",
                    help="the dear level, run on realisations 0..N-1 (default: contact)")
    mf.add_argument("--low", choices=MODELS, default="quasi-static",
                    help="the cheap level, run on realisations 0..M-1 (default: quasi-static)")
    mf.add_argument("-n", type=_int_at_least(3), default=64,
                    help="high-level realisations N, 3 or more (default 64); no interval below N = 32")
    mf.add_argument("--low-n", type=_positive_int, default=1024,
                    help="low-level realisations M, at least N (default 1024)")
    mf.add_argument("-o", "--output", required=True,
                    help="multi-fidelity netCDF file F.nc; the two ensembles are ordinary rss6 run "
                         "files beside it, F.high.nc and F.low.nc, resumed like any other")
    mf.add_argument("--parents", action="store_true", help="create the output's missing folders")
    mf.add_argument("--seed", type=_nonnegative_int, default=0,
                    help="random seed, 0 or more (default 0)")
    mf.add_argument("--confidence", type=_fraction, default=CONFIDENCE,
                    help="confidence of the two-sided intervals, in (0, 1) (default 0.95)")
    mf.add_argument("--cost-ratio", type=_positive_float, metavar="C",
                    help="cost of one high realisation over one low one (e.g. from rss6 tradeoff); "
                         "adds the cost-optimal M/N and the cost against plain MC (default: none)")
    mf.add_argument("--width", type=_fraction, metavar="REL",
                    help="with --cost-ratio: also the realisations plain MC and multi-fidelity need "
                         "for a half-width of REL times the mean, e.g. 0.02 (default: none)")
    mf.add_argument("--window", choices=WINDOWS, default="whole",
                    help="analysis window of the means: whole (t >= the scene's settle_time_s), "
                         "startup (before its steady_after_s) or steady (from it) (default whole)")
    mf.add_argument("--workers", type=_positive_int,
                    help="local dask workers, one thread each (default 2)")
    mf.add_argument("--scheduler", type=_scheduler_address, help=SCHEDULER_HELP)
    mf.add_argument("--json", action="store_true",
                    help="print one strict JSON object (SI units; null where no number)")
    mf.set_defaults(func=_multifidelity)


def _tradeoff(args) -> int:
    from .files.outputs import check_output_folder
    from .studies.tradeoff import tradeoff, write_tradeoff
    scene = find_scene(args.config)
    check_output_folder(args.output, args.parents)
    print(f"rss6 tradeoff: {scene.name}, {args.n} realisations per setting (seed {args.seed})")
    ds = tradeoff(scene, args.n, args.seed)
    ref = ds.attrs["reference"]
    change = float(ds["reference_change"].max())
    print(f"reference {ref}: its step halved and mesh doubled change the statistics by at most "
          f"{100 * change:.2f} %" + ("" if change < 0.01 else " (not converged to 1 %)"))
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


def _stability(args) -> int:
    from .files.outputs import check_output_folder
    from .studies.stability import stability, write_stability
    scene = find_scene(args.config)
    check_output_folder(args.output, args.parents)
    print(f"rss6 stability: {scene.name}, tolerance {100 * args.tolerance:g} %")
    ds = stability(scene, args.tolerance, args.n, args.seed, args.horizon)
    write_stability(ds, args.output)
    print(f"wrote {args.output}/stability.csv, stability.nc, stability.png")
    for name in ds["sweep"].values:
        print(f"{name}: " + ", ".join(
            f"{lim.removesuffix('_s').replace('_', ' ')} "
            + (f"{v:.3g} s" if np.isfinite(v := float(ds[lim].sel(sweep=name))) else "-")
            for lim in ("largest_not_failed_s", "smallest_failed_s", "largest_accurate_s")))
    print(f"central-difference 2/omega_max: {ds.attrs['central_difference_limit_s']:.3g} s")
    return 0


def _sensitivity(args) -> int:
    import time
    from pathlib import Path

    from .files.outputs import OutputLock, check_new_output
    from .analysis.plots import plot_sensitivity
    from .ensemble.run import EnsembleSpec
    from .studies.sensitivity import SensitivityError, format_joints, format_sensitivity, sensitivity
    from .files.store import load_netcdf, write_netcdf
    scene = find_scene(args.config)
    model, integrator, dt, elements = _settings(args, scene)
    output = check_new_output(args.output or f"{scene.name}_{model}_sobol.nc", "rss6 sensitivity",
                              args.parents)
    _warn_oversubscription(args.workers, None)
    spec = EnsembleSpec(scene.source_text, str(args.config), model, integrator, dt, elements, args.seed)
    start = time.perf_counter()
    with OutputLock(output):
        try:
            ds = sensitivity(spec, args.n, args.per_joint, args.confidence, args.workers,
                             announce=lambda line: print(f"rss6 sensitivity: {line}", file=sys.stderr),
                             window=args.window)
        except SensitivityError as exc:
            raise SceneError(str(exc)) from None
        except KeyboardInterrupt:
            return _interrupted(None)
        write_netcdf(ds, output)
    plots = Path(args.plots or output.with_name(output.stem + "_plots"))
    paths = [] if args.no_plots else plot_sensitivity(load_netcdf(output), plots)
    print(f"wrote {output} in {time.perf_counter() - start:.1f} s" + (f"; bar charts in {plots}/" if paths else ""))
    print(format_sensitivity(ds))
    if args.per_joint:
        print(format_joints(ds))
    return 0


def _budget(args) -> int:
    from .studies.budget import BudgetError, budget, format_budget
    from .files.outputs import check_output_folder
    from .ensemble.run import EnsembleSpec
    from .analysis.spec import SpecError, parse_spec
    try:
        specs = [parse_spec(t) for t in args.spec]
    except SpecError as exc:
        raise SceneError(str(exc).replace("--require", "--spec", 1)) from None
    scene = find_scene(args.config)
    model, integrator, dt, elements = _settings(args, scene)
    folder = check_output_folder(args.output or f"budget_{scene.name}_{model}", args.parents)
    _warn_oversubscription(args.workers, None)
    spec = EnsembleSpec(scene.source_text, str(args.config), model, integrator, dt, elements, args.seed)
    try:
        b = budget(spec, specs, args.n, folder, args.confidence, args.workers, args.tolerance)
    except BudgetError as exc:
        raise SceneError(str(exc)) from None
    except KeyboardInterrupt:
        return _interrupted(f"finished ensembles and chunks are kept in {folder}")
    print(format_budget(b, scene.name, model))
    return 0


def _sensitivity_parser(sub) -> None:
    from .studies.sensitivity import LEVELS, MIN_N
    from .vocabulary import WINDOWS
    se = sub.add_parser("sensitivity", help="Sobol' indices of the error statistics by joint family "
                                            "(and joint), with bootstrap intervals (SALib)")
    se.add_argument("config", nargs="?", default="paper",
                    help="scene TOML file or embedded scene name (default: paper)")
    se.add_argument("--model", choices=LEVELS, default="quasi-static",
                    help="model level (default quasi-static; contact costs about 0.4 s per evaluation "
                         "on the paper scene)")
    se.add_argument("-n", type=_positive_int, default=1024,
                    help=f"base sample N, a power of 2 of at least {MIN_N}; the level is evaluated "
                         "N (G + 2) times for G groups: 6 N for the 4 families, 20 N more for the "
                         "18 joints (default 1024)")
    se.add_argument("-o", "--output", help="netCDF file of the indices (default: SCENE_MODEL_sobol.nc)")
    se.add_argument("--parents", action="store_true", help="create the output's missing folders")
    se.add_argument("--plots", help="folder of the bar charts (default: OUTPUT's name + _plots)")
    se.add_argument("--no-plots", action="store_true", help="write no bar charts")
    se.add_argument("--per-joint", action="store_true",
                    help="also the indices of each of the 18 joints (a second design)")
    se.add_argument("--seed", type=_nonnegative_int, default=0, help="random seed (default 0)")
    se.add_argument("--confidence", type=_fraction, default=CONFIDENCE,
                    help="confidence of the bootstrap intervals (default 0.95)")
    se.add_argument("--window", choices=WINDOWS, default="whole",
                    help="analysis window of the statistics: whole (t >= the scene's settle_time_s), "
                         "startup (before its steady_after_s) or steady (from it) (default whole)")
    se.add_argument("--workers", type=_positive_int, default=2,
                    help="local dask workers (1: in this process) (default 2)")
    se.set_defaults(func=_sensitivity, dt=None, integrator=None, elements=None)


def _budget_parser(sub) -> None:
    bu = sub.add_parser("budget", help="the largest common clearance scale factor for which "
                                       "requirement specs pass")
    bu.add_argument("config", nargs="?", default="paper",
                    help="scene TOML file or embedded scene name (default: paper)")
    bu.add_argument("--spec", action="append", required=True, metavar="SPEC",
                    help="an upper limit QUANTITY:DIRECTIONS <= VALUE UNIT@STATISTIC, as for "
                         "rss6 run --require, e.g. 'displacement:x,y,z<=0.1mm@q95' (repeatable; required, no "
                         "default)")
    bu.add_argument("--model", choices=MODELS, default="quasi-static",
                    help="model level (default quasi-static: exact scaling from one ensemble; other "
                         "levels: a bisection of ensemble runs)")
    bu.add_argument("-n", type=_positive_int, default=200,
                    help="realisations per ensemble (default 200; q95 has an interval from n = 59)")
    bu.add_argument("-o", "--output", help="folder of the ensembles and the budget scene "
                                           "(default: budget_SCENE_MODEL); rerunning resumes")
    bu.add_argument("--parents", action="store_true", help="create the output's missing folders")
    bu.add_argument("--seed", type=_nonnegative_int, default=0, help="random seed (default 0)")
    bu.add_argument("--confidence", type=_fraction, default=CONFIDENCE,
                    help="confidence of the one-sided bounds the specs are judged on, above 0.5 "
                         "(default 0.95)")
    bu.add_argument("--tolerance", type=_positive_float, default=0.05,
                    help="sweep levels: relative width in the scale at which bisection stops "
                         "(default 0.05)")
    bu.add_argument("--workers", type=_positive_int, default=2,
                    help="local dask workers (default 2)")
    bu.set_defaults(func=_budget, dt=None, integrator=None, elements=None)


def _study_arguments(p, output: str, n: int, tolerance_help: str) -> None:
    p.add_argument("config", nargs="?", default="paper",
                   help="scene TOML file or embedded scene name (default: paper)")
    p.add_argument("-o", "--output", default=output, help=f"output folder (default: {output})")
    p.add_argument("--parents", action="store_true", help="create the output's missing folders")
    p.add_argument("-n", type=_positive_int, default=n, help=f"realisations per setting (default {n})")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--tolerance", type=_positive_float, default=0.05,
                   help=f"{tolerance_help} (default 0.05)")


def _stats_parser(sub) -> None:
    st = sub.add_parser("stats", help="error statistics of an ensemble file (or a simulate -o file)")
    st.add_argument("file", help="netCDF file of rss6 run, or of rss6 simulate -o (one realisation: "
                                 "estimates only)")
    st.add_argument("--quantity", help="displacement, velocity or acceleration (default: all)")
    st.add_argument("--direction", help="x, y, z, rx, ry or rz (default: all)")
    st.add_argument("--json", action="store_true",
                    help="print one strict JSON object (SI units; null where no number)")
    st.add_argument("-o", "--output", help="also write the statistics Dataset to this new netCDF file")
    st.add_argument("--parents", action="store_true", help="create the output's missing folders")
    st.add_argument("--confidence", type=_fraction, default=CONFIDENCE,
                    help="confidence of the two-sided intervals, in (0, 1), and of each one-sided bound "
                         "a --require is decided on, then above 0.5 (default 0.95)")
    st.add_argument("--window", help="analysis window: whole, startup (t < the scene's "
                                     "steady_after_s) or steady; also the window of a --require "
                                     "without '/WINDOW' (default: every window shown, --require "
                                     "judged on the whole run)")
    _require_arguments(st)
    st.set_defaults(func=_stats)


LEVELS_HELP = ("Levels, cheapest first: rigid (no error, a check), quasi-static (clearances, no "
               "dynamics), elastic (flexible links, no clearances), paper (elastic + the paper's "
               "clearance closure), contact (clearance contact dynamics, by far the dearest)")
INTEGRATOR_HELP = ("time integrator: newmark, hht, generalized-alpha or central-difference (explicit, "
                   "diverges above the critical step `rss6 check` prints) (default: the scene's; "
                   "the contact level has its own)")
DT_HELP = ("time step, s; must divide the trajectory's duration (default: the scene's "
           "time_step_s, contact_time_step_s at the contact level)")
ELEMENTS_HELP = "beam elements per crank and per rod (default: the scene's elements_per_link)"
START_HELP = ("contact level's initial state: 'drawn' (links offset by the drawn eccentricities, "
              "joints open) or 'equilibrium' (the static contact equilibrium at t = 0, every loaded "
              "joint resting on its wall); default: the scene's [simulation] contact_start")
LOCAL_WORKERS = 2   # --workers' default where --scheduler is the alternative
SCHEDULER_HELP = ("address of a running dask.distributed scheduler, e.g. tcp://10.0.0.5:8786 "
                  "(default: none, a local cluster of --workers processes)")


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (the option and the problem; ``-h`` gives the usage)."""

    def error(self, message: str):
        print(f"{self.prog}: error: {message} (see {self.prog} -h)", file=sys.stderr)
        sys.exit(2)


def _simulate_parser(sub) -> None:
    sim = sub.add_parser("simulate", help="run one deterministic simulation")
    sim.add_argument("config", nargs="?", default="paper",
                     help="scene TOML file or embedded scene name (default: paper)")
    sim.add_argument("--model", choices=MODELS, help=f"model level (default: the scene's). {LEVELS_HELP}")
    sim.add_argument("--integrator", choices=INTEGRATORS, help=INTEGRATOR_HELP)
    sim.add_argument("--dt", type=_positive_float, help=DT_HELP)
    sim.add_argument("--elements", type=_positive_int, help=ELEMENTS_HELP)
    sim.add_argument("--start", choices=CONTACT_STARTS, help=START_HELP)
    sim.add_argument("--seed", type=_nonnegative_int, default=0,
                     help="random seed of the run, 0 or more (default 0)")
    sim.add_argument("--realization", type=_nonnegative_int, default=0,
                     help="which clearance realisation of the seeded run (default 0)")
    sim.add_argument("-o", "--output", help="write the error histories to this netCDF file "
                     "(default: none); its folder must exist unless --parents is given")
    sim.add_argument("--parents", action="store_true", help="create the output's missing folders")
    sim.add_argument("--json", action="store_true", help="print one JSON object (SI units)")
    sim.set_defaults(func=_simulate)


def _run_parser(sub) -> None:
    from .vocabulary import STORES
    run = sub.add_parser("run", help="run a Monte Carlo ensemble of clearance realisations")
    run.add_argument("config", nargs="?", default="paper",
                     help="scene TOML file or embedded scene name (default: paper)")
    run.add_argument("-n", type=_positive_int, default=32, help="realisations (default 32)")
    run.add_argument("-o", "--output", help="ensemble netCDF file (default: SCENE_MODEL.nc); its "
                     "folder must exist unless --parents is given. Rerunning the same command "
                     "resumes from the parts stored in OUTPUT.parts")
    run.add_argument("--parents", action="store_true", help="create the output's missing folders")
    run.add_argument("--seed", type=_nonnegative_int, default=0,
                     help="random seed, 0 or more (default 0)")
    run.add_argument("--model", choices=MODELS,
                     help="model level (default: the scene's if it has clearances; a scene whose "
                          f"level has none asks for --model). {LEVELS_HELP}")
    run.add_argument("--integrator", choices=INTEGRATORS, help=INTEGRATOR_HELP)
    run.add_argument("--dt", type=_positive_float, help=DT_HELP)
    run.add_argument("--elements", type=_positive_int, help=ELEMENTS_HELP)
    run.add_argument("--start", choices=CONTACT_STARTS, help=START_HELP)
    run.add_argument("--workers", type=_positive_int,
                     help="local dask workers, one thread each (default 2)")
    _scheduler_options(run)
    from .ensemble.run import MAX_AUTO_CHUNK, MAX_AUTO_CHUNK_BY_MODEL
    larger = ", ".join(f"{n} for {m}" for m, n in MAX_AUTO_CHUNK_BY_MODEL.items())
    run.add_argument("--chunk", type=_positive_int,
                     help="realisations per task (default: n cut into a multiple of the workers "
                          f"nearly equal chunks of at most {MAX_AUTO_CHUNK}, {larger}; each task integrates "
                          "its realisations as one batch)")
    run.add_argument("--store", choices=STORES, default="summary",
                     help="summary: per-realisation maxima and means; full: also time histories "
                          "(default: summary)")
    _require_arguments(run)
    run.add_argument("--until", action="append", metavar="TARGET",
                     help="add realisations until a confidence interval is this narrow, e.g. "
                          "'displacement:x,y,z@q95<=5%%' (half-width relative to the estimate) or "
                          "'displacement:z@mean<=0.001mm' (absolute), 95 %% confidence; checked at "
                          "fixed n (x1.25 from the statistic's minimum n; qmc: doubling), up to -n "
                          "as the cap; exit 1 if the cap comes first (repeatable; default: none)")
    run.add_argument("--sampler", choices=("mc", "qmc"), default="mc",
                     help="mc: independent random draws; qmc: randomised quasi-Monte Carlo, "
                          "scrambled Sobol' points in --replicates independent scramblings, "
                          "-n a multiple of them; intervals from the replicates (default: mc)")
    run.add_argument("--replicates", type=_int_at_least(2), metavar="R",
                     help="with --sampler qmc: independent scramblings (default 8)")
    run.set_defaults(func=_run)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="rss6", description="Joint clearance and link elasticity errors of a 6-RSS robot.",
        epilog="shipped scenes (a CONFIG argument takes one of these names or a TOML file): "
               + ", ".join(scene_names()))
    parser.add_argument("--version", action="version", version=f"rss6 {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    check = sub.add_parser("check", help="validate a scene and print its summary")
    check.add_argument("config", nargs="?", default="paper",
                       help="scene TOML file or embedded scene name (default: paper)")
    check.add_argument("--json", action="store_true", help="print one JSON object")
    check.set_defaults(func=_check)
    _simulate_parser(sub)
    warm = sub.add_parser("warm", help="compile the contact level's kernels into numba's cache now (minutes "
                                       "once per machine and rss6 version; quick when already done)")
    warm.set_defaults(func=_warm)

    _run_parser(sub)

    rp = sub.add_parser("report", help="the paper's section 6 reproduced: OUT/results.md and figures")
    rp.add_argument("configs", nargs="+", help="scene TOML files or embedded scene names")
    rp.add_argument("-o", "--output", default="rss6-report",
                    help="output folder (default: rss6-report); files git tracks there are not "
                         "overwritten unless --overwrite-tracked is given")
    rp.add_argument("--overwrite-tracked", action="store_true",
                    help="allow overwriting results.md and figures that git tracks (e.g. -o docs)")
    rp.add_argument("--data", help="folder of the ensemble files (default: OUTPUT/results-data)")
    rp.add_argument("-n", type=_positive_int, default=1000,
                    help="realisations per level and scene (default 1000)")
    rp.add_argument("--family-n", type=_positive_int, default=100,
                    help="realisations per joint-family run (default 100)")
    rp.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    rp.add_argument("--workers", type=_positive_int,
                    help="local dask workers, one thread each (default 2)")
    _scheduler_options(rp)
    rp.set_defaults(func=_report)

    _stats_parser(sub)
    _multifidelity_parser(sub)
    _sensitivity_parser(sub)
    _budget_parser(sub)

    pl = sub.add_parser("plot", help="PNG figures of an ensemble file, or the error histories of "
                                     "a simulate -o file")
    pl.add_argument("file", help="netCDF file of rss6 run, or of rss6 simulate -o")
    pl.add_argument("-o", "--output", default="plots", help="output folder (default: plots)")
    pl.add_argument("--parents", action="store_true", help="create the output's missing folders")
    pl.set_defaults(func=_plot)

    tr = sub.add_parser("tradeoff", help="cost and error of every model level, integrator, step and mesh")
    _study_arguments(tr, "tradeoff", 8, "relative error allowed on every statistic")
    tr.set_defaults(func=_tradeoff)

    sb = sub.add_parser("stability", help="time-step sweeps: stable, inaccurate or failed")
    _study_arguments(sb, "stability", 2, "change vs the finest step that counts as inaccurate")
    sb.add_argument("--horizon", type=_positive_float, default=0.2,
                    help="simulated time of the contact sweeps, s (default 0.2)")
    sb.set_defaults(func=_stability)
    return parser


def _scheduler_options(parser) -> None:
    """--scheduler and --worker-timeout, the same for every command that runs ensembles."""
    parser.add_argument("--scheduler", type=_scheduler_address, help=SCHEDULER_HELP)
    parser.add_argument("--worker-timeout", type=_positive_float, metavar="S",
                        help="with --scheduler: stop (exit 2, finished chunks kept) once the "
                             "scheduler has had no workers for S seconds (default 60)")


def _cluster_options(args) -> None:
    """--worker-timeout only with --scheduler (rss6's own local workers are never missing), --workers
    only without it (the scheduler's workers are its own); their defaults filled in."""
    from .ensemble.cluster import WORKER_TIMEOUT_S
    if getattr(args, "scheduler", None) and getattr(args, "workers", None) is not None:
        raise SceneError(f"--workers {args.workers}: sets the local cluster; with --scheduler the "
                         "scheduler's own workers run the tasks")
    if getattr(args, "workers", 0) is None:
        args.workers = LOCAL_WORKERS
    if not hasattr(args, "worker_timeout"):
        return
    if args.worker_timeout is not None and not args.scheduler:
        raise SceneError(f"--worker-timeout {args.worker_timeout:g}: applies with --scheduler only "
                         "(a local cluster's workers are rss6's own)")
    if args.worker_timeout is None:
        args.worker_timeout = WORKER_TIMEOUT_S


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from .files.store import EnsembleFileError
    try:
        _cluster_options(args)
        return args.func(args)
    except (SceneError, EnsembleFileError) as exc:
        print(f"rss6: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader went away (rss6 stats F | head): stop quietly
        import os
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # Python's final flush must not fail again
        return 141


if __name__ == "__main__":
    sys.exit(main())
