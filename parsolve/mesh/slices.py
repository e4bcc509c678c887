"""The distributed mesh built from slices: no rank reads, holds or partitions the whole mesh.

Every rank starts from a contiguous slice of the cells and of the points (rows
``partition.block_starts``) of a mesh source — the parallel mesh file (``h5mesh``) or a
generator building its slab (``generators.SLICED``), or either with midside nodes
(``midside.QuadraticSlices``) — its
**home** slice: a node's home is the rank whose point slice holds it. Then:

1. the coordinates of the slice cells' nodes are fetched from their homes (all-to-all), and the
   cells are checked and their block of the dual graph built as on the rank-0 path
   (``blocks.check_jacobians``, ``blocks.facet_groups``: the slice is the block);
2. PT-Scotch partitions the distributed graph (``partition.scotch_block``; from 4096 cells per
   part, the graph of aggregates of 16 cells: ``_vertices``); without it, or on
   request, the cells are cut along a space-filling curve (Morton order of the centroids, the
   cuts found by a distributed bisection of the keys: ``morton_parts``);
3. each node's owner (the lowest part among its cells) and global number (owners' blocks, input
   order inside a block) are decided at its home;
4. each cell goes to every rank owning one of its nodes (its owned and ghost cells: one ghost
   layer), each facet of a facet group to every rank owning one of its nodes, in one all-to-all;
   the nodes' coordinates, owners, numbers and node groups come from their homes.

The result is the ``distribute.LocalMesh`` the rank-0 path gives for the same cell partition
(same local numbering, same groups, same dtypes). ``LARGEST`` records the largest mesh array
(bytes) the path allocated on this rank, which a test holds against the whole mesh's size.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from mpi4py import MPI

from parsolve.collective import agree
from parsolve.errors import InputError
from parsolve.mesh import blocks, checks, memory, topology
from parsolve.mesh.blocks import exchange
from parsolve.mesh.distribute import COMPONENT_MARGIN, LocalMesh, index_dtype
from parsolve import progress
from parsolve.mesh.partition import MIN_CELLS_PER_PART, PARTITIONERS, block_starts, scotch_block

# the largest mesh array this rank allocated on the slice path (bytes); tests reset it
LARGEST = {"bytes": 0}
# PT-Scotch partitions aggregates of this many cells (``_vertices``) once a mesh has
# COARSE_MIN cells per part or more
AGGREGATE = 16
COARSE_MIN = 256 * AGGREGATE


def _note(*arrays: np.ndarray) -> None:
    LARGEST["bytes"] = max([LARGEST["bytes"]] + [a.nbytes for a in arrays])


class SliceSource(Protocol):
    """What the slice path reads: sizes, names, and slices of rows (see ``h5mesh.MeshFile``)."""

    path: str
    cell_type: str
    num_cells: int
    num_points: int
    dim: int
    cell_groups: tuple[str, ...]
    node_groups: tuple[str, ...]
    facet_groups: tuple[str, ...]

    def cells(self, start: int, stop: int) -> np.ndarray: ...
    def points(self, start: int, stop: int) -> np.ndarray: ...
    def cell_flags(self, start: int, stop: int) -> np.ndarray: ...
    def node_flags(self, start: int, stop: int) -> np.ndarray: ...
    def facet_slice(self, name: str, rank: int, size: int) -> tuple[np.ndarray, np.ndarray]: ...


# ------------------------------------------------------------------ all-to-all


def fetch(comm, ids: np.ndarray, starts: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Rows ``table[id - starts[home]]`` of each of ``ids`` from its home rank (the block of
    ``starts`` it falls in), in the order of ``ids``. Collective."""
    ids = np.asarray(ids, dtype=np.int64)
    home = np.searchsorted(starts, ids, side="right") - 1
    if ids.size < 2 or np.all(home[1:] >= home[:-1]):   # in rank order (1 rank): no copies
        asked, counts = exchange(comm, ids, home)
        return exchange(comm, table[asked - starts[comm.rank]],
                        np.repeat(np.arange(comm.size), counts))[0]
    order = blocks.rank_order(home, comm.size)
    asked, counts = exchange(comm, ids[order], home[order])
    reply = table[asked - starts[comm.rank]]
    back, _ = exchange(comm, reply, np.repeat(np.arange(comm.size), counts))
    out = np.empty_like(back)
    out[order] = back
    return out


class CellCoords:
    """The coordinates of a slice's cells' nodes, (ncells, nodes, dim) by blocks of cells as
    they are asked for (``checks.jacobian_range_of`` takes them a chunk at a time): the
    array itself would be 3 times the cells' (doubles, 2 or 3 per node)."""

    def __init__(self, node_points: np.ndarray, inverse: np.ndarray):
        self.node_points, self.inverse = node_points, inverse
        self.shape = inverse.shape + node_points.shape[1:]
        _note(node_points, inverse)

    def __getitem__(self, rows: slice) -> np.ndarray:
        return self.node_points[self.inverse[rows]]

    def centroids(self) -> np.ndarray:
        out = np.empty((self.shape[0], self.shape[2]))
        for start in range(0, self.shape[0], checks.JACOBIAN_CHUNK):
            stop = start + checks.JACOBIAN_CHUNK
            out[start:stop] = self[start:stop].mean(axis=1)
        return out

    def morton_order(self) -> np.ndarray:
        """The order of the cells along the Morton curve of their centroids' box, the
        centroids and their keys computed a chunk at a time (the centroids, their grid and
        its spread bits at once were 7 doubles a cell)."""
        chunks = range(0, self.shape[0], checks.JACOBIAN_CHUNK)
        dim = self.shape[2]
        lo, hi = np.full(dim, np.inf), np.full(dim, -np.inf)
        for start in chunks:
            c = self[start:start + checks.JACOBIAN_CHUNK].mean(axis=1)
            lo, hi = np.minimum(lo, c.min(axis=0)), np.maximum(hi, c.max(axis=0))
        key = np.empty(self.shape[0], dtype=np.uint64)
        for start in chunks:
            stop = start + checks.JACOBIAN_CHUNK
            key[start:stop] = morton_keys(self[start:stop].mean(axis=1), lo, hi)
        return np.argsort(key)


# ------------------------------------------------------------------ partition


# the bits of a number spread 2 or 3 apart by shifts and masks (Morton interleaving)
_SPREAD_STEPS = {
    2: [(16, 0x0000FFFF0000FFFF), (8, 0x00FF00FF00FF00FF), (4, 0x0F0F0F0F0F0F0F0F),
        (2, 0x3333333333333333), (1, 0x5555555555555555)],
    3: [(32, 0x001F00000000FFFF), (16, 0x001F0000FF0000FF), (8, 0x100F00F00F00F00F),
        (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)],
}


def _spread(v: np.ndarray, dim: int) -> np.ndarray:
    """The bits of v (uint64, < 2**(63 // dim)) spread ``dim`` apart (Morton interleaving):
    five shift-and-mask steps instead of a step per bit."""
    out = v.copy()
    for shift, mask in _SPREAD_STEPS.get(dim, []):
        out = (out | (out << np.uint64(shift))) & np.uint64(mask)
    return out


def morton_keys(centroids: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The place of each point along the Morton curve of the box [lo, hi] (uint64)."""
    dim = centroids.shape[1]
    bits = 63 // dim
    span = hi - lo   # 0 along a flat direction (a bar's cells on one line): no cut along it
    scale = np.where(span > 0, (2.0**bits - 1) / np.where(span > 0, span, 1.0), 0.0)
    grid = np.clip((centroids - lo) * scale, 0, 2.0**bits - 1).astype(np.uint64)
    key = np.zeros(centroids.shape[0], dtype=np.uint64)
    for a in range(dim):
        key |= _spread(grid[:, a], dim) << np.uint64(a)
    return key


def morton_parts(comm, centroids: np.ndarray) -> np.ndarray:
    """Parts of near-equal size along the Morton curve of the cells' centroids (this rank's
    cells; every rank its own): the cuts are the keys below which N·k/P cells fall, found by a
    bisection of the key range, all cuts at once, one allreduce per bit."""
    size = comm.size
    key = morton_keys(centroids, *bounds(comm, centroids))
    total = comm.allreduce(centroids.shape[0])
    target = np.array([total * k // size for k in range(1, size)], dtype=np.int64)
    low = np.zeros(size - 1, dtype=np.uint64)
    high = np.full(size - 1, np.uint64(2**63))
    key_sorted = np.sort(key)
    while np.any(high - low > 1):
        mid = low + (high - low) // np.uint64(2)
        below = comm.allreduce(np.searchsorted(key_sorted, mid).astype(np.int64))
        enough = below >= target
        high = np.where(enough, mid, high)
        low = np.where(enough, low, mid)
    cuts = np.where(comm.allreduce(np.searchsorted(key_sorted, low).astype(np.int64)) >= target,
                    low, high)
    return np.searchsorted(cuts, key, side="right").astype(np.int64)


def _vertices(comm, method: str, block: blocks.CellBlock, coords: CellCoords
              ) -> tuple[bool, blocks.Vertices | None]:
    """(whether PT-Scotch gets a graph, the aggregates that are its vertices or None for the
    cells). A mesh of at least ``COARSE_MIN`` cells per part is partitioned as the graph of its
    aggregates: each slice's cells in runs of ``AGGREGATE`` along the Morton curve of the
    slice (compact clumps of neighbours whatever the input order), two aggregates adjacent
    when two of their cells are. PT-Scotch's time goes with the graph's size; the parts keep
    within 1/AGGREGATE of a balanced cut (equal aggregates: uniform vertex weights stay right)
    and the edge cut within ~10 % of the cells' graph's (a 1.05M-tetrahedra box at 2 ranks:
    6825 facets against 6286, in 0.45 s of CPU against 1.1 s). The aggregates are decided
    before the facets, so that the graph is built on them directly (``blocks.facet_groups``):
    the cells' graph is never held."""
    size = comm.size
    if size == 1 or method != "scotch" or block.num_cells < MIN_CELLS_PER_PART * size:
        return False, None
    if block.num_cells < COARSE_MIN * size:
        return True, None
    order = coords.morton_order()
    n = order.size
    count = -(-n // AGGREGATE)
    starts = np.concatenate([[0], np.cumsum(comm.allgather(count))]).astype(np.int64)
    agg = np.empty(n, dtype=index_dtype(count))
    agg[order] = np.arange(n) // AGGREGATE
    return True, blocks.Vertices(agg, starts)


def _cell_parts(comm, block: blocks.CellBlock, coords: CellCoords, graph,
                vertices: blocks.Vertices | None) -> tuple[np.ndarray, str]:
    """(the part of each slice cell, the partitioner that ran): PT-Scotch's on ``graph`` (the
    rows of ``vertices``, or of the cells), else (no graph, no PT-Scotch, a part left empty)
    the Morton cuts of the centroids."""
    if comm.size == 1:
        return np.zeros(block.cells.shape[0], dtype=np.int64), "none"
    if graph is not None:
        total = block.num_cells if vertices is None else int(vertices.starts[-1])
        local = scotch_block(comm, total, *graph)
        if comm.allreduce(local is not None, MPI.LAND):
            local = local if vertices is None else local[vertices.of_cell]
            filled = comm.allreduce(np.bincount(local, minlength=comm.size), MPI.SUM)
            if filled.min() > 0:
                return local.astype(np.int64), "scotch"
    return morton_parts(comm, coords.centroids()), "bisection"


# ------------------------------------------------------------------ the path


@dataclass
class _Homes:
    """This rank's home slice of the nodes: owner, global number, groups, coordinates."""

    starts: np.ndarray
    table: np.ndarray     # (nhome, 2 + node groups + dim) int64: owner, new, flags, coord bits
    unused: np.ndarray    # input ids of home nodes no cell uses
    node_ranges: np.ndarray


def distribute_slices(comm, src: SliceSource, method: str, source: str, key: str) -> LocalMesh:
    """Every rank's ``LocalMesh`` from slices of ``src`` (see the module's doc). Collective;
    InputError on every rank for an invalid mesh."""
    if method not in PARTITIONERS:
        raise ValueError(f"unknown partitioner {method!r} (expected one of {PARTITIONERS})")
    size, rank = comm.size, comm.rank
    cs, ps = block_starts(src.num_cells, size), block_starts(src.num_points, size)
    with progress.phase("mesh read"):
        cells, points = agree(comm, _read_slice, src, cs, ps, rank, source, key)
        _note(cells, points)
        nodes, inverse = local_nodes(cells)
        coords = CellCoords(fetch(comm, nodes, ps, points), inverse)
    block = blocks.CellBlock(cells, coords, int(cs[rank]), src.num_cells, src.cell_type, src.dim)
    # (memory.release between the phases: each phase's freed arrays back to the system)
    progress.timed("checks", blocks.check_jacobians, comm, block, source, key)
    with progress.phase("partition"):
        memory.release()
        scotch, vertices = _vertices(comm, method, block, coords)
        memory.release()
        graph = blocks.facet_groups(comm, block, source, key, graph=scotch, vertices=vertices)
        memory.release()
        part, used = _cell_parts(comm, block, coords, graph, vertices)
        block.coords = coords = None
        del graph, vertices
        homes = _homes(comm, src, nodes, inverse, part, ps, points, rank)
        memory.release()
        mine = _cells_to_owners(comm, src, cells, nodes, inverse.ravel(), homes, cs[rank])
        del cells, part, nodes, inverse
        memory.release()
        mesh = _local_mesh(comm, src, mine, homes, source, key)
        del mine
        memory.release()
    mesh.partitioner = used
    mesh.extent = _extent(comm, points, src.dim)
    warnings = _unused_warning(comm, homes.unused) + _duplicate_warning(comm, points, homes, ps)
    mesh.warnings = [f"{source}: {key}: {w}" for w in warnings]
    return mesh


def local_nodes(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the sorted distinct nodes of ``cells``, each entry's position among them: int32 while
    it fits). A sort of a copy and a search, not ``np.unique``'s inverse (its permutation,
    sorted copy and inverse: 3 more int64 per entry, the mesh read's peak)."""
    nodes = np.unique(cells)
    inverse = np.empty(cells.shape, dtype=index_dtype(nodes.size))
    for start in range(0, cells.shape[0], checks.JACOBIAN_CHUNK):
        stop = start + checks.JACOBIAN_CHUNK
        inverse[start:stop] = np.searchsorted(nodes, cells[start:stop])
    return nodes, inverse


def _read_slice(src: SliceSource, cs, ps, rank: int, source: str, key: str):
    cells = src.cells(int(cs[rank]), int(cs[rank + 1]))
    if cells.size and (cells.min() < 0 or cells.max() >= src.num_points):
        raise InputError("cells refer to points that do not exist", source, key)
    points = src.points(int(ps[rank]), int(ps[rank + 1]))
    finite = np.isfinite(points).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite) + ps[rank]
        raise InputError(f"{bad.size} point(s) have non-finite coordinates (NaN or inf): "
                         f"points {checks._ids(bad)}", source, key)
    huge = np.abs(points).max(axis=1, initial=0.0) > checks.MAX_COORDINATE
    if huge.any():
        bad = np.flatnonzero(huge) + ps[rank]
        raise InputError(f"{bad.size} point(s) have absurd coordinates (beyond "
                         f"{checks.MAX_COORDINATE:g}): points {checks._ids(bad)}", source, key)
    return cells, points


def _homes(comm, src: SliceSource, nodes, inverse, part, ps, points, rank: int) -> _Homes:
    """Owners (lowest part among a node's cells; nodes of no cell: the last rank) and global
    numbers (owners' blocks, input order inside) of this rank's home nodes (``nodes``,
    ``inverse``: the slice's, ``local_nodes``)."""
    size = comm.size
    kind = index_dtype(max(nodes.size, 1), size)   # (local node, part) keys in int32 if they fit
    pairs = np.unique(inverse.astype(kind) * kind.type(size) + part.astype(kind)[:, None]) \
        if inverse.size else np.zeros(0, kind)
    local, owner_of = np.divmod(pairs.astype(np.int64), size)
    node = nodes[local]
    del pairs, local
    got, _ = exchange(comm, np.column_stack([node, owner_of]),
                      np.searchsorted(ps, node, side="right") - 1)
    nhome = int(ps[rank + 1] - ps[rank])
    owner = np.full(nhome, size, dtype=np.int64)
    if got.size:   # the lowest part per node: sorted by (node, part), the first of each node
        got = got[np.lexsort((got[:, 1], got[:, 0]))]
        first = np.r_[True, got[1:, 0] != got[:-1, 0]]
        owner[got[first, 0] - ps[rank]] = got[first, 1]
    unused = np.flatnonzero(owner == size) + ps[rank]
    owner[owner == size] = size - 1
    counts = np.array(comm.allgather(np.bincount(owner, minlength=size)), dtype=np.int64)
    node_ranges = np.concatenate([[0], np.cumsum(counts.sum(axis=0))])
    offset = node_ranges[:-1] + counts[:rank].sum(axis=0)
    order = np.argsort(owner, kind="stable")
    first_of = np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=size))[:-1]])
    new = np.empty(nhome, dtype=np.int64)
    new[order] = offset[owner[order]] + np.arange(nhome) - first_of[owner[order]]
    flags = src.node_flags(int(ps[rank]), int(ps[rank + 1])).astype(np.int64)
    table = np.column_stack([owner, new, flags, points.view(np.int64).reshape(nhome, src.dim)])
    _note(table)
    return _Homes(ps, table, unused, node_ranges)


def _cells_to_owners(comm, src: SliceSource, cells, nodes, inverse, homes: _Homes,
                     start: int) -> np.ndarray:
    """The rows (input id, nodes, cell groups) of every cell of the ghost layer of this rank,
    received from the slices: each cell goes to every rank owning one of its nodes."""
    size = comm.size
    owner = fetch(comm, nodes, homes.starts, homes.table[:, :1])[:, 0] \
        .astype(index_dtype(size))[inverse].reshape(cells.shape)
    ncells = cells.shape[0]
    owner.sort(axis=1)   # each cell's distinct owners: the first of each run of its row
    first = np.ones(owner.shape, dtype=bool)
    first[:, 1:] = owner[:, 1:] != owner[:, :-1]
    cell, col = np.nonzero(first)   # (by cell, then rank)
    dest = owner[cell, col]
    del owner, first, col
    if size > 1:   # the rows built in rank order: the exchange sends them without a copy
        by_rank = blocks.rank_order(dest, size)
        cell, dest = cell[by_rank], dest[by_rank]
        del by_rank
    flags = src.cell_flags(start, start + ncells)
    # int32 while the ids fit: a cell of the ghost layer travels (and lands) in half the bytes
    kind = index_dtype(max(src.num_cells, src.num_points))
    rows = np.empty((cell.size, 1 + cells.shape[1] + flags.shape[1]), dtype=kind)
    rows[:, 0] = cell + start
    rows[:, 1:1 + cells.shape[1]] = cells[cell]
    rows[:, 1 + cells.shape[1]:] = flags[cell]
    _note(rows)
    del cell
    got, _ = exchange(comm, rows, dest)
    del rows, dest
    _note(got)
    if got.shape[0] < 2 or np.all(got[1:, 0] >= got[:-1, 0]):   # (1 rank: in order)
        return got
    return got[np.argsort(got[:, 0], kind="stable")]


def _local_mesh(comm, src: SliceSource, mine: np.ndarray, homes: _Homes, source: str,
                key: str) -> LocalMesh:
    """This rank's ``LocalMesh`` from its cells' rows (sorted by input id)."""
    size, rank, dim = comm.size, comm.rank, src.dim
    nen = mine.shape[1] - 1 - len(src.cell_groups)
    gcells = mine[:, 1:1 + nen]
    ids = np.unique(gcells)   # (in the rows' dtype: int32 while the ids fit)
    if rank == size - 1 and homes.unused.size:   # nodes of no cell
        ids = np.union1d(ids, homes.unused)
    info = fetch(comm, ids, homes.starts, homes.table)
    owner, new = info[:, 0], info[:, 1]
    owned = np.flatnonzero(owner == rank)
    ghosts = np.flatnonzero(owner != rank)
    ghosts = ghosts[np.argsort(new[ghosts], kind="stable")]
    local = np.concatenate([owned, ghosts])     # positions in ids, in local order
    node_type = index_dtype(src.num_points, COMPONENT_MARGIN)
    local_type = index_dtype(local.size, COMPONENT_MARGIN)
    to_local = np.empty(ids.size, dtype=local_type)
    to_local[local] = np.arange(local.size)
    ngroups = len(src.node_groups)
    flags = info[local, 2:2 + ngroups].astype(bool)
    points = np.ascontiguousarray(info[local, 2 + ngroups:]).view(float).reshape(-1, dim)
    global_nodes = ids[local]
    cells = np.empty(gcells.shape, dtype=local_type)
    for start in range(0, cells.shape[0], checks.JACOBIAN_CHUNK):   # (no int64 of them all)
        stop = start + checks.JACOBIAN_CHUNK
        cells[start:stop] = to_local[np.searchsorted(ids, gcells[start:stop])]
    _note(points, cells)
    cflags = mine[:, 1 + nen:].astype(bool)
    nlocal = mine.shape[0]
    by_id = np.argsort(global_nodes, kind="stable")
    mesh = LocalMesh(
        points=points, cell_type=src.cell_type, cells=cells,
        cell_groups={n: np.flatnonzero(cflags[:, k]).astype(index_dtype(nlocal))
                     for k, n in enumerate(src.cell_groups)},
        node_groups={n: by_id[flags[by_id, k]].astype(local_type)
                     for k, n in enumerate(src.node_groups)},
        facet_groups=_facet_groups(comm, src, ids, to_local, owned.size, homes, source),
        global_nodes=global_nodes.astype(node_type),
        global_cells=mine[:, 0].astype(index_dtype(src.num_cells)),
        node_new=new[local].astype(node_type), node_ranges=homes.node_ranges,
        num_global_points=src.num_points, num_global_cells=src.num_cells, rank=rank)
    return mesh


def _facet_groups(comm, src: SliceSource, ids, to_local, n_owned: int, homes: _Homes,
                  source: str) -> dict:
    """Each facet group's facets with an owned node, all nodes local, in the group's order:
    every rank reads a slice of each group's rows and sends each facet to its nodes' owners."""
    size, rank = comm.size, comm.rank
    nfn = len(_facet_shape(src.cell_type))
    parts = []
    for g, name in enumerate(src.facet_groups):
        facets, order = agree(comm, _facet_rows, src, name, rank, size, source)
        parts.append(np.column_stack([np.full(len(facets), g), order, facets]))
    rows = np.concatenate(parts) if parts else np.zeros((0, 2 + nfn), np.int64)
    nodes, inverse = np.unique(rows[:, 2:], return_inverse=True)
    owner = fetch(comm, nodes, homes.starts, homes.table[:, :1])[:, 0][inverse] \
        .reshape(-1, nfn)
    pairs = np.unique(np.repeat(np.arange(rows.shape[0], dtype=np.int64), nfn) * size
                      + owner.ravel())
    row, dest = np.divmod(pairs, size)
    got, _ = exchange(comm, rows[row], dest)
    got = got[np.lexsort((got[:, 1], got[:, 0]))]
    pos = np.minimum(np.searchsorted(ids, got[:, 2:]), max(ids.size - 1, 0))
    present = (ids[pos] == got[:, 2:]).all(axis=1) if ids.size else np.zeros(len(got), bool)
    mapped = to_local[pos] if ids.size else np.zeros((0, nfn), to_local.dtype)
    keep = present & (mapped < n_owned).any(axis=1)
    return {name: mapped[keep & (got[:, 0] == g)] for g, name in enumerate(src.facet_groups)}


def _facet_rows(src: SliceSource, name: str, rank: int, size: int, source: str):
    facets, order = src.facet_slice(name, rank, size)
    if facets.size and (facets.min() < 0 or facets.max() >= src.num_points):
        raise InputError(f"facet group {name!r} refers to points that do not exist", source,
                         "mesh.file")
    return facets, order


def _facet_shape(cell_type: str) -> tuple:
    from parsolve.mesh.topology import FACETS

    return FACETS[cell_type][0]


def bounds(comm, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lowest, highest) coordinates over every rank's ``points`` (n, dim). Collective."""
    dim = points.shape[1]
    lo = points.min(axis=0) if points.size else np.full(dim, np.inf)
    hi = points.max(axis=0) if points.size else np.full(dim, -np.inf)
    comm.Allreduce(MPI.IN_PLACE, lo, MPI.MIN)
    comm.Allreduce(MPI.IN_PLACE, hi, MPI.MAX)
    return lo, hi


def _extent(comm, points: np.ndarray, dim: int) -> np.ndarray:
    lo, hi = bounds(comm, points.reshape(-1, dim))
    return hi - lo if np.all(np.isfinite(hi - lo)) else np.zeros(dim)


def _unused_warning(comm, unused: np.ndarray) -> list[str]:
    """``checks.unused_warning``'s message from every home's nodes of no cell."""
    count = comm.allreduce(int(unused.size))
    if count == 0:
        return []
    first = np.sort(np.concatenate(comm.allgather(unused[:checks.SHOW])))[:checks.SHOW]
    shown = ", ".join(str(int(i)) for i in first) + (f", ... ({count} in all)"
                                                     if count > checks.SHOW else "")
    return [f"{count} point(s) are used by no cell (points {shown}): they are left out "
            "of the system"]


def hash_ranks(keys: np.ndarray, size: int) -> np.ndarray:
    """The rank where each row of integer ``keys`` meets the rows equal to it: a
    multiplicative hash of its columns, its high bits (a structured grid's rounded coordinates,
    or its node ids, are all multiples of one spacing, which low bits would send to one rank)."""
    mix = np.zeros(keys.shape[0], dtype=np.uint64)
    for a in range(keys.shape[1]):
        mix = (mix ^ keys[:, a].astype(np.uint64)) * np.uint64(0x9E3779B97F4A7C15)
    return ((mix >> np.uint64(33)) % np.uint64(size)).astype(np.int64)


def _duplicate_warning(comm, points: np.ndarray, homes: _Homes, ps) -> list[str]:
    """``checks.duplicate_warning``'s message: the used points rounded onto the same grid
    (``checks.duplicate_points``' spacing), each grid cell's points met on the rank its hash
    names."""
    used = np.ones(points.shape[0], dtype=bool)
    used[homes.unused - ps[comm.rank]] = False
    ids = np.flatnonzero(used) + ps[comm.rank]
    pts = points[used]
    lo, hi = bounds(comm, pts)
    if not np.all(np.isfinite(hi - lo)):
        return []
    extent = max(float((hi - lo).max()), 1e-300)
    grid = np.rint((pts - lo) / (1e-10 * extent)).astype(np.int64)
    dest = hash_ranks(grid, comm.size)
    dim = grid.shape[1]
    rows = np.column_stack([grid, ids])   # (the coordinates: of the first pair's point only)
    del pts
    got, _ = exchange(comm, rows, dest)
    del rows, grid, dest
    if got.shape[0] > 1 and not np.all(got[1:, dim] >= got[:-1, dim]):
        got = got[np.argsort(got[:, dim], kind="stable")]   # by input id, as duplicate_points
    group, counts = topology._row_groups(got[:, :dim]) if got.size else (np.zeros(0, np.int64),
                                                                          np.zeros(0, np.int64))
    dup = np.flatnonzero(counts[group] > 1) if group.size else group
    first_of = np.full(counts.size, -1, dtype=np.int64)
    first_of[group[dup[::-1]]] = dup[::-1]         # the lowest id of each group
    others = dup[first_of[group[dup]] != dup]
    pairs = np.column_stack([got[first_of[group[others]], dim], got[others, dim]])
    count = comm.allreduce(int(pairs.shape[0]))
    if count == 0:
        return []
    mine = None
    if pairs.size:   # this rank's first pair (lexicographic)
        mine = tuple(int(v) for v in pairs[np.lexsort(pairs.T[::-1])[0]])
    a, b = min(c for c in comm.allgather(mine) if c is not None)
    at = fetch(comm, np.array([a] if comm.rank == 0 else [], np.int64), ps, points)
    at = comm.bcast(at[0] if comm.rank == 0 else None, root=0)
    where = ", ".join(f"{c:g}" for c in at)
    return [f"{count} point(s) duplicate another (first: points {a} and {b} at ({where})): "
            "the cells on either side are not connected there (a crack?)"]
