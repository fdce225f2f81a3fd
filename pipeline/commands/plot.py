"""rss6 plot: PNG figures of an ensemble file, or the error histories of a simulate -o file."""
from __future__ import annotations

import sys

from ..vocabulary import FINISHED
from .options import add_parents, figure_request


def add_parser(sub) -> None:
    p = sub.add_parser("plot", help="PNG figures of an ensemble file, or the error histories of "
                                    "a simulate -o file")
    p.add_argument("file", help="netCDF file of rss6 run, or of rss6 simulate -o")
    p.add_argument("-o", "--output", default="plots",
                   help="output folder (default: plots); it holds one file's figures: replotting that file "
                        "rewrites them, another file's are refused")
    add_parents(p)
    p.set_defaults(main=main)


FIGURES = ("envelope_*.png", "hist_max_*.png", "convergence_*.png", "history_*.png")   # what rss6 plot writes


def main(args) -> int:
    from ..files.opening import open_results
    from ..files.outputs import check_output_folder, claimed_output_folder
    check_output_folder(args.output, args.parents)
    ds = open_results(args.file)
    with claimed_output_folder(args.output, "plot", figure_request(args.file), FIGURES):
        paths = _figures(ds, args.file, args.output)
    for p in paths:
        print(p)
    return 0


def _figures(ds, file, folder) -> list:
    """Write the figures of ``ds`` (an ensemble or a simulate -o file) into ``folder``."""
    from ..analysis.ensemble_plots import plot_ensemble
    from ..analysis.run_plots import plot_run
    from ..files.schema import EnsembleFileError
    if "realization" not in ds.dims:                      # rss6 simulate -o: one run's histories
        if str(ds.attrs.get("status", FINISHED)) != FINISHED:
            raise EnsembleFileError(f"{file}: nothing to plot, the run failed "
                                    f"({ds.attrs.get('status_message', 'no reason recorded')})")
        paths = plot_run(ds, folder)
    else:
        if not (ds["status"].values.astype(str) == FINISHED).any():
            message = str(ds["status_message"].values.astype(str)[0])
            raise EnsembleFileError(f"{file}: nothing to plot, all {ds.sizes['realization']} "
                                    f"realisations failed (first reason: {message})")
        paths = plot_ensemble(ds, folder)
        if "error" not in ds:
            print("no time histories in the file (run with --store full): envelope plots skipped",
                  file=sys.stderr)
    return paths
