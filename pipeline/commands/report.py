"""rss6 report: the paper's section 6 reproduced, OUT/results.md and its figures."""
from __future__ import annotations

import subprocess
from pathlib import Path

from ..ensemble.settings import resolve_cluster
from ..vocabulary import OptionError
from .messages import interrupted, scheduler_lost
from .options import add_scheduler, add_seed, add_workers, realisations


def add_parser(sub) -> None:
    p = sub.add_parser("report", help="the paper's section 6 reproduced: OUT/results.md and figures")
    p.add_argument("configs", nargs="+", help="scene TOML files or embedded scene names")
    p.add_argument("-o", "--output", default="rss6-report",
                   help="output folder (default: rss6-report); files git tracks there are not "
                        "overwritten unless --overwrite-tracked is given")
    p.add_argument("--overwrite-tracked", action="store_true",
                   help="allow overwriting results.md and figures that git tracks (e.g. -o docs)")
    p.add_argument("--data", help="folder of the ensemble files (default: OUTPUT/results-data)")
    p.add_argument("-n", type=realisations, default=1000, help="realisations per level and scene (default 1000)")
    p.add_argument("--family-n", type=realisations, default=100,
                   help="realisations per joint-family run (default 100)")
    add_seed(p)
    add_workers(p)
    add_scheduler(p)
    p.set_defaults(main=main)


def _tracked(paths: list) -> list[str]:
    """Those of ``paths`` (files or folders) that hold files git tracks; none outside a repository."""
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


def main(args) -> int:
    from ..ensemble.cluster import SchedulerUnavailable
    from ..studies.report import ReportPlan, write_report
    from ..files.outputs import check_output_folder
    from ..scenes.catalogue import find_scene
    for config in args.configs:   # every scene checked before any folder is made
        find_scene(config)
    cluster = resolve_cluster(args.workers, args.scheduler, args.worker_timeout)
    out = check_output_folder(args.output, create_parents=True)   # the report makes its folders
    if args.data:
        check_output_folder(args.data, create_parents=True, option="--data")
    tracked = [] if args.overwrite_tracked else _tracked([out / "results.md", out / "results"])
    if tracked:
        raise OptionError(f"{args.output}: would overwrite {tracked[0]}, which git tracks "
                          f"({len(tracked)} tracked files); choose another -o or pass --overwrite-tracked")
    plan = ReportPlan(args.n, args.family_n, cluster.workers, cluster.scheduler, args.seed, cluster.worker_timeout,
                      args.overwrite_tracked)
    kept = f"finished ensembles and chunks are kept in {args.data or out / 'results-data'}"
    try:
        path = write_report(args.configs, args.output, plan, args.data)
    except SchedulerUnavailable as exc:
        return scheduler_lost("report", exc, kept)
    except KeyboardInterrupt:
        return interrupted(kept)
    print(f"wrote {path}")
    return 0
