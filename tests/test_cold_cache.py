"""The contact level gives the same bits whether numba compiles its kernel or loads it from the
cache: one realisation run cold then cached, and an ensemble interrupted while its worker compiles
then resumed on the filled cache, against one run without interruption.

The two cold compiles run at once, each into its own empty cache, so the test pays one compile.
The cold ensemble says once that it compiles the kernels, the warm runs do not; `rss6 warm` compiles
into an empty cache what a contact run then loads (a compile of its own)."""
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.ensemble.run import TEST_HOLD_ENV

SMOKE = Path(__file__).resolve().parent.parent / "configs" / "smoke.toml"
KERNELS = "contact_kernel.advance_chunk, contact_kernel.newton_step"
N = 6       # one-realisation chunks: the first is stored, the others wait for SIGINT (TEST_HOLD_ENV)
RUN = ["run", "smoke", "--model", "contact", "-n", str(N), "--chunk", "1", "--workers", "1", "--seed", "2"]

# one contact realisation; every number of its result as float.hex, which is exact
_ONE = """
import json, sys
import numpy as np
from rss6core import load_scene
from rss6core.models import simulate
res = simulate(load_scene(sys.argv[1]), "contact", realization=3)
arrays = dict(displacement=res.displacement, velocity=res.velocity, acceleration=res.acceleration,
              peak=res.peak_abs_error, contact_peak=res.contact_force_peak)
print(json.dumps({k: [float(x).hex() for x in np.ravel(v)] for k, v in arrays.items()}
                 | dict(status=res.status, steps=res.steps, iterations=res.iterations)))
"""


def _env(cache: Path) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    env.pop("NUMBA_DISABLE_JIT", None)
    return env


def _one_realisation(cache: Path) -> subprocess.Popen:
    """Realisation 3 of the smoke scene at the contact level, in a new process using ``cache``."""
    return subprocess.Popen([sys.executable, "-c", _ONE, str(SMOKE)], env=_env(cache),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _finished_json(proc: subprocess.Popen) -> dict:
    out, err = proc.communicate(timeout=1200)
    assert proc.returncode == 0, err
    return json.loads(out)


def _ensemble(out: Path, cache: Path, hold: dict | None = None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "pipeline.cli", *RUN, "-o", str(out)],
                            env=_env(cache) | (hold or {}), cwd=out.parent, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _interrupt_after_first_part(out: Path, cache: Path) -> str:
    """Run the ensemble on the cold ``cache`` and SIGINT it once its first chunk is stored (the
    others wait for it: TEST_HOLD_ENV); returns its stderr."""
    parts = Path(str(out) + ".parts")
    proc = _ensemble(out, cache, {TEST_HOLD_ENV: f"1:{out.parent / 'never'}"})
    try:
        while not list(parts.glob("chunk-*.nc")) and proc.poll() is None:   # compiling: minutes
            time.sleep(0.1)
        assert proc.poll() is None, f"the run ended before it could be interrupted: {proc.stderr.read()}"
        os.kill(proc.pid, signal.SIGINT)
        try:
            _, err = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:             # a lost first Ctrl-C (test_sigint.py): again
            os.kill(proc.pid, signal.SIGINT)
            _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err
    assert len(list(parts.glob("chunk-*.nc"))) == 1 and not out.exists()
    return err


def _complete(out: Path, cache: Path) -> str:
    proc = _ensemble(out, cache)
    _, err = proc.communicate(timeout=1200)
    assert proc.returncode == 0, err
    return err


def _rss6(cache: Path, *args) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-m", "pipeline.cli", *args], env=_env(cache),
                          capture_output=True, text=True, timeout=3600)
    assert proc.returncode == 0, proc.stderr
    return proc


def _assert_same_bits(cold: dict, warm: dict) -> None:
    assert cold["status"] == "finished" and cold["steps"] > 0
    differ = {k: sum(a != b for a, b in zip(cold[k], warm[k])) for k in cold if isinstance(cold[k], list)}
    assert all(len(cold[k]) == len(warm[k]) for k in differ)
    assert differ == dict.fromkeys(differ, 0), f"numbers differing cold vs cached: {differ}"
    assert (cold["steps"], cold["iterations"]) == (warm["steps"], warm["iterations"])


@pytest.mark.slow   # compiles the contact kernel twice at once into empty caches: minutes
def test_compiled_and_cached_kernels_agree_bit_for_bit(tmp_path):
    one_cache, run_cache = tmp_path / "cache_one", tmp_path / "cache_run"
    one_cache.mkdir()
    run_cache.mkdir()
    cold_one = _one_realisation(one_cache)            # compiles in its own process, meanwhile...
    resumed, whole = tmp_path / "resumed.nc", tmp_path / "whole.nc"
    err = _interrupt_after_first_part(resumed, run_cache)   # ...the ensemble's worker compiles too
    assert err.count(f"rss6 run: compiling {KERNELS} first") == 1, err
    cold = _finished_json(cold_one)
    assert any(one_cache.rglob("*contact_kernel.advance_chunk*.nbc")), "the cold run wrote no cache"
    assert any(run_cache.rglob("*.nbc")), "the cold ensemble wrote no compiled kernel to the cache"
    _assert_same_bits(cold, _finished_json(_one_realisation(one_cache)))
    for out in (resumed, whole):   # the stored chunks, then the rest; every chunk: warm, no note
        err = _complete(out, run_cache)
        assert "compiling" not in err, err
    assert resumed.read_bytes() == whole.read_bytes()
    # the cache one realisation filled serves `rss6 warm` too
    assert _rss6(one_cache, "warm").stdout.startswith(f"rss6 warm: nothing to compile: {KERNELS}")


@pytest.mark.slow   # compiles the contact kernel into an empty cache: minutes
def test_warm_compiles_into_an_empty_cache_what_a_contact_run_then_loads(tmp_path):
    """`rss6 warm` on an empty cache names both kernels and their compile times; afterwards `rss6
    warm` has nothing to compile and `rss6 simulate --model contact` prints no compile note."""
    cold = _rss6(tmp_path, "warm").stdout
    assert re.fullmatch(r"rss6 warm: compiled contact_kernel\.(newton_step|advance_chunk) \(\d+ s\), "
                        r"contact_kernel\.(newton_step|advance_chunk) \(\d+ s\) into numba's cache "
                        rf"\({re.escape(str(tmp_path))}/\S+\) in \d+ s; every level's draw kernels compiled or "
                        r"loaded at their import in \d+\.\d s\n", cold), cold
    assert _rss6(tmp_path, "warm").stdout.startswith(f"rss6 warm: nothing to compile: {KERNELS}")
    simulated = _rss6(tmp_path, "simulate", "smoke", "--model", "contact")
    assert "compiling" not in simulated.stderr and "finished" in simulated.stdout, simulated


_COMPILE_ONE = """
import json, sys
from rss6core import compile_kernel, kernels_to_compile
from pipeline.scenes.catalogue import find_scene
seconds = compile_kernel(sys.argv[1], find_scene("smoke"))
print(json.dumps(dict(seconds=seconds, left=kernels_to_compile("contact"))))
"""


def _compile_one(cache: Path, name: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", _COMPILE_ONE, name], env=_env(cache), capture_output=True,
                          text=True, timeout=3600)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.slow   # compiles both kernels into two empty caches, one of them by a two-worker run: minutes
def test_each_kernel_compiled_on_its_own_serves_a_run_with_the_same_bits(tmp_path):
    """compile_kernel compiles the one entry point it names (the other is still to compile
    afterwards, then neither); a run on that cache loads both and gives the bits of a run that
    compiled them itself. A two-worker ensemble on an empty cache (its workers compile one kernel
    each, pipeline.ensemble.progress.compile_apart) writes the file a warm-cache run writes."""
    split, cold = tmp_path / "split", tmp_path / "cold"
    split.mkdir()
    cold.mkdir()
    args = ["run", "smoke", "--model", "contact", "-n", "4", "--workers", "2", "--seed", "2"]
    ensemble = subprocess.Popen([sys.executable, "-m", "pipeline.cli", *args, "-o", str(cold / "e.nc")],
                                env=_env(cold / "cache"), cwd=cold, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True)
    first = _compile_one(split / "cache", "newton_step")
    assert first["seconds"] > 0 and first["left"] == ["contact_kernel.advance_chunk"], first
    second = _compile_one(split / "cache", "advance_chunk")
    assert second["seconds"] > 0 and second["left"] == [], second
    assert _compile_one(split / "cache", "advance_chunk")["seconds"] == 0.0     # cached: nothing to do
    reference = subprocess.Popen([sys.executable, "-c", _ONE, str(SMOKE)], stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True)   # the suite's own cache, compiled whole
    _assert_same_bits(_finished_json(_one_realisation(split / "cache")), _finished_json(reference))
    _, err = ensemble.communicate(timeout=3600)
    assert ensemble.returncode == 0 and err.count(f"rss6 run: compiling {KERNELS} first") == 1, err
    _rss6(split / "cache", *args, "-o", str(split / "e.nc"))
    assert (cold / "e.nc").read_bytes() == (split / "e.nc").read_bytes()
