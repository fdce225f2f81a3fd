"""A contact kernel's fastmath flags reach every operation it compiles, whatever the process compiled
before: numba keeps the subroutines some operations compile into (``x ** 2``) per process by code
and signature, not by the fastmath flags they take from their caller (numba issue 7168), so a square
first compiled for code without fastmath (the draw kernel) served a later fastmath kernel without its
flags, and its bits depended on the process's history (tests/test_cold_cache.py, docs/performance.md
section 36).  :func:`rss6core.contact_kernel.own_subroutines` gives the kernel's compile a cache of
its own.  Each case runs in a new process, so that the order of compiles is the case's."""
import json
import subprocess
import sys

import pytest

_PROCESS = r"""
import contextlib, json, re, sys
import numpy as np
from numba import njit, types
from rss6core import contact_kernel

@njit                                       # no fastmath, as the draw kernel
def plain(e):
    return np.sqrt(e[0] ** 2 + e[1] ** 2)

@njit(fastmath=contact_kernel._FAST)         # the contact kernel's flags and its |f|
def fast(e):
    return np.sqrt(e[0] ** 2 + e[1] ** 2)

vector = types.float64[::1]
if sys.argv[1] == "plain-first":
    plain.compile((vector,))
with contact_kernel.own_subroutines() if sys.argv[2] == "own" else contextlib.nullcontext():
    fast.compile((vector,))
ir = fast.inspect_llvm(fast.signatures[0])
print(json.dumps(sorted({flags.strip() for flags in re.findall(r"= fmul ([a-z ]*)double", ir)})))
"""
FAST = "reassoc nsz arcp contract"   # the order LLVM prints contact_kernel._FAST in


def _square_flags(first: str, cache: str) -> list[str]:
    """The fastmath flags on the multiplications of ``fast``'s squares, compiled after ``first``
    ("plain-first" or "alone") with numba's subroutine cache ("numba") or its own ("own")."""
    proc = subprocess.run([sys.executable, "-c", _PROCESS, first, cache], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("first", ["plain-first", "alone"])
def test_a_kernel_compiled_with_its_own_subroutines_keeps_its_flags_on_every_square(first):
    assert _square_flags(first, "own") == [FAST]


def test_without_its_own_subroutines_a_kernel_takes_the_flags_of_whoever_compiled_the_square_first():
    """The defect the fix removes, so that the test above can fail: numba's own cache (skipped on a numba
    that no longer shares the subroutine across flags)."""
    assert _square_flags("alone", "numba") == [FAST]
    shared = _square_flags("plain-first", "numba")
    if shared == [FAST]:
        pytest.skip("this numba keeps a subroutine per caller's flags (numba issue 7168 fixed)")
    assert shared == [""]
