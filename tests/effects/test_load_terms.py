"""Constant loads as vector terms (``Term`` without a trial field): on every cell, on a
region's cells and on tuples of nodes, their load patterns (``loads.base.load_patterns``, the
one path every load takes) are their forces;
the owned rows of every rank together are the whole mesh's loads, assembled independently
node by node, on 1, 2 and 3 ranks."""

from __future__ import annotations

import tomllib

import numpy as np
from mpi4py import MPI

from helpers.saddle import SCENE

from parsolve.effects.base import Effect
from parsolve.loads.base import Instant, load_patterns
from parsolve.fem.element_matrices import NodeForces, Term
from parsolve.mesh.regions import allgather_rows
from parsolve.model import build_model
from parsolve.scene import parse_scene

COMM = MPI.COMM_WORLD
TEXT = SCENE.format(cell="quad", preset="direct", eliminate="false")


def centres(mesh) -> np.ndarray:
    return mesh.points[mesh.cells].mean(axis=1)


class Loads(Effect):
    """Three constant loads on the displacement: x_c (1, 2) at each node of every cell c,
    (0, 2) at each node of the cells left of x = 0.45, and (y, 1) at each node right of
    x = 0.7."""

    name = "loads"

    def __init__(self, mesh):
        self.mesh = mesh
        self.every = Term("u", None)
        self.region = Term("u", None, cells=np.flatnonzero(centres(mesh)[:, 0] < 0.45))
        self.nodes = Term("u", None, np.flatnonzero(mesh.points[:, 0] > 0.7))

    def terms(self) -> list[Term]:
        return [self.every, self.region, self.nodes]

    def term_values(self, term: Term, cells: np.ndarray):
        nen = self.mesh.cells.shape[1]
        if term is self.nodes:
            y = self.mesh.points[term.nodes[:, 0], 1]
            return NodeForces(term.nodes, np.stack([y, np.ones_like(y)], axis=1)[:, None, :])
        if term is self.region:
            return np.broadcast_to([0.0, 2.0], (len(cells), nen, 2)).copy()
        x = centres(self.mesh)[cells, 0]
        return x[:, None, None] * np.broadcast_to([1.0, 2.0], (len(cells), nen, 2))


def whole_loads(mesh) -> np.ndarray:
    """The same loads on the whole mesh (one process), node by node: (npoints, 2)."""
    out = np.zeros((mesh.num_points, 2))
    x = centres(mesh)[:, 0]
    for n in range(mesh.num_points):
        cells = np.flatnonzero(np.any(mesh.cells == n, axis=1))
        out[n] += x[cells].sum() * np.array([1.0, 2.0])
        out[n, 1] += 2.0 * np.count_nonzero(x[cells] < 0.45)
        if mesh.points[n, 0] > 0.7:
            out[n] += [mesh.points[n, 1], 1.0]
    return out


def model(comm):
    return build_model(parse_scene(tomllib.loads(TEXT), "t.toml", TEXT), comm)


def test_vector_terms_on_cells_a_region_and_nodes_are_the_known_loads():
    m = model(COMM)
    effect = Loads(m.mesh)
    local = m.mesh.partition().local_cells(COMM.rank, m.mesh.cells)
    patterns = load_patterns([effect], local, m.fields, m.mesh.num_points * 2)
    assert list(patterns) == ["loads"]   # the declarer's name: none of its terms names one
    loads = patterns["loads"].at(Instant(0.5)).reshape(-1, 2)
    owned = np.arange(m.mesh.n_owned)
    got = allgather_rows(COMM, np.column_stack([m.mesh.global_nodes[owned], loads[owned]]))
    got = got[np.argsort(got[:, 0])]

    whole = model(MPI.COMM_SELF).mesh
    expected = whole_loads(whole)[np.argsort(whole.global_nodes)]
    np.testing.assert_array_equal(got[:, 0], np.arange(whole.num_points))
    assert np.all(expected[:, 1] > 0)   # every node loaded
    np.testing.assert_allclose(got[:, 1:], expected, rtol=1e-13, atol=0)
