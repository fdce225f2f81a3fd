"""rss6 warm: compile the kernels every level uses into numba's cache now, and say which and how long."""
from __future__ import annotations

import time

from ..scenes.catalogue import find_scene


def add_parser(sub) -> None:
    p = sub.add_parser("warm", help="compile the contact level's kernels and every level's draw kernels into "
                                    "numba's cache now (minutes once per machine and rss6 version; quick when "
                                    "already done)")
    p.set_defaults(main=main)


def main(args) -> int:
    from rss6core import MODELS, compile_kernels, kernel_cache_folder, level_kernels, load_draw_kernels
    start = time.perf_counter()
    compiled = compile_kernels(find_scene("smoke"))
    wall = time.perf_counter() - start
    draws = load_draw_kernels()
    where = f"numba's cache ({kernel_cache_folder()})"
    every = f"; every level's draw kernels compiled or loaded at their import in {draws:.1f} s"
    if not compiled:
        kernels = [k for model in MODELS for k in level_kernels(model)]
        print(f"rss6 warm: nothing to compile: {', '.join(kernels)} (the contact level's) are in {where}; "
              f"checked in {wall:.1f} s{every}")
        return 0
    print("rss6 warm: compiled " + ", ".join(f"{k} ({s:.0f} s)" for k, s in compiled.items())
          + f" into {where} in {wall:.0f} s{every}")
    return 0
