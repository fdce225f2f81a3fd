"""Benchmark: where the contact kernels' compile time goes, and which code it gives.

Run on demand: ``python benchmarks/kernel_compile.py [--plain] [--llvm] [--json]``.
On a fresh temporary ``NUMBA_CACHE_DIR`` (nothing compiled), compiles the contact level's kernels as
``rss6 warm`` does, but one after the other in this process (:func:`rss6core.kernels.compile_kernel`,
which ``compile_kernels`` runs in a process per kernel: a two-step contact run of configs/paper.toml),
so that their compile metadata is here to read; with :func:`rss6core.contact_kernel.fast_inlining`
(the default) or, with ``--plain``, numba's own inliner. Prints the wall and CPU seconds of the
compile, per kernel its overloads, numba's seconds per compiler pass (``pipeline_times``, wall) and,
with ``--llvm`` (``NUMBA_LLVM_PASS_TIMINGS``), LLVM's totals; and a SHA-256 of each kernel's LLVM IR
and assembly with the mangled names masked (their hash differs from process to process). The same
hashes from a run with and without ``--plain`` mean the same compiled code.
"""
from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "paper.toml"


def _masked_sha(text: str) -> str:
    """SHA-256 (16 hex digits) of LLVM IR or assembly with mangled names and their lengths masked."""
    text = re.sub(r"_ZN[0-9A-Za-z_]+", "_ZN<name>", text)
    text = re.sub(r"\[\d+ x i8\] c\"missing Environment", "c\"missing Environment", text)
    text = re.sub(r"(\.size\t\"\.const\.missing Environment: _ZN<name>\"), \d+", r"\1", text)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _kernel(dispatcher, llvm: bool) -> dict:
    out = {"overloads": len(dispatcher.overloads)}
    for cres in dispatcher.overloads.values():
        passes = cres.metadata["pipeline_times"]["nopython"]
        seconds = {name: t.init + t.run + t.finalize for name, t in passes.items()}
        out["passes_s"] = {k: round(v, 1) for k, v in sorted(seconds.items(), key=lambda kv: -kv[1]) if v >= 0.5}
        out["llvm_ir_sha"] = _masked_sha(cres.library.get_llvm_str())
        out["asm_sha"] = _masked_sha(cres.library.get_asm_str())
        if llvm:
            out["llvm_s"] = {r.name.split(" on ")[0]: round(r.timings.get_total_time(), 1)
                             for r in cres.metadata["llvm_pass_timings"]}
    return out


def measure(plain: bool, llvm: bool) -> dict:
    from rss6core import contact_kernel, kernels, load_scene
    if plain:
        contact_kernel.fast_inlining = contextlib.nullcontext   # kernel_compiling's, read at each compile
    scene = load_scene(CONFIG)
    cpu, wall = time.process_time(), time.perf_counter()
    compiled = {f"contact_kernel.{name}": kernels.compile_kernel(name, scene) for name in kernels.ENTRY_POINTS}
    result = {"inliner": "numba's own" if plain else "fast_inlining", "wall_s": time.perf_counter() - wall,
              "cpu_s": time.process_time() - cpu, "kernel_s": compiled}
    for name in kernels.ENTRY_POINTS:
        result[name] = _kernel(getattr(contact_kernel, name), llvm)
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plain", action="store_true", help="numba's own inliner, not fast_inlining")
    parser.add_argument("--llvm", action="store_true", help="LLVM's pass timings too (NUMBA_LLVM_PASS_TIMINGS)")
    parser.add_argument("--json", action="store_true")
    opts = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="kernel_compile_") as cache:
        os.environ["NUMBA_CACHE_DIR"] = cache          # before numba is imported: an empty cache
        if opts.llvm:
            os.environ["NUMBA_LLVM_PASS_TIMINGS"] = "1"
        os.environ.pop("NUMBA_DISABLE_JIT", None)
        result = measure(opts.plain, opts.llvm)
    if opts.json:
        print(json.dumps(result, indent=1))
        return 0
    per_kernel = {k: round(v, 1) for k, v in result["kernel_s"].items()}
    print(f"{result['inliner']}: compile {result['wall_s']:.1f} s wall, {result['cpu_s']:.1f} s CPU, load "
          f"{os.getloadavg()[0]:.1f}; per kernel (s): {json.dumps(per_kernel)}")
    for name in ("newton_step", "advance_chunk"):
        k = result[name]
        if not k["overloads"]:   # compiled in a process of its own (compile_kernels, docs/performance.md 28)
            print(f"  {name}: compiled in a process of its own; its passes and hashes are not in this one")
            continue
        print(f"  {name}: {k['overloads']} overload(s), LLVM IR {k['llvm_ir_sha']}, asm {k['asm_sha']}")
        print(f"    numba passes (s, wall): {json.dumps(k['passes_s'])}")
        if "llvm_s" in k:
            print(f"    LLVM (s): {json.dumps(k['llvm_s'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
