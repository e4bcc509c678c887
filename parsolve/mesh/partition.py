"""Cell partition and node renumbering.

Every rank holds the whole (replicated) mesh and computes the same partition, so no
communication is needed to agree on it. Cells are split by recursive coordinate bisection of
their centroids; a node belongs to the lowest rank among the cells that touch it. Nodes are then
renumbered so that each rank owns a contiguous block, keeping the input order inside a block
(which keeps the bandwidth the input mesh had).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.mesh.mesh import Mesh


@dataclass
class Partition:
    """Where each cell and node lives, and the contiguous node numbering that follows."""

    nparts: int
    cell_part: np.ndarray   # (ncells,) rank owning each cell
    node_part: np.ndarray   # (npoints,) rank owning each node
    new_of_old: np.ndarray  # (npoints,) new node number of each input node
    node_ranges: np.ndarray  # (nparts + 1,) node block [node_ranges[r], node_ranges[r+1]) of rank r

    def local_cells(self, rank: int, cells: np.ndarray) -> np.ndarray:
        """Cells that touch a node owned by ``rank``: the ones it needs to assemble its rows."""
        return np.flatnonzero((self.node_part[cells] == rank).any(axis=1))

    def owned_cells(self, rank: int, cells: np.ndarray) -> np.ndarray:
        """Cells this rank reports: those whose lowest node owner is ``rank`` (a subset of its
        local cells, so it holds their history variables)."""
        return np.flatnonzero(self.node_part[cells].min(axis=1) == rank)


def bisect(centroids: np.ndarray, nparts: int) -> np.ndarray:
    """Recursive coordinate bisection: part index of each point, parts of near-equal size."""
    part = np.zeros(len(centroids), dtype=np.int64)
    stack = [(np.arange(len(centroids)), 0, nparts)]
    while stack:
        idx, first, count = stack.pop()
        if count == 1 or idx.size == 0:
            part[idx] = first
            continue
        left_count = count // 2
        pts = centroids[idx]
        axis = int(np.argmax(pts.max(axis=0) - pts.min(axis=0)))
        # stable sort so that ties split the same way on every rank
        order = idx[np.argsort(pts[:, axis], kind="stable")]
        cut = (idx.size * left_count) // count
        stack.append((order[:cut], first, left_count))
        stack.append((order[cut:], first + left_count, count - left_count))
    return part


def partition(mesh: Mesh, nparts: int) -> Partition:
    """Partition cells, assign node owners and renumber nodes contiguously per rank."""
    npts = mesh.num_points
    if nparts == 1:
        cell_part = np.zeros(mesh.num_cells, dtype=np.int64)
    else:
        cell_part = bisect(mesh.points[mesh.cells].mean(axis=1), nparts)
    node_part = np.full(npts, nparts, dtype=np.int64)
    for rank in range(nparts - 1, -1, -1):  # lowest rank written last wins
        node_part[mesh.cells[cell_part == rank]] = rank
    # nodes no cell uses (stray points of a mesh file) go to the last rank
    node_part[node_part == nparts] = nparts - 1
    order = np.argsort(node_part, kind="stable")
    new_of_old = np.empty(npts, dtype=np.int64)
    new_of_old[order] = np.arange(npts)
    counts = np.bincount(node_part, minlength=nparts)
    node_ranges = np.concatenate([[0], np.cumsum(counts)])
    return Partition(nparts, cell_part, node_part, new_of_old, node_ranges)
