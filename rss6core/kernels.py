"""The compiled (numba) kernels of the levels: which a level uses, which are not yet compiled on this
machine, and compiling them all up front (``rss6 warm``).

Only the contact level has compiled kernels (:mod:`.contact_kernel`'s entry points).  numba compiles
a kernel at its first call in a process unless its on-disk cache (``NUMBA_CACHE_DIR``, else
``__pycache__`` beside the source) holds it for this CPU, this numba and this source file; compiling
the contact level's takes minutes, loading them well under a second.  Every realisation and scene
calls a kernel with the same argument types (tests/test_kernels.py), so one compiled overload per
kernel serves every run; the cache check below takes any overload for this CPU and source as the one.
Asking about a level without kernels imports nothing (numba is 0.3 s of import per process).
Every level's clearance draw also runs compiled code (:mod:`.draw_kernel`), small enough to compile
or load at its import (about 1.5 s on an empty cache), which is why it is not listed here;
``rss6 warm`` imports it too (:func:`load_draw_kernels`).
"""
from __future__ import annotations

import concurrent.futures
import dataclasses
import multiprocessing
import os
import time

from .levels import MODELS, model_level

__all__ = ["level_kernels", "kernels_to_compile", "compile_kernels", "compile_kernel", "kernel_cache_folder",
           "load_draw_kernels",
           "ENTRY_POINTS"]

ENTRY_POINTS = ("advance_chunk", "newton_step")   # .contact_kernel's, called by the contact-joint levels


def _entry_points(model: str) -> tuple[str, ...]:
    """The compiled entry points ``model`` calls: the contact kernel's where its joints are contact
    pairs (the level table's ``contact_joints``), none elsewhere."""
    return ENTRY_POINTS if model_level(model).contact_joints else ()


def level_kernels(model: str) -> tuple[str, ...]:
    """Names of the compiled kernels ``model`` calls (none for the levels without any)."""
    return tuple(f"contact_kernel.{name}" for name in _entry_points(model))


def kernels_to_compile(model: str) -> list[str]:
    """The kernels of ``model`` this process would compile before running it: neither compiled here
    already nor in numba's on-disk cache for this machine and source."""
    if not _entry_points(model):
        return []
    return [f"contact_kernel.{name}" for name, kernel in _dispatchers(model) if not _cached(kernel)]


def kernel_cache_folder() -> str:
    """Where numba keeps the compiled kernels (``NUMBA_CACHE_DIR``, else beside the source)."""
    from . import contact_kernel
    try:
        return str(contact_kernel.advance_chunk._cache._cache_path)   # numba's own choice (internal)
    except AttributeError:   # a numba without that internal: its documented rule
        return os.environ.get("NUMBA_CACHE_DIR") or os.path.join(os.path.dirname(contact_kernel.__file__),
                                                                 "__pycache__")


def load_draw_kernels() -> float:
    """Seconds to import :mod:`.draw_kernel`, whose import compiles (or loads from numba's cache) the
    clearance draws every level runs: a few seconds on an empty cache, then well under one."""
    start = time.perf_counter()
    from . import draw_kernel  # noqa: F401
    return time.perf_counter() - start


def compile_kernels(scene) -> dict[str, float]:
    """Compile every level's kernels not yet cached, into numba's on-disk cache, each by
    :func:`compile_kernel` in a process of its own, at once (two entry points, two cores: the wait
    is the longer compile, not both); returns seconds spent compiling per kernel compiled (empty
    when all were cached: then this takes about a second)."""
    todo = sorted({name for model in MODELS for name in kernels_to_compile(model)})
    if not todo:
        return {}
    points = [name.rsplit(".", 1)[-1] for name in todo]
    with concurrent.futures.ProcessPoolExecutor(len(points), mp_context=multiprocessing.get_context("spawn")) as pool:
        seconds = list(pool.map(compile_kernel, points, [scene] * len(points)))
    return dict(zip(todo, seconds))


class _Arguments(Exception):
    """Raised by a stand-in kernel with the arguments it was called with."""


def compile_kernel(name: str, scene) -> float:
    """Compile only the entry point ``name`` (of :data:`ENTRY_POINTS`) into numba's cache, for the
    arguments the contact level passes it on ``scene``, and return the seconds it took (0 when it
    was cached): a short run whose calls of both entry points are stand-ins, the other one doing
    nothing (its results are not used) and this one handing over its arguments, which are then
    compiled as a call would (the dispatcher's own argument types, the same overload and cache
    entry).  Two processes can so compile the two entry points at once, each then loading the
    other's from the cache (pipeline.ensemble.run)."""
    from . import contact_dynamics, contact_kernel
    from .models import prepare_level
    if name not in ENTRY_POINTS:
        raise ValueError(f"unknown kernel {name!r}; choose one of {', '.join(ENTRY_POINTS)}")
    kernel = getattr(contact_kernel, name)
    if _cached(kernel):
        return 0.0

    def hand_over(*args):
        raise _Arguments(args)

    stand_ins = {other: (hand_over if other == name else (lambda *args: None)) for other in ENTRY_POINTS}
    saved = {other: getattr(contact_dynamics, other) for other in ENTRY_POINTS}
    sim = scene.simulation
    short = dataclasses.replace(scene, trajectory=dataclasses.replace(scene.trajectory, duration=2 * sim.time_step))
    try:
        for other, stand_in in stand_ins.items():
            setattr(contact_dynamics, other, stand_in)
        prepare_level(short, "contact").simulate(0, [0])
        raise RuntimeError(f"the contact level did not call {name}")
    except _Arguments as called:
        args = called.args[0]
    finally:
        for other, original in saved.items():
            setattr(contact_dynamics, other, original)
    start = time.perf_counter()
    with contact_kernel.kernel_compiling():
        kernel.compile(tuple(kernel.typeof_pyval(a) for a in args))
    return time.perf_counter() - start


def _dispatchers(model: str) -> list:
    from . import contact_kernel
    return [(name, getattr(contact_kernel, name)) for name in _entry_points(model)]


def _cached(kernel) -> bool:
    """Whether ``kernel`` (a numba dispatcher) runs without compiling: compiled or loaded in this
    process, or an overload for this CPU and source in its on-disk cache (index and data file).
    numba's cache has no public API: where its private one (0.60-0.68) is not found, False (a
    compile note too many rather than minutes unexplained)."""
    if kernel.overloads:
        return True
    try:
        files = kernel._cache._cache_file
        index = files._load_index()   # empty when the source changed since it was written
        _, machine, source = kernel._cache._index_key(None, kernel.targetctx.codegen())
    except AttributeError:
        return False
    return any(key[1:] == (machine, source) and os.path.exists(files._data_path(name))
               for key, name in index.items())
