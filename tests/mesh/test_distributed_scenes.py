"""Scenes on the distributed mesh: which ones get it, and what a rank then holds. (Every
shipped scene is compared with the replicated mesh in ``test_partition``.)"""

import pytest

from conftest import CONFIGS
from parsolve.model import build_model
from parsolve.scene import load_scene

SOLUBILITY = sorted(p.name for p in CONFIGS.glob("solubility*.toml"))


@pytest.mark.parametrize("name", ["contact_block_friction.toml"])
def test_effects_that_need_the_whole_mesh_keep_it(name, comm):
    scene = load_scene(CONFIGS / name)
    scene.solver.mesh = "distributed"
    model = build_model(scene, comm)
    assert not model.distributed
    assert model.mesh.num_points == build_model(load_scene(CONFIGS / name)).mesh.num_points


def test_arc_length_gets_the_parts(comm):
    """Arc-length does not fall back: its arc and dot products are the system's (owned rows,
    summed over the ranks), so it runs on the parts (tests/solvers/test_distributed_arc_length)."""
    scene = load_scene(CONFIGS / "cantilever_3d.toml")
    scene.solver.mesh = "distributed"
    nl = scene.nonlinear
    nl.method, nl.arc_pattern, nl.arc_length = "arc_length", "end_load", 1e-3
    model = build_model(scene, comm)
    assert model.distributed == (comm.size > 1)
    assert model.reference_patterns == ("end_load",)


@pytest.mark.parametrize("name", SOLUBILITY)
def test_solubility_scenes_get_the_parts(name, comm):
    """Solubility runs on the parts (its relation is gathered from the owned nodes)."""
    scene = load_scene(CONFIGS / name)
    scene.solver.mesh = "distributed"
    model = build_model(scene, comm)
    assert model.distributed == (comm.size > 1)
    if comm.size > 1:
        assert model.mesh.num_points < model.mesh.num_global_points


def test_a_distributed_model_holds_its_part(comm):
    scene = load_scene(CONFIGS / "cantilever_3d.toml")
    scene.solver.mesh = "distributed"
    model = build_model(scene, comm)
    assert model.distributed == (comm.size > 1)
    if comm.size > 1:
        assert model.mesh.num_points < model.mesh.num_global_points
        assert model.mesh.num_cells < model.mesh.num_global_cells
