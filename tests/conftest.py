"""Shared fixtures: the shipped scenes, found in the installed package (not the checkout), loaded once."""
from importlib import resources
from pathlib import Path

import pytest

import pipeline
import rss6core
from pipeline.scenes.catalogue import PACKAGE
from rss6core import load_scene


BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def load_benchmark(name: str):
    """The module benchmarks/NAME.py of this checkout (benchmarks are scripts, not part of the package),
    for tests that check its arithmetic."""
    import importlib.util
    import sys
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def pytest_report_header(config):
    return [f"rss6core from {Path(rss6core.__file__).parent}",
            f"pipeline from {Path(pipeline.__file__).parent}"]


@pytest.fixture(scope="session")
def configs() -> Path:
    """The folder holding the shipped scene files (configs/ in a checkout)."""
    folder = Path(str(resources.files(PACKAGE)))
    assert (folder / "paper.toml").is_file(), f"no shipped scenes in {folder}"
    return folder


@pytest.fixture(scope="session")
def paper(configs):
    return load_scene(configs / "paper.toml")


@pytest.fixture(scope="session")
def smoke(configs):
    return load_scene(configs / "smoke.toml")


@pytest.fixture(scope="session")
def paper_text(configs):
    return (configs / "paper.toml").read_text()


@pytest.fixture(scope="session")
def cluster_client():
    """One local dask cluster of 2 workers shared by the tests that run ensembles without testing
    the cluster itself (each cluster costs seconds to start, and its workers their imports)."""
    from pipeline.ensemble.cluster import dask_client
    with dask_client(2) as client:
        yield client


def _first_cycle(graph: dict[str, set[str]]) -> list[str]:
    """One import cycle of ``graph`` as a list of modules, or [] if it has none."""
    state, path = {}, []

    def visit(m):
        state[m] = "open"
        path.append(m)
        for n in sorted(graph.get(m, ())):
            if state.get(n) == "open":
                return path[path.index(n):] + [n]
            if n not in state and (found := visit(n)):
                return found
        state[m] = "done"
        path.pop()
        return []

    for m in sorted(graph):
        if m not in state and (found := visit(m)):
            return found
    return []


@pytest.fixture(scope="session")
def find_cycle():
    """One import cycle of a {module: imported modules} graph as a list, or []: for the layout tests
    of the core (tests/test_boundaries.py) and of the pipeline (tests/test_pipeline_layout.py)."""
    return _first_cycle
