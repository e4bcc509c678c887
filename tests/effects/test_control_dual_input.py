"""A control relation whose load pattern acts only on DOFs that Dirichlet relations hold:
refused before any solve (exit 2, file and key), not a MUMPS null pivot (exit 3)."""

from __future__ import annotations

import pytest
from mpi4py import MPI

from helpers.scene import scene, shipped
from parsolve.errors import InputError
from parsolve.model import build_model
from parsolve.scene import load_scene

BAR = shipped("controlled_bar.toml")
PULL = BAR["loads"][0]
assert len(BAR["loads"]) == 1 and PULL == {"name": "pull", "region": "right", "total_force": [1.0, 0.0]}


def _scene(folder, text):
    path = folder / "bar.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.barrier()
    return load_scene(path)


def test_pattern_on_held_dofs_only_is_refused(shared_tmp):
    # the pull moved onto the clamped edge: its x components are held by 'left_x'
    text = scene(BAR, loads=[PULL | {"region": "left"}])
    with pytest.raises(InputError) as exc:
        build_model(_scene(shared_tmp, text), MPI.COMM_WORLD)
    assert exc.value.key == "relations[2].dual"
    assert "'left_x'" in exc.value.message and "'pull'" in exc.value.message


def test_pattern_partly_on_held_dofs_is_accepted(shared_tmp):
    # a pull on the whole boundary: the held part is taken by reactions, the rest drives
    text = scene(BAR, loads=[{"name": "pull", "region": "all", "body": PULL["total_force"]}])
    model = build_model(_scene(shared_tmp, text), MPI.COMM_WORLD)
    assert any(r.shared_dual is not None for r in model.relations)
