"""The node-pair pattern against the reference (one np.unique over every element pair, the
builder it replaced) and against a dense adjacency matrix, on every cell type, renumbered
nodes and the ownership ranges of 1, 2 and 3 ranks."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.la.pattern import NodePattern, node_pattern
from parsolve.mesh.generators import box, rectangle
from parsolve.mesh.partition import bisect, from_cell_parts


def reference_pattern(cells: np.ndarray, lo: int, hi: int, ncomp: int, nnodes: int) -> NodePattern:
    """The previous builder: sorts every (row node, column node) key of every element."""
    ct = np.ascontiguousarray(cells.T)
    nen, ncells = ct.shape
    rows = np.broadcast_to(ct[:, None, :], (nen, nen, ncells))
    cols = np.broadcast_to(ct[None, :, :], (nen, nen, ncells))
    own_row = (ct >= lo) & (ct < hi)
    own = np.broadcast_to(own_row[:, None, :], rows.shape)
    key = (rows[own] - lo).astype(np.int64) * nnodes + cols[own]
    ukey, inv = np.unique(key, return_inverse=True)
    urow = ukey // nnodes
    nown = hi - lo
    nb = np.bincount(urow, minlength=nown)
    bptr = np.concatenate([[0], np.cumsum(nb)])
    pair_slot = np.full((nen, nen, ncells), ukey.size, dtype=np.intp)
    pair_slot[own] = inv
    diag = np.searchsorted(ukey, np.arange(nown, dtype=np.int64) * nnodes + lo + np.arange(nown))
    return NodePattern(lo, nown, ncomp, nb, ukey % nnodes, pair_slot,
                       (np.minimum(diag, ukey.size - 1) - bptr[:-1]).astype(np.int64))


def reference_block_positions(p: NodePattern, row_start: np.ndarray) -> np.ndarray:
    nc = p.ncomp
    bptr = np.concatenate([[0], np.cumsum(p.nb)])
    row = np.repeat(np.arange(p.nown), p.nb)
    rank = np.arange(p.nnzb) - bptr[row]
    starts = row_start.reshape(-1, nc)[row].T
    return starts[:, None, :] + nc * rank[None, None, :] + np.arange(nc)[None, :, None]


MESHES = {
    "triangle": lambda: rectangle(1.0, 0.5, 7, 4, cell="triangle"),
    "triangle6": lambda: rectangle(1.0, 0.5, 5, 3, cell="triangle6"),
    "quad": lambda: rectangle(1.0, 0.5, 7, 4, cell="quad"),
    "tetra": lambda: box(1.0, 0.5, 0.5, 3, 2, 2, cell="tetra"),
    "tetra10": lambda: box(1.0, 0.5, 0.5, 2, 2, 1, cell="tetra10"),
    "hexahedron": lambda: box(1.0, 0.5, 0.5, 4, 3, 2, cell="hexahedron"),
}


def assert_same(new: NodePattern, ref: NodePattern) -> None:
    assert (new.lo, new.nown, new.ncomp) == (ref.lo, ref.nown, ref.ncomp)
    for name in ("nb", "ucol", "pair_slot", "diag_rank"):
        a, b = getattr(new, name), getattr(ref, name)
        if name in ("pair_slot", "ucol"):  # int32 below 2³¹: half the memory of the reference's
            assert a.dtype == np.int32, name
        else:
            assert a.dtype == b.dtype, name
        np.testing.assert_array_equal(a, b, err_msg=name)


def dense_check(p: NodePattern, cells: np.ndarray, nnodes: int) -> None:
    """Independent: node rows [lo, hi) of the boolean adjacency matrix of the cells."""
    adj = np.zeros((nnodes, nnodes), dtype=bool)
    nen = cells.shape[1]
    adj[np.repeat(cells, nen, axis=1).ravel(), np.tile(cells, nen).ravel()] = True
    rows = adj[p.lo:p.lo + p.nown]
    np.testing.assert_array_equal(p.nb, rows.sum(axis=1))
    np.testing.assert_array_equal(p.ucol, np.nonzero(rows)[1])   # row-major: sorted in a row
    bptr = np.concatenate([[0], np.cumsum(p.nb)])
    # every element pair of an owned row points at the entry holding its column
    ct = cells.T
    for i in range(nen):
        for j in range(nen):
            owned = (ct[i] >= p.lo) & (ct[i] < p.lo + p.nown)
            slot = p.pair_slot[i, j]
            np.testing.assert_array_equal(slot[~owned], p.nnzb)
            np.testing.assert_array_equal(p.ucol[slot[owned]], ct[j][owned])
            r = ct[i][owned] - p.lo
            assert np.all((slot[owned] >= bptr[r]) & (slot[owned] < bptr[r + 1]))
    has = p.nb > 0
    np.testing.assert_array_equal(p.ucol[bptr[:-1][has] + p.diag_rank[has]],
                                  np.arange(p.lo, p.lo + p.nown)[has])


@pytest.mark.parametrize("cell", list(MESHES))
@pytest.mark.parametrize("nparts", [1, 2, 3])
@pytest.mark.parametrize("shuffle", [False, True])
def test_pattern_matches_reference(cell, nparts, shuffle):
    mesh = MESHES[cell]()
    if shuffle:  # a random renumbering of the input nodes before partitioning
        perm = np.random.default_rng(nparts).permutation(mesh.num_points)
        mesh.points, mesh.cells = mesh.points[np.argsort(perm)], perm[mesh.cells]
    part = from_cell_parts(mesh, bisect(mesh.points[mesh.cells].mean(axis=1), nparts), nparts,
                           "bisection")
    ncomp = mesh.points.shape[1]
    for rank in range(nparts):
        cells = part.new_of_old[mesh.cells[part.local_cells(rank, mesh.cells)]]
        lo, hi = int(part.node_ranges[rank]), int(part.node_ranges[rank + 1])
        new = node_pattern(cells, lo, hi, ncomp, mesh.num_points)
        assert_same(new, reference_pattern(cells, lo, hi, ncomp, mesh.num_points))
        dense_check(new, cells, mesh.num_points)
        # any increasing row starts with room for the stiffness entries (relation columns after)
        extra = np.random.default_rng(rank).integers(0, 3, new.nown * ncomp)
        row_start = np.concatenate([[0], np.cumsum(new.row_nnz() + extra)])[:-1]
        got = new.block_positions(row_start)
        np.testing.assert_array_equal(got, reference_block_positions(new, row_start))
        assert got.dtype == np.int64
        starts = new.block_starts(row_start)
        np.testing.assert_array_equal(starts, got[:, 0])
        small = new.block_positions(row_start.astype(np.int32), dtype=np.int32)
        assert small.dtype == np.int32
        np.testing.assert_array_equal(small, got)


def test_rows_without_cells_and_repeated_nodes():
    # node 1 and node 5 (the last owned) are in no cell; the second cell repeats node 4
    cells = np.array([[0, 2, 3], [4, 4, 2], [3, 6, 0]])
    for lo, hi in [(0, 6), (1, 6), (2, 4), (5, 6), (0, 7)]:
        new = node_pattern(cells, lo, hi, 2, 7)
        assert_same(new, reference_pattern(cells, lo, hi, 2, 7))
    np.testing.assert_array_equal(node_pattern(cells, 0, 7, 2, 7).nb, [4, 0, 4, 4, 2, 0, 3])


def test_no_cells():
    cells = np.zeros((0, 3), dtype=np.int64)
    assert_same(node_pattern(cells, 0, 4, 2, 4), reference_pattern(cells, 0, 4, 2, 4))
