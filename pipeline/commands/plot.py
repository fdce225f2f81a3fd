"""rss6 plot: PNG figures of an ensemble file, or the error histories of a simulate -o file."""
from __future__ import annotations

import sys

from ..vocabulary import FINISHED
from .options import add_parents


def add_parser(sub) -> None:
    p = sub.add_parser("plot", help="PNG figures of an ensemble file, or the error histories of "
                                    "a simulate -o file")
    p.add_argument("file", help="netCDF file of rss6 run, or of rss6 simulate -o")
    p.add_argument("-o", "--output", default="plots", help="output folder (default: plots)")
    add_parents(p)
    p.set_defaults(main=main)


def main(args) -> int:
    from ..analysis.ensemble_plots import plot_ensemble
    from ..analysis.run_plots import plot_run
    from ..files.opening import open_results
    from ..files.outputs import check_output_folder
    from ..files.schema import EnsembleFileError
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
