"""Scene names: the TOML files shipped with rss6 (the repository's ``configs/``, installed as
the data package ``pipeline.scene_files``) and how a command-line argument finds one."""
from __future__ import annotations

import sys
from functools import cache
from importlib import resources
from pathlib import Path

from rss6core import Scene, SceneError, load_scene, parse_scene

PACKAGE = "pipeline.scene_files"


def scene_names() -> list[str]:
    """Names of the shipped scenes (``paper``, ``smoke``, ...), sorted."""
    return sorted(p.name.removesuffix(".toml") for p in resources.files(PACKAGE).iterdir()
                  if p.name.endswith(".toml"))


def scene_text(name: str) -> str:
    """The TOML text of the shipped scene NAME; SceneError listing the names if there is none."""
    if name not in scene_names():
        raise SceneError(f"{name}: no such scene file or shipped scene "
                         f"(shipped scenes: {', '.join(scene_names())})")
    return (resources.files(PACKAGE) / f"{name}.toml").read_text(encoding="utf-8")


def find_scene(config: str | Path) -> Scene:
    """The scene of a TOML file path, else of the shipped scene of that name; SceneError naming a folder,
    or a missing file whose name is a shipped scene's (``configs/paper.toml`` outside the repository)."""
    path = Path(config)
    if path.is_dir() and str(config) not in scene_names():   # a folder named like a shipped scene is not one
        raise SceneError(f"{config}: is a folder; give a scene file (.toml) or a shipped scene "
                         f"({', '.join(scene_names())})")
    if not path.is_file() and path.suffix == ".toml" and path.stem in scene_names():
        raise SceneError(f"{config}: no such scene file; the shipped scene of that name is {path.stem!r} "
                         f"(rss6 check {path.stem} works from any folder)")
    if path.is_file() or str(config).endswith(".toml"):
        return load_scene(config)
    if path.with_name(path.name + ".toml").is_file():
        _note_shipped_over_local(str(config))
    return parse_scene(scene_text(str(config)), str(config))


@cache   # once per command, however often it looks the scene up
def _note_shipped_over_local(name: str) -> None:
    """Say that a bare NAME is the shipped scene although NAME.toml lies here (an edited copy, most likely)."""
    if name in scene_names():
        print(f"rss6: note: {name!r} is the shipped scene; {name}.toml in this folder is not read (give "
              f"{name}.toml to use it)", file=sys.stderr)
