"""Mortar contact through the contact effect (``discretization = "mortar"``): the patch test on
non-matching interfaces with randomly distorted meshes (which node-to-segment fails), with
linear (line) and quadratic (line3) facets; Coulomb friction of a block on a meshed rough
foundation; the bad inputs."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from helpers.contact import FOUNDATION, PATCH as CONTACT_PATCH, write_mesh  # noqa: F401
from parsolve.contact.friction import OPEN, SLIP, STICK
from parsolve.errors import InputError
from parsolve.model import build_model
from parsolve.scene import load_scene

def patch(mesh, traction: float, discretization: str) -> str:
    """The two-body patch scene of test_contact.py with the contact's discretization."""
    return CONTACT_PATCH.format(mesh=mesh, traction=traction,
                                extra=f'discretization = "{discretization}"')


def slave_weights(x: np.ndarray, quadratic: bool) -> np.ndarray:
    """∫φ_i ds of the slave nodes at abscissae x on the straight interface: half of each
    adjacent facet (line); a sixth at the ends, two thirds for the midside node (line3)."""
    order = np.argsort(x)
    xs = x[order]
    w = np.zeros_like(xs)
    if quadratic:                         # corners at even positions, midside nodes between
        length = xs[2::2] - xs[:-2:2]
        w[:-2:2] += length / 6
        w[2::2] += length / 6
        w[1::2] += 2 * length / 3
    else:
        length = np.diff(xs)
        w[:-1] += length / 2
        w[1:] += length / 2
    out = np.empty_like(w)
    out[order] = w
    return out


@pytest.mark.parametrize("nx_low, nx_up, cell", [(3, 5, "quad"), (5, 3, "quad"), (4, 7, "triangle"),
                                                 (3, 5, "triangle6")])
def test_mortar_patch_pressure_is_transmitted_exactly(run, shared_tmp, nx_low, nx_up, cell):
    """Non-matching, randomly distorted meshes on each side (no slave node on a master node
    but the ends): the uniform stress sigma_yy = -p is the discrete solution to round-off,
    every slave node carries p ∫φ_i (the multiplier of the normalised mortar row is a nodal
    force), the resultant is p per unit width, one iteration per step."""
    mesh = shared_tmp / f"mortar_{nx_low}_{nx_up}_{cell}.msh"
    write_mesh(mesh, nx_low, nx_up, cell)
    p = 10.0
    res = run(patch(mesh, -p, "mortar"),
              name=f"mortar_patch_{nx_low}_{nx_up}_{cell}")
    stress = res["fields/stress"][-1]
    np.testing.assert_allclose(stress[:, 1], -p, atol=1e-12 * p)
    np.testing.assert_allclose(stress[:, [0, 2]], 0.0, atol=1e-12 * p)
    state = res["fields/joint_state"][-1, :, 0]
    slave = np.flatnonzero(state >= 0)
    quadratic = cell == "triangle6"
    assert slave.size == nx_up * (2 if quadratic else 1) + 1 and np.all(state[slave] == STICK)
    x = res["mesh/points"][slave, 0]
    np.testing.assert_allclose(res["fields/joint_normal_reaction"][-1, slave, 0],
                               p * slave_weights(x, quadratic), rtol=1e-11)
    np.testing.assert_allclose(res["fields/joint_gap"][-1, slave, 0], 0.0, atol=1e-15)
    np.testing.assert_allclose(res["relations/joint_normal/normal_force"][:, 0], [p / 2, p],
                               rtol=1e-12)
    assert np.all(res["steps/iterations"] == 1)


def test_node_to_segment_fails_the_same_patch(run, shared_tmp):
    """The same distorted non-matching scene with node-to-segment rows: the stress is not
    uniform (what the mortar rows fix)."""
    mesh = shared_tmp / "nts_3_5.msh"
    write_mesh(mesh, 3, 5)
    p = 10.0
    res = run(patch(mesh, -p, "node_to_segment"),
              name="nts_patch_3_5")
    stress = res["fields/stress"][-1]
    assert np.abs(stress[:, 1] + p).max() > 1e-3 * p
    np.testing.assert_allclose(res["relations/joint_normal/normal_force"][:, 0], [p / 2, p],
                               rtol=1e-12)


@pytest.mark.parametrize("discretization", ["mortar", "node_to_segment"])
def test_block_on_meshed_rough_foundation(run, shared_tmp, discretization):
    """The block of configs/contact_block_friction.toml pressed on a deformable foundation
    meshed differently (5 against 8 elements, distorted): with mortar rows the frictional
    dual Dn − μ Dt·s works unchanged. Normal resultant p, the friction balances the force
    that moves the top, never above μN and μN exactly once every node slides, every node in
    its cone, no penetration, at most 3 iterations per step."""
    mesh = shared_tmp / "foundation_5_8.msh"
    write_mesh(mesh, 5, 8, ny_up=4, seed=4)
    res = run(FOUNDATION.format(mesh=mesh, discretization=discretization),
              name=f"foundation_{discretization}")
    p, mu, width = 10.0, 0.3, 1.0
    n_force = res["relations/base_normal/normal_force"][:, 0]
    t_force = res["relations/base_normal/tangential_force"][:, 0]
    np.testing.assert_allclose(n_force, p * width, rtol=1e-12)
    np.testing.assert_allclose(t_force, -res["relations/shift/multiplier"].sum(axis=1),
                               rtol=1e-11)
    assert np.all(np.abs(t_force) <= mu * n_force * (1 + 1e-10))
    state = res["fields/base_state"][:, :, 0]
    rn = res["fields/base_normal_reaction"][:, :, 0]
    rt = res["fields/base_tangential_reaction"][:, :, 0]
    assert np.all(mu * rn - np.abs(rt) >= -1e-10 * mu * rn.max())
    assert res["fields/base_gap"].min() >= -1e-12
    closed = state > OPEN
    sliding = np.array([np.all(s[c] == SLIP) for s, c in zip(state, closed)])
    assert not sliding[0] and sliding[-1]
    assert any(np.any(s == STICK) and np.any(s == SLIP) for s in state)   # partial slip
    np.testing.assert_allclose(np.abs(t_force[sliding]), mu * p * width, rtol=1e-12)
    assert np.all(np.abs(t_force[~sliding]) < mu * p * width)
    assert res["steps/iterations"].max() <= 3


BASE = """
[mesh]
generator = "{generator}"
lx = 1.0
ly = 0.5
nx = 2
ny = 2
{extra_mesh}
[model]
hypothesis = "{hypothesis}"
[[materials]]
E = 1000.0
nu = 0.3
[[contact]]
name = "base"
slave = "bottom"
{contact}
"""

PLANE = 'obstacle = { plane = { origin = [0.0, 0.0], normal = [0.0, 1.0] } }'
PLANE_3D = 'obstacle = { plane = { origin = [0.0, 0.0, 0.0], normal = [0.0, 0.0, 1.0] } }'
FLAT = {"generator": "rectangle", "extra_mesh": "", "hypothesis": "plane_strain"}
SOLID = {"generator": "box", "extra_mesh": "lz = 0.5\nnz = 2", "hypothesis": "3d"}


@pytest.mark.parametrize("contact, mesh, words", [
    ('master = "top"\ndiscretization = "segment"', FLAT, "one of"),
    (f'{PLANE}\ndiscretization = "mortar"', FLAT, "needs a master region"),
    (f'{PLANE_3D}\ndiscretization = "mortar"', SOLID, "needs a master region"),
])
def test_bad_mortar_input_names_file_and_key(shared_tmp, contact, mesh, words):
    text = BASE.format(contact=contact, **mesh)
    path = shared_tmp / "bad_mortar.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.Barrier()
    with pytest.raises(InputError) as err:
        build_model(load_scene(path))
    assert err.value.key == "contact[0].discretization" and words in str(err.value)
    assert str(path) in str(err.value)
