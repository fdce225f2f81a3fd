"""rss6 simulate: one deterministic simulation, its error summary printed and optionally written."""
from __future__ import annotations

import json
import time

from rss6core import FINISHED, SceneError, model_level

from ..analysis.summary import CHECK_HINT, contact_peaks, error_summary, format_errors
from ..ensemble.settings import resolve_level
from ..scenes.catalogue import find_scene
from ..vocabulary import QUANTITIES, UserError
from .messages import note_compiling
from .options import LEVELS_HELP, add_json, add_level_settings, add_model, add_parents, add_scene, add_seed, seed_int


def add_parser(sub) -> None:
    p = sub.add_parser("simulate", help="run one deterministic simulation")
    add_scene(p)
    add_model(p, f"model level (default: the scene's). {LEVELS_HELP}")
    add_level_settings(p)
    add_seed(p, "random seed of the run")
    p.add_argument("--realization", type=seed_int, default=0,
                   help="which clearance realisation of the seeded run (default 0)")
    p.add_argument("-o", "--output", help="write the error histories to this netCDF file "
                   "(default: none); its folder must exist unless --parents is given")
    add_parents(p)
    add_json(p, "print one JSON object (SI units)")
    p.set_defaults(main=main)


def main(args) -> int:
    from rss6core import simulate

    from ..files.outputs import check_new_output
    from ..files.records import run_dataset
    from ..files.writing import write_netcdf
    level = resolve_level(find_scene(args.config), args.config, model=args.model, integrator=args.integrator,
                          dt=args.dt, elements=args.elements, start=args.start)
    if args.output:
        check_new_output(args.output, "rss6 simulate", args.parents)
    note_compiling(level.model)
    start = time.perf_counter()
    try:
        result = simulate(level.scene, level.model, level.integrator, level.dt, level.elements, args.seed,
                          args.realization)
    except ValueError as exc:  # a time step that does not divide the duration, ...
        raise SceneError(f"{args.config}: {exc}") from None
    wall = time.perf_counter() - start
    ds = run_dataset(level.scene, result, model=level.model, integrator=level.integrator, dt=level.dt,
                     elements=level.elements, seed=args.seed, realization=args.realization)
    if result.status != FINISHED:   # its maxima would be the divergence's, not the robot's
        if args.output:
            write_netcdf(ds, args.output)
        kept = f"; {args.output} keeps its status and message" if args.output else ""
        if args.json:   # a script reads the status from stdout; the one-line error still goes to stderr
            print(json.dumps(_run_fields(level, result, wall), indent=2))
        raise UserError(f"{args.config}: the {level.model} run failed: {result.message}{kept}; {CHECK_HINT}")
    summary = error_summary(ds)
    if result.contact_force_peak is not None:
        summary["max_contact_force_N"] = contact_peaks(result.contact_force_peak)
    from ..analysis.stats import level_notes
    _print(args, level, result, summary, wall, level_notes(ds.attrs, set(QUANTITIES), {"whole", "steady"}))
    if args.output:   # after the summary is printed: a full disk loses the file, not the run's answer
        write_netcdf(ds, args.output)
    return 0


def _print(args, level, result, summary: dict, wall: float, notes: list[str]) -> None:
    """The run's summary (``--json``: as JSON) and ``notes``, what of it does not measure the robot."""
    if args.json:
        print(json.dumps({**summary, **_run_fields(level, result, wall)} | ({"notes": notes} if notes else {}),
                         indent=2))
        return
    integrated = (f"{level.integrator}, dt = {level.dt:g} s, {level.elements} elements per link"
                  if model_level(level.model).elastic_links else f"dt = {level.dt:g} s, rigid links")
    print(f"scene {level.scene.name!r}, model {level.model}, {integrated}: {result.status} in {wall:.2f} s")
    print(format_errors(summary))
    if "max_contact_force_N" in summary:
        forces = summary["max_contact_force_N"]
        closed = model_level(level.model).redraws_every_step and not any(forces.values())
        print("max contact force (N): " + ", ".join(f"{k} {v:.4g}" for k, v in forces.items())
              + (" (the paper's method keeps every joint inside its clearance, so eq. 17 gives none)"
                 if closed else ""))
    for line in notes:
        print(f"note: {line}")


def _run_fields(level, result, wall: float) -> dict:
    """What ``--json`` says of the run itself, finished or not: its status, message and settings (SI)."""
    return {"wall_time_s": wall, "status": result.status, "message": result.message, "model": level.model,
            "integrator": level.integrator, "time_step_s": level.dt, "elements_per_link": level.elements}
