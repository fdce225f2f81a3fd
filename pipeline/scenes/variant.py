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

__all__ = ["dump_scene_toml", "scene_variant", "uncertain_tables"]


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
    """TOML text of a scene's data: top-level keys, then one [table] per nested dict (sub-tables
    such as [tolerance.spherical_B] as dotted headers)."""
    lines = [f"# {line}" for line in header.splitlines()]
    lines += [f"{k} = {_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    return "\n".join(lines + _tables("", data)) + "\n"


def _tables(prefix: str, data: dict) -> list[str]:
    """The [prefix.name] tables of ``data``'s dict values, each followed by its own sub-tables."""
    lines = []
    for name, values in data.items():
        if isinstance(values, dict):
            plain = [f"{k} = {_value(v)}" for k, v in values.items() if not isinstance(v, dict)]
            if plain or not values:
                lines += ["", f"[{prefix}{name}]"] + plain
            lines += _tables(f"{prefix}{name}.", values)
    return lines


def scene_variant(text: str, overrides: dict[str, dict], source: str = "<variant>", add: bool = False,
                  drop: dict[str, list[str]] | None = None) -> str:
    """The scene ``text`` with ``overrides`` {table: {key: value}} set (keys must exist, unless
    ``add``: then a key the text leaves at its default may be set) and the sub-tables ``drop``
    {table: [name, ...]} removed where present, as TOML text whose first line records the change;
    checked by parsing it as a scene."""
    data = tomllib.loads(text)
    for table, values in overrides.items():
        present = data.get(table)
        if not isinstance(present, dict):
            raise ValueError(f"{source}: no [{table}] table to override")
        missing = sorted(set(values) - set(present))
        if missing and not add:
            raise ValueError(f"{source}: [{table}] has no {', '.join(missing)} to set")
        present.update(values)
    dropped = [f"[{t}.{n}]" for t, names in (drop or {}).items() for n in names
               if data.get(t, {}).pop(n, None) is not None]
    note = "; ".join([f"[{t}] " + ", ".join(f"{k} = {v!r}" for k, v in vals.items())
                      for t, vals in overrides.items()] + [f"without {', '.join(dropped)}"] * bool(dropped))
    out = dump_scene_toml(data, f"rss6 variant of {source}: {note}")
    parse_scene(out, source)
    return out


def uncertain_tables(scene) -> dict[str, list[str]]:
    """The scene's [uncertain.*] and [correlation.*] sub-tables as a ``drop`` of :func:`scene_variant`:
    dropping them holds every uncertain input at its nominal value (empty for a scene without any)."""
    tables = {"uncertain": [i.name for i in scene.uncertain.inputs],
              "correlation": [c.name for c in scene.uncertain.correlations]}
    return {k: names for k, names in tables.items() if names}
