"""An ensemble interrupted while numba compiles its contact kernel (an empty cache) and resumed with
the filled cache gives the same file, byte for byte, as one run without interruption."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

RUN = ["run", "smoke", "--model", "contact", "-n", "4", "--chunk", "1", "--workers", "1", "--seed", "2"]


def _rss6(out: Path, cache: Path, **kw) -> subprocess.Popen:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    env.pop("NUMBA_DISABLE_JIT", None)
    return subprocess.Popen([sys.executable, "-m", "pipeline.cli", *RUN, "-o", str(out)], env=env,
                            cwd=out.parent, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, **kw)


def _interrupt_after_first_part(out: Path, cache: Path) -> None:
    """Run on the cold ``cache`` and SIGINT the run once its first chunk is stored."""
    parts = Path(str(out) + ".parts")
    proc = _rss6(out, cache)
    try:
        deadline = time.monotonic() + 1200          # compiling the kernel: minutes on shared cores
        while not list(parts.glob("chunk-*.nc")) and proc.poll() is None and time.monotonic() < deadline:
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
    assert 1 <= len(list(parts.glob("chunk-*.nc"))) < 4 and not out.exists()


def _complete(out: Path, cache: Path) -> None:
    proc = _rss6(out, cache)
    _, err = proc.communicate(timeout=1200)
    assert proc.returncode == 0, err


@pytest.mark.slow   # compiles the contact kernel into an empty cache: one to several minutes
def test_interrupted_on_a_cold_cache_and_resumed_on_a_warm_one_is_byte_identical(tmp_path):
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    resumed, whole = tmp_path / "resumed.nc", tmp_path / "whole.nc"
    _interrupt_after_first_part(resumed, cache)
    assert any(cache.rglob("*.nbc")), "the cold run wrote no compiled kernel to the cache"
    _complete(resumed, cache)                         # the stored chunks, then the rest, warm
    _complete(whole, cache)                           # every chunk warm
    assert resumed.read_bytes() == whole.read_bytes()
