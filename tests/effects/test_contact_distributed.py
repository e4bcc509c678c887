"""Contact and friction (the relations form) on the distributed mesh: each rank its part, the
contact surfaces gathered once, rows in input DOFs. Node-to-segment with friction, mortar
with friction (2D, a meshed foundation), 3D friction against a plane: the same results as the
1-rank run (1e-10 of each quantity, active rows and states exactly) and the known
resultants; the bad surfaces raised on every rank. The penalty and augmented-Lagrangian
baselines on the parts: the 1-rank run too."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from conftest import assert_same_results
from parsolve.contact.friction import SLIP, STICK
from parsolve.errors import InputError
from parsolve.model import build_model
from parsolve.scene import load_scene
from helpers.contact import BASE, FOUNDATION, OBLIQUE, PLANE, write_mesh
from helpers.scene import DROP, scene, shipped


def both_meshes(run, text: str, name: str) -> tuple[dict, dict]:
    """(results on the parts of every rank, results of each rank alone) of a scene."""
    parts = run(text, name=f"{name}_parts")
    whole = run(text, name=f"{name}_whole", comm=MPI.COMM_SELF)
    return parts, whole


@pytest.mark.parametrize("discretization", ["node_to_segment", "mortar"])
def test_foundation_friction_on_parts_is_the_one_rank_run(run, shared_tmp, discretization):
    """A block (8 elements, distorted) pressed by p = 10 on a meshed foundation (5 elements)
    and shifted: a master region, Coulomb friction (mu = 0.3). On the parts: the 1-rank
    run's fields, multipliers, states and active rows; the normal resultant p, the friction
    balancing the force that moves the top (1e-11), μN exactly once every node slides."""
    mesh = shared_tmp / "foundation_parts.msh"
    write_mesh(mesh, 5, 8, ny_up=4, seed=4)
    parts, whole = both_meshes(run, FOUNDATION.format(mesh=mesh, discretization=discretization),
                               f"foundation_{discretization}")
    assert_same_results(parts, whole)
    p, mu = 10.0, 0.3
    n_force = parts["relations/base_normal/normal_force"][:, 0]
    t_force = parts["relations/base_normal/tangential_force"][:, 0]
    np.testing.assert_allclose(n_force, p, rtol=1e-12)
    np.testing.assert_allclose(t_force, -parts["relations/shift/multiplier"].sum(axis=1),
                               rtol=1e-11)
    state = parts["fields/base_state"][:, :, 0]
    all_slide = np.all((state == SLIP) | (state < STICK), axis=1)   # every closed node slides
    assert all_slide[-1] and not all_slide[0]              # sticks first, slides at the end
    np.testing.assert_allclose(np.abs(t_force[all_slide]), mu * p, rtol=1e-10)


def test_oblique_pull_3d_on_parts_is_the_one_rank_run(run):
    """3D: a box pressed by p = 10 on a rough plane (mu = 0.3) and pulled along (2, 1)/√5
    up to 0.9 μp, partial slip with slip directions turned between iterations: on the parts
    the 1-rank run to 1e-10 (states and active rows exactly), the friction equal to the
    pull to 1e-10, the same iterations per step."""
    mu, p = 0.3, 10.0
    e = np.array([2.0, 1.0]) / np.sqrt(5.0)
    q = 0.9 * mu * p * e
    parts, whole = both_meshes(run, OBLIQUE.format(cell="hexahedron", E=1000.0, NU=0.3,
                                                   qx=q[0], qy=q[1]), "oblique")
    assert_same_results(parts, whole)
    assert np.array_equal(parts["steps/iterations"], whole["steps/iterations"])
    times = parts["steps/time"]
    np.testing.assert_allclose(parts["relations/base_normal/tangential_force"],
                               -np.outer(times, q), atol=1e-10 * p)
    np.testing.assert_allclose(parts["relations/base_normal/normal_force"][:, 0], p, rtol=1e-12)
    state = parts["fields/base_state"][-1, :, 0]
    assert np.any(state == SLIP) and np.any(state == STICK)          # partial slip


@pytest.mark.parametrize("formulation, extra", [
    ("penalty", {"penalty": 1e6}),
    ("augmented_lagrangian", {"augmentation_tolerance": 1e-9}),
])
def test_block_baselines_on_parts_are_the_one_rank_run(run, formulation, extra):
    """contact_block_friction.toml (p = 10 on a rough plane, μ = 0.3) with the penalty or the
    augmented-Lagrangian baseline, the top shifted by 0.005 in 3 steps (stick, then slip
    spreading from the trailing corner): on the parts the 1-rank run to 1e-10 (states
    exactly, the same steps and iterations); Σ Rn = p, the friction balancing the pull
    (1e-9) and under μN; the penalty's penetration is Rn / (ε A) (ε = 1e6, A = 1/8 at an inner
    node), the augmented Lagrangian's gap closed.

    (Not further: once the block slides, a slid node's committed friction sits on the cone,
    |t_tr| = μ p_N to round-off, and whether it sticks for one iteration, which adds
    iterations, varied from run to run at 2 and 3 ranks.)"""
    block = shipped("contact_block_friction.toml")
    (contact,) = block["contact"]
    assert contact["friction"] == 0.3 and block["steps"]["count"] == 10 and "nonlinear" not in block
    shift = [r | {"value": 0.005} if r["name"] == "shift" else r for r in block["relations"]]
    assert [r["value"] for r in block["relations"] if r["name"] == "shift"] == [0.02]
    # as test_contact_baselines: status cycles of the inner Newton cut some steps
    text = scene(block, contact=[contact | {"formulation": formulation} | extra], relations=shift,
                 steps={"count": 3}, output=DROP, nonlinear={"max_iterations": 15})
    parts, whole = both_meshes(run, text, f"block_{formulation}")
    assert_same_results(parts, whole)
    np.testing.assert_array_equal(parts["steps/iterations"], whole["steps/iterations"])
    rn = parts["fields/base_normal_reaction"][:, :, 0]
    rt = parts["fields/base_tangential_reaction"][:, :, 0]
    np.testing.assert_allclose(rn.sum(axis=1), 10.0, rtol=1e-10)
    pull = parts["relations/shift/multiplier"].sum(axis=1)
    np.testing.assert_allclose(rt.sum(axis=1), -pull, rtol=1e-9)
    assert np.all(np.abs(rt.sum(axis=1)) < 0.3 * 10.0)
    state = parts["fields/base_state"][:, :, 0]
    assert np.any(state == STICK) and np.any(state == SLIP)     # partial slip
    gap = parts["fields/base_gap"][:, :, 0]
    if formulation == "penalty":
        pts = parts["mesh/points"]
        inner = np.isclose(pts[:, 1], 0.0) & (pts[:, 0] > 1e-9) & (pts[:, 0] < 1 - 1e-9)
        closed = rn[:, inner] > 0
        assert closed.sum() > 12
        np.testing.assert_allclose(gap[:, inner][closed], -rn[:, inner][closed] / (1e6 / 8),
                                   rtol=1e-12)
    else:
        u = parts["fields/displacement"]
        assert -gap.min() < 1e-9 * np.abs(u).max()


@pytest.mark.parametrize("contact, key, words", [
    (f'slave = "middle"\n{PLANE}', "contact[0].slave", "boundary"),
    ('slave = "bottom"\nmaster = "bottom"', "contact[0].master", "share"),
    ('slave = "bottom"\nmaster = "middle"', "contact[0].master", "no boundary facet"),
    ('slave = "bottom"\nmaster = "top"', "contact[0].slave", "faces the master"),
    ('slave = "bottom"\nobstacle = { plane = { origin = [0.0, 0.0], normal = [0.0, 0.0] } }',
     "contact[0].obstacle.plane", "non-zero"),
])
def test_bad_surfaces_on_parts_raise_on_every_rank(shared_tmp, comm, contact, key, words):
    """A surface error found on the parts (some ranks hold none of the slave region) is the
    whole mesh's, raised on every rank."""
    text = BASE.format(contact=contact) + '\n[regions]\nmiddle = "abs(y - 0.25) < 1e-9"\n'
    path = shared_tmp / "bad_contact_parts.toml"
    if comm.rank == 0:
        path.write_text(text)
    comm.Barrier()
    scene = load_scene(path)
    with pytest.raises(InputError) as err:
        build_model(scene, comm)
    assert err.value.key == key and words in str(err.value) and str(path) in str(err.value)
