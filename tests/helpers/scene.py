"""Scene builder for tests: TOML scene text from nested Python data plus keyword overrides.

Instead of pasting a whole scene and varying it with ``text.replace("nx = 8", "nx = 16")``,
a test keeps the scene as data and states only what differs::

    scene(BASE, mesh={"nx": 16}, solver={"preset": "iterative"}, relations=[...])

Overrides deep-merge into tables (dicts) and replace everything else, arrays of tables included
(a test that changes one relation restates the list it means). ``DROP`` removes a key. The
base is never modified. ``base`` may be a parsed shipped config (``shipped("x.toml")``).
"""

from __future__ import annotations

import copy
import tomllib
from pathlib import Path

from parsolve.batch.toml_write import dumps

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


class _Drop:
    def __repr__(self) -> str:
        return "DROP"


DROP = _Drop()   # an override value that removes the key from the scene


def merge(base: dict, overrides: dict) -> dict:
    """A deep copy of ``base`` with ``overrides`` merged in: dict into dict recursively, any
    other value (lists, arrays of tables, scalars) replaces; ``DROP`` deletes the key."""
    out = copy.deepcopy(base)
    for key, new in overrides.items():
        if new is DROP:
            out.pop(key, None)
        elif isinstance(new, dict) and isinstance(out.get(key), dict):
            out[key] = merge(out[key], new)
        else:
            out[key] = copy.deepcopy(new)
    return out


def scene_data(base: dict | None = None, /, **overrides) -> dict:
    """The merged scene as data (what ``tomllib`` reads back from :func:`scene`)."""
    return merge(base or {}, overrides)


def scene(base: dict | None = None, /, **overrides) -> str:
    """The merged scene as TOML text (``tomllib.loads`` of it gives :func:`scene_data`)."""
    text = dumps(scene_data(base, **overrides))
    # the writer round-trips (compared as text, so that a nan value compares equal to itself)
    assert dumps(tomllib.loads(text)) == text, "scene data not representable in TOML"
    return text


def write_scene(path: Path, base: dict | None = None, /, **overrides) -> Path:
    """Write the merged scene to ``path`` and return it."""
    path.write_text(scene(base, **overrides), encoding="utf-8")
    return path


def shipped(name: str) -> dict:
    """A shipped config of configs/ parsed, to use as a base."""
    return tomllib.loads((CONFIGS / name).read_text(encoding="utf-8"))
