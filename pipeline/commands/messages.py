"""What a command says on stderr besides its result: a stop by Ctrl-C or a lost scheduler and what
it kept, too many local workers, kernels about to compile; and imports overlapped with start-up."""
from __future__ import annotations

import sys


AGAIN = "rerun the same command to continue"


def continue_line(kept: str, again: str = AGAIN) -> str:
    """What a stopped command kept (e.g. "finished chunks are kept in X.parts") and how it continues
    from it (``again``): one wording for Ctrl-C and a lost scheduler alike."""
    return f"{kept}; {again}"


def interrupted(kept: str | None, again: str = AGAIN) -> int:
    """Exit code 130 after Ctrl-C, with one line: :func:`continue_line` of what is kept, or, when
    nothing had finished (``kept`` None), that nothing is kept."""
    what = continue_line(kept, again) if kept else "nothing had finished, so nothing is kept"
    print(f"rss6: interrupted; {what}", file=sys.stderr)
    return 130


def scheduler_lost(command: str, exc, kept: str, resumable: bool = True) -> int:
    """Exit code 2 after the scheduler went away, with one line (``rss6 COMMAND: error: ...``, as every
    error of a command) and what was kept."""
    print(f"rss6 {command}: error: {exc}" + (f"; {continue_line(kept)}" if resumable else ""), file=sys.stderr)
    return 2


def warn_oversubscription(workers: int, scheduler: str | None) -> None:
    import os
    cores = os.cpu_count() or 1
    if not scheduler and workers > cores:
        print(f"rss6: warning: --workers {workers} exceeds the {cores} cores of this machine; the "
              "workers will share them and the run will not be faster", file=sys.stderr)


def note_compiling(model: str) -> None:
    """One line on stderr when this process is about to compile ``model``'s kernels."""
    from rss6core import kernels_to_compile
    cold = kernels_to_compile(model)
    if cold:
        from ..ensemble.progress import compile_note
        print(f"rss6 simulate: {compile_note(cold)}", file=sys.stderr, flush=True)


def import_meanwhile(*modules: str) -> None:
    """Import ``modules`` (needed only once the realisations are computed) in a thread, in order,
    while this one starts the workers and waits for them: the statistics' scipy.stats alone was a
    large share of a short run when imported first (docs/performance.md section 15b). An import that
    fails there is retried, and then reported, where the module is used."""
    import importlib
    import threading

    def load() -> None:
        for name in modules:
            try:
                importlib.import_module(name)
            except Exception:   # noqa: BLE001 (the caller's own import reports it)
                return
    threading.Thread(target=load, name="rss6-imports", daemon=True).start()


def note_loaded_joints(command: str, scene, model: str, specs=(),
                       robot: str = "the nominal robot at its nominal sizes") -> None:
    """Print on stderr the lines after a designer's answer at a level that places the joints inside their
    play rather than where the loads push them (:func:`pipeline.studies.loaded_joints.loaded_joints_note`)."""
    loaded_joints_meanwhile(command, scene, model, specs, robot)()


class LoadedJointsNote:
    """The loaded-joints lines of a command's answer, computed in a thread meanwhile (or none): ``lines()``
    for a --json answer, calling it prints them on stderr once the answer is out."""

    def __init__(self, command: str, future=None):
        self.command, self._future = command, future

    def lines(self) -> list[str]:
        return self._future.result() if self._future is not None else []

    def json(self) -> dict:
        """What a --json answer adds: {"notes": the lines}, or nothing when there are none."""
        return {"notes": self.lines()} if self.lines() else {}

    def __call__(self) -> None:
        for line in self.lines():
            print(f"rss6 {self.command}: {line}", file=sys.stderr)


def loaded_joints_meanwhile(command: str, scene, model: str, specs=(),
                            robot: str = "the nominal robot at its nominal sizes") -> LoadedJointsNote:
    """Start :func:`note_loaded_joints`'s computation in a thread and return the note: its quasi-static
    run (and the draw kernels' import) then overlaps the command's own work instead of following it
    (docs/performance.md section 36)."""
    from ..studies.loaded_joints import leaves_out_loaded_joints, loaded_joints_note
    if not leaves_out_loaded_joints(scene, model):
        return LoadedJointsNote(command)
    import concurrent.futures
    pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="rss6-note")
    note = pool.submit(loaded_joints_note, scene, model, specs, robot)
    pool.shutdown(wait=False)
    return LoadedJointsNote(command, note)
