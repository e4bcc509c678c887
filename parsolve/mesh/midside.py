"""Quadratic cells by slices: the midside nodes of a slice source's triangles or tetrahedra
numbered without any rank holding the whole mesh's edges.

Each edge belongs to the home of its lower node (the rank whose point slice holds it,
``partition.block_starts``). A home numbers its edges in (lower, upper) node order after the
edges of the lower ranks (an exclusive scan of the counts), the mesh's points first: exactly
``generators.make_quadratic``'s numbering (every edge by sorted key), so the slices give the
whole upgrade's mesh bit for bit. The midside coordinates are computed at the home (the
upper node's coordinates fetched), then every row goes to the slice of the quadratic mesh
(points and midside nodes together) it belongs to. ``QuadraticSlices`` is a slice source
(``slices.SliceSource``) of the quadratic mesh: ``slices.distribute_slices`` takes it as any
other.
"""

from __future__ import annotations

import numpy as np

from parsolve.collective import agree
from parsolve.errors import InputError
from parsolve.mesh.blocks import exchange, rank_order
from parsolve.mesh.partition import block_starts

# local vertex pairs of the midside nodes (meshio/VTK order) and of a facet's midside nodes
EDGES = {
    "triangle": np.array([(0, 1), (1, 2), (2, 0)]),
    "tetra": np.array([(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]),
}
FACET_EDGES = {"triangle": np.array([(0, 1)]), "tetra": np.array([(0, 1), (1, 2), (2, 0)])}
QUADRATIC = {"triangle": "triangle6", "tetra": "tetra10"}


class QuadraticSlices:
    """The quadratic mesh of ``src`` (triangle or tetra cells) as a slice source: this rank's
    slices of it, built collectively by ``__init__`` (each rank reads its own slices of
    ``src``). ``midside_groups``: a midside node is in a node group when both its ends are
    (the generators' quadratic cells, whose groups are their sides: planes and the hole);
    otherwise node groups keep the mesh's nodes only (``make_quadratic``'s rule)."""

    def __init__(self, comm, src, source: str, key: str, midside_groups: bool = False):
        if src.cell_type not in EDGES:   # the caller names the scene's key
            raise ValueError(f"no midside nodes for {src.cell_type} cells")
        self.path, self.dim = src.path, src.dim
        self.cell_type = QUADRATIC[src.cell_type]
        self.cell_groups, self.node_groups = src.cell_groups, src.node_groups
        self.facet_groups = src.facet_groups
        self.num_cells, self._src = src.num_cells, src
        self._rank = comm.rank
        n = src.num_points
        ps = block_starts(n, comm.size)
        cells, points, flags = agree(comm, _read, src, comm.rank, comm.size, source, key)
        keys, inverse = _unique_inverse(_edge_keys(cells, EDGES[src.cell_type], n))
        owned = _owned_edges(comm, keys, ps * n)
        counts = np.array(comm.allgather(owned.size), dtype=np.int64)
        first = n + int(counts[:comm.rank].sum())
        self.num_points = n + int(counts.sum())
        facets = agree(comm, _facet_rows, src, comm.rank, comm.size, source)
        numbers = _edge_numbers(comm, np.concatenate([keys] + [f[1] for f in facets]),
                                ps * n, owned, first)
        if comm.allreduce(int(np.any(numbers[keys.size:] < 0))):
            raise InputError("a facet group contains an edge that is not a mesh edge", source,
                             key)
        self._cells = np.hstack([cells, numbers[:keys.size][inverse.reshape(cells.shape[0], -1)]])
        self._facets = _quadratic_facets(facets, numbers[keys.size:])
        del cells, keys, inverse, numbers, facets   # (the peak is in the moves below)
        mid, mid_flags = _midsides(comm, src, owned, n, ps, points, flags, midside_groups)
        self._points, self._flags, self.point_starts = _to_slices(
            comm, [(int(ps[comm.rank]), points, flags), (first, mid, mid_flags)], self.num_points)

    def cells(self, start: int, stop: int) -> np.ndarray:
        return self._cells

    def points(self, start: int, stop: int) -> np.ndarray:
        return self._points

    def node_flags(self, start: int, stop: int) -> np.ndarray:
        return self._flags

    def cell_flags(self, start: int, stop: int) -> np.ndarray:
        return self._src.cell_flags(start, stop)

    def facet_slice(self, name: str, rank: int, size: int) -> tuple[np.ndarray, np.ndarray]:
        return self._facets[name]

    def close(self) -> None:
        getattr(self._src, "close", lambda: None)()


def _read(src, rank: int, size: int, source: str, key: str):
    """This rank's cells (int64), points and node flags of ``src``."""
    cs, ps = block_starts(src.num_cells, size), block_starts(src.num_points, size)
    cells = np.asarray(src.cells(int(cs[rank]), int(cs[rank + 1])), dtype=np.int64)
    if cells.size and (cells.min() < 0 or cells.max() >= src.num_points):
        raise InputError("cells refer to points that do not exist", source, key)
    points = src.points(int(ps[rank]), int(ps[rank + 1]))
    flags = src.node_flags(int(ps[rank]), int(ps[rank + 1]))
    return cells, points, flags


def _unique_inverse(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(keys, return_inverse=True)`` with the inverse written over ``keys`` and the
    running count over the sorted copy: three key-sized arrays at the peak, not np.unique's
    five (the quadratic slices' peak)."""
    flat = keys.reshape(-1)
    order = np.argsort(flat)
    ranked = flat[order]
    new = np.empty(flat.size, dtype=bool)
    new[:1] = True
    np.not_equal(ranked[1:], ranked[:-1], out=new[1:])
    unique = ranked[new]
    np.cumsum(new, out=ranked)
    ranked -= 1
    flat[order] = ranked
    return unique, flat


def _edge_keys(cells: np.ndarray, pairs: np.ndarray, n: int) -> np.ndarray:
    """(cells, edges) keys lower · n + upper of the cells' edges, an edge column at a time
    (no (cells, edges, 2) array)."""
    keys = np.empty((cells.shape[0], len(pairs)), dtype=np.int64)
    for e, (a, b) in enumerate(pairs):
        keys[:, e] = np.minimum(cells[:, a], cells[:, b]) * n + np.maximum(cells[:, a], cells[:, b])
    return keys


def _facet_rows(src, rank: int, size: int, source: str) -> list:
    """Each facet group's (name, its edges' keys, corner rows, order) of this rank's rows."""
    out = []
    nv = 2 if src.cell_type == "triangle" else 3
    for name in src.facet_groups:
        facets, order = src.facet_slice(name, rank, size)
        facets = np.asarray(facets, dtype=np.int64)[:, :nv]
        if facets.size and (facets.min() < 0 or facets.max() >= src.num_points):
            raise InputError(f"facet group {name!r} refers to points that do not exist",
                             source, "mesh.file")
        keys = _edge_keys(facets, FACET_EDGES[src.cell_type], src.num_points)
        out.append((name, keys.ravel(), facets, order))
    return out


def _home_of(keys: np.ndarray, key_starts: np.ndarray) -> np.ndarray:
    return np.searchsorted(key_starts, keys, side="right") - 1


def _owned_edges(comm, keys: np.ndarray, key_starts: np.ndarray) -> np.ndarray:
    """The sorted keys of the edges this rank is the home of (its lower node's home)."""
    got, _ = exchange(comm, keys, _home_of(keys, key_starts))
    return np.unique(got)


def _edge_numbers(comm, keys: np.ndarray, key_starts: np.ndarray, owned: np.ndarray,
                  first: int) -> np.ndarray:
    """Each key's midside node number from its home (-1: not an edge of the mesh)."""
    home = _home_of(keys, key_starts)
    order = rank_order(home, comm.size)
    asked, counts = exchange(comm, keys[order], home[order])
    pos = np.minimum(np.searchsorted(owned, asked), max(owned.size - 1, 0))
    found = owned[pos] == asked if owned.size else np.zeros(asked.size, bool)
    reply = np.where(found, first + pos, -1)
    back, _ = exchange(comm, reply, np.repeat(np.arange(comm.size), counts))
    out = np.empty_like(back)
    out[order] = back
    return out


def _quadratic_facets(facets: list, numbers: np.ndarray) -> dict:
    """Each group's (line3 or triangle6 rows, order) from its corners and edge numbers."""
    out, at = {}, 0
    for name, keys, corners, order in facets:
        width = 1 if corners.shape[1] == 2 else 3   # a line's midside node, a triangle's three
        mids = numbers[at:at + keys.size].reshape(corners.shape[0], width)
        at += keys.size
        out[name] = (np.hstack([corners, mids]), order)
    return out


def _midsides(comm, src, owned: np.ndarray, n: int, ps: np.ndarray, points: np.ndarray,
              flags: np.ndarray, midside_groups: bool) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates and node flags of this rank's midside nodes: the mean of the ends
    (``src.midside_points`` may move them onto a curved side)."""
    from parsolve.mesh.slices import fetch

    lo, hi = np.divmod(owned, n)
    dim = points.shape[1]
    start = ps[comm.rank]
    columns = [points.view(np.int64).reshape(-1, dim)]
    if midside_groups:
        columns.append(_bits(flags))
    far = fetch(comm, hi, ps, np.column_stack(columns))
    mid = 0.5 * (points[lo - start] + np.ascontiguousarray(far[:, :dim]).view(float))
    mid = getattr(src, "midside_points", lambda lo, hi, mid: mid)(lo, hi, mid)
    if not midside_groups:
        return mid, np.zeros((owned.size, flags.shape[1]), dtype=bool)
    return mid, _unbits(_bits(flags)[lo - start] & far[:, dim:], flags.shape[1])


def _bits(flags: np.ndarray) -> np.ndarray:
    """Rows of node flags as bits, 64 groups to an int64 column (at least one): a column or two
    to send, not one per group."""
    packed = np.packbits(flags.astype(bool), axis=1, bitorder="little")
    out = np.zeros((flags.shape[0], max(-(-packed.shape[1] // 8), 1) * 8), dtype=np.uint8)
    out[:, :packed.shape[1]] = packed
    return out.view(np.int64)


def _unbits(bits: np.ndarray, count: int) -> np.ndarray:
    return np.unpackbits(np.ascontiguousarray(bits).view(np.uint8), axis=1, count=count,
                         bitorder="little").astype(bool)


def _to_slices(comm, parts: list, total: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows (node id, coordinates, flag bits) of ``parts`` — (first id, points, flags) of
    consecutive ids, written into one array (no stacked copies) — moved to the quadratic
    mesh's point slices: (points, flags, the slices' starts)."""
    starts = block_starts(total, comm.size)
    dim, count = parts[0][1].shape[1], parts[0][2].shape[1]
    bits = [_bits(f) for _, _, f in parts]
    rows = np.empty((sum(len(b) for b in bits), 1 + dim + bits[0].shape[1]), dtype=np.int64)
    at = 0
    for (first, points, _), b in zip(parts, bits):
        rows[at:at + len(b), 0] = np.arange(first, first + len(b))
        rows[at:at + len(b), 1:1 + dim] = np.ascontiguousarray(points).view(np.int64)
        rows[at:at + len(b), 1 + dim:] = b
        at += len(b)
    del bits
    got, _ = exchange(comm, rows, np.searchsorted(starts, rows[:, 0], side="right") - 1)
    del rows
    got = got[np.argsort(got[:, 0], kind="stable")]
    return (np.ascontiguousarray(got[:, 1:1 + dim]).view(float).reshape(-1, dim),
            _unbits(got[:, 1 + dim:], count), starts)
