"""Every shipped scene solved on the distributed mesh gives the replicated mesh's results (to
1e-10 of each quantity's size, active rows exactly), at any number of ranks; scenes whose
effects need the whole mesh run on the replicated one."""

import pytest

from conftest import CONFIGS, assert_same_results, run_scene
from parsolve.model import build_model, distributed_mesh
from parsolve.scene import load_scene

SHIPPED = sorted(p.name for p in CONFIGS.glob("*.toml"))
# past its peak the softening bar amplifies the round-off of a different summation order
TOLERANCE = {"localization_bar.toml": 1e-9}


def supported(name: str, comm) -> bool:
    scene = load_scene(CONFIGS / name)
    scene.solver.mesh = "distributed"
    return distributed_mesh(scene, comm)


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scene_same_on_the_distributed_mesh(name, shared_tmp, comm):
    if comm.size == 1:
        pytest.skip("one rank: the distributed mesh is the whole mesh")
    if not supported(name, comm):
        pytest.skip("an effect of this scene needs the whole mesh (see the next test)")
    replicated = run_scene(CONFIGS / name, shared_tmp / "replicated.h5", mesh="replicated")
    distributed = run_scene(CONFIGS / name, shared_tmp / "distributed.h5", mesh="distributed")
    assert_same_results(distributed, replicated, TOLERANCE.get(name, 1e-10))


@pytest.mark.parametrize("name", ["contact_block_friction.toml", "solubility_well_mixed.toml"])
def test_effects_that_need_the_whole_mesh_keep_it(name, comm):
    scene = load_scene(CONFIGS / name)
    scene.solver.mesh = "distributed"
    model = build_model(scene, comm)
    assert not model.distributed
    assert model.mesh.num_points == build_model(load_scene(CONFIGS / name)).mesh.num_points


def test_a_distributed_model_holds_its_part(comm):
    scene = load_scene(CONFIGS / "cantilever_3d.toml")
    scene.solver.mesh = "distributed"
    model = build_model(scene, comm)
    assert model.distributed == (comm.size > 1)
    if comm.size > 1:
        assert model.mesh.num_points < model.mesh.num_global_points
        assert model.mesh.num_cells < model.mesh.num_global_cells
