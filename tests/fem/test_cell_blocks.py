"""Assembly and post-processing in cell blocks: the block size does not change the answer.

The same scene is assembled and post-processed with blocks of 7 cells and with one block of
every cell (2D triangles and quads, 3D hexahedra, two materials): the operator's values and
the cell and nodal stresses agree to 1e-14 of their scale (blocks only change the order in
which cells are summed into a node pair). On 1 and 2 ranks (each rank's own cells).
"""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

import parsolve.effects.elasticity as elasticity
import parsolve.fem.element_matrices as element_matrices
from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem

COMM = MPI.COMM_WORLD

MESHES = {
    "triangle": 'generator = "rectangle"\nlx = 2.0\nly = 1.0\nnx = 13\nny = 7\ncell = "triangle"',
    "quad": 'generator = "rectangle"\nlx = 2.0\nly = 1.0\nnx = 13\nny = 7\ncell = "quad"',
    "hexahedron": 'generator = "box"\nlx = 2.0\nly = 1.0\nlz = 1.0\nnx = 7\nny = 4\nnz = 3\n'
                  'cell = "hexahedron"',
}

SCENE = """
[mesh]
{mesh}
[model]
hypothesis = "{hypothesis}"
[regions]
stiff = "x < 0.9"
[[materials]]
E = 1.0
nu = 0.3
[[materials]]
region = "stiff"
E = 3.0
nu = 0.2
[[relations]]
name = "clamp"
type = "dirichlet"
region = "{left}"
components = {components}
"""


def scene(cell: str) -> str:
    three = cell == "hexahedron"
    return SCENE.format(mesh=MESHES[cell], hypothesis="3d" if three else "plane_strain",
                        left="xmin" if three else "left",
                        components='["x", "y", "z"]' if three else '["x", "y"]')


def assembled(cell: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(operator values, cell stresses, nodal stress sums, weights) of this rank."""
    text = scene(cell)
    model = build_model(parse_scene(tomllib.loads(text), "t.toml", text), COMM)
    system = SaddleSystem(COMM, model)
    system.assemble()
    mech = next(e for e in model.effects if e.name == "elasticity")
    x = model.mesh.points
    u = np.stack([np.sin(x[:, 0] + 2 * x[:, 1]), np.cos(3 * x[:, 0] * x[:, 1])]
                 + ([x[:, 2] ** 2 - x[:, 0]] if x.shape[1] == 3 else []), axis=1)
    nodal, cell = mech.outputs(system.local_cells, {"u": u}, None, system.local_cells)
    sums, weights = nodal["stress"]
    return system.op.data.copy(), cell["stress"], sums, weights


def close(a: np.ndarray, b: np.ndarray) -> None:
    scale = COMM.allreduce(float(np.abs(a).max(initial=0.0)), op=MPI.MAX)
    assert a.shape == b.shape
    assert np.abs(a - b).max(initial=0.0) <= 1e-14 * scale


@pytest.mark.parametrize("cell", list(MESHES))
def test_block_size_does_not_change_the_answer(cell, monkeypatch):
    whole = assembled(cell)          # the default budget: every cell of these meshes in one block
    monkeypatch.setattr(element_matrices, "block_cells", lambda *args: 7)
    monkeypatch.setattr(elasticity, "block_cells", lambda *args: 7)
    blocked = assembled(cell)
    ncells = COMM.allreduce(len(blocked[1]))
    assert ncells > 7 * 10   # many blocks
    for a, b in zip(whole, blocked):
        close(a, b)
    assert np.abs(whole[0]).max() > 0 and np.abs(whole[1]).max() > 0
