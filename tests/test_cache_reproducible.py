"""The contact level gives the same bits whether numba compiles its kernel or loads it from the cache."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

SMOKE = Path(__file__).resolve().parent.parent / "configs" / "smoke.toml"

# one contact realisation; every number of its result as float.hex, which is exact
_RUN = """
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


def _run_contact(cache_dir: Path) -> dict:
    """Realisation 3 of the smoke scene at the contact level, in a new process using ``cache_dir``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    env.pop("NUMBA_DISABLE_JIT", None)
    done = subprocess.run([sys.executable, "-c", _RUN, str(SMOKE)], env=env, capture_output=True,
                          text=True, timeout=900, check=True)
    return json.loads(done.stdout)


@pytest.mark.slow
def test_contact_kernel_compiled_and_cached_agree_bit_for_bit(tmp_path):
    cache = tmp_path / "numba_cache"
    cache.mkdir()
    cold = _run_contact(cache)                 # empty cache: compiles, then writes the cache
    assert any(cache.rglob("*contact_kernel.advance_chunk*.nbc")), "the first run wrote no cache"
    warm = _run_contact(cache)                 # filled cache: loads
    assert cold["status"] == "finished" and cold["steps"] > 0
    differ = {k: sum(a != b for a, b in zip(cold[k], warm[k])) for k in cold if isinstance(cold[k], list)}
    assert all(len(cold[k]) == len(warm[k]) for k in differ)
    assert differ == dict.fromkeys(differ, 0), f"numbers differing cold vs cached: {differ}"
    assert (cold["steps"], cold["iterations"]) == (warm["steps"], warm["iterations"])
