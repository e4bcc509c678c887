"""The distributed mesh: each rank keeps only its part, with the input ids of what it holds.
Every run goes through it, 1 rank included.

Here rank 0 reads the whole mesh — Gmsh and other meshio files (``order = 2`` on them
included) — every rank checks a block of its cells and builds
that block's rows of the dual graph (``blocks``), its cells are partitioned (PT-Scotch through
PETSc, every rank handing it its block of the graph; or coordinate bisection), and rank 0 sends
every rank its part, one at a time; then it drops the whole mesh like the others never had it.
Parallel mesh files and the generated meshes give the same parts without any rank holding the
whole mesh (``slices``; their midside nodes: ``midside``).
On 1 rank the part is the whole mesh, its arrays taken as they are (not copied: the mesh is
never held twice). The rules are ``partition.from_cell_parts``':

* a node belongs to the lowest rank among the cells that touch it;
* a rank's **local cells** are every cell that touches one of its nodes (its owned cells and one
  layer of ghosts): every sum over cells (stiffness, internal forces, loads, nodal averages) is
  complete on the owned nodes without communication;
* **local nodes** are its owned nodes (increasing input id, which is the global numbering's
  order) then the ghost nodes of its cells (increasing global number).

The part is a ``LocalMesh``: a ``Mesh`` in local numbering, so that everything working on cells
and nodes (effects, regions, loads) works on it unchanged, plus the input ids of its nodes and
cells (``global_nodes``, ``global_cells``: results are written in input order) and the global
numbers of its nodes (``node_new``); their owners follow from those and the ranks' node blocks
(``node_owner``, computed when asked, not kept).

Index arrays are int32 while the numbers fit (``index_dtype``): a part's index arrays are then
half the whole mesh's int64 per node. Node numbers keep a margin of 64 components per node
because they are multiplied into DOF numbers (``node * ncomp + c``, e.g. ``Layout.new_dof``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from parsolve.mesh import blocks
from parsolve.mesh.mesh import Mesh
from parsolve.mesh.partition import (MIN_CELLS_PER_PART, PARTITIONERS, Partition, bisect,
                                     from_cell_parts, scotch_block)


# node numbers are multiplied by up to this many components per node into DOF numbers
COMPONENT_MARGIN = 64
INT32_MAX = np.iinfo(np.int32).max
PART_TAG = 72   # the message of a rank's part


def index_dtype(count: int, per_item: int = 1) -> np.dtype:
    """int32 when every number below ``count`` times ``per_item`` fits it, else int64."""
    return np.dtype(np.int32) if count * per_item <= INT32_MAX else np.dtype(np.int64)


@dataclass
class LocalMesh(Mesh):
    """One rank's part of a distributed mesh, in local numbering (see the module's doc)."""

    global_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    global_cells: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    node_new: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    node_ranges: np.ndarray = field(default_factory=lambda: np.zeros(2, np.int64))
    num_global_points: int = 0
    num_global_cells: int = 0
    partitioner: str = "none"
    extent: np.ndarray = field(default_factory=lambda: np.zeros(0))  # ptp of all points

    rank: int = 0

    @property
    def n_owned(self) -> int:
        """Owned nodes: the first ``n_owned`` local nodes."""
        return int(self.node_ranges[self.rank + 1] - self.node_ranges[self.rank])

    def owner_of(self, nodes: np.ndarray) -> np.ndarray:
        """The rank owning each of the local ``nodes`` (any shape): the block of the ranks'
        node numbering (``node_ranges``) its global number falls in."""
        new = self.node_new[np.asarray(nodes)]
        return (np.searchsorted(self.node_ranges, new, side="right") - 1).astype(np.int32)

    @property
    def node_owner(self) -> np.ndarray:
        """The rank owning each local node (a new array: not kept, see ``owner_of``)."""
        return self.owner_of(np.arange(self.num_points))

    def partition(self) -> Partition:
        """The ``Partition`` of this part (arrays over local nodes/cells)."""
        nparts = self.node_ranges.size - 1
        owner = self.node_owner
        return Partition(nparts, owner[self.cells].min(axis=1), owner, self.node_new,
                         self.node_ranges, self.partitioner)


def distribute(comm, whole: Mesh | None, method: str = "scotch",
               graph: tuple[np.ndarray, np.ndarray] | None = None) -> LocalMesh:
    """Rank 0's ``whole`` mesh (None on the other ranks) → every rank's ``LocalMesh``.
    ``graph``: this rank's block of the dual graph (``blocks.check_cells``, which a run has
    made while checking the cells), else it is made here the same way. Collective."""
    if method not in PARTITIONERS:
        raise ValueError(f"unknown partitioner {method!r} (expected one of {PARTITIONERS})")
    if comm.size == 1:
        return _whole_part(whole)
    cell_part, used = _cell_parts(comm, whole, method, graph)
    if comm.rank != 0:
        return LocalMesh(rank=comm.rank, **comm.recv(source=0, tag=PART_TAG))
    part = from_cell_parts(whole, cell_part, comm.size, used)
    del cell_part
    extent = np.ptp(whole.points, axis=0) if whole.num_points else np.zeros(whole.dim)
    common = {"cell_type": whole.cell_type, "node_ranges": part.node_ranges,
              "num_global_points": whole.num_points, "num_global_cells": whole.num_cells,
              "partitioner": used, "warnings": list(whole.warnings), "extent": extent}
    # one part at a time, sent before the next is cut out: rank 0 holds the whole mesh and
    # one other part (and its message), not every rank's part at once
    for r in range(1, comm.size):
        comm.send({**_extract(whole, part, r), **common}, dest=r, tag=PART_TAG)
    return LocalMesh(rank=0, **_extract(whole, part, 0), **common)


def _cell_parts(comm, whole: Mesh | None, method: str, graph=None
                ) -> tuple[np.ndarray | None, str]:
    """(rank 0: the part of every cell; elsewhere None, the partitioner that ran)."""
    size = comm.size
    if size == 1:
        return np.zeros(whole.num_cells, dtype=np.int64), "none"
    use_scotch = comm.bcast(method == "scotch" and whole is not None
                            and whole.num_cells >= MIN_CELLS_PER_PART * size, root=0)
    part = None
    if use_scotch:
        ptr, idx = graph if graph is not None else blocks.check_cells(
            comm, whole if comm.rank == 0 else None, None, None)
        n = comm.bcast(whole.num_cells if comm.rank == 0 else None, root=0)
        local = scotch_block(comm, n, ptr, idx)
        gathered = comm.gather(local, root=0)
        if comm.rank == 0 and all(g is not None for g in gathered):
            part = np.concatenate(gathered).astype(np.int64)
            if np.bincount(part, minlength=size).min() == 0:
                part = None
    used = None
    if comm.rank == 0:
        if part is None:
            part = bisect(whole.points[whole.cells].mean(axis=1), size)
            used = "bisection"
        else:
            used = "scotch"
    used = comm.bcast(used, root=0)
    return part, used


def _whole_part(whole: Mesh) -> LocalMesh:
    """The one rank's part: the whole mesh, every node owned, input numbering kept (what
    ``_extract`` gives on 1 rank), its arrays shared rather than copied."""
    n, nc = whole.num_points, whole.num_cells
    node_type = index_dtype(n, COMPONENT_MARGIN)
    ids = np.arange(n, dtype=node_type)
    return LocalMesh(whole.points, whole.cell_type, whole.cells.astype(node_type, copy=False),
                     cell_groups={k: np.asarray(v).astype(index_dtype(nc), copy=False)
                                  for k, v in whole.cell_groups.items()},
                     facet_groups=_whole_facet_groups(whole, node_type),
                     node_groups={k: np.asarray(v).astype(node_type, copy=False)
                                  for k, v in whole.node_groups.items()},
                     warnings=list(whole.warnings), global_nodes=ids,
                     global_cells=np.arange(nc, dtype=index_dtype(nc)), node_new=ids,
                     node_ranges=np.array([0, n], dtype=np.int64), num_global_points=n,
                     num_global_cells=nc, partitioner="none",
                     extent=np.ptp(whole.points, axis=0) if n else np.zeros(whole.dim), rank=0)


def _whole_facet_groups(whole: Mesh, node_type) -> dict:
    """``_extract``'s facet groups on 1 rank: every facet of a group is kept."""
    out = {}
    for name, facets in whole.facet_groups.items():
        facets = np.asarray(facets, dtype=np.int64)
        if facets.ndim != 2 or facets.size == 0:
            facets = facets.reshape(0, facets.shape[-1] if facets.ndim == 2 else 1)
        out[name] = facets.astype(node_type, copy=False)
    return out


def _extract(whole: Mesh, part: Partition, rank: int) -> dict:
    """Rank ``rank``'s part of the whole mesh (see the module's doc), as LocalMesh fields."""
    cells = whole.cells
    node_part = part.node_part
    local_cells = np.flatnonzero((node_part[cells] == rank).any(axis=1))
    owned = np.flatnonzero(node_part == rank)
    touched = np.zeros(whole.num_points, dtype=bool)   # a mask, not a sort: np.unique's ids
    touched[cells[local_cells]] = True
    touched = np.flatnonzero(touched)
    ghosts = touched[node_part[touched] != rank]
    ghosts = ghosts[np.argsort(part.new_of_old[ghosts], kind="stable")]
    local_nodes = np.concatenate([owned, ghosts])
    node_type = index_dtype(whole.num_points, COMPONENT_MARGIN)
    local_type = index_dtype(local_nodes.size, COMPONENT_MARGIN)
    to_local = np.full(whole.num_points, -1, dtype=local_type)
    to_local[local_nodes] = np.arange(local_nodes.size)
    cell_groups = {}
    for name, ids in whole.cell_groups.items():
        ids = np.asarray(ids, dtype=np.int64)
        pos = np.searchsorted(local_cells, ids)
        hit = (pos < local_cells.size) & (local_cells[np.minimum(pos, local_cells.size - 1)] == ids) \
            if local_cells.size else np.zeros(ids.size, dtype=bool)
        cell_groups[name] = pos[hit].astype(index_dtype(local_cells.size))
    facet_groups = {}
    for name, facets in whole.facet_groups.items():
        facets = np.asarray(facets, dtype=np.int64)
        if facets.ndim != 2 or facets.size == 0:
            facet_groups[name] = facets.reshape(0, facets.shape[-1] if facets.ndim == 2 else 1) \
                .astype(local_type)
            continue
        mapped = to_local[facets]
        # facets with an owned node: their cell is local, so they are boundary facets here too
        keep = (mapped >= 0).all(axis=1) & (mapped < owned.size).any(axis=1)
        facet_groups[name] = mapped[keep]
    node_groups = {}
    for name, ids in whole.node_groups.items():
        mapped = to_local[np.asarray(ids, dtype=np.int64)]
        node_groups[name] = mapped[mapped >= 0]
    return {"points": whole.points[local_nodes], "cells": to_local[cells[local_cells]],
            "cell_groups": cell_groups, "facet_groups": facet_groups, "node_groups": node_groups,
            "global_nodes": local_nodes.astype(node_type),
            "global_cells": local_cells.astype(index_dtype(whole.num_cells)),
            "node_new": part.new_of_old[local_nodes].astype(node_type)}
