"""The ``rss6`` command line: parse, build the work, print or write the result.

User mistakes (a bad scene file, a bad option) end with exit code 2 and one
line naming what is wrong; no traceback.
"""
from __future__ import annotations

import argparse
import json
import sys

from rss6core import SceneError, __version__, load_scene

from .summary import format_summary, scene_summary


def _check(args) -> int:
    summary = scene_summary(load_scene(args.config))
    print(json.dumps(summary, indent=2) if args.json else format_summary(summary))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rss6", description="Joint clearance and link elasticity errors of a 6-RSS robot.")
    parser.add_argument("--version", action="version", version=f"rss6 {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    check = sub.add_parser("check", help="validate a scene and print its summary")
    check.add_argument("config", nargs="?", default="paper",
                       help="scene TOML file or embedded scene name (default: paper)")
    check.add_argument("--json", action="store_true", help="print one JSON object")
    check.set_defaults(func=_check)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except SceneError as exc:
        print(f"rss6: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
