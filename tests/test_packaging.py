"""What a user installs: one version, the shipped scenes, and (in CI) the wheel, not the checkout."""
import importlib.metadata
import os
from pathlib import Path

import pytest

import pipeline
import rss6core
from pipeline.scenes import scene_names

REPO = Path(__file__).resolve().parents[1]


def test_the_distribution_version_is_the_package_version():
    assert importlib.metadata.version("rss6") == rss6core.__version__


def test_every_configs_file_ships_as_a_scene():
    shipped = {p.stem for p in (REPO / "configs").glob("*.toml")}
    assert shipped and set(scene_names()) == shipped


@pytest.mark.skipif(not os.environ.get("RSS6_TEST_INSTALLED"),
                    reason="CI only (.ci/run sets RSS6_TEST_INSTALLED): tests the installed wheel")
def test_ci_imports_the_installed_wheel_not_the_checkout():
    for module in (pipeline, rss6core):
        where = Path(module.__file__).resolve()
        assert "site-packages" in where.parts and not where.is_relative_to(REPO), where
