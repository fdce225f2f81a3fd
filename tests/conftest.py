"""Shared fixtures: the reference scenes, loaded once."""
from pathlib import Path

import pytest

from rss6core import load_scene

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


@pytest.fixture(scope="session")
def paper():
    return load_scene(CONFIGS / "paper.toml")


@pytest.fixture(scope="session")
def smoke():
    return load_scene(CONFIGS / "smoke.toml")


@pytest.fixture(scope="session")
def paper_text():
    return (CONFIGS / "paper.toml").read_text()
