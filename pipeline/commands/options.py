"""The options several commands share, each declared once here and opted into by a command's
parser (no shared base parser to remove options from), with their value types and help texts."""
from __future__ import annotations

import argparse
from pathlib import Path

from rss6core import CONTACT_STARTS, INTEGRATORS, MAX_ELEMENTS_PER_LINK, MODELS, MODEL_LEVELS

from ..ensemble.settings import LOCAL_WORKERS, MAX_LOCAL_WORKERS
from ..vocabulary import CONFIDENCE, WINDOWS


def positive_float(text: str) -> float:
    """An argparse type: a finite number above 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite positive number, got {text}")
    return value


def scheduler_address(text: str) -> str:
    """A dask.distributed scheduler address (tcp://host:port or host:port), checked before any work."""
    from distributed.comm.addressing import parse_address, parse_host_port
    try:
        parse_host_port(parse_address(text)[1])
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r} is no scheduler address ({exc}); e.g. "
                                         "tcp://10.0.0.5:8786") from None
    return text


def fraction_above(low: float = 0.0):
    """An argparse type: a number strictly between ``low`` and 1."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not low < value < 1:
            raise argparse.ArgumentTypeError(f"must lie strictly between {low:g} and 1, got {text}")
        return value
    return parse


fraction = fraction_above()   # an argparse type: a number strictly between 0 and 1


def int_at_least(minimum: int, maximum: int | None = None, why: str = ""):
    """An argparse type: an integer of at least ``minimum`` (and at most ``maximum``, ``why`` saying why)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be {minimum} or more, got {text}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {maximum}{why}, got {text}")
        return value
    return parse


positive_int = int_at_least(1)
nonnegative_int = int_at_least(0)
MAX_REALISATIONS = 10_000_000   # an ensemble's at most: ten times the largest measured (docs/performance.md 26)
realisations = int_at_least(1, MAX_REALISATIONS, " per ensemble (a rare event: rss6 reliability's subset method)")
evaluations = int_at_least(1, MAX_REALISATIONS, " model evaluations (rss6 reliability's subset method reaches "
                                                "probabilities far below 1 / N)")
MAX_SEED = 2 ** 63 - 1   # a file's seed attribute is a netCDF int64


def seed_int(text: str) -> int:
    """An argparse type: a seed or a realisation's index, 0 to MAX_SEED (refused before any work, not when
    the file is written)."""
    value = nonnegative_int(text)
    if value > MAX_SEED:
        raise argparse.ArgumentTypeError(f"must be at most 2^63 - 1 = {MAX_SEED} (the files store it as a 64-bit "
                                         f"integer), got {text}")
    return value

LEVELS_HELP = "Levels, cheapest first: " + ", ".join(f"{m.name} ({m.description})" for m in MODEL_LEVELS.values())
INTEGRATOR_HELP = ("time integrator: newmark, hht, generalized-alpha or central-difference (explicit, "
                   "diverges above the critical step `rss6 check` prints) (default: the scene's; "
                   "the contact level has its own)")
DT_HELP = ("time step, s; must divide the trajectory's duration (default: the scene's "
           "time_step_s, contact_time_step_s at the contact level)")
ELEMENTS_HELP = "beam elements per crank and per rod (default: the scene's elements_per_link)"
START_HELP = ("contact level's initial state: 'drawn' (links offset by the drawn eccentricities, "
              "joints open) or 'equilibrium' (the static contact equilibrium at t = 0, every loaded "
              "joint resting on its wall); default: the scene's [simulation] contact_start")
SCHEDULER_HELP = ("address of a running dask.distributed scheduler, e.g. tcp://10.0.0.5:8786 "
                  "(default: none, a local cluster of --workers processes)")
WINDOW_HELP = ("analysis window of the {what}: whole (t >= the scene's settle_time_s), startup (before "
               "its steady_after_s) or steady (from it) (default whole)")


def add_scene(p, names_output: bool = False) -> None:
    """The CONFIG argument; ``names_output``: the command names its default output after the scene."""
    named = "; its name without .toml is the SCENE of a default output name" if names_output else ""
    p.add_argument("config", nargs="?", default="paper",
                   help=f"scene TOML file or embedded scene name (default: paper){named}")


def output_stem(config: str) -> str:
    """The SCENE of a default output name: the scene file's name without .toml, or the shipped scene's
    name (a copy of paper.toml saved as my.toml writes my_..., not paper_..., whatever its name key)."""
    return Path(str(config)).stem


def add_seed(p, what: str = "random seed") -> None:
    p.add_argument("--seed", type=seed_int, default=0, help=f"{what}, 0 to 2^63 - 1 (default 0)")


def add_parents(p) -> None:
    p.add_argument("--parents", action="store_true", help="create the output's missing folders")


def add_json(p, what: str = "print one strict JSON object (SI units; null where no number)") -> None:
    p.add_argument("--json", action="store_true", help=what)


def add_confidence(p, what: str, above: float = 0.0) -> None:
    """--confidence, a number in (above, 1): one-sided bounds need above = 0.5 (rss6 budget, allocate)."""
    p.add_argument("--confidence", type=fraction_above(above), default=CONFIDENCE,
                   help=f"{what} (default {CONFIDENCE})")


def add_window_choice(p, what: str) -> None:
    p.add_argument("--window", choices=WINDOWS, default="whole", help=WINDOW_HELP.format(what=what))


def add_model(p, help_text: str, choices=MODELS, default=None) -> None:
    p.add_argument("--model", choices=choices, default=default, help=help_text)


def add_level_settings(p) -> None:
    """--integrator, --dt, --elements and --start: a level's numerics, the scene's unless given."""
    p.add_argument("--integrator", choices=INTEGRATORS, help=INTEGRATOR_HELP)
    p.add_argument("--dt", type=positive_float, help=DT_HELP)
    p.add_argument("--elements", type=int_at_least(1, MAX_ELEMENTS_PER_LINK, " (a scene's elements_per_link bound)"),
                   help=ELEMENTS_HELP)
    p.add_argument("--start", choices=CONTACT_STARTS, help=START_HELP)


def add_workers(p, what: str = "local dask workers, one thread each") -> None:
    """--workers; left None here, so that resolve_cluster can tell it from --scheduler's workers."""
    p.add_argument("--workers", type=int_at_least(1, MAX_LOCAL_WORKERS, " (one machine; more: --scheduler)"),
                   help=f"{what} (default {LOCAL_WORKERS})")


def add_scheduler(p, worker_timeout: bool = True) -> None:
    """--scheduler (and --worker-timeout), the same for every command that runs ensembles on it."""
    p.add_argument("--scheduler", type=scheduler_address, help=SCHEDULER_HELP)
    if worker_timeout:
        p.add_argument("--worker-timeout", type=positive_float, metavar="S",
                       help="with --scheduler: stop (exit 2, finished chunks kept) once the "
                            "scheduler has had no workers for S seconds (default 60)")


def add_require(p) -> None:
    p.add_argument("--require", action="append", metavar="SPEC",
                   help="a requirement QUANTITY:DIRECTIONS OP VALUE UNIT@STATISTIC[:mean][/WINDOW], e.g. "
                        "'displacement:x,y<=0.05mm@q95' or '...@q95/steady' (OP <= or < for an upper limit, "
                        ">= or > for a lower one; STATISTIC mean, std, q05, q50, "
                        "q95, q99 of the realisations' maximum |error| over the window, or with ':mean' of "
                        "their mean |error|; or pf<=P, the probability that a realisation's maximum exceeds "
                        "the limit, e.g. '...<=0.1mm@pf<=1e-3'; window whole, startup or steady; default "
                        "whole) (repeatable): fails when the statistic's one-sided "
                        "95 %% bound (rss6 stats: --confidence) on the limit's side violates the limit, "
                        "passes when the other one-sided bound meets it, else undecided; exit 0 if all "
                        "pass, 1 if any fails, 3 if none fails but some are undecided (default: none)")
    p.add_argument("--undecided", choices=("fail", "pass"),
                   help="count undecided requirements as failed (exit 1) or passed (exit 0) "
                        "(default: neither, exit 3)")


def add_study_arguments(p, output: str, n: int, tolerance_help: str) -> None:
    """The scene, output folder, size, seed and tolerance of rss6 tradeoff and rss6 stability."""
    add_scene(p)
    p.add_argument("-o", "--output", default=output, help=f"output folder (default: {output})")
    add_parents(p)
    p.add_argument("-n", type=realisations, default=n, help=f"realisations per setting (default {n})")
    add_seed(p)
    p.add_argument("--tolerance", type=positive_float, default=0.05, help=f"{tolerance_help} (default 0.05)")


def figure_request(path) -> dict:
    """What a figure folder answers (:func:`claimed_output_folder`): the file it was drawn from, by its
    absolute path (a grown ensemble is replotted into the same folder; another file needs its own)."""
    return {"file": str(Path(path).resolve())}


def study_request(scene, args, **extra) -> dict:
    """What a tradeoff's or stability's folder answers (:func:`claimed_output_folder`): the scene and
    :func:`add_study_arguments`' settings, with ``extra`` options (keyed by their names)."""
    from ..files.outputs import text_identity
    return {"scene": text_identity(scene.source_text), "-n": args.n, "--seed": args.seed,
            "--tolerance": args.tolerance} | extra
