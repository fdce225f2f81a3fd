"""pipeline/files/ in its documented order (pipeline/files/__init__.py): each module imports only the
modules of files/ before it and the parts below files/, at module level; so opening a file (read,
then checked) sits above the checks, and the checks import nothing that opens a file."""
import ast
from pathlib import Path

import pipeline.files

FILES = Path(pipeline.files.__file__).parent
ORDER = ("schema", "records", "checksums", "writing", "outputs", "reading", "check", "opening", "error_map")
BELOW = {"vocabulary", "scenes"}   # the parts of pipeline/ below files/


def _pipeline_imports(tree: ast.Module) -> list[tuple[ast.ImportFrom, bool]]:
    """Every relative import of ``tree`` and whether it is at module level."""
    top = {id(n) for n in tree.body}
    return [(n, id(n) in top) for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.level]


def _problems(name: str, tree: ast.Module) -> list[str]:
    out = []
    for node, at_top in _pipeline_imports(tree):
        target = (node.module or "").split(".")[0]
        if not at_top:
            out.append(f"{name} imports {'.' * node.level}{node.module} inside a function")
        if node.level == 1 and ORDER.index(target) >= ORDER.index(name):
            out.append(f"{name} imports .{target}, which is not before it")
        if node.level == 2 and target not in BELOW:
            out.append(f"{name} imports ..{target}, a part above files/")
    return out


def test_every_files_module_is_in_the_order():
    assert {p.stem for p in FILES.glob("*.py")} - {"__init__"} == set(ORDER)


def test_files_modules_import_only_what_is_before_them_at_module_level():
    problems = [p for path in sorted(FILES.glob("*.py")) if path.stem != "__init__"
                for p in _problems(path.stem, ast.parse(path.read_text(encoding="utf-8")))]
    assert problems == []


def test_the_order_check_finds_an_upward_and_a_deferred_import():
    tree = ast.parse("from .opening import open_results\n"
                     "def f():\n    from ..analysis.stats import ensemble_stats\n")
    assert _problems("check", tree) == ["check imports .opening, which is not before it",
                                        "check imports ..analysis.stats inside a function",
                                        "check imports ..analysis, a part above files/"]
