"""Scenes on the distributed mesh: what a rank holds, the relations whole on every rank as on
one rank alone. (Every shipped scene is compared across rank counts in ``test_partition``.)"""

import numpy as np
import pytest

from conftest import CONFIGS
from parsolve.model import build_model
from parsolve.scene import load_scene

def penalty_contact(path, formulation: str = "penalty"):
    """contact_block_friction.toml with a baseline (penalty by default) instead of relations."""
    text = (CONFIGS / "contact_block_friction.toml").read_text()
    path.write_text(text.replace("friction = 0.3",
                                 f'friction = 0.3\nformulation = "{formulation}"'))
    return path


@pytest.mark.parametrize("formulation", ["penalty", "augmented_lagrangian"])
def test_contact_baselines_get_the_parts(comm, shared_tmp, formulation):
    """Contact's penalty / augmented-Lagrangian baselines run on the parts too (no effect
    keeps the whole mesh): a rank holds its part and its own slave nodes' pairs (input ids);
    together they are the one-process pairing, with its tributary areas (per-node penalties)."""
    path = shared_tmp / f"{formulation}_contact.toml"
    if comm.rank == 0:
        penalty_contact(path, formulation)
    comm.Barrier()
    scene = load_scene(path)
    assert scene.effect_specs["contact"][0].formulation == formulation
    model = build_model(scene, comm)
    whole = build_model(load_scene(path))
    assert model.mesh.num_points < whole.mesh.num_points or comm.size == 1
    ours, theirs = model.effects[-1], whole.effects[-1]
    # each rank holds its own slaves' pairs: together, the one-process pairing, each pair once
    slave = np.concatenate(comm.allgather(np.asarray(ours.pairing.slave)))
    gap = np.concatenate(comm.allgather(np.asarray(ours.pairing.gap)))
    eps = np.concatenate(comm.allgather(np.asarray(ours.eps_n)))
    order = np.argsort(slave, kind="stable")
    np.testing.assert_array_equal(slave[order], theirs.pairing.slave)
    np.testing.assert_array_equal(gap[order], theirs.pairing.gap)
    np.testing.assert_allclose(eps[order], theirs.eps_n, rtol=1e-14)
    # Σ A_i: the bottom's length 1 (thickness 1): the areas are complete, each node once
    np.testing.assert_allclose(eps.sum(), ours.penalty, rtol=1e-12)


def test_relations_contact_gets_the_parts(comm):
    """Contact as relations (the paper's form) runs on the parts: the surfaces are gathered
    once; a relation is whole on every rank, or built per rank (the rigid obstacle's rows, on
    their slave node's owner), in input numbering: the one-process model's rows, DOFs and
    values, each row on every rank or on exactly one."""
    scene = load_scene(CONFIGS / "contact_block_friction.toml")
    model = build_model(scene, comm)
    whole = build_model(load_scene(CONFIGS / "contact_block_friction.toml"))
    assert model.mesh.num_points < whole.mesh.num_points or comm.size == 1
    ours = {r.name: r for r in model.relations}
    for r in whole.relations:
        mine = ours[r.name]
        ids = mine.row_ids()
        here = np.isin(r.a_rows, ids)
        assert np.array_equal(mine.a_dofs, r.a_dofs[here])
        np.testing.assert_array_equal(mine.a_vals, r.a_vals[here])
        np.testing.assert_array_equal(mine.values, r.values[ids])
        held = comm.allreduce(np.bincount(ids, minlength=r.nrows))
        assert np.all(held == (comm.size if mine.whole else 1)), (r.name, held)
    assert not ours["base_normal"].whole


def test_a_distributed_model_holds_its_part(comm):
    scene = load_scene(CONFIGS / "cantilever_3d.toml")
    model = build_model(scene, comm)
    if comm.size > 1:
        assert model.mesh.num_points < model.mesh.num_global_points
        assert model.mesh.num_cells < model.mesh.num_global_cells
