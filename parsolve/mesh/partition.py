"""Cell partition and node renumbering.

Rank 0 holds the whole mesh (``distribute``). Cells are split into one part per rank either by
PT-Scotch (a graph partitioner, through PETSc's MatPartitioning) on the cell dual graph (cells
sharing a facet; every rank builds its block of rows, ``blocks.facet_groups``), or by recursive
coordinate bisection of the centroids (RCB: no communication, the fallback for one rank, for
meshes too small to be worth a graph partitioner, or on request). PT-Scotch runs once at
set-up, each rank handing it its block of dual-graph rows (``scotch_block``); rank 0 gathers
the parts (``distribute``).

A node belongs to the lowest rank among the cells that touch it. Nodes are then renumbered so
that each rank owns a contiguous block, keeping the input order inside a block (which keeps the
bandwidth the input mesh had).
"""

from __future__ import annotations

import ctypes
import functools
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parsolve.mesh.mesh import Mesh

PARTITIONERS = ("scotch", "bisection")
# below this many cells per part a graph partitioner has nothing to gain (and PT-Scotch may
# leave a part empty): coordinate bisection instead
MIN_CELLS_PER_PART = 8


@dataclass
class Partition:
    """Where each cell and node lives, and the contiguous node numbering that follows."""

    nparts: int
    cell_part: np.ndarray   # (ncells,) rank owning each cell
    node_part: np.ndarray   # (npoints,) rank owning each node
    new_of_old: np.ndarray  # (npoints,) new node number of each input node
    node_ranges: np.ndarray  # (nparts + 1,) node block [node_ranges[r], node_ranges[r+1]) of rank r
    method: str = "bisection"  # the partitioner that actually ran ("none" for one part)

    def local_cells(self, rank: int, cells: np.ndarray) -> np.ndarray:
        """Cells that touch a node owned by ``rank``: the ones it needs to assemble its rows."""
        return np.flatnonzero((self.node_part[cells] == rank).any(axis=1))

    def owned_cells(self, rank: int, cells: np.ndarray) -> np.ndarray:
        """Cells this rank reports: those whose lowest node owner is ``rank`` (a subset of its
        local cells, so it holds their history variables)."""
        return np.flatnonzero(self.node_part[cells].min(axis=1) == rank)


# ------------------------------------------------------------------ dual graph


def edge_cut(indptr: np.ndarray, indices: np.ndarray, cell_part: np.ndarray) -> int:
    """Dual-graph edges (shared facets) between cells of different parts."""
    rows = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    return int(np.count_nonzero(cell_part[rows] != cell_part[indices])) // 2


# ------------------------------------------------------------------ partitioners


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


@functools.lru_cache(maxsize=1)
def _loaded_ptscotch() -> ctypes.CDLL | None:
    """The PT-Scotch library PETSc loaded (found in this process's memory map: faster than
    ctypes.util.find_library, which runs ldconfig), or None."""
    try:
        maps = Path("/proc/self/maps").read_text()
    except OSError:
        return None
    paths = {line.split()[-1] for line in maps.splitlines() if "/libptscotch-" in line
             or line.endswith("/libptscotch.so")}
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
            lib.SCOTCH_randomReset  # noqa: B018 (present?)
            return lib
        except (OSError, AttributeError):
            continue
    return None


def _scotch_random_reset() -> None:
    """Restart Scotch's random generator from its fixed seed, so that a second partition in
    the same process repeats the first (the generator's state otherwise carries over).
    Without the library (another platform), determinism rests on the single thread alone."""
    lib = _loaded_ptscotch()
    if lib is not None:
        lib.SCOTCH_randomReset()


def block_starts(n: int, size: int) -> np.ndarray:
    """Rows [starts[r], starts[r+1]) of a graph of n vertices that rank r hands PT-Scotch."""
    return np.array([n * r // size for r in range(size + 1)], dtype=np.int64)


def scotch_block(comm, n: int, local_ptr: np.ndarray, local_idx: np.ndarray) -> np.ndarray | None:
    """PT-Scotch parts of this rank's block of rows (``block_starts``) of a graph of n
    vertices given as the block's CSR (global column ids), into comm.size parts; collective;
    None when PETSc has no PT-Scotch.

    The block goes to PETSc as an MPIAIJ adjacency matrix that MatPartitioning converts to
    MPIAdj (petsc4py 3.18 has no createAdj); the parts come back as an IS of the block.
    Deterministic: PT-Scotch is run with one thread per process (Debian's build spawns threads
    whose timing changes the result from run to run; no MatPartitioning strategy avoids that)
    and its random generator restarted from its fixed seed. Uniform vertex weights: a mesh has
    one cell type, so nodes per cell are the same for every cell."""
    from petsc4py import PETSc

    local_ptr = np.asarray(local_ptr).astype(PETSc.IntType)
    local_idx = np.asarray(local_idx).astype(PETSc.IntType)
    nloc = local_ptr.size - 1
    adj = PETSc.Mat().createAIJ(size=((nloc, n), (nloc, n)),
                                csr=(local_ptr, local_idx, np.ones(local_idx.size)), comm=comm)
    adj.assemble()
    part = PETSc.MatPartitioning().create(comm=comm)
    part.setAdjacency(adj)
    try:
        part.setType(PETSc.MatPartitioning.Type.PARTITIONINGPTSCOTCH)
    except PETSc.Error:  # a PETSc built without PT-Scotch (on every rank alike)
        part.destroy()
        adj.destroy()
        return None
    threads = os.environ.get("SCOTCH_PTHREAD_NUMBER")
    os.environ["SCOTCH_PTHREAD_NUMBER"] = "1"  # read by Scotch at each call
    try:
        _scotch_random_reset()
        parts = PETSc.IS()
        part.apply(parts)
    finally:
        if threads is None:
            del os.environ["SCOTCH_PTHREAD_NUMBER"]
        else:
            os.environ["SCOTCH_PTHREAD_NUMBER"] = threads
    local = parts.getIndices().astype(np.int64)
    for obj in (parts, part, adj):
        obj.destroy()
    return local


def from_cell_parts(mesh: Mesh, cell_part: np.ndarray, nparts: int, used: str) -> Partition:
    """Node owners (the lowest rank among the cells that touch a node) and the contiguous
    node numbering that follow from the cells' parts."""
    npts = mesh.num_points
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
    return Partition(nparts, cell_part, node_part, new_of_old, node_ranges, used)
