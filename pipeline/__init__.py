"""pipeline: ensembles, storage, statistics, plots and the rss6 command line, in parts that depend
one way: vocabulary, scenes/, files/, ensemble/, analysis/, studies/, commands/ and the dispatcher
cli.py (docs/developer.md).

The public names import from here (``from pipeline import open_ensemble, ensemble_stats,
run_ensemble, labelled, find_scene``), each on first use: importing them at once would load dask
and xarray for every ``rss6`` command, ``rss6 --help`` included.
"""
from __future__ import annotations

import importlib

# public name -> the module that defines it
_PUBLIC = {"open_ensemble": "files.opening", "labelled": "files.schema", "load_netcdf": "files.reading",
           "ensemble_stats": "analysis.stats", "run_ensemble": "ensemble.run", "EnsembleSpec": "ensemble.run",
           "find_scene": "scenes.catalogue"}

__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    if name not in _PUBLIC:
        raise AttributeError(f"module 'pipeline' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_PUBLIC[name]}", __name__), name)
    globals()[name] = value   # the next look-up finds it directly
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_PUBLIC))
