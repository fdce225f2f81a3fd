"""The compiled kernels (rss6core/kernels.py): which levels have them, whether numba's on-disk cache
holds them, `rss6 warm`, and a compile note only where a kernel is being compiled.  The cold cache's
side (the note appears, `rss6 warm` compiles) is tests/test_cold_cache.py's (slow)."""
import io
import json
import os
import subprocess
import sys

import pytest

import pipeline.ensemble.progress as progress
from pipeline.cli import main


def _python(code: str) -> dict:
    """``code``'s last printed line, as JSON, from a new process (its numba has compiled nothing)."""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=3600)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_only_the_contact_level_has_kernels_and_asking_about_the_others_imports_no_numba():
    found = _python("""
import json, sys
from rss6core import MODELS, kernels_to_compile, level_kernels
print(json.dumps(dict(levels={m: level_kernels(m) for m in MODELS},
                      others=[kernels_to_compile(m) for m in MODELS if m != "contact"],
                      numba="numba" in sys.modules)))""")
    assert found["levels"] == {"rigid": [], "quasi-static": [], "elastic": [], "paper": [],
                               "contact": ["contact_kernel.advance_chunk", "contact_kernel.newton_step"]}
    assert found["others"] == [[]] * 4 and not found["numba"]


def test_one_compiled_overload_per_kernel_serves_every_scene_start_and_step():
    """The cache check takes any cached overload for this machine as the one a run needs: true only
    while every run calls a kernel with the same argument types.  Drawn and equilibrium starts,
    fixed and adaptive steps, two scenes: one signature per kernel, all from the cache."""
    found = _python("""
import dataclasses, json
from pipeline.scenes.catalogue import find_scene
from rss6core import compile_kernels, kernels_to_compile, prepare_level
import rss6core.contact_kernel as ck
compile_kernels(find_scene("smoke"))   # the cache filled, if it was not (a fresh tree: minutes)
cached = kernels_to_compile("contact")
for name, kw in (("smoke", {}), ("paper_tolerance", {}), ("paper", dict(tolerance=1e-8, refinements=2))):
    scene = find_scene(name)
    short = dataclasses.replace(scene, trajectory=dataclasses.replace(scene.trajectory, duration=0.004))
    prepare_level(short, "contact", **kw).simulate(1, [0, 1])
kernels = (ck.advance_chunk, ck.newton_step)
starts = [find_scene(n).simulation.contact_start for n in ("smoke", "paper_tolerance")]
print(json.dumps(dict(cached=cached, starts=starts,
                      signatures={k.__name__: len(k.signatures) for k in kernels},
                      misses={k.__name__: sum(k._cache_misses.values()) for k in kernels})))""")
    assert found["starts"] == ["drawn", "equilibrium"]
    assert found["signatures"] == {"advance_chunk": 1, "newton_step": 1}, found
    assert found["misses"] == {"advance_chunk": 0, "newton_step": 0} and found["cached"] == [], found


def test_warm_on_a_warm_cache_compiles_nothing():
    """`rss6 warm` twice (the first compiles on a cold cache): the second says nothing to compile,
    and a new process finds both kernels in the cache."""
    for _ in range(2):
        proc = subprocess.run([sys.executable, "-m", "pipeline.cli", "warm"], capture_output=True,
                              text=True, timeout=3600)
        assert proc.returncode == 0, proc.stderr
    line = proc.stdout.strip()
    assert line.startswith("rss6 warm: nothing to compile: contact_kernel.advance_chunk, "
                           "contact_kernel.newton_step (the contact level's"), line
    assert "every level's draw kernels compiled or loaded at their import in " in line   # newcomer55
    # a new process loads every draw kernel warm left in the cache: no compile, only cache hits
    hits = _python("import json; from rss6core import draw_kernel as k; "
                   "print(json.dumps({n: [sum(f.stats.cache_hits.values()), sum(f.stats.cache_misses.values())] "
                   "for n in ('eccentricities_into', 'truncated_normals') for f in [getattr(k, n)]}))")
    assert all(h >= 1 and m == 0 for h, m in hits.values()), hits
    assert _python("import json; from rss6core import kernels_to_compile; "
                   "print(json.dumps(kernels_to_compile('contact')))") == []


def test_a_warm_quasi_static_run_prints_no_compile_note(tmp_path, capsys):
    assert main(["run", "smoke", "--model", "quasi-static", "-n", "4", "--chunk", "2", "--workers", "1",
                 "-o", str(tmp_path / "q.nc")]) == 0
    err = capsys.readouterr().err
    assert "rss6 run: 4 realisations to compute in 2 chunks" in err
    assert "compil" not in err, err


def test_the_compile_note_names_the_kernels_once_per_command(monkeypatch):
    """A command's batches (rss6 run --until: up to 14) share one note; none without kernels."""
    monkeypatch.setattr(progress, "_COMPILE_NOTED", [])
    stream = io.StringIO()
    bar = progress._Progress(4, 0, stream)
    bar.begin(2, "1 worker")
    bar.compiling([])
    assert "compil" not in stream.getvalue()
    for _ in range(3):
        progress._Progress(4, 0, stream).compiling(["contact_kernel.advance_chunk"])
    lines = [ln for ln in stream.getvalue().splitlines() if "compil" in ln]
    assert lines == [f"rss6 run: {progress.compile_note(['contact_kernel.advance_chunk'])}"]
    assert "contact_kernel.advance_chunk" in lines[0] and "rss6 warm" in lines[0]


@pytest.mark.parametrize("model", ["quasi-static", "paper"])
def test_workers_of_a_level_without_kernels_are_not_asked(model):
    class Client:   # stands for a dask client: any question to the workers fails
        def run(self, *args):
            raise AssertionError("asked the workers")
    assert progress._kernels_to_compile(Client(), model) == []


def test_workers_are_asked_about_the_contact_levels_kernels(cluster_client):
    """Each worker answers from its own numba cache; the union of their answers."""
    answers = cluster_client.run(__import__("rss6core").kernels_to_compile, "contact")
    assert len(answers) == 2
    expected = sorted({k for names in answers.values() for k in names})
    assert progress._kernels_to_compile(cluster_client, "contact") == expected


def test_the_cache_folder_is_named_without_numbas_internal_too(monkeypatch, tmp_path):
    """`rss6 warm` names numba's cache folder from a numba internal; a numba without it gets the
    documented rule (NUMBA_CACHE_DIR, else __pycache__ beside the source) instead of an AttributeError."""
    from rss6core import contact_kernel, kernel_cache_folder
    monkeypatch.setattr(contact_kernel.advance_chunk, "_cache", object())
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    assert kernel_cache_folder() == os.path.join(os.path.dirname(contact_kernel.__file__), "__pycache__")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert kernel_cache_folder() == str(tmp_path)
