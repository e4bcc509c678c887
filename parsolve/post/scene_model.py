"""The scene stored in a result file (its ``scene`` attribute), rebuilt for post-processing."""

from __future__ import annotations

import tomllib

from parsolve.errors import InputError
from parsolve.mesh.regions import RegionResolver
from parsolve.post.result import Result


def scene_of(res: Result, key: str):
    from parsolve.scene import parse_scene

    text = res.attrs.get("scene", "")
    if not text:
        raise InputError("the file stores no scene text (attribute 'scene')", res.path, key)
    try:
        return parse_scene(tomllib.loads(text), res.path + ":scene", text)
    except InputError as exc:
        raise InputError(f"its scene no longer loads: {exc.oneline()}", res.path, key) from None


def model_of(res: Result, key: str):
    """The model (mesh, materials per cell) of the stored scene. A scene whose mesh file is
    relative is read relative to the current directory."""
    from parsolve.model import build_model

    model = build_model(scene_of(res, key))
    if model.mesh.num_points != len(res.points):
        raise InputError("the stored scene's mesh differs from the file's mesh", res.path, key)
    return model


def regions(res: Result, key: str) -> RegionResolver:
    from parsolve.model import build_mesh

    scene = scene_of(res, key)
    return RegionResolver(build_mesh(scene), scene.regions, res.path)
