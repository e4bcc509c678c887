"""The whole mesh checked, and its dual graph built, by every rank on one block of cells.

A run's rank 0 reads or generates the whole mesh; the cell checks (Jacobians,
cells folded over a neighbour, facets of three cells) and the dual graph PT-Scotch partitions
cost time and memory in proportion to the mesh, so rank 0 hands each rank a block of cells
(``partition.block_starts``, the block PT-Scotch takes anyway) with its nodes' coordinates, and
the ranks do that work together:

* Jacobians: per cell, on the block's own cells;
* facets: every block's cell facets are sent to the rank ``min corner id % size``, so that the
  copies of a facet meet on one rank, which groups them: a facet of three cells or more, two
  cells running through it the same way (a fold), or else a pair of neighbours, sent back to
  both cells' blocks as rows of the dual graph.

The graph is the cell dual graph (cells are neighbours when they share a facet, the same
corner nodes; boundary facets, the two sides of a crack and facets of three cells are not
edges), its rows in increasing order without self loops, and the error messages name the same
cells, at any rank count: a run does not depend on where this happened. This is the only
place the whole mesh's cells are checked and its graph built.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsolve.errors import InputError
from parsolve.mesh import checks, memory
from parsolve.mesh.mesh import CELL_INFO, Mesh
from parsolve.mesh.partition import block_starts
from parsolve.mesh.topology import (FACETS, NUM_VERTICES, _pack, _row_groups,
                                    _sorted_vertex_keys, sorted_row_groups)


@dataclass
class CellBlock:
    """Rank r's cells [start, start + cells.shape[0]) of the whole mesh (input node ids) and
    the coordinates of their nodes, (ncells, nodes per cell, dim)."""

    cells: np.ndarray
    coords: np.ndarray
    start: int
    num_cells: int        # of the whole mesh
    cell_type: str
    dim: int


@dataclass
class Vertices:
    """The dual graph's vertices when they are not the cells but aggregates of them: each
    block cell's vertex, numbered from 0 on every rank, and every rank's first (size + 1)."""

    of_cell: np.ndarray
    starts: np.ndarray


def _vertex_of(block: CellBlock, vertices: Vertices | None, cells: np.ndarray,
               rank: int) -> np.ndarray:
    """The graph's vertex of each of the block's ``cells`` (global ids): the cell itself, or
    its aggregate's global number."""
    if vertices is None:
        return cells
    return vertices.of_cell[cells - block.start].astype(np.int64) + vertices.starts[rank]


def scatter_blocks(comm, whole: Mesh | None) -> CellBlock:
    """Rank 0's whole mesh (None elsewhere) → every rank's block. Collective."""
    meta = comm.bcast((whole.num_cells, whole.cell_type, whole.dim, whole.cells.shape[1])
                      if comm.rank == 0 else None, root=0)
    n, cell_type, dim, nen = meta
    if comm.size == 1:   # the one block is the whole mesh: its cells taken as they are
        return CellBlock(np.asarray(whole.cells, dtype=np.int64), whole.points[whole.cells], 0, n,
                         cell_type, dim)
    starts = block_starts(n, comm.size)
    counts = np.diff(starts)
    mine = int(counts[comm.rank])
    cells = np.empty((mine, nen), dtype=np.int64)
    coords = np.empty((mine, nen, dim))
    send_cells = send_coords = None
    if comm.rank == 0:
        send_cells = (np.ascontiguousarray(whole.cells, dtype=np.int64), counts * nen)
    comm.Scatterv(send_cells, cells, root=0)
    # coordinates a block at a time from rank 0 (never the whole mesh's cell coordinates)
    if comm.rank == 0:
        coords[:] = whole.points[whole.cells[:mine]]
        for r in range(1, comm.size):
            comm.Send(np.ascontiguousarray(whole.points[whole.cells[starts[r]:starts[r + 1]]]),
                      dest=r, tag=71)
    else:
        comm.Recv(coords, source=0, tag=71)
    return CellBlock(cells, coords, int(starts[comm.rank]), n, cell_type, dim)


# ------------------------------------------------------------------ checks


def check_cells(comm, whole: Mesh | None, source: str | None, key: str | None,
                graph: bool = True) -> tuple[np.ndarray, np.ndarray] | None:
    """Rank 0's ``whole`` mesh (None elsewhere): its cells checked (Jacobians, folds, facets
    of three cells) by every rank on its block, and this rank's rows of the dual graph
    (``facet_groups``; ``graph`` False: the checks only). Collective."""
    block = scatter_blocks(comm, whole)
    check_jacobians(comm, block, source, key)
    block.coords = None   # (the facets need the cells only: the coordinates go before them)
    return facet_groups(comm, block, source, key, graph=graph)


def check_jacobians(comm, block: CellBlock, source: str | None, key: str | None) -> None:
    """Every cell positively oriented with det J clearly positive at every checked point
    (``checks.reference_points``), from the blocks; collective."""
    with np.errstate(all="ignore"):
        lo, hi, scale = checks.jacobian_range_of(block.coords, block.cell_type, block.dim)
        bad = ~(lo > checks.RELATIVE_JACOBIAN * scale)  # also NaN
    mine = np.flatnonzero(bad)
    gathered = comm.allgather((mine + block.start, lo[mine], hi[mine], scale[mine]))
    ids = np.concatenate([g[0] for g in gathered])
    if ids.size:
        lo, hi, scale = (np.concatenate([g[k] for g in gathered]) for k in (1, 2, 3))
        checks.raise_jacobians(ids, lo, hi, checks.RELATIVE_JACOBIAN * scale, block.cell_type,
                               source, key)


def facet_groups(comm, block: CellBlock, source: str | None, key: str | None,
                 graph: bool = True, vertices: Vertices | None = None
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """Check the facets of the whole mesh and return this block's rows of the dual graph as
    CSR (indptr, neighbour cell ids) (``graph`` False: the checks only, None returned: one
    rank partitions nothing; ``vertices``: the graph of these aggregates of cells instead,
    this rank's rows of its block of them, built without the cells' graph). Two positively
    oriented cells sharing a facet run through it in opposite directions; the same direction
    means one is folded over the other (an inverted cell in a file whose node order was
    flipped on reading, or a cell given twice). A facet
    of 3 cells or more is not a volume mesh. Collective.

    The block's facets are matched within the block first: most of a contiguous slice's
    facets are shared by two of its own cells, and those pairs are rows of this block's graph
    at once. Only one row per facet key crosses ranks, to the rank the key names: a single
    facet (its cell and direction, to be matched with another block's) or a count (a facet
    matched here, which another block's copy would make a facet of three cells)."""
    keys, forward = _facet_keys(comm, block)
    memory.release()   # (each step's freed arrays back to the system before the next's)
    order, counts = _sorted_runs(keys)
    memory.release()
    two = order[np.repeat(counts == 2, counts)]   # (masks of the facets' size: bytes)
    many = order[np.repeat(counts > 2, counts)]
    first = order[np.cumsum(counts) - counts] if comm.size > 1 else None   # a key's first
    del order
    folded = _cell_of(block, _folded_here(two, forward))
    if comm.size > 1:
        memory.release()
        cross, cross_folded, bad = _match_across(comm, keys, first, counts, block, forward,
                                                 vertices)
        memory.release()
        folded = np.concatenate([folded, cross_folded])
    else:
        cross, bad = np.zeros((0, 2), np.int64), keys[many]
    del forward, first, many, counts
    _raise_cells(comm, _cell_of(block, _rows_of_keys(keys, bad)), lambda cells: (
        f"a facet is shared by more than two cells (cells {checks._ids(cells)}): not a valid "
        "volume mesh"), source, key)
    del keys
    _raise_cells(comm, folded, lambda cells: (
        f"{cells.size} cells overlap a neighbour (inverted or folded over a shared facet): "
        f"cells {checks._ids(cells)}"), source, key)
    if not graph:
        return None
    return _graph_rows(comm, block, two, cross, vertices)


def _sorted_runs(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the order that sorts the rows of ``keys``, int32 while it fits; the lengths of the
    runs of equal rows in it): ``topology.sorted_row_groups`` without its group of every row,
    the sorted keys compared by chunks (the facets' largest arrays are the keys and the
    order)."""
    n = keys.shape[0]
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = np.argsort(keys[:, 0]) if keys.shape[1] == 1 else np.lexsort(keys.T[::-1])
    order = order.astype(np.int32 if n <= np.iinfo(np.int32).max else np.int64, copy=False)
    new = np.zeros(n, dtype=bool)
    new[0] = True
    for start in range(0, n - 1, CHUNK):
        ahead = keys[order[start:start + CHUNK + 1]]
        new[start + 1:start + ahead.shape[0]] = (ahead[1:] != ahead[:-1]).any(axis=1)
    return order, np.diff(np.append(np.flatnonzero(new), n)).astype(order.dtype, copy=False)


CHUNK = 1 << 16   # rows of the facets' arrays at a time


def _cell_of(block: CellBlock, rows: np.ndarray) -> np.ndarray:
    """The cell of each of the block's facets ``rows`` (facet-major: local facet, then cell)."""
    return rows.astype(np.int64) % max(block.cells.shape[0], 1) + block.start


def _facet_keys(comm, block: CellBlock) -> tuple[np.ndarray, np.ndarray]:
    """(every facet's sorted corners packed into as few int64 as fit, the same packing on
    every rank; its direction), facet-major (``_cell_of`` gives its cell). Built one local
    facet at a time: the corners of every facet at once (and their sorted copy) were the mesh
    stage's peak."""
    ftype = CELL_INFO[block.cell_type][1]
    nv = NUM_VERTICES[ftype]
    local = FACETS[block.cell_type]
    ncells = block.cells.shape[0]
    corners = sorted({int(i) for f in local for i in f[:nv]})
    top = int(block.cells[:, corners].max(initial=0)) if ncells else 0
    base = comm.allreduce(top) + 1   # the largest corner id of any facet
    width = _packed(np.zeros((1, nv), np.int64), base).shape[1]
    packed = np.empty((ncells * len(local), width), dtype=np.int64)
    forward = np.empty(ncells * len(local), dtype=bool)
    for k, f in enumerate(local):
        for start in range(0, ncells, CHUNK):   # (the temporaries of a chunk only)
            nodes = block.cells[start:start + CHUNK, list(f[:nv])]
            rows = slice(k * ncells + start, k * ncells + start + nodes.shape[0])
            forward[rows] = checks.facet_direction(nodes)
            packed[rows] = _packed(_sorted_vertex_keys(nodes, ftype), base)
    return packed, forward


def _folded_here(two, forward) -> np.ndarray:
    """The facets (rows) of this block's facets of exactly two copies here (``two``: their
    rows, pair by pair) that run through them the same way (folded over each other)."""
    fwd = forward[two].reshape(-1, 2)
    return two.reshape(-1, 2)[fwd[:, 0] == fwd[:, 1]].ravel()


def _match_across(comm, keys, first, counts, block: CellBlock, forward,
                  vertices: Vertices | None):
    """One row per facet key of this block to the rank the key names: (key, cell * 2 +
    direction, [its vertex]) for a facet single here, (key, -copies) for the others
    (``first``: each key's first facet, ``counts``: its copies). There: the keys of more than
    two copies in all (``bad``, every rank's), and the pairs of two singles — vertex pairs
    across blocks — and their folded cells. In rounds of at most ``ROUND_ROWS`` keys a rank (a
    round: the keys of one residue of key // size, so a facet's copies meet in the same round),
    each round's rows built when it comes: a round's rows, exchange and grouping, not the
    block's, are the transient."""
    size = comm.size
    rounds = max(comm.allreduce(-(-first.size // ROUND_ROWS), MPI.MAX), 1)
    turn = None
    if rounds > 1:
        turn = np.empty(first.size, dtype=np.int16 if rounds < 2**15 else np.int32)
        for start in range(0, first.size, CHUNK):
            turn[start:start + CHUNK] = keys[first[start:start + CHUNK], 0] // size % rounds
    found = []
    for k in range(rounds):
        sel = slice(None) if turn is None else np.flatnonzero(turn == k)
        rows = _round_rows(keys, first[sel], counts[sel], block, forward, vertices, comm.rank)
        found.append(_match_round(comm, rows, keys.shape[1]))
    del turn
    pairs, cells, fwd, bad = (np.concatenate(parts) for parts in zip(*found))
    bad = np.concatenate(comm.allgather(bad)) if comm.allreduce(bad.shape[0]) else bad
    return pairs, cells[fwd != 1].ravel(), bad


ROUND_ROWS = 1 << 15


def _round_rows(keys, first, counts, block: CellBlock, forward, vertices: Vertices | None,
                rank: int) -> np.ndarray:
    """A round's rows (``_match_across``): key columns, the code, and the vertex of a single's
    cell when the graph's vertices are aggregates."""
    cell = _cell_of(block, first)
    cols = [keys[first], np.where(counts == 1, cell * 2 + forward[first], -counts)[:, None]]
    if vertices is not None:
        cols.append(_vertex_of(block, vertices, cell, rank)[:, None])
    return np.hstack(cols)


def _match_round(comm, rows, width: int):
    """One round of ``_match_across``: (vertex pairs, cell pairs, their directions' sum, bad
    keys)."""
    got, _ = exchange(comm, rows, rows[:, 0] % comm.size)
    o, g, c = sorted_row_groups(got[:, :width])
    last = got[o, width]
    copies = np.bincount(g, weights=np.where(last >= 0, 1, -last), minlength=c.size)
    bad = got[o[copies[g] > 2], :width]
    two = (c[g] == 2) & (copies[g] == 2)
    cells = (last[two] >> 1).reshape(-1, 2)
    pairs = got[o[two], width + 1].reshape(-1, 2) if got.shape[1] > width + 1 else cells
    return pairs, cells, (last[two] & 1).reshape(-1, 2).sum(axis=1), bad


def _rows_of_keys(keys, bad) -> np.ndarray:
    """The facets (rows) of this block whose key is one of ``bad`` (every rank's alike)."""
    if bad.shape[0] == 0:
        return np.zeros(0, np.int64)
    g, _ = _row_groups(np.concatenate([keys, bad]))
    hit = np.zeros(g.max() + 1, dtype=bool)
    hit[g[keys.shape[0]:]] = True
    return np.flatnonzero(hit[g[:keys.shape[0]]])


def _graph_rows(comm, block: CellBlock, two, cross, vertices: Vertices | None
                ) -> tuple[np.ndarray, np.ndarray]:
    """This block's CSR rows from the pairs of facets matched here (``two``, pair by pair) and
    the vertex pairs across blocks (``cross``, sent to both vertices' blocks), sorted, without
    repeats (two cells sharing two facets, which only a folded mesh has; cells of one
    aggregate) or self loops. Built a chunk of pairs at a time, each chunk's keys made distinct
    at once: aggregates' rows repeat, and the cells' pairs as one array were the 4-rank
    peak."""
    size, rank = comm.size, comm.rank
    starts = vertices.starts if vertices is not None else block_starts(block.num_cells, size)
    n, first = max(int(starts[-1]), 1), int(starts[rank])
    keys = []
    for start in range(0, two.size, 2 * CHUNK):
        pair = _vertex_of(block, vertices, _cell_of(block, two[start:start + 2 * CHUNK]),
                          rank).reshape(-1, 2)
        pair = pair[pair[:, 0] != pair[:, 1]]   # (a collapsed cell seeing itself twice)
        keys.append(_distinct(np.concatenate([(pair[:, 0] - first) * n + pair[:, 1],
                                              (pair[:, 1] - first) * n + pair[:, 0]])))
    if size > 1:   # each pair across blocks to both vertices' blocks, that vertex first
        both = np.concatenate([cross, cross[:, ::-1]])
        got = exchange(comm, both, np.searchsorted(starts, both[:, 0], side="right") - 1)[0]
        keys.append(_distinct((got[:, 0] - first) * n + got[:, 1]))
        del both, got
    key = _distinct(np.concatenate(keys)) if keys else np.zeros(0, np.int64)
    del keys
    indptr = np.searchsorted(key, np.arange(int(starts[rank + 1]) - first + 1,
                                            dtype=np.int64) * n)
    key %= n
    return indptr.astype(np.int64), key


def _distinct(key: np.ndarray) -> np.ndarray:
    """``key`` sorted in place, without repeats."""
    key.sort()
    return key[np.r_[True, key[1:] != key[:-1]]] if key.size else key


def _packed(keys: np.ndarray, base: int) -> np.ndarray:
    """The rows of ``keys`` (ids < base) packed into as few int64 columns as fit, in the same
    lexicographic order."""
    width = keys.shape[1]
    fit = 1
    while fit < width and base ** (fit + 1) < 2**62:
        fit += 1
    return np.column_stack([_pack(keys, range(start, min(start + fit, width)), base)
                            for start in range(0, width, fit)])


def _raise_cells(comm, cells: np.ndarray, message, source, key) -> None:
    """InputError on every rank when any rank found such cells (named in increasing id)."""
    found = np.unique(np.concatenate(comm.allgather(np.unique(cells))))
    if found.size:
        raise InputError(message(found), source, key)


def rank_order(dest: np.ndarray, size: int) -> np.ndarray:
    """The stable order that sorts ``dest`` (ranks < size): a radix sort on 16-bit ranks, a
    few times faster than the merge sort numpy runs on 64-bit ones."""
    small = np.uint16 if size <= 2**16 else np.int64
    return np.argsort(dest.astype(small, copy=False), kind="stable")


def exchange(comm, rows: np.ndarray, dest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows (any dtype, 2D) sent to rank ``dest`` of each; returns (the rows received in
    (source rank, row order), how many from each rank). Two Alltoallv calls."""
    size = comm.size
    rows = np.asarray(rows)
    ordered = dest.size < 2 or bool(np.all(dest[1:] >= dest[:-1]))   # (1 rank: no copy)
    send = np.ascontiguousarray(rows if ordered else rows[rank_order(dest, size)])
    width = send.dtype.itemsize * (int(np.prod(send.shape[1:])) if send.ndim > 1 else 1)
    counts = np.bincount(dest, minlength=size).astype(np.int64) if dest.size \
        else np.zeros(size, np.int64)
    recv_counts = np.empty(size, dtype=np.int64)
    comm.Alltoall(counts, recv_counts)
    recv = np.empty((int(recv_counts.sum()),) + send.shape[1:], dtype=send.dtype)
    displ = lambda c: np.concatenate([[0], np.cumsum(c)[:-1]]) * width  # noqa: E731
    comm.Alltoallv([send.view(np.uint8), counts * width, displ(counts), MPI.BYTE],
                   [recv.view(np.uint8), recv_counts * width, displ(recv_counts), MPI.BYTE])
    return recv, recv_counts
