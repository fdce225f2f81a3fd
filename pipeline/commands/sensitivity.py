"""rss6 sensitivity: Sobol' indices of the error statistics by joint family (and joint), SALib."""
from __future__ import annotations

import contextlib
import sys
import time
from pathlib import Path

from rss6core import models_with

from ..ensemble.settings import resolve_cluster, resolve_level
from ..scenes.catalogue import find_scene
from ..vocabulary import OptionError
from .messages import interrupted, warn_oversubscription
from .options import (add_confidence, add_model, add_parents, add_scene, add_seed, add_window_choice, add_workers,
                      figure_request, int_at_least, output_stem)


def add_parser(sub) -> None:
    from ..studies.sensitivity import MAX_N, MIN_N
    p = sub.add_parser("sensitivity", help="Sobol' indices of the error statistics by joint family "
                                           "(and joint), with bootstrap intervals (SALib); keeps its "
                                           "finished evaluations in OUTPUT.parts, so a rerun of the same "
                                           "command resumes")
    add_scene(p, names_output=True)
    add_model(p, "model level (default quasi-static; contact costs about 0.4 s per evaluation on the paper "
                 "scene)", choices=models_with("function_of_one_draw"), default="quasi-static")
    p.add_argument("-n", type=int_at_least(1, MAX_N, " (26 N evaluations with --per-joint)"), default=1024,
                   help=f"base sample N, a power of 2 of at least {MIN_N}; the level is evaluated "
                        "N (G + 2) times for G groups: 6 N for the 4 families, 20 N more for the "
                        "18 joints (default 1024)")
    p.add_argument("-o", "--output", help="netCDF file of the indices (default: SCENE_MODEL_sobol.nc); "
                                          "finished evaluations are kept in OUTPUT.parts until it is "
                                          "written, and the same command resumes from them")
    add_parents(p)
    p.add_argument("--plots", help="folder of the bar charts (default: OUTPUT's name + _plots)")
    p.add_argument("--no-plots", action="store_true", help="write no bar charts")
    p.add_argument("--per-joint", action="store_true",
                   help="also the indices of each of the 18 joints (a second design)")
    add_seed(p)
    add_confidence(p, "confidence of the bootstrap intervals")
    add_window_choice(p, "statistics")
    add_workers(p, what="local dask workers (1: in this process)")
    p.set_defaults(main=main)


def main(args) -> int:
    from ..analysis.sensitivity_plots import plot_sensitivity
    from ..files.outputs import OutputLock, answered_request, check_output_folder, claimed_output_folder
    from ..files.reading import load_netcdf
    from ..studies.sensitivity_table import format_joints, format_sensitivity
    cluster = resolve_cluster(args.workers)
    level = resolve_level(find_scene(args.config), args.config, model=args.model)
    output = Path(args.output or f"{output_stem(args.config)}_{level.model}_sobol.nc")
    request = _request(args, level)
    answered = answered_request(output, "sensitivity", request, args.parents)
    plots = Path(args.plots or output.with_name(output.stem + "_plots"))
    if args.plots and args.no_plots:
        raise OptionError("--plots and --no-plots: give one")
    if not args.no_plots:
        check_output_folder(plots, args.parents, "--plots")   # before the work, which the charts follow
    warn_oversubscription(cluster.workers, None)
    start = time.perf_counter()
    charts = (contextlib.nullcontext() if args.no_plots else   # one file's charts per folder, claimed before the work
              claimed_output_folder(plots, "sensitivity", figure_request(output), ("sobol_*.png",), "--plots"))
    with charts, OutputLock(output):
        ds = _held(output) if answered else _compute(args, level, cluster, output, request)
        if ds is None:
            return 130
        try:
            paths = [] if args.no_plots else plot_sensitivity(load_netcdf(output), plots)
        except KeyboardInterrupt:
            return interrupted(f"the indices are in {output}", "rerun the same command to print them and draw "
                                                               "the charts")
    said = f"read back {output}" if answered else f"wrote {output} in {time.perf_counter() - start:.1f} s"
    print(said + (f"; bar charts in {plots}/" if paths else ""))
    print(format_sensitivity(ds))
    if args.per_joint:
        print(format_joints(ds))
    return 0


def _request(args, level) -> dict:
    """What a sensitivity file answers (pipeline.files.outputs.answered_request): the scene's sha256, the level's
    numerics and every option that changes the indices."""
    from ..files.outputs import text_identity
    return {"scene": text_identity(level.scene.source_text), "--model": level.model, "--integrator": level.integrator,
            "--dt": level.dt, "--elements": level.elements, "-n": args.n, "--per-joint": args.per_joint,
            "--seed": args.seed, "--confidence": args.confidence, "--window": args.window}


def _held(output):
    """The indices an earlier run of the same request wrote to ``output`` (files.outputs.reuse_answer)."""
    from ..ensemble.run import parts_dir
    from ..files.outputs import reuse_answer
    from ..files.reading import load_netcdf
    return reuse_answer(output, "sensitivity", load_netcdf, parts_dir(output))


def _compute(args, level, cluster, output, request):
    """The indices, resumed from and kept in OUTPUT.parts, written to ``output`` with ``request``; None after
    Ctrl-C (said on stderr)."""
    import json
    import shutil

    from ..ensemble.run import parts_dir
    from ..files.outputs import REQUEST_ATTR
    from ..files.writing import write_netcdf
    from ..studies.sensitivity import sensitivity
    parts = parts_dir(output)
    try:
        ds = sensitivity(level.ensemble_spec(args.seed), args.n, args.per_joint, args.confidence,
                         cluster.workers, window=args.window, parts=parts,
                         announce=lambda line: print(f"rss6 sensitivity: {line}", file=sys.stderr))
    except KeyboardInterrupt:
        interrupted(f"finished chunks are kept in {parts}" if parts.exists() else None)
        return None
    ds = ds.assign_attrs({REQUEST_ATTR: json.dumps(request, sort_keys=True)})
    write_netcdf(ds, output)
    if parts.exists():
        shutil.rmtree(parts)
    return ds
