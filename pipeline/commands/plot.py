"""rss6 plot: PNG figures of an ensemble file, or the error histories of a simulate -o file."""
from __future__ import annotations

import sys

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
    from ..analysis.summary import every_realisation_failed
    from ..files.opening import open_results
    from ..files.outputs import check_output_folder, claimed_output_folder
    from ..files.schema import EnsembleFileError
    check_output_folder(args.output, args.parents)
    ds = open_results(args.file)
    none_finished = every_realisation_failed(ds, args.file, so="there is nothing to plot")
    if none_finished:
        raise EnsembleFileError(none_finished)
    with claimed_output_folder(args.output, "plot", figure_request(args.file), FIGURES):
        paths = _figures(ds, args.output)
    for p in paths:
        print(p)
    return 0


def _figures(ds, folder) -> list:
    """Write the figures of ``ds`` (an ensemble or a simulate -o file) into ``folder``."""
    from ..analysis.ensemble_plots import plot_ensemble
    from ..analysis.run_plots import plot_run
    if "realization" not in ds.dims:                      # rss6 simulate -o: one run's histories
        paths = plot_run(ds, folder)
    else:
        paths = plot_ensemble(ds, folder)
        if "error" not in ds:
            print("no time histories in the file (run with --store full): envelope plots skipped",
                  file=sys.stderr)
    return paths
