"""The ``rss6`` command line: the dispatcher. Each command lives in its own module of
:mod:`pipeline.commands` (its options and ``main(args) -> int``); here they are assembled into one
parser, and every user mistake (a bad option, file, scene or spec: :class:`UserError` or the core's
``SceneError``) becomes one line on stderr and exit code 2, in this one place."""
from __future__ import annotations

import argparse
import atexit
import json
import os
import re
import signal
import sys

from .commands.prepare_ahead import PREPARE_ENV
from .ensemble.cluster import start_worker_server, stop_worker_server

# the commands that run ensembles on a local cluster unless given --scheduler (those with --workers)
LOCAL_CLUSTER_COMMANDS = frozenset({"run", "report", "multifidelity", "sensitivity", "reliability", "budget",
                                    "allocate"})
# those of them for which --workers 1 means this process, no cluster
IN_PROCESS_AT_ONE_WORKER = frozenset({"reliability", "sensitivity"})


def commands() -> tuple:
    """The command modules, in the order ``rss6 -h`` lists them (imported here, not at the top: see
    :func:`main`)."""
    from .commands import (allocate, budget, check, map, multifidelity, plot, reliability, report, run, sensitivity,
                           simulate, stability, stats, tradeoff, warm)
    return (check, simulate, warm, run, report, stats, multifidelity, sensitivity, reliability, budget, allocate,
            plot, tradeoff, stability, map)


class _ParseError(Exception):
    """An argument error found by the parser ``prog`` (the top one or a command's), reported by the top parser,
    which holds the command line."""

    def __init__(self, prog: str, message: str):
        super().__init__(message)
        self.prog, self.message = prog, message


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (the option and the problem; ``-h`` gives the usage); an option
    the command does not take names the commands that take it, or this command's nearest options."""

    def error(self, message: str):
        raise _ParseError(self.prog, message)

    def parse_args(self, args=None, namespace=None):
        words = list(sys.argv[1:] if args is None else args)
        try:
            parsed, extras = self.parse_known_args(words, namespace)
        except _ParseError as e:
            _exit_with(e.prog, _with_negative_value_hint(e.message, words))
        if extras:
            command = getattr(parsed, "command", None)
            where = f"{self.prog} {command}" if command else self.prog
            hints = [hint for hint in (_option_hint(self, command, word) for word in extras) if hint]
            _exit_with(where, f"unrecognized arguments: {' '.join(extras)}" + "".join(f"; {hint}" for hint in hints))
        return parsed


def _exit_with(prog: str, message: str):
    print(f"{prog}: error: {message} (see {prog} -h)", file=sys.stderr)
    sys.exit(2)


def _with_negative_value_hint(message: str, words: list[str]) -> str:
    """argparse reads "-1e-6" as an option, not as the value it looks like: say how to write it."""
    missing = re.fullmatch(r"argument (\S+): expected one argument", message)
    value = _value_read_as_option(missing.group(1).split("/"), words) if missing else None
    if not value:
        return message
    option = missing.group(1).split("/")[-1]
    return message + f"; a value that starts with '-' ({value}) is read as an option: write {option}={value}"


def _value_read_as_option(names: list[str], words: list[str]) -> str | None:
    """The word after option ``names`` in ``words`` when it is a negative number (argparse took it for an
    option), else None."""
    for before, word in zip(words, words[1:]):
        if before in names and re.fullmatch(r"-(\d|\.\d)\S*", word):
            return word
    return None


def _option_hint(parser: argparse.ArgumentParser, command: str | None, word: str) -> str:
    """What to say of an argument ``command`` does not take: for an option, the other commands that
    take it, else the command's own options it is closest to; nothing for a value."""
    import difflib
    option = word.split("=", 1)[0]
    if not option.startswith("--") or command is None:
        return ""
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    takers = [name for name, sub in commands.items() if option in sub._option_string_actions]
    if takers:
        return f"{option} is an option of " + ", ".join(f"{parser.prog} {name}" for name in takers)
    own = [o for o in commands[command]._option_string_actions if o.startswith("--")]
    near = difflib.get_close_matches(option, own, n=2)
    return f"{command} has no {option}" + (f"; did you mean {' or '.join(near)}?" if near else "")


def build_parser() -> argparse.ArgumentParser:
    from rss6core import __version__

    from .scenes.catalogue import scene_names
    parser = _Parser(
        prog="rss6", description="Joint clearance and link elasticity errors of a 6-RSS robot.",
        epilog="shipped scenes (a CONFIG argument takes one of these names or a TOML file): "
               + ", ".join(scene_names()))
    parser.add_argument("--version", action="version", version=f"rss6 {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in commands():
        command.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """The ``rss6`` command (``argv`` None: this process's own arguments). A Ctrl-C that no command
    handled (during the imports, or in a command without its own account of what it kept) is one line
    and exit 130, not a traceback."""
    if argv is None:
        for stop in (signal.SIGTERM, signal.SIGHUP):
            signal.signal(stop, _stop_as_ctrl_c)
    try:
        return _main(argv)
    except KeyboardInterrupt:
        print("rss6: interrupted", file=sys.stderr)
        return 130


def command() -> None:
    """The ``rss6`` executable: :func:`main` on this process's arguments, then the end of the process
    (:func:`_end`)."""
    _end(main())


def _end(code: int) -> None:
    """End the process with ``code`` once the command is done: its exit handlers run (the workers'
    server stopped, dask's and multiprocessing's own), its output is flushed, and the interpreter's
    teardown of every imported module, a cost paid after every run (docs/performance.md section 34),
    is skipped; no thread but dask's daemon offload thread is left by then."""
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):   # a reader gone (rss6 stats F | head) or a stream closed
            pass
    os._exit(code)


def _stop_as_ctrl_c(signum, frame) -> None:
    """SIGTERM (a batch scheduler's or ``docker stop``'s) and SIGHUP (a closed terminal) end the command
    as Ctrl-C does: raised as SIGINT, so held where a file is written or dask is waited on, finished
    chunks kept, the output's lock removed, one line, exit 130."""
    signal.raise_signal(signal.SIGINT)


def _check_output_name(output) -> None:
    """OptionError for an -o path that is empty (a command's `args.output or DEFAULT` would take the default)
    or whose name starts or ends with whitespace (the netCDF library strips it, so the file would land
    beside the name rss6 renames and locks)."""
    from .vocabulary import OptionError
    if output is None:
        return
    if not str(output).strip():
        raise OptionError("-o: the path is empty; give a file or folder name, or leave -o out for the default")
    name = os.path.basename(str(output).rstrip("/")) or str(output)
    if name != name.strip():
        raise OptionError(f"-o {output!r}: the name starts or ends with whitespace, which the netCDF library "
                          "strips; give the name without it")


def _main(argv: list[str] | None) -> int:
    if argv is None:
        _start_workers_ahead(sys.argv[1:])
    from rss6core import SceneError

    from .vocabulary import UserError
    args = build_parser().parse_args(argv)
    try:
        _check_output_name(getattr(args, "output", None))
        return args.main(args)
    except (UserError, SceneError) as exc:
        print(f"rss6 {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader went away (rss6 stats F | head): stop quietly
        import os
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # Python's final flush must not fail again
        return 141


def _one_worker(argv: list[str]) -> bool:
    """Whether the command line says --workers 1 (or --workers=1)."""
    return "--workers=1" in argv or any(a == "--workers" and b == "1" for a, b in zip(argv, argv[1:]))


def _start_workers_ahead(argv: list[str]) -> None:
    """A command that will start a local cluster starts its workers' fork server first, so that the
    server's imports and this process's run side by side: docs/performance.md
    section 31. The server is stopped at exit, whether the command used it or stopped early."""
    if not argv or argv[0] not in LOCAL_CLUSTER_COMMANDS:
        return
    if any(a.startswith("--scheduler") or a in ("-h", "--help") for a in argv):
        return
    if argv[0] in IN_PROCESS_AT_ONE_WORKER and _one_worker(argv):
        return
    if argv[0] == "run":   # the server also prepares the run's level (pipeline/commands/prepare_ahead.py)
        start_worker_server(("pipeline.commands.prepare_ahead",), {PREPARE_ENV: json.dumps(argv[1:])})
    else:
        start_worker_server()
    atexit.register(stop_worker_server)


if __name__ == "__main__":
    command()
