"""rss6core: the physics of a 6-RSS robot with elastic links and clearance joints.

Pure numpy/scipy: no dask, xarray or netCDF here (those live in ``pipeline``).
"""
from .results import ContactBatch, SimulationResult, time_grid
from .scene import Scene, SceneError, load_scene, parse_scene

__version__ = "0.1.0"
__all__ = ["Scene", "SceneError", "load_scene", "parse_scene", "SimulationResult", "ContactBatch",
           "time_grid", "__version__"]
