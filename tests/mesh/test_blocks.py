"""The whole mesh's cell checks and dual graph by blocks of cells (parsolve/mesh/blocks.py):
at any rank count, the rows of the graph one block (one process) gives and the same errors;
the graph's known numbers are in tests/mesh/test_partition.py, the errors' in test_checks.py."""

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.errors import InputError
from parsolve.mesh import blocks
from parsolve.mesh.generators import box, plate_with_hole, rectangle
from parsolve.mesh.mesh import Mesh
from parsolve.mesh.partition import block_starts
from parsolve.mesh.topology import FLIP, NUM_VERTICES

from helpers.cells import reference_cell

MESHES = {
    "quad": lambda: rectangle(1.0, 1.0, 30, 20, cell="quad"),
    "triangle6": lambda: rectangle(1.0, 1.0, 9, 7, cell="triangle6"),
    "tetra": lambda: box(1.0, 1.0, 1.0, 4, 3, 5, cell="tetra"),
    "tetra10": lambda: box(1.0, 1.0, 1.0, 3, 3, 2, cell="tetra10"),
    "hexahedron": lambda: box(1.0, 1.0, 1.0, 4, 3, 5),
    "plate": lambda: plate_with_hole(5.0, 5.0, 1.0, 8, 12, cell="triangle"),
}


def by_blocks(comm, mesh: Mesh):
    return blocks.check_cells(comm, mesh if comm.rank == 0 else None, "m.msh", "mesh.file")


@pytest.mark.parametrize("round_rows", [None, 7])
@pytest.mark.parametrize("name", sorted(MESHES))
def test_the_dual_graph_by_blocks_is_one_blocks(name, round_rows, comm, monkeypatch):
    """(``round_rows``: the facets matched across blocks in rounds of 7 rows a rank.)"""
    if round_rows:
        monkeypatch.setattr(blocks, "ROUND_ROWS", round_rows)
    mesh = MESHES[name]()
    ptr, idx = by_blocks(comm, mesh)
    indptr, indices = by_blocks(MPI.COMM_SELF, mesh)
    s = block_starts(mesh.num_cells, comm.size)[comm.rank:comm.rank + 2]
    assert np.array_equal(ptr, indptr[s[0]:s[1] + 1] - indptr[s[0]])
    assert np.array_equal(idx, indices[indptr[s[0]]:indptr[s[1]]])
    # and it is the dual graph: symmetric, no self loops or repeats, neighbours share a facet
    rows = np.repeat(np.arange(mesh.num_cells), np.diff(indptr))
    key = rows * mesh.num_cells + indices
    assert np.all(rows != indices) and np.all(np.diff(key) > 0)
    assert np.array_equal(np.sort(key), np.sort(indices * mesh.num_cells + rows))
    nv = NUM_VERTICES[{"quad": "line", "triangle6": "line3", "plate": "line"}.get(
        name, "triangle" if name.startswith("tetra") else "quad")]
    c = mesh.cells[:, :NUM_VERTICES[mesh.cell_type]]
    same = (c[rows][:, :, None] == c[indices][:, None, :]).any(axis=2).sum(axis=1)
    assert np.all(same == nv)


def _inverted(cell_type):
    m = reference_cell(cell_type)
    m.cells = m.cells[:, FLIP[cell_type]]
    return m


def _collapsed(cell_type):
    m = reference_cell(cell_type)
    m.points[:, -1] = 0.0
    return m


def _many():
    m = rectangle(1.0, 1.0, 4, 4, "quad")
    bad = [3, 5, 8, 9, 11, 14]
    m.cells[bad] = m.cells[bad][:, [0, 1, 3, 2]]
    return m


def _folded():
    """Two triangles on the same side of their shared edge, among good cells."""
    m = rectangle(1.0, 1.0, 3, 3, cell="triangle")
    a, b = m.cells[0][:2]
    pts = np.vstack([m.points, m.points[[a, b]].mean(axis=0) + [0.0, 0.2]])
    # the new cell (a, b, new) lies over cell 0 (above the edge a-b): folded over it
    cells = np.vstack([m.cells, [[a, b, pts.shape[0] - 1]]])
    return Mesh(pts, "triangle", cells)


def _three_on_a_facet():
    pts = np.array([[0, 0], [1, 0], [0.5, 1], [0.5, -1], [0.6, 2]], float)
    cells = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    return Mesh(pts, "triangle", cells)


# (name: the mesh, words of its error)
BAD = {f"inverted_{t}": (lambda t=t: _inverted(t)) for t in ("triangle", "quad", "tetra10", "hexahedron")}
BAD |= {"collapsed_tetra": lambda: _collapsed("tetra"), "many": _many, "folded": _folded,
        "three_on_a_facet": _three_on_a_facet}


@pytest.mark.parametrize("round_rows", [None, 2])
@pytest.mark.parametrize("name", sorted(BAD))
def test_the_errors_are_one_blocks(name, round_rows, comm, monkeypatch):
    if round_rows:
        monkeypatch.setattr(blocks, "ROUND_ROWS", round_rows)
    mesh = BAD[name]()
    with pytest.raises(InputError) as serial:
        by_blocks(MPI.COMM_SELF, mesh)
    with pytest.raises(InputError) as parallel:
        by_blocks(comm, mesh)
    assert str(parallel.value) == str(serial.value)
    assert WORDS[name.split("_")[0]] in str(parallel.value)


WORDS = {"inverted": "is inverted", "collapsed": "is collapsed", "many": "cells 3, 5, 8, 9, 11, ... (6 in all)",
         "folded": "overlap a neighbour", "three": "shared by more than two cells"}


def test_rank_order_is_the_stable_sort_of_the_ranks():
    rng = np.random.default_rng(3)
    for size in (1, 3, 70_000):
        dest = rng.integers(0, size, 5000)
        assert np.array_equal(blocks.rank_order(dest, size), np.argsort(dest, kind="stable"))


@pytest.mark.parametrize("base", [7, 2**20, 2**31 + 5])
def test_packed_keys_keep_equality_and_order(base):
    rng = np.random.default_rng(4)
    keys = rng.integers(0, base, (400, 3))
    keys[200:] = keys[:200]                     # every row twice
    keys[:50, 2] = base - 1                     # the largest id fits
    packed = blocks._packed(keys, base)
    assert packed.shape[1] == {7: 1, 2**20: 1, 2**31 + 5: 3}[base]
    # the same lexicographic order, and equal rows exactly where the keys are equal
    assert np.array_equal(np.lexsort(packed.T[::-1]), np.lexsort(keys.T[::-1]))
    _, inv_p = np.unique(packed, axis=0, return_inverse=True)
    _, inv_k = np.unique(keys, axis=0, return_inverse=True)
    assert np.array_equal(inv_p, inv_k)


def test_exchange_sends_each_row_to_its_rank(comm):
    """Rows of any dtype to the rank each names; received in (source rank, row order)."""
    size, rank = comm.size, comm.rank
    rows = np.array([[rank, k, 2 * k] for k in range(7)], dtype=np.int32)
    dest = (np.arange(7) * (rank + 1)) % size
    got, counts = blocks.exchange(comm, rows, dest)
    want = [[r, k, 2 * k] for r in range(size) for k in range(7) if (k * (r + 1)) % size == rank]
    assert got.dtype == np.int32 and np.array_equal(got, np.array(want, np.int32).reshape(-1, 3))
    assert counts.tolist() == [sum((k * (r + 1)) % size == rank for k in range(7))
                               for r in range(size)]
