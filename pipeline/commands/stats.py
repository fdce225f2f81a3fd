"""rss6 stats: error statistics of an ensemble (or simulate) file, their intervals and --require verdicts."""
from __future__ import annotations

import json
from dataclasses import replace

from ..vocabulary import OptionError, UserError
from .options import add_confidence, add_json, add_parents, add_require
from .requirements import judge, known_windows, requirements, robot_measures, verdict_attrs


def add_parser(sub) -> None:
    p = sub.add_parser("stats", help="error statistics of an ensemble file (or a simulate -o file)")
    p.add_argument("file", help="netCDF file of rss6 run, or of rss6 simulate -o (one realisation: "
                                "estimates only)")
    p.add_argument("--quantity", help="displacement, velocity or acceleration (default: all)")
    p.add_argument("--direction", help="x, y, z, rx, ry or rz (default: all)")
    add_json(p)
    p.add_argument("-o", "--output", help="also write the statistics Dataset to this new netCDF file (default: "
                                          "none, print only)")
    add_parents(p)
    add_confidence(p, "confidence of the two-sided intervals, in (0, 1), and of each one-sided bound "
                      "a --require is decided on, then above 0.5")
    p.add_argument("--window", metavar="{whole,startup,steady}",
                   help="analysis window: whole, startup (t < the scene's steady_after_s) or steady, each "
                        "from its settle_time_s on; also the window of a --require without '/WINDOW' "
                        "(default: every window shown, --require judged on the whole run)")
    add_require(p)
    p.add_argument("--event", action="append", metavar="EVENT",
                   help="also print the probability that a realisation's maximum |error| exceeds a limit, "
                        "QUANTITY:DIRECTIONS>VALUE UNIT[/WINDOW], e.g. 'displacement:z>0.1mm', or "
                        "'displacement:x,y,z>0.05mm' for any of them (repeatable): k/n and its exact "
                        "Clopper-Pearson interval at --confidence (not for --sampler qmc files) "
                        "(default: none)")
    p.set_defaults(main=main)


def main(args) -> int:
    from ..analysis.gate import check_confidence, exit_code, start_up_note, verdicts_json, verdicts_with_note
    from ..analysis.exceedance import exceedance_json, format_exceedance
    from ..analysis.stats import ensemble_stats, format_stats, table_notes, to_json
    from ..analysis.resolution import resolution_attrs
    from ..analysis.summary import every_realisation_failed
    from ..files.opening import open_results
    from ..files.outputs import check_new_output
    from ..files.writing import write_netcdf
    specs = requirements(args)
    known_windows(specs)
    events = _events(args)
    if specs:
        try:
            check_confidence(args.confidence)
        except ValueError as exc:
            raise OptionError(f"--{exc} (with --require)") from None
    if args.output:
        check_new_output(args.output, "rss6 stats", args.parents)
    if args.window is not None:
        specs = [replace(s, window=s.window or args.window) for s in specs]
    ds = open_results(args.file)
    none_finished = every_realisation_failed(ds, args.file)
    if none_finished:
        raise UserError(none_finished)
    robot_measures(specs, str(ds.attrs.get("model", "")))
    robot_measures(events, str(ds.attrs.get("model", "")), "--event")
    note = _loaded_joints_note(ds, args.file, specs + events)
    full = ensemble_stats(ds, args.confidence, window=None)
    if args.window is not None:
        full = _window_of(full, args.window)
    verdicts = judge(ds, specs, args.confidence)
    probabilities = _probabilities(ds, events, args.confidence)
    sds = _selection(full, args)
    sds = sds.assign_attrs(resolution_attrs(sds, ds))   # intervals of a spread the level does not resolve
    notes = table_notes(sds)   # what the text table says under its numbers, kept by the file and the JSON too
    if args.output:
        write_netcdf(sds.assign_attrs(verdict_attrs(verdicts) if specs else {}, table_notes="\n".join(notes)),
                     args.output)
    if args.json:
        out = to_json(sds) | {"table_notes": notes} | ({"requirements": verdicts_json(verdicts)} if specs else {})
        out |= ({"requirements_note": startup.removeprefix("note: ")}
                if specs and (startup := start_up_note(verdicts, ds)) else {})
        out |= {"exceedance": exceedance_json(probabilities)} if events else {}
        out |= note.json()
        print(json.dumps(out, indent=2, allow_nan=False))
    else:
        print(format_stats(sds))
        if events:
            print(format_exceedance(probabilities))
        if specs:
            print(verdicts_with_note(verdicts, ds))
    note()
    return exit_code(verdicts, args.undecided) if specs else 0


def _loaded_joints_note(ds, path, limits):
    """The function that prints what the file's level leaves out and which of ``limits`` (specs and events) the
    loaded robot is past (:func:`.messages.loaded_joints_meanwhile`, computed meanwhile); nothing for a file
    without its scene and level."""
    from .messages import LoadedJointsNote, loaded_joints_meanwhile
    if "scene_toml" not in ds.attrs or "model" not in ds.attrs:
        return LoadedJointsNote("stats")
    from rss6core import parse_scene
    return loaded_joints_meanwhile("stats", parse_scene(ds.attrs["scene_toml"], str(path)), str(ds.attrs["model"]),
                                   limits)


def _events(args) -> list:
    """The parsed --event options (EventError, one line, on a malformed one)."""
    from ..analysis.exceedance import parse_event
    return [parse_event(text) for text in args.event or []]


def _probabilities(ds, events: list, confidence: float) -> list:
    """Each event's exceedance probability; a QMC file or an absent window is an OptionError."""
    from ..analysis.exceedance import exceedance
    try:
        return [exceedance(ds, e, confidence) for e in events]
    except ValueError as exc:
        raise OptionError(f"--event {exc}") from None


def _window_of(sds, window: str):
    """The statistics of analysis window ``window`` only (dimension kept); an unknown window, or a
    file without windows, is an OptionError naming it."""
    from ..analysis.stats import check_window_samples, windows_of
    if window not in windows_of(sds):
        raise OptionError(f"--window: unknown window {window!r}; the file has "
                          f"{', '.join(windows_of(sds)) or 'no analysis windows'}")
    try:
        check_window_samples(sds, window)
    except ValueError as exc:
        raise OptionError(f"--window {window}: {exc}") from None
    return sds.sel(window=[window])


def _selection(sds, args):
    """The statistics of the quantity and direction asked for; OptionError names an unknown one."""
    for dim in ("quantity", "direction"):
        given = getattr(args, dim)
        allowed = [str(v) for v in sds[dim].values]
        if given is not None and given not in allowed:
            raise OptionError(f"--{dim}: unknown {dim} {given!r}; choose one of {', '.join(allowed)}")
        if given is not None:
            sds = sds.sel({dim: [given]})
    return sds
