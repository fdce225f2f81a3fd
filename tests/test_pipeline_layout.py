"""The pipeline's shape, read from the installed sources: named parts with a one-way dependency
order, no import cycle, modules and functions of a readable size, a small dispatcher, one module
per command, and the shared words (statistics, the default confidence, "finished", the level
table) written in one place each."""
import ast
from pathlib import Path

import pipeline

PIPELINE = Path(pipeline.__file__).parent
# bottom to top: a module imports from its own part and the parts before it only
PARTS = ("vocabulary", "scenes", "files", "ensemble", "analysis", "studies", "commands", "cli")
DATA = "scene_files"   # the shipped scenes' data package (configs/ in the source tree): TOML, no code
MAX_MODULE_LINES, MAX_FUNCTION_LINES, MAX_DISPATCHER_LINES = 500, 60, 250


def _modules(folder: Path = PIPELINE) -> dict[str, ast.Module]:
    """{dotted name below pipeline: parsed source} of every module (``__init__`` as its package)."""
    out = {}
    for path in sorted(folder.rglob("*.py")):
        parts = path.relative_to(folder).with_suffix("").parts
        if parts[0] == DATA:
            continue
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts) or "__init__"
        out[name] = ast.parse(path.read_text(encoding="utf-8"), str(path))
    return out


def _pipeline_imports(name: str, tree: ast.Module, packages: set[str]) -> set[str]:
    """The pipeline modules ``name`` imports anywhere (inside functions too), as dotted names."""
    here = [] if name == "__init__" else name.split(".")
    package = here if name in packages else here[:-1]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name.removeprefix("pipeline.") for a in node.names if a.name.startswith("pipeline.")}
        elif isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith("pipeline.")):
            base = package[:len(package) - node.level + 1] if node.level else []
            module = (node.module or "").removeprefix("pipeline") if not node.level else (node.module or "")
            target = ".".join([*base, *module.strip(".").split(".")]).strip(".")
            found |= {f"{target}.{a.name}".strip(".") if f"{target}.{a.name}".strip(".") in _ALL else target
                      for a in node.names}
    return {m for m in found if m}


_ALL = set(_modules())
_PACKAGES = {n for n in _ALL if (PIPELINE / n.replace(".", "/") / "__init__.py").exists()}


def _part(module: str) -> str:
    return module.split(".")[0]


def _graph() -> dict[str, set[str]]:
    return {name: _pipeline_imports(name, tree, _PACKAGES) - {name} for name, tree in _modules().items()}


def _upward(graph: dict[str, set[str]]) -> list[str]:
    """Imports from a part after the importer's own in PARTS (the package's __init__ is exempt: it
    names the public functions lazily, by string)."""
    rank = {p: i for i, p in enumerate(PARTS)}
    return sorted(f"{a} -> {b}" for a, targets in graph.items() if a != "__init__" for b in targets
                  if _part(b) in rank and rank[_part(b)] > rank[_part(a)])


def test_every_module_belongs_to_a_part():
    assert sorted({_part(m) for m in _ALL} - set(PARTS) - {"__init__"}) == []
    assert len([p for p in PARTS if p in _PACKAGES]) >= 4


def test_parts_depend_one_way_and_without_a_cycle(find_cycle):
    graph = _graph()
    assert "vocabulary" in graph and graph["vocabulary"] == set()
    assert _upward(graph) == []
    assert find_cycle(graph) == []


def test_the_layout_checks_can_fail(find_cycle):
    """The finders find an upward import and a cycle in a made-up graph."""
    graph = {"files.store": {"analysis.stats"}, "analysis.stats": {"files.store"}}
    assert _upward(graph) == ["files.store -> analysis.stats"]
    assert find_cycle(graph) == ["analysis.stats", "files.store", "analysis.stats"]
    tree = ast.parse("from ..analysis.stats import x\nfrom . import check\ndef f():\n    from ..vocabulary import Y\n")
    assert _pipeline_imports("files.store", tree, set()) == {"analysis.stats", "files.check", "vocabulary"}


def _long_functions(tree: ast.Module) -> list[str]:
    return [f"{n.name} ({n.end_lineno - n.lineno + 1} lines)" for n in ast.walk(tree)
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))
            and n.end_lineno - n.lineno + 1 > MAX_FUNCTION_LINES]


def test_modules_and_functions_have_a_readable_size():
    long_modules = {p.relative_to(PIPELINE).as_posix(): n for p in PIPELINE.rglob("*.py")
                    if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES}
    assert long_modules == {}
    long_functions = {name: f for name, tree in _modules().items() if (f := _long_functions(tree))}
    assert long_functions == {}
    assert len((PIPELINE / "cli.py").read_text(encoding="utf-8").splitlines()) <= MAX_DISPATCHER_LINES


def test_every_command_has_its_own_module_with_a_main():
    from pipeline.cli import build_parser, commands
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    modules = {name: sub.choices[name].get_default("main").__module__ for name in sub.choices}
    assert modules == {name: f"pipeline.commands.{name}" for name in sub.choices}
    assert len(commands()) == len(sub.choices)


def test_the_commands_that_start_their_workers_ahead_are_those_with_a_local_cluster():
    """pipeline.cli starts the fork server before it imports the commands, from their names alone:
    the names must be those of the commands that take --workers (a local cluster)."""
    from pipeline.cli import LOCAL_CLUSTER_COMMANDS, build_parser
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    with_workers = {name for name, p in sub.choices.items()
                    if any("--workers" in a.option_strings for a in p._actions)}
    assert LOCAL_CLUSTER_COMMANDS == with_workers


def _defined_names(tree: ast.Module) -> set[str]:
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names |= {t.id for t in targets if isinstance(t, ast.Name)}
            names |= {e.id for t in targets if isinstance(t, ast.Tuple) for e in t.elts if isinstance(e, ast.Name)}
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
    return names


def test_shared_words_are_defined_once():
    """STATISTICS, QUANTILES, CONFIDENCE and the other shared words in pipeline/vocabulary.py alone; the
    level table and FINISHED in the core alone."""
    owners = {}
    for name, tree in _modules().items():
        for word in _defined_names(tree):
            owners.setdefault(word, []).append(name)
    shared = ("STATISTICS", "QUANTILES", "CONFIDENCE", "QUANTITIES", "DIRECTIONS", "WINDOWS", "SUMMARIES",
              "STORES", "FAMILIES")
    assert {w: owners.get(w) for w in shared} == {w: ["vocabulary"] for w in shared}
    assert [owners.get(w) for w in ("FINISHED", "MODELS", "MODEL_LEVELS")] == [None, None, None]


def _confidence_literals(tree: ast.Module) -> list[int]:
    """Lines where 0.95 is written as a number (a confidence or a quantile's probability)."""
    return sorted({n.lineno for n in ast.walk(tree) if isinstance(n, ast.Constant) and n.value == 0.95})


def test_the_default_confidence_is_written_once():
    found = {name: lines for name, tree in _modules().items() if (lines := _confidence_literals(tree))}
    assert list(found) == ["vocabulary"] and len(found["vocabulary"]) == 2   # CONFIDENCE and q95's probability
