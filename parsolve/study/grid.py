"""A study's grid: one setting per (family, refinement level), each an effective scene."""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from parsolve.batch.scene_edit import effective_scene, read_scene, split_path
from parsolve.errors import InputError
from parsolve.study.config import Study


@dataclass
class Setting:
    name: str                 # run folder name
    family: str
    level: int                # index into study.levels
    label: str                # "×2" or the mesh file name
    changes: dict             # dotted path -> value, family's then refinement's
    scene_text: str


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "_", text).strip("_") or "run"


def _lookup(data: dict, path: str):
    node = data
    for part in split_path(path):
        node = node[part]
    return node


def expand(study: Study) -> list[Setting]:
    """Every (family, level) setting, families in order, levels coarse to fine. A path that the
    scene does not have, or an effective scene that does not validate, is an InputError naming
    the study file and the key."""
    from parsolve.scene import parse_scene

    base = read_scene(study.scene)
    for fam in study.families:
        _make_tables(base, fam.changes)
    out = []
    for i, fam in enumerate(study.families):
        for j, level in enumerate(study.levels):
            changes = dict(fam.changes)
            try:
                if study.refine_keys == ["mesh.file"]:
                    changes["mesh.file"] = level
                    label = Path(level).name
                else:
                    with_family = tomllib.loads(effective_scene(base, fam.changes, study.scene.parent))
                    for key in study.refine_keys:
                        try:
                            value = _lookup(with_family, key)
                        except (KeyError, IndexError, TypeError, ValueError):
                            raise InputError(f"{key!r} does not exist in the scene {study.scene}",
                                             study.source, "refine.keys") from None
                        if not isinstance(value, int) or isinstance(value, bool):
                            raise InputError(f"{key!r} is {value!r} in the scene, not an integer",
                                             study.source, "refine.keys")
                        changes[key] = value * level
                    label = f"x{level}"
                text = effective_scene(base, changes, study.scene.parent,
                                       header=f"study {study.source}: {fam.name}, level {label}")
            except (KeyError, ValueError) as exc:
                raise InputError(str(exc).strip("'\""), study.source, fam.key) from None
            _validate(text, study, fam.key, parse_scene)
            out.append(Setting(f"{i:02d}_{_slug(fam.name)}_{j:02d}", fam.name, j, label, changes, text))
    return out


def _make_tables(data: dict, changes: dict) -> None:
    """Create the missing tables on the way of a dotted path (``solver`` for ``solver.preset``
    when the base scene has no [solver]); the scene validation judges the key itself."""
    for path in changes:
        node = data
        parts = split_path(path)
        for part, nxt in zip(parts[:-1], parts[1:]):
            if isinstance(part, str) and isinstance(node, dict) and part not in node and isinstance(nxt, str):
                node[part] = {}
            try:
                node = node[part]
            except (KeyError, IndexError, TypeError):
                break


def _validate(text: str, study: Study, key: str, parse_scene) -> None:
    try:
        parse_scene(tomllib.loads(text), str(study.scene), text, study.scene.parent)
    except InputError as exc:
        raise InputError(f"the effective scene is invalid: {exc.oneline()}", study.source, key) from None
