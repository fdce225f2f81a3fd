"""numba's inliner with :func:`rss6core.contact_kernel.fast_inlining` (the callee's blocks share one copy
of its scope) gives the same compiled code as numba's own: the LLVM IR of a kernel of nested
inline="always" functions with branches and loops, compiled each way in a new process (the same
sequence of compiles) is the same text but for the mangled names (their hash differs from process to
process, as between two plain compiles), and the fast copier did the copies."""
import json
import subprocess
import sys

_KERNEL = r"""
import contextlib, hashlib, json, re, sys
import numpy as np
from numba import njit, types
from rss6core import contact_kernel

@njit(inline="always", fastmath=contact_kernel._FAST)
def _leaf(a, i, w):
    s = 0.0
    for k in range(3):
        if a[i, k] > w:
            s += a[i, k] * w
        else:
            s -= np.sqrt(abs(a[i, k]))
    return s, s * w

@njit(inline="always", fastmath=contact_kernel._FAST)
def _middle(a, out, w):
    for i in range(a.shape[0]):
        x, y = _leaf(a, i, w)
        u, v = _leaf(a, i, y)
        out[i] = x + u * v if x > 0.0 else y - v
    return out[0]

@njit(fastmath=contact_kernel._FAST)
def top(a, out):
    t = 0.0
    for j in range(2):
        t += _middle(a, out, 0.5 * j) + _middle(a, out, t)
    return t

copies = []
class Counting(contact_kernel._BlockCopier):
    def deepcopy(self, x, memo=None):
        copies.append(memo is None)
        return super().deepcopy(x, memo)
if sys.argv[1] == "fast":
    contact_kernel._BlockCopier = Counting
with contact_kernel.fast_inlining() if sys.argv[1] == "fast" else contextlib.nullcontext():
    top.compile((types.float64[:, ::1], types.float64[::1]))
ir = top.overloads[top.signatures[0]].library.get_llvm_str()
ir = re.sub(r'_ZN[0-9A-Za-z_]+', '_ZN<name>', ir)   # mangled names: their hash varies between processes
ir = re.sub(r'\[\d+ x i8\] c"missing Environment', 'c"missing Environment', ir)
a = np.linspace(-1.0, 1.0, 12).reshape(4, 3)
print(json.dumps(dict(ir=hashlib.sha256(ir.encode()).hexdigest(), lines=ir.count(chr(10)),
                      copies=sum(copies), value=float(top(a, np.zeros(4))).hex())))
"""


def _compiled(mode: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", _KERNEL, mode], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_fast_inlining_compiles_the_same_llvm_ir_as_numbas_own_inliner():
    fast, plain = _compiled("fast"), _compiled("plain")
    assert fast["copies"] > 10 and plain["copies"] == 0      # the blocks copied, by the fast copier
    assert fast["lines"] > 100
    assert (fast["ir"], fast["value"]) == (plain["ir"], plain["value"])
