"""The ``rss6`` command line: the dispatcher. Each command lives in its own module of
:mod:`pipeline.commands` (its options and ``main(args) -> int``); here they are assembled into one
parser, and every user mistake (a bad option, file, scene or spec: :class:`UserError` or the core's
``SceneError``) becomes one line on stderr and exit code 2, in this one place."""
from __future__ import annotations

import argparse
import sys

from rss6core import SceneError, __version__

from .commands import (allocate, budget, check, map, multifidelity, plot, reliability, report, run, sensitivity,
                       simulate, stability, stats, tradeoff, warm)
from .scenes.catalogue import scene_names
from .vocabulary import UserError

COMMANDS = (check, simulate, warm, run, report, stats, multifidelity, sensitivity, reliability, budget, allocate, plot,
            tradeoff, stability, map)   # in the order ``rss6 -h`` lists them


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error (the option and the problem; ``-h`` gives the usage)."""

    def error(self, message: str):
        print(f"{self.prog}: error: {message} (see {self.prog} -h)", file=sys.stderr)
        sys.exit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="rss6", description="Joint clearance and link elasticity errors of a 6-RSS robot.",
        epilog="shipped scenes (a CONFIG argument takes one of these names or a TOML file): "
               + ", ".join(scene_names()))
    parser.add_argument("--version", action="version", version=f"rss6 {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.main(args)
    except (UserError, SceneError) as exc:
        print(f"rss6: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader went away (rss6 stats F | head): stop quietly
        import os
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # Python's final flush must not fail again
        return 141


if __name__ == "__main__":
    sys.exit(main())
