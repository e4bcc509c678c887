"""A small TOML writer for scene data (what ``tomllib`` reads back identically).

Python ships a TOML reader but no writer, and the stack is fixed: scenes hold only tables,
arrays of tables, strings, numbers, booleans and arrays of those, which is all this handles.
"""

from __future__ import annotations

import json
import math
import re

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def dumps(data: dict) -> str:
    lines: list[str] = []
    _table(data, [], lines)
    return "\n".join(lines).strip() + "\n"


def _key(name: str) -> str:
    return name if _BARE.match(name) else json.dumps(name, ensure_ascii=False)


def _is_tables(value) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def _table(data: dict, path: list[str], lines: list[str]) -> None:
    plain = {k: v for k, v in data.items() if not isinstance(v, dict) and not _is_tables(v)}
    for k, v in plain.items():
        lines.append(f"{_key(k)} = {value(v)}")
    for k, v in data.items():
        here = path + [_key(k)]
        if isinstance(v, dict):
            lines += ["", f"[{'.'.join(here)}]"]
            _table(v, here, lines)
        elif _is_tables(v):
            for item in v:
                lines += ["", f"[[{'.'.join(here)}]]"]
                _table(item, here, lines)


def value(v) -> str:
    """One value in TOML syntax (inline tables for dicts inside arrays)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} as TOML")
