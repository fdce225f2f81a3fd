"""docs/developer.md names only paths that exist: the map stays true when code moves."""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAP = ROOT / "docs" / "developer.md"


def _paths(text: str) -> list[str]:
    """Backticked tokens that are paths: a folder ending in / or a file with an extension."""
    return [t for t in re.findall(r"`([^`\s]+)`", text) if re.fullmatch(r"[\w./-]+(/|\.\w+)", t) and "/" in t]


def test_every_path_in_the_developer_map_exists():
    paths = _paths(MAP.read_text(encoding="utf-8"))
    assert len(paths) >= 20
    assert [p for p in paths if not (ROOT / p).exists()] == []


def test_the_path_finder_finds_files_and_folders():
    assert _paths("`pipeline/files/` and `rss6core/scene.py`, not `main(args)` or `--seed`") == [
        "pipeline/files/", "rss6core/scene.py"]
