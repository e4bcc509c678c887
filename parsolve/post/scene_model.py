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


# effects whose state at t = 0 is not zero whatever the loads (a contact's initial gaps)
NOT_AT_REST = ("contact",)


def starts_from_rest(res: Result) -> bool:
    """Whether the run's state at t = 0 is the unloaded one, zero everywhere: a static scene
    (no [time]) whose loads, relation values and effects' evolutions are all 0 at t = 0, with
    no effect whose rest state is not zero (contact: its gaps). A file without its scene
    text, or whose scene no longer loads, is not known to be."""
    from parsolve.effects.registry import EFFECTS

    try:
        scene = scene_of(res, "--x")
    except InputError:
        return False
    if scene.time is not None or any(name in scene.effect_specs for name in NOT_AT_REST):
        return False
    names = [l.evolution for l in scene.loads] + [r.evolution for r in scene.relations]
    for name, specs in scene.effect_specs.items():
        names += [e for spec in specs for e, _ in EFFECTS[name].evolutions(spec)]
    return all(scene.evolutions[n](0.0) == 0.0 for n in names)
