"""A cell term on a region's cells (``Term.cells``): the system gives it its cells' slots, the
assembled operator holds it on those cells only, and its products are its element products
there; against a brute-force dense assembly, on 1, 2 and 3 ranks."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from conftest import stiffness_block
from helpers.saddle import SCENE
from helpers.terms import check_products

from parsolve.effects.base import Effect
from parsolve.fem import diffusion as kern
from parsolve.fem.element_matrices import ElementMatrices, Term
from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem

COMM = MPI.COMM_WORLD
K = 7.5   # the foundation's stiffness per unit area


class Foundation(Effect):
    """k ∫ u · v over the cells left of x = 0.45 (an elastic bed under part of the body)."""

    name = "foundation"

    def __init__(self, mesh):
        self.mesh = mesh
        centre = mesh.points[mesh.cells].mean(axis=1)[:, 0]
        self.term = Term("u", "u", cells=np.flatnonzero(centre < 0.45))

    def terms(self) -> list[Term]:
        return [self.term]

    def term_values(self, term: Term, cells: np.ndarray) -> ElementMatrices:
        m = K * kern.mass(self.mesh.points[self.mesh.cells[cells]], self.mesh.cell_type)[0]
        values = np.zeros((4,) + m.shape)
        values[0] = values[3] = m            # (x, x) and (y, y)
        return ElementMatrices(values=values)


def brute_foundation(model) -> np.ndarray:
    """Dense k ∫ u · v over the region (input numbering), cell by cell with np.add.at."""
    mesh = model.mesh
    n = mesh.num_points * 2
    out = np.zeros((n, n))
    f = Foundation(mesh)
    cells = f.term.cells
    m = K * kern.mass(mesh.points[mesh.cells[cells]], mesh.cell_type)[0]   # (nen, nen, nc)
    nodes = mesh.cells[cells].T                                             # (nen, nc)
    for c in range(2):
        rows, cols = np.broadcast_arrays(nodes[:, None, :] * 2 + c, nodes[None, :, :] * 2 + c)
        np.add.at(out, (rows.ravel(), cols.ravel()), m.ravel())
    return out


@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_a_cell_term_on_a_region(cell):
    text = SCENE.format(cell=cell, preset="direct", eliminate="false")

    def model():
        return build_model(parse_scene(tomllib.loads(text), "t.toml", text), COMM)

    bare = stiffness_block(COMM, SaddleSystem(COMM, model()))
    with_bed = model()
    with_bed.effects.append(Foundation(with_bed.mesh))
    system = SaddleSystem(COMM, with_bed)
    got = stiffness_block(COMM, system)
    whole = build_model(parse_scene(tomllib.loads(text), "t.toml", text))
    expected = brute_foundation(whole)
    assert np.abs(expected).max() > 0 and np.count_nonzero(expected.any(axis=1)) < len(expected)
    scale = np.abs(bare).max()
    np.testing.assert_allclose(got - bare, expected, rtol=0, atol=1e-12 * scale)
    # its slots are its cells' own: as many as the region holds of this rank's local cells
    term = with_bed.effects[-1].term
    local = np.isin(system.local_cells, term.cells).sum()
    assert term.slots.shape[2] == local

    # its products (the default evaluate, the composition's product) are K_bed q
    check_products(whole, Foundation(whole.mesh), expected, K)
