"""Effective scenes: a base scene with some values replaced by dotted paths.

A path names any value of the scene: ``mesh.nx``, ``materials[0].E``, ``relations[2].value``,
``steps.count``. Every table or array entry on the way must exist in the base scene; the last
key may be new (an optional key the base leaves at its default, e.g. ``mesh.order``): the scene
validation that follows rejects it if the scene does not know it.
"""

from __future__ import annotations

import copy
import re
import tomllib
from pathlib import Path

from parsolve.batch.toml_write import dumps
from parsolve.errors import InputError

_NAME = r"[A-Za-z0-9_-]+"
_PATH = re.compile(rf"{_NAME}(\[\d+\])*(\.{_NAME}(\[\d+\])*)*")
_STEP = re.compile(rf"({_NAME})|\[(\d+)\]")


def split_path(path: str) -> list[str | int]:
    """``"materials[0].E"`` → ``["materials", 0, "E"]``; ValueError when malformed."""
    if not isinstance(path, str) or not _PATH.fullmatch(path):
        raise ValueError(f"malformed path {path!r} (expected e.g. mesh.nx or materials[0].E)")
    return [m.group(1) if m.group(1) is not None else int(m.group(2)) for m in _STEP.finditer(path)]


def set_path(data: dict, path: str, new) -> None:
    """Replace the value at ``path``; KeyError / IndexError / ValueError name what is missing."""
    parts = split_path(path)
    node = data
    for i, part in enumerate(parts[:-1]):
        node = _child(node, part, parts[: i + 1], path)
    last = parts[-1]
    if isinstance(last, int):
        if not isinstance(node, list) or last >= len(node):
            raise KeyError(f"{_show(parts)} does not exist in the scene")
        node[last] = new
    else:
        if not isinstance(node, dict):
            raise KeyError(f"{_show(parts[:-1])} is not a table")
        node[last] = new


def _child(node, part, done, path):
    if isinstance(part, int):
        if not isinstance(node, list) or part >= len(node):
            size = len(node) if isinstance(node, list) else 0
            raise KeyError(f"{_show(done)} does not exist in the scene ({size} entries)")
        return node[part]
    if not isinstance(node, dict) or part not in node:
        raise KeyError(f"{_show(done)} does not exist in the scene")
    return node[part]


def _show(parts) -> str:
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else p)
    return out


def read_scene(path: Path) -> dict:
    try:
        return tomllib.loads(Path(path).read_text())
    except OSError as exc:
        raise InputError(f"cannot read scene file ({exc.strerror})", str(path)) from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"invalid TOML: {exc}", str(path)) from None


def effective_scene(base: Path | str | dict, changes: dict, base_dir: Path | None = None,
                    relative_to: Path | None = None, header: str = "") -> str:
    """The TOML text of ``base`` (a scene file, or its parsed data) with ``changes``
    (dotted path → value) applied. A relative ``mesh.file`` becomes absolute: relative to the
    base scene's folder (``base_dir``) when it comes from the base, to ``relative_to`` (default:
    the same folder) when a change sets it. KeyError when a path does not exist."""
    if isinstance(base, dict):
        data = copy.deepcopy(base)
        folder = Path(base_dir or ".")
    else:
        data = read_scene(Path(base))
        folder = Path(base_dir or Path(base).parent)
    for path, new in changes.items():
        set_path(data, path, copy.deepcopy(new))
    mesh = data.get("mesh")
    if isinstance(mesh, dict) and isinstance(mesh.get("file"), str):
        changed = any(split_path(p)[:2] == ["mesh", "file"] for p in changes)
        origin = Path(relative_to or folder) if changed else folder
        mesh["file"] = str((origin / mesh["file"]).resolve())
    comment = "".join(f"# {line}\n" for line in header.splitlines())
    return comment + dumps(data)
