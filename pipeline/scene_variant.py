"""Scene variants made on the parsed TOML data: tomllib dict -> overridden dict -> TOML text.

Python 3.11 reads TOML but cannot write it; scenes are plain tables of strings,
numbers and lists of numbers, which :func:`dump_scene_toml` writes.  The
override is recorded as the text's first line, so an ensemble file's
``scene_toml`` attribute says which variant of which scene it holds.
"""
from __future__ import annotations

import json
import math
import tomllib

from rss6core import parse_scene

__all__ = ["dump_scene_toml", "scene_variant"]


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)             # a TOML basic string: JSON's escapes are TOML's
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"scene values are finite, got {v!r}")
        return repr(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise ValueError(f"a scene holds strings, numbers and lists of them, got {v!r}")


def dump_scene_toml(data: dict, header: str = "") -> str:
    """TOML text of a scene's data: top-level keys, then one [table] per nested dict."""
    lines = [f"# {line}" for line in header.splitlines()]
    lines += [f"{k} = {_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for table, values in data.items():
        if isinstance(values, dict):
            if any(isinstance(v, dict) for v in values.values()):
                raise ValueError(f"[{table}]: nested tables are not scene tables")
            lines += ["", f"[{table}]"] + [f"{k} = {_value(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"


def scene_variant(text: str, overrides: dict[str, dict], source: str = "<variant>", add: bool = False) -> str:
    """The scene ``text`` with ``overrides`` {table: {key: value}} set (keys must exist, unless
    ``add``: then a key the text leaves at its default may be set), as TOML text whose first line
    records the override; checked by parsing it as a scene."""
    data = tomllib.loads(text)
    for table, values in overrides.items():
        present = data.get(table)
        if not isinstance(present, dict):
            raise ValueError(f"{source}: no [{table}] table to override")
        missing = sorted(set(values) - set(present))
        if missing and not add:
            raise ValueError(f"{source}: [{table}] has no {', '.join(missing)} to set")
        present.update(values)
    note = "; ".join(f"[{t}] " + ", ".join(f"{k} = {v!r}" for k, v in vals.items())
                     for t, vals in overrides.items())
    out = dump_scene_toml(data, f"rss6 variant of {source}: {note}")
    parse_scene(out, source)
    return out
