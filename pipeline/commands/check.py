"""rss6 check: validate a scene and print its summary."""
from __future__ import annotations

import json

from ..analysis.summary import format_summary, scene_summary
from ..scenes.catalogue import find_scene
from .options import add_json, add_scene


def add_parser(sub) -> None:
    p = sub.add_parser("check", help="validate a scene and print its summary")
    add_scene(p)
    add_json(p, "print one JSON object")
    p.set_defaults(main=main)


def main(args) -> int:
    summary = scene_summary(find_scene(args.config))
    print(json.dumps(summary, indent=2) if args.json else format_summary(summary))
    return 0
