"""The core's boundaries, read from the installed sources: an acyclic import graph with every import
at module level and the level table at its bottom, each module exporting only what it defines, the
level names and the status "finished" written once, and a pipeline that uses the core through its
public facade (``rss6core/__init__.py``) alone."""
import ast
import re
import subprocess
import sys
from pathlib import Path

import pipeline
import rss6core

CORE = Path(rss6core.__file__).parent
PIPELINE = Path(pipeline.__file__).parent


def _trees(folder: Path) -> dict[str, ast.Module]:
    """{module path below ``folder`` without .py: parsed source}, sub-packages included."""
    return {p.relative_to(folder).with_suffix("").as_posix(): ast.parse(p.read_text(encoding="utf-8"), str(p))
            for p in sorted(folder.rglob("*.py"))}


def _imports(tree: ast.Module, everywhere: bool = True) -> list:
    nodes = ast.walk(tree) if everywhere else tree.body
    return [n for n in nodes if isinstance(n, (ast.Import, ast.ImportFrom))]


def _core_modules_imported(node) -> set[str]:
    """The rss6core modules (``__init__`` for the facade) an import statement inside rss6core loads."""
    if isinstance(node, ast.Import):
        return {a.name.split(".")[1] if "." in a.name else "__init__" for a in node.names
                if a.name.split(".")[0] == "rss6core"}
    if node.level == 0 and not (node.module or "").startswith("rss6core"):
        return set()
    parts = (node.module or "").split(".")[1:] if node.level == 0 else (node.module or "").split(".")
    if parts and parts[0]:
        return {parts[0]}
    return {a.name for a in node.names}                 # from . import x: x is a module


# the imports inside functions, for import time and not to dodge a cycle: the contact level's
# compiled kernel (numba, 0.3 s per process) loads only when a contact level runs or its kernels
# are asked about or compiled (rss6 warm; kernels.compile_kernel runs a level with stand-in kernels);
# the clearance laws' compiled arithmetic (draw_kernel, numba too) loads at a process's first draw;
# scipy.stats and scipy.interpolate load at a scene's first uncertain law
# or spline, not in every rss6 process (docs/performance.md section 31)
LAZY = {("models", "contact_dynamics"), ("models", "contact_start"), ("kernels", "contact_kernel"),
        ("kernels", "models"), ("kernels", "contact_dynamics"), ("clearance", "draw_kernel"),
        ("kernels", "draw_kernel"),   # rss6 warm's load_draw_kernels: numba's import only when asked
        ("uncertain", "<not core: scipy>"), ("trajectory_kinds", "<not core: scipy.interpolate>")}
# the modules that run a level: none of them is the scene's business
LADDER = {"models", "assembly", "elastic", "quasi_static", "paper_method", "contact_dynamics", "contact_kernel",
          "contact_numpy", "contact_start"}


def _module_of(node) -> str:
    return node.module if isinstance(node, ast.ImportFrom) else ", ".join(a.name for a in node.names)


def test_core_imports_only_at_module_level_and_without_a_cycle(find_cycle):
    trees = _trees(CORE)
    deferred = {(name, m) for name, tree in trees.items()
                for n in set(_imports(tree)) - set(_imports(tree, everywhere=False))
                for m in _core_modules_imported(n) or {f"<not core: {_module_of(n)}>"}}
    assert deferred == LAZY, f"imports inside functions or classes: {sorted(deferred - LAZY)}"
    graph = {name: set().union(*map(_core_modules_imported, _imports(tree))) - {name}   # deferred too
             for name, tree in trees.items()}
    assert find_cycle(graph) == []
    assert graph["levels"] == set()                 # the level table is a leaf, and the scene reads it
    assert "levels" in graph["scene"] and "levels" in graph["models"]
    # reading a scene loads none of the ladder (scene -> models had been a cycle, then a top floor)
    assert _reach(graph, "scene").isdisjoint(LADDER), sorted(_reach(graph, "scene") & LADDER)


def _reach(graph: dict[str, set[str]], start: str) -> set[str]:
    """The modules ``start`` imports, directly or through others."""
    seen, todo = set(), [start]
    while todo:
        for m in graph.get(todo.pop(), ()):
            if m not in seen:
                seen.add(m)
                todo.append(m)
    return seen


def test_reading_a_scene_and_the_paper_level_do_not_load_the_contact_kernel(paper):
    """Reading a scene, the facade and the pipeline's run module leave numba unloaded (it costs 0.3 s
    of import in a paper-level run's main process); the paper level's draw loads numba and the draw
    kernel (in the workers, preloaded by their fork server), never the contact kernel."""
    watched = ('numba', 'rss6core.contact_kernel', 'rss6core.draw_kernel')
    modules = f"print(sorted(m for m in {watched!r} if m in sys.modules))"
    code = ("import sys, pipeline.ensemble.run, rss6core\n"
            f"s = rss6core.load_scene({str(paper.source_path)!r})\n"
            f"{modules}\n"
            "assert rss6core.simulate_batch(s, 'paper', realizations=[0])[0].status == 'finished'\n"
            f"{modules}\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split("\n")[:2] == ["[]", "['numba', 'rss6core.draw_kernel']"]


def test_cycle_finder_finds_a_cycle(find_cycle):
    assert find_cycle({"scene": {"kinematics"}, "kinematics": {"trajectory", "scene"}}) == [
        "kinematics", "scene", "kinematics"]


def test_reach_follows_imports_through_other_modules():
    graph = {"scene": {"levels", "kinematics"}, "kinematics": {"trajectory"}, "models": {"scene"}}
    assert _reach(graph, "scene") == {"levels", "kinematics", "trajectory"}


def _defined(tree: ast.Module) -> set[str]:
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names |= {t.id for t in targets if isinstance(t, ast.Name)}
    return names


def _exported(tree: ast.Module) -> list[str]:
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "__all__" for t in node.targets):
            return list(ast.literal_eval(node.value))
    return []


def test_every_core_module_exports_only_names_it_defines():
    """Names are owned where they are defined: MODELS in models, INTEGRATORS in integrators (the
    scene schema imports them from there), not re-exported by another module."""
    trees = _trees(CORE)
    foreign = {name: sorted(set(_exported(tree)) - _defined(tree)) for name, tree in trees.items()
               if name != "__init__"}
    assert {k: v for k, v in foreign.items() if v} == {}
    names = ("MODELS", "MODEL_LEVELS", "INTEGRATORS", "FINISHED")
    owners = {n: sorted(m for m, tree in trees.items() if n in _defined(tree)) for n in names}
    assert owners == {"MODELS": ["levels"], "MODEL_LEVELS": ["levels"], "INTEGRATORS": ["integrators"],
                      "FINISHED": ["status"]}


def _is_level_name(node) -> bool:
    return isinstance(node, ast.Constant) and node.value in rss6core.MODELS


def _lists_level_names(node) -> bool:
    """A tuple, list or set of level names only, or a dict keyed by level names only."""
    items = node.keys if isinstance(node, ast.Dict) else getattr(node, "elts", None)
    if not isinstance(node, (ast.Tuple, ast.List, ast.Set, ast.Dict)) or not items:
        return False
    return all(_is_level_name(k) for k in items)


def _written_again(folder: Path, owners: dict[str, str]) -> list[str]:
    """Where a module other than the idea's owner writes the level table again (a comparison with a
    level name, a collection of level names) or compares with the status literal "finished"."""
    found = []
    for path in sorted(folder.rglob("*.py")):
        where = path.relative_to(folder).as_posix()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            operands = [node.left, *node.comparators] if isinstance(node, ast.Compare) else []
            if where != owners["levels"] and (_lists_level_names(node) or any(map(_is_level_name, operands))):
                found.append(f"{where}:{node.lineno} level names")
            if where != owners["status"] and any(isinstance(o, ast.Constant) and o.value == rss6core.FINISHED
                                                 for o in operands):
                found.append(f"{where}:{node.lineno} \"finished\"")
    return sorted(set(found))


def test_the_core_writes_the_level_table_and_finished_once():
    """A level's properties are asked of rss6core.levels, not by comparing or listing level names; the
    status "finished" is compared as status.FINISHED."""
    assert _written_again(CORE, {"levels": "levels.py", "status": "status.py"}) == []


# the pipeline's choices of particular levels (not their properties): module -> how many sites
CHOSEN_LEVELS = {
    "studies/report.py": 4,      # the paper's section 6: its method against contact, level by level
    "studies/report_figures.py": 1,   # its figures of the same two levels (figs. 11-16)
    "studies/stability.py": 1,   # the figure's two panels: the elastic and the contact sweeps
    "studies/tradeoff.py": 1,    # one colour per level in the trade-off figure
}
DASK_FINISHED = "ensemble/cluster.py"   # dask's own future status "finished", not rss6's


def test_the_pipeline_writes_the_level_table_and_finished_nowhere():
    """The pipeline asks rss6core's level table (model_level, models_with) for a level's properties and
    compares statuses with FINISHED; the only level names it writes are the choices in CHOSEN_LEVELS."""
    found = _written_again(PIPELINE, {"levels": "-", "status": "-"})
    levels = [f.split(":")[0] for f in found if f.endswith("level names")]
    assert {m: levels.count(m) for m in set(levels)} == CHOSEN_LEVELS
    assert [f.split(":")[0] for f in found if f.endswith('"finished"')] == [DASK_FINISHED]


def test_written_again_finds_level_names_and_finished(tmp_path):
    (tmp_path / "a.py").write_text('CHEAP = ("rigid", "quasi-static")\nBY = {"paper": 1, "contact": 2}\n'
                                   'if model == "contact" or "paper" in x or s != "finished":\n    pass\n'
                                   'OTHER = ("uniform", "paper")\nz = f(model="elastic")\n')
    assert _written_again(tmp_path, {"levels": "-", "status": "-"}) == [
        "a.py:1 level names", "a.py:2 level names", "a.py:3 \"finished\"", "a.py:3 level names"]


def test_pipeline_imports_the_core_through_its_facade_only():
    """No pipeline module (at any depth, inside functions too) imports rss6core.<submodule>, and
    every name it takes from rss6core is in the facade's __all__ and described in its docstring."""
    offences = []
    for name, tree in _trees(PIPELINE).items():
        for node in _imports(tree):
            if isinstance(node, ast.Import):
                offences += [f"{name}.py:{node.lineno} import {a.name}" for a in node.names
                             if a.name.startswith("rss6core.")]
            elif node.level == 0 and (node.module or "").startswith("rss6core"):
                if node.module != "rss6core":
                    offences.append(f"{name}.py:{node.lineno} from {node.module}")
                offences += [f"{name}.py:{node.lineno} {a.name} is not in rss6core.__all__"
                             for a in node.names if a.name not in rss6core.__all__]
    assert offences == []
    undocumented = [n for n in rss6core.__all__ if n != "__version__"
                    and not re.search(rf"^- (\w+, )*{n}[:,]", rss6core.__doc__, re.M)]
    assert undocumented == []


def test_load_scene_names_a_missing_file_without_the_shipped_scenes(tmp_path):
    """In a process where ``pipeline`` (and with it the shipped scenes' package) cannot be imported,
    ``load_scene`` of a missing file still raises SceneError naming the file."""
    code = ("import sys\nsys.modules['pipeline'] = None   # any import of pipeline now fails\n"
            "import rss6core\n"
            "try:\n    rss6core.load_scene('nope.toml')\n"
            "except rss6core.SceneError as exc:\n    print(type(exc).__name__, exc)\n")
    done = subprocess.run([sys.executable, "-I", "-c", code], cwd=tmp_path, capture_output=True,
                          text=True, timeout=120)
    assert (done.returncode, done.stdout, done.stderr) == (0, "SceneError nope.toml: no such scene file\n", "")
