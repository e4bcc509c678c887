"""A Gmsh MSH 4.1 or 2.2 file as a mesh, never read whole by one rank (``gmsh.scan``'s layout):

* ``GmshSlices``: every rank reads its slice of the nodes and of the cells (the rows
  ``partition.block_starts`` gives, as for the parallel mesh file) and its share of the group
  blocks; the node tags are mapped to the file's order at the tags' homes; the slice path
  (``mesh.slices``) takes it from there;
* ``read_whole``: the whole mesh on one process (``reader.read_mesh``: checks, ``order = 2``
  upgrades on rank 0, the regions of ``parsolve post``);
* ``convert``: the parallel mesh file (``h5mesh``'s layout) written by chunks of rows.

The mesh is the one meshio's reading gives (``reader.mesh_from_meshio``): the same points,
cells (positively oriented), groups and facet order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsolve.collective import agree
from parsolve.errors import InputError
from parsolve.mesh.blocks import exchange
from parsolve.mesh.gmsh import ROWS, Layout, scan
from parsolve.mesh.mesh import Mesh, volume_type
from parsolve.mesh.partition import block_starts
from parsolve.mesh.topology import orient_cells

_KEY = "mesh.file"


def read_rows(array: np.ndarray, have: tuple[int, int], start: int, stop: int) -> np.ndarray:
    """The rows ``start:stop`` a slice source read at its start (``have``): the slice path asks
    for this rank's rows only, so any other range is a caller's error."""
    if (start, stop) != have:
        raise ValueError(f"rows {start}:{stop} asked, {have[0]}:{have[1]} read")
    return array


@dataclass
class Plan:
    """Which blocks are cells, facets, lower-dimensional groups; the groups' names."""

    cell_type: str
    dim: int
    cells: list[int]
    facets: list[int]
    nodes: list[int]
    cell_groups: tuple[str, ...]
    facet_groups: tuple[str, ...]
    node_groups: tuple[str, ...]


def plan_of(lay: Layout, key: str = _KEY) -> Plan:
    """The blocks' roles (``reader.mesh_from_meshio``'s rules and errors)."""
    from parsolve.mesh.gmsh import TYPES

    def fail(message: str) -> InputError:
        return InputError(message, lay.path, key)

    blocks = lay.element_blocks
    dims = {name: d for name, _, d in TYPES.values()}
    kinds = [kind for _, _, kind, _ in blocks]
    vtype, ftype, vdim = volume_type(kinds, [dims[k] for k in kinds], fail)
    role: dict[str, list[int]] = {"cell": [], "facet": [], "node": []}
    names: dict[str, set] = {"cell": set(), "facet": set(), "node": set()}
    for b, (_, _, kind, rows) in enumerate(blocks):
        cat = ("cell" if kind == vtype else "facet" if kind == ftype
               else "node" if dims[kind] < vdim - 1 else None)
        groups = lay.block_names(b) if rows.n else []
        if cat is None:
            if groups:
                raise fail(f"group {groups[0]!r} has {kind} elements, expected {vtype} cells, "
                           f"{ftype} facets or lower-dimensional entities")
            continue
        role[cat].append(b)
        names[cat].update(groups)
    return Plan(vtype, vdim, role["cell"], role["facet"], role["node"],
                *(tuple(sorted(names[c])) for c in ("cell", "facet", "node")))


def open_gmsh(comm, path: str, key: str = _KEY) -> "GmshSlices":
    """The slices of ``path`` (rank 0 scans the layout, every rank reads its rows).
    Collective; InputError on every rank."""
    found, error = None, None
    if comm.rank == 0:
        try:
            found = scan(path, key)
            plan_of(found, key)
        except InputError as exc:
            error = (exc.message, exc.source, exc.key)
    found, error = comm.bcast((found, error), root=0)
    if error is not None:
        raise InputError(*error)
    return GmshSlices(comm, found, key)


class _TagIndex:
    """Node tag -> position in the file's node order. Tags 1..N in the file's order map by
    arithmetic; other tags through a table split over the ranks by tag ranges (each rank's
    range: its tags' positions), asked by all-to-all."""

    def __init__(self, comm, tags: np.ndarray, first: int, total: int):
        self.comm, self.total = comm, total
        here = np.array_equal(tags, np.arange(first + 1, first + tags.size + 1))
        self.dense = comm.allreduce(here, MPI.LAND)
        if self.dense:
            return
        low = comm.allreduce(int(tags.min(initial=2**62)), MPI.MIN)
        high = comm.allreduce(int(tags.max(initial=-1)), MPI.MAX)
        self.low, self.high = low, high
        self.starts = block_starts(max(high - low + 1, 0), comm.size) + low
        home = np.searchsorted(self.starts, tags, side="right") - 1
        got, _ = exchange(comm, np.column_stack([tags, np.arange(tags.size) + first]), home)
        r = comm.rank
        self.table = np.full((int(self.starts[r + 1] - self.starts[r]), 1), -1, np.int64)
        self.table[got[:, 0] - self.starts[r], 0] = got[:, 1]

    def __call__(self, tags: np.ndarray) -> np.ndarray:
        """Positions of ``tags`` (any shape; -1: no such node). Collective unless dense."""
        from parsolve.mesh.slices import fetch

        flat = tags.ravel()
        if self.dense:
            out = flat - 1
            out[(flat < 1) | (flat > self.total)] = -1
            return out.reshape(tags.shape)
        inside = (flat >= self.low) & (flat <= self.high)
        out = np.full(flat.size, -1, np.int64)
        out[inside] = fetch(self.comm, flat[inside], self.starts, self.table)[:, 0]
        return out.reshape(tags.shape)


class GmshSlices:
    """A Gmsh file as a ``slices.SliceSource``: this rank's rows, read at construction
    (collective: the tags' mapping and the cells' orientation ask other ranks)."""

    def __init__(self, comm, lay: Layout, key: str = _KEY):
        size, rank = comm.size, comm.rank
        plan = plan_of(lay, key)
        self.path, self.plan, self.layout = lay.path, plan, lay
        self.cell_type, self.dim = plan.cell_type, plan.dim
        self.num_points = lay.num_nodes
        self.num_cells = sum(lay.element_blocks[b][3].n for b in plan.cells)
        self.cell_groups, self.node_groups = plan.cell_groups, plan.node_groups
        self.facet_groups = plan.facet_groups
        cs, ps = block_starts(self.num_cells, size), block_starts(self.num_points, size)
        self._cs, self._ps = (int(cs[rank]), int(cs[rank + 1])), (int(ps[rank]), int(ps[rank + 1]))
        with lay.open() as fh:
            tags, xyz = agree(comm, lay.node_rows, fh, *self._ps)
            self._points = _planar(comm, xyz, plan.dim, lay.path, key)
            index = _TagIndex(comm, tags, self._ps[0], self.num_points)
            del tags, xyz
            cells = index(agree(comm, lay.element_rows, fh, plan.cells, *self._cs))
            agree(comm, _in_range, cells, "cells refer to points that do not exist", lay.path, key)
            self._cells = _oriented(comm, cells, ps, self._points, plan.cell_type)
            self._node_flags = _node_flags(comm, fh, lay, plan, index, ps, key)
            self._facets = _facet_slices(comm, fh, lay, plan, index, key)

    def cells(self, start: int, stop: int) -> np.ndarray:
        return self._mine(self._cells, self._cs, start, stop)

    def points(self, start: int, stop: int) -> np.ndarray:
        return self._mine(self._points, self._ps, start, stop)

    def node_flags(self, start: int, stop: int) -> np.ndarray:
        return self._mine(self._node_flags, self._ps, start, stop)

    def cell_flags(self, start: int, stop: int) -> np.ndarray:
        """The cells' groups (any rows): from the blocks' headers, or their rows' tags."""
        with self.layout.open() as fh:
            return cell_flags(self.layout, self.plan, fh, start, stop)

    def facet_slice(self, name: str, rank: int, size: int) -> tuple[np.ndarray, np.ndarray]:
        return self._facets[name]

    _mine = staticmethod(read_rows)


def cell_flags(lay: Layout, plan: Plan, fh, start: int, stop: int) -> np.ndarray:
    """(stop - start, cell groups) bool: the groups of cells ``start:stop``."""
    out = np.zeros((max(stop - start, 0), len(plan.cell_groups)), dtype=bool)
    for k, name in enumerate(plan.cell_groups):
        out[:, k] = lay.in_group(fh, plan.cells, name, start, stop)
    return out


def _planar(comm, xyz: np.ndarray, dim: int, path: str, key: str) -> np.ndarray:
    """The points' ``dim`` coordinates; a 2D mesh's z must be constant (meshio's rule)."""
    if dim == 3:
        return np.ascontiguousarray(xyz)
    z = xyz[:, dim:]
    lo = comm.allreduce(float(z.min(initial=np.inf)), MPI.MIN)
    hi = comm.allreduce(float(z.max(initial=-np.inf)), MPI.MAX)
    scale = max(comm.allreduce(float(np.abs(xyz).max(initial=0.0)), MPI.MAX), 1.0)
    if hi - lo > 1e-12 * scale:
        raise InputError(f"{dim}D mesh with non-constant z coordinates", path, key)
    return np.ascontiguousarray(xyz[:, :dim])


def _in_range(ids: np.ndarray, message: str, path: str, key: str, n: int | None = None) -> None:
    """InputError unless every id is a point: none below 0 (a Gmsh tag no node has maps to
    -1) and, given the number of points ``n``, none at n or above (ids read as they are)."""
    if ids.size and (ids.min() < 0 or (n is not None and ids.max() >= n)):
        raise InputError(message, path, key)


def _oriented(comm, cells: np.ndarray, ps: np.ndarray, points: np.ndarray,
              cell_type: str) -> np.ndarray:
    """``cells`` with the nodes of negatively oriented ones reordered in place (their
    coordinates fetched from the nodes' homes), a chunk of cells at a time."""
    from parsolve.mesh.slices import fetch, local_nodes

    nodes, inverse = local_nodes(cells)
    coords = fetch(comm, nodes, ps, points)
    for start in range(0, cells.shape[0], ROWS):
        with np.errstate(invalid="ignore"):   # NaN coordinates: the slice path's checks say so
            local, flipped = orient_cells(coords, cell_type, inverse[start:start + ROWS])
        if flipped:
            cells[start:start + ROWS] = nodes[local]
    return cells


def _group_rows(lay: Layout, blocks: list[int], name: str) -> list[int]:
    return [b for b in blocks if name in lay.block_names(b)]


def _node_flags(comm, fh, lay: Layout, plan: Plan, index: _TagIndex, ps, key: str):
    """This rank's home nodes' node groups: each rank reads a share of every group block
    and sends each node's flag to its home."""
    rank, size = comm.rank, comm.size
    flags = np.zeros((int(ps[rank + 1] - ps[rank]), len(plan.node_groups)), dtype=bool)

    def read() -> np.ndarray:
        pairs = [np.zeros((0, 2), np.int64)]
        for k, name in enumerate(plan.node_groups):
            for b in _group_rows(lay, plan.nodes, name):
                n = lay.element_blocks[b][3].n
                lo, hi = n * rank // size, n * (rank + 1) // size
                tags = lay.element_rows(fh, [b], lo, hi)[lay.in_group(fh, [b], name, lo, hi)]
                pairs.append(np.column_stack([tags.ravel(), np.full(tags.size, k)]))
        return np.concatenate(pairs)

    pairs = agree(comm, read)
    pairs[:, 0] = index(pairs[:, 0])
    agree(comm, _in_range, pairs[:, 0], "a node group refers to points that do not exist",
          lay.path, key)
    got, _ = exchange(comm, pairs, np.searchsorted(ps, pairs[:, 0], side="right") - 1)
    flags[got[:, 0] - ps[rank], got[:, 1]] = True
    return flags


def _facet_slices(comm, fh, lay: Layout, plan: Plan, index: _TagIndex, key: str) -> dict:
    """Each facet group's rows of this rank (an even split of the rows of the group's blocks,
    those of the group kept) and their row numbers in the group."""
    rank, size = comm.rank, comm.size

    def read() -> list[np.ndarray]:
        out = []
        for name in plan.facet_groups:
            blocks = _group_rows(lay, plan.facets, name)
            n = sum(lay.element_blocks[b][3].n for b in blocks)
            a, c = n * rank // size, n * (rank + 1) // size
            out.append(lay.element_rows(fh, blocks, a, c)[lay.in_group(fh, blocks, name, a, c)])
        return out

    parts = agree(comm, read)
    counts = np.array([len(f) for f in parts], dtype=np.int64)
    before = comm.exscan(counts)   # (collective; None on rank 0)
    before = np.zeros_like(counts) if rank == 0 else before
    nfn = len(_facet_nodes(plan.cell_type))
    tags = np.concatenate(parts) if parts else np.zeros((0, nfn), np.int64)
    ids = index(tags)
    agree(comm, _in_range, ids, "a facet group refers to points that do not exist", lay.path,
          key)
    split = np.split(ids, np.cumsum(counts)[:-1]) if parts else []
    return {name: (facets, np.arange(first, first + len(facets), dtype=np.int64))
            for name, facets, first in zip(plan.facet_groups, split, before)}


def _facet_nodes(cell_type: str) -> tuple:
    from parsolve.mesh.topology import FACETS

    return FACETS[cell_type][0]


def read_whole(path: str, key: str = _KEY) -> Mesh:
    """The whole mesh of a MSH 4.1 or 2.2 file on this process."""
    src = GmshSlices(MPI.COMM_SELF, scan(path, key), key)
    cflags = src.cell_flags(0, src.num_cells)
    nflags = src.node_flags(0, src.num_points)
    return Mesh(src.points(0, src.num_points), src.cell_type, src.cells(0, src.num_cells),
                cell_groups={n: np.flatnonzero(cflags[:, k]) for k, n in enumerate(src.cell_groups)},
                facet_groups={n: src.facet_slice(n, 0, 1)[0] for n in src.facet_groups},
                node_groups={n: np.flatnonzero(nflags[:, k]) for k, n in enumerate(src.node_groups)})


# ------------------------------------------------------------------ convert


def convert(path: str, target: str, key: str = _KEY) -> tuple[str, int, int, int]:
    """Write the parallel mesh file ``target`` from the MSH 4.1 or 2.2 file ``path`` by chunks of
    ``gmsh.ROWS`` rows: held whole are the points' coordinates (the cells' orientation looks
    them up), a byte per node and node group, and the tags' map when the tags are not 1..N in
    the file's order. Returns (cell type, cells, points, groups)."""
    import h5py

    from parsolve.mesh.h5mesh import FORMAT, VERSION

    lay = scan(path, key)
    plan = plan_of(lay, key)
    num_cells = sum(lay.element_blocks[b][3].n for b in plan.cells)
    with lay.open() as fh, h5py.File(target, "w") as f:
        g = f.create_group("mesh")
        g.attrs["format"], g.attrs["version"] = FORMAT, VERSION
        points, positions = _stream_points(fh, lay, plan, g, key)
        _stream_cells(fh, lay, plan, g, points, positions, num_cells, key)
        _write_groups(fh, lay, plan, g, positions, num_cells, key)
    groups = len(plan.cell_groups) + len(plan.facet_groups) + len(plan.node_groups)
    return plan.cell_type, num_cells, lay.num_nodes, groups


def _stream_points(fh, lay: Layout, plan: Plan, g, key: str):
    """(the points, the tags' map: None for tags 1..N in order, else tag -> position)."""
    n = lay.num_nodes
    points = np.empty((n, plan.dim))
    tags = np.empty(n, np.int64)
    zlo, zhi, scale = np.inf, -np.inf, 1.0
    for a in range(0, n, ROWS):
        t, xyz = lay.node_rows(fh, a, min(a + ROWS, n))
        tags[a:a + len(t)], points[a:a + len(t)] = t, xyz[:, :plan.dim]
        scale = max(scale, float(np.abs(xyz).max(initial=0.0)))
        zlo, zhi = min(zlo, xyz[:, 2].min(initial=np.inf)), max(zhi, xyz[:, 2].max(initial=-np.inf))
    if plan.dim == 2 and zhi - zlo > 1e-12 * scale:
        raise InputError("2D mesh with non-constant z coordinates", lay.path, key)
    g.create_dataset("points", data=points)
    if np.array_equal(tags, np.arange(1, n + 1)):
        return points, None
    positions = np.full(int(tags.max(initial=0)) + 1, -1, np.int64)
    positions[tags] = np.arange(n)
    return points, positions


def _map(tags: np.ndarray, positions, n: int) -> np.ndarray:
    if positions is None:
        out = tags - 1
        out[(tags < 1) | (tags > n)] = -1
        return out
    inside = (tags >= 0) & (tags < positions.size)
    return np.where(inside, positions[np.where(inside, tags, 0)], -1)


def _stream_cells(fh, lay, plan, g, points, positions, num_cells: int, key: str) -> None:
    nodes = lay.nodes_per_row(plan.cells[0])
    out = g.create_group("cells").create_dataset(plan.cell_type, (num_cells, nodes), np.int64)
    for a in range(0, num_cells, ROWS):
        cells = _map(lay.element_rows(fh, plan.cells, a, min(a + ROWS, num_cells)), positions,
                     lay.num_nodes)
        _in_range(cells, "cells refer to points that do not exist", lay.path, key)
        with np.errstate(invalid="ignore"):
            out[a:a + len(cells)] = orient_cells(points, plan.cell_type, cells)[0]


def _write_groups(fh, lay, plan, g, positions, num_cells: int, key: str) -> None:
    for name in plan.cell_groups:
        mask = g.require_group("cell_groups").create_dataset(name, (num_cells,), np.uint8)
        for a in range(0, num_cells, ROWS):
            b = min(a + ROWS, num_cells)
            mask[a:b] = lay.in_group(fh, plan.cells, name, a, b)
    for name in plan.node_groups:
        mask = np.zeros(lay.num_nodes, np.uint8)
        for b in _group_rows(lay, plan.nodes, name):
            n = lay.element_blocks[b][3].n
            for a in range(0, n, ROWS):
                c = min(a + ROWS, n)
                ids = _map(lay.element_rows(fh, [b], a, c)[lay.in_group(fh, [b], name, a, c)],
                           positions, lay.num_nodes)
                _in_range(ids, "a node group refers to points that do not exist", lay.path, key)
                mask[ids.ravel()] = 1
        g.require_group("node_groups").create_dataset(name, data=mask)
    nfn = len(_facet_nodes(plan.cell_type))
    for name in plan.facet_groups:
        blocks = _group_rows(lay, plan.facets, name)
        n = sum(lay.element_blocks[b][3].n for b in blocks)
        out = g.require_group("facet_groups").create_dataset(
            name, (lay.group_count(blocks, name), nfn), np.int64)
        at = 0
        for a in range(0, n, ROWS):
            c = min(a + ROWS, n)
            ids = _map(lay.element_rows(fh, blocks, a, c)[lay.in_group(fh, blocks, name, a, c)],
                       positions, lay.num_nodes)
            _in_range(ids, "a facet group refers to points that do not exist", lay.path, key)
            out[at:at + len(ids)] = ids
            at += len(ids)
