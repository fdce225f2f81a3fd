"""What a run tells its user while it computes: the progress bar and the one note that the workers
compile kernels first (asked of the workers before the first chunk)."""
from __future__ import annotations

import sys
import time

__all__ = ["compile_note", "cluster_label"]


_COMPILE_NOTED: list = []   # the kernels a compile note of this process named (said once per command)


def compile_note(kernels: list[str]) -> str:
    """The one line that says kernels are being compiled (rss6 run and rss6 simulate)."""
    return (f"compiling {', '.join(kernels)} first: numba's cache holds no copy for this machine and "
            "rss6 version; this takes minutes once (rss6 warm pays it up front)")


def cluster_label(workers: int, scheduler: str | None) -> str:
    """Where a run computes, as its progress lines say it: "2 workers" or "scheduler tcp://..."."""
    return f"scheduler {scheduler}" if scheduler else f"{workers} worker{'s' if workers != 1 else ''}"


class _Progress:
    """A bar on a terminal, plain lines otherwise; a first line at once (starting workers), a line
    when the workers compile kernels (:meth:`compiling`), then done/total with the elapsed time and
    an ETA."""

    def __init__(self, total: int, done: int, stream=None):
        self.total, self.done, self.stream = total, done, stream or sys.stderr
        self.tty, self.start, self.last = self.stream.isatty(), time.perf_counter(), 0.0
        self.first = done

    def begin(self, chunks: int, where: str, starting: bool = True) -> None:
        """The first line, at once; ``starting``: the run starts its workers now (not when it runs on
        workers started before, as the batches of --until do)."""
        noun = "chunk" if chunks == 1 else "chunks"
        self.stream.write(f"rss6 run: {self.total - self.done} realisations to compute in {chunks} {noun} "
                          f"on {where}" + (f" ({self.done} stored)" if self.done else "")
                          + ("; starting workers" if starting else "") + "\n")
        self.stream.flush()

    def compiling(self, kernels: list[str]) -> None:
        """Say, once per process (a command's batches share it), that the workers compile
        ``kernels`` before their first chunk (none: nothing said)."""
        if not kernels or _COMPILE_NOTED:
            return
        _COMPILE_NOTED.append(kernels)
        self.stream.write(f"rss6 run: {compile_note(kernels)}\n")
        self.stream.flush()

    def _eta(self, elapsed: float) -> str:
        computed = self.done - self.first
        if computed <= 0 or self.done >= self.total:
            return ""
        return f", about {elapsed / computed * (self.total - self.done):.0f} s left"

    def advance(self, n: int) -> None:
        self.done += n
        elapsed = time.perf_counter() - self.start
        frac = self.done / max(self.total, 1)
        if self.tty:
            bar = "#" * int(30 * frac)
            self.stream.write(f"\r[{bar:<30s}] {self.done}/{self.total} realisations, "
                              f"{elapsed:.1f} s{self._eta(elapsed)}   ")
            if self.done >= self.total:
                self.stream.write("\n")
        elif elapsed - self.last >= 2.0 or self.done >= self.total:
            self.last = elapsed
            self.stream.write(f"rss6 run: {self.done}/{self.total} realisations "
                              f"({100 * frac:.0f} %), {elapsed:.1f} s{self._eta(elapsed)}\n")
        self.stream.flush()


def _kernels_to_compile(client, model: str) -> list[str]:
    """The compiled kernels of ``model`` that any of the client's workers would compile first (each
    worker asked, from its own cache); none for levels without kernels, without asking, and none
    when a worker cannot answer (lost meanwhile: the run itself reports that)."""
    from rss6core import level_kernels, kernels_to_compile
    if not level_kernels(model):
        return []
    try:
        answers = client.run(kernels_to_compile, model)
    except (OSError, TimeoutError):
        return []
    return sorted({name for names in answers.values() for name in names})


def compile_apart(client, kernels: list[str], scheduler: str | None, interrupted: list) -> None:
    """On a local cluster where every worker would compile both contact kernels first, compile them
    once, one per worker at once (rss6core.compile_kernel), each worker then loading the other's
    from numba's on-disk cache: the first run waits for the longer compile instead of both, one
    after the other, in every worker.  Nothing on an external scheduler (its workers may not share
    a cache) or with fewer than two kernels or workers.  A Ctrl-C held in ``interrupted``
    (pipeline.files.writing.sigint_deferred) stops the wait between polls, never inside dask."""
    workers = sorted(client.scheduler_info()["workers"]) if not scheduler else []
    if len(kernels) < 2 or len(workers) < 2:
        return
    futures = [client.submit(_compile_one, name.rsplit(".", 1)[-1], workers=[worker], allow_other_workers=False,
                             pure=False) for name, worker in zip(kernels, workers)]
    while not all(f.done() for f in futures):
        if interrupted:
            client.cancel(futures)
            raise KeyboardInterrupt
        time.sleep(0.2)
    client.gather(futures)     # a compile's error, raised


def _compile_one(entry_point: str) -> float:
    """A worker's part of :func:`compile_apart`: one entry point, for the arguments of the embedded
    smoke scene's run (one overload serves every scene, tests/test_kernels.py)."""
    from rss6core import compile_kernel
    from ..scenes.catalogue import find_scene
    return compile_kernel(entry_point, find_scene("smoke"))
