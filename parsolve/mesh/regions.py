"""Regions: named sets of nodes, boundary facets and cells, resolved on one rank's part of the
mesh (``distribute.LocalMesh``; on 1 rank the whole mesh).

Node, facet and cell sets are local (local ids), but every decision is the whole mesh's: the
geometric tolerance from the whole extent, a point region's node (the closest over all ranks,
ties to the lowest input id), "selects nothing" from the counts over all ranks, and an input
error raised on one rank is raised on every rank. Boundary facets are kept only where they have
an owned node: a facet of a ghost cell whose other side lives on another rank looks like a
boundary facet here, but it has no owned node.

Relations are built on the whole mesh's numbering (input ids), each rank on the nodes and cells
it owns; ``relation_nodes`` gathers a region's owned nodes from every rank (the region's size,
not the mesh's) for the effects that still need a region whole (springs, contact surfaces).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsolve.collective import agree
from parsolve.errors import InputError
from parsolve.mesh import selectors
from parsolve.mesh.distribute import LocalMesh, distribute
from parsolve.mesh.mesh import Mesh
from parsolve.mesh.topology import boundary_facets, facets_from_nodes, match_facets


@dataclass
class Region:
    name: str
    nodes: np.ndarray        # node ids
    facets: np.ndarray       # (nf, nfn) outward-oriented boundary facets all of whose nodes are in the region
    cells: np.ndarray        # cell ids


def allgather_rows(comm, local: np.ndarray) -> np.ndarray:
    """Every rank's rows, concatenated in rank order (buffer collective)."""
    local = np.ascontiguousarray(local)
    width = int(np.prod(local.shape[1:], dtype=np.int64))
    counts = np.array(comm.allgather(local.shape[0]), dtype=np.int64)
    out = np.empty((int(counts.sum()),) + local.shape[1:], dtype=local.dtype)
    kind = MPI._typedict[local.dtype.char]
    comm.Allgatherv([local, kind], [out, counts * width, kind])
    return out


class RegionResolver:
    """Resolves region names (scene selectors, file or generator groups, 'all') lazily, once,
    on a rank's part of the mesh; collective over ``comm``. A whole ``Mesh`` (with no
    ``comm``: this process alone) is taken as its 1-rank part (a view, not a copy)."""

    def __init__(self, mesh: Mesh, specs: dict, source: str, comm=None):
        self.comm = MPI.COMM_SELF if comm is None else comm
        if not isinstance(mesh, LocalMesh):
            mesh = distribute(MPI.COMM_SELF, mesh)
        self.mesh, self.specs, self.source = mesh, specs, source
        extent = float(mesh.extent.max()) if mesh.extent.size else 1.0
        self.tol = 1e-8 * max(extent, 1e-300)
        self.cache: dict[str, Region] = {}
        self._centroids = None
        self._coords: dict[str, np.ndarray] = {}

    def names(self) -> set[str]:
        m = self.mesh
        return set(self.specs) | set(m.cell_groups) | set(m.facet_groups) | set(m.node_groups) | {"all"}

    def __call__(self, name: str, key: str) -> Region:
        if name not in self.cache:
            self.cache[name] = self._resolve(name, key)
        return self.cache[name]

    def centroids(self) -> np.ndarray:
        if self._centroids is None:
            self._centroids = self.mesh.points[self.mesh.cells].mean(axis=1)
        return self._centroids

    def _from_mask(self, name: str, mask: np.ndarray, cell_mask: np.ndarray) -> Region:
        facets = self._kept(facets_from_nodes(self.mesh, mask)[0])
        return Region(name, np.flatnonzero(mask), facets, np.flatnonzero(cell_mask))

    def _reported(self, nodes: np.ndarray) -> np.ndarray:
        """Which cells or facets (rows of node ids) this rank counts: those whose lowest node
        owner it is, so that each is counted once over the ranks."""
        if nodes.size == 0:
            return np.zeros(nodes.shape[0], dtype=bool)
        return self.mesh.owner_of(nodes).min(axis=1) == self.mesh.rank

    def _local(self, fn, *args):
        """A check on this rank's points: its InputError raised on every rank."""
        return agree(self.comm, fn, *args)

    def _kept(self, facets: np.ndarray) -> np.ndarray:
        """The boundary facets with an owned node (see the module's doc)."""
        if facets.size == 0:
            return facets
        return facets[(facets < self.mesh.n_owned).any(axis=1)]

    def _closest(self, spec) -> np.ndarray:
        m = self.mesh
        p = self._local(selectors._as_point, spec.value, m.points.shape[1], "point",
                        self.source, spec.key)
        d2 = np.sum((m.points[:m.n_owned] - p) ** 2, axis=1)
        best = (float(d2.min()), int(m.global_nodes[np.argmin(d2)])) if d2.size else (np.inf, -1)
        # the smallest distance, then the lowest input id (the whole mesh's argmin's first)
        candidates = self.comm.allgather(best)
        dist = min(c[0] for c in candidates)
        node = min(c[1] for c in candidates if c[0] == dist)
        if node < 0:
            raise InputError("no points to choose from", self.source, spec.key)
        return m.global_nodes == node

    def _empty(self, region: Region) -> bool:
        m = self.mesh
        count = int(np.count_nonzero(region.nodes < m.n_owned)) + \
            int(self._reported(m.cells[region.cells]).sum())
        return self.comm.allreduce(count) == 0

    def _resolve(self, name: str, key: str) -> Region:
        m = self.mesh
        if name in self.specs:
            spec = self.specs[name]
            pts, cen = m.points, self.centroids()
            if spec.kind == "expr":
                mask, cmask = self._local(lambda: (
                    selectors.evaluate(spec.value, pts, self.tol, self.source, spec.key),
                    selectors.evaluate(spec.value, cen, self.tol, self.source, spec.key)))
            elif spec.kind == "box":
                mask, cmask = self._local(lambda: (
                    selectors.box(*spec.value, pts, self.tol, self.source, spec.key),
                    selectors.box(*spec.value, cen, self.tol, self.source, spec.key)))
            elif spec.kind == "point":
                mask = self._closest(spec)
                cmask = np.zeros(m.num_cells, dtype=bool)
            else:
                return self._group(spec.value, spec.key, name)
            region = self._from_mask(name, mask, cmask)
            if self._empty(region):
                raise InputError(f"region {name!r} selects no node and no cell", self.source, spec.key)
            return region
        return self._group(name, key, name)

    def _group(self, group: str, key: str, name: str) -> Region:
        m = self.mesh
        if group == "all":
            return Region(name, np.arange(m.num_points), self._kept(boundary_facets(m)[0]),
                          np.arange(m.num_cells))
        if group in m.cell_groups:
            cells = m.cell_groups[group]
            mask = np.zeros(m.num_points, dtype=bool)
            mask[m.cells[cells]] = True
            region = self._from_mask(name, mask, np.zeros(m.num_cells, dtype=bool))
            region.cells = cells
            return region
        if group in m.facet_groups:
            facets = self._local(match_facets, m, m.facet_groups[group], self.source, key)[2]
            return Region(name, np.unique(facets), facets, np.zeros(0, dtype=np.int64))
        if group in m.node_groups:
            nodes = np.asarray(m.node_groups[group], dtype=np.int64)
            return Region(name, nodes, np.zeros((0, 0), dtype=np.int64), np.zeros(0, dtype=np.int64))
        known = ", ".join(sorted(self.names()))
        raise InputError(f"unknown region {group!r} (known: {known})", self.source, key)

    def relation_nodes(self, name: str, key: str) -> np.ndarray:
        """The region's nodes as input ids, the whole region on every rank (sorted)."""
        if name not in self._coords:
            region = self(name, key)
            own = region.nodes[region.nodes < self.mesh.n_owned]
            # input ids as int64: relations turn them into DOFs (node * ncomp + c)
            ids = allgather_rows(self.comm, self.mesh.global_nodes[own].astype(np.int64))
            pts = allgather_rows(self.comm, self.mesh.points[own])
            order = np.argsort(ids)
            self._coords[name] = (ids[order], pts[order])
        return self._coords[name][0]

    def points_of(self, nodes: np.ndarray) -> np.ndarray:
        """Coordinates of input ids of nodes of regions already asked for ``relation_nodes``."""
        for ids, pts in self._coords.values():
            pos = np.minimum(np.searchsorted(ids, nodes), max(ids.size - 1, 0))
            if ids.size and np.array_equal(ids[pos], nodes):
                return pts[pos]
        raise KeyError("points_of: nodes of no gathered region")

    def owned_cells(self, cells: np.ndarray) -> np.ndarray:
        """Those of the local ``cells`` this rank counts (the rank of their lowest-owner node:
        each cell of the mesh counted by one rank)."""
        cells = np.asarray(cells, dtype=np.int64)
        return cells[self._reported(self.mesh.cells[cells])]

    def cell_count(self, cells: np.ndarray) -> int:
        m = self.mesh
        own = self._reported(m.cells[cells])
        return self.comm.allreduce(int(own.sum()))

    def facet_count(self, facets: np.ndarray) -> int:
        return self.comm.allreduce(int(facets.shape[0]))

    def facet_total(self, facets: np.ndarray, values: np.ndarray) -> float:
        """Each facet counted by the rank owning its lowest-owner node."""
        m = self.mesh
        own = self._reported(facets)
        return self.comm.allreduce(float(np.sum(np.asarray(values)[own])))

    def relation_vector(self, vector: np.ndarray, ncomp: int) -> tuple[np.ndarray, np.ndarray]:
        """This rank's part of a load pattern as a relation's dual: the nonzeros of a local
        primal vector on its owned DOFs, as input DOFs (sorted), each DOF on its owner alone
        (``Relation.shared_dual``); no rank holds another's."""
        nz = np.flatnonzero(vector[:self.mesh.n_owned * ncomp])
        node, comp = np.divmod(nz, ncomp)
        dofs = self.mesh.global_nodes[node].astype(np.int64) * ncomp + comp
        order = np.argsort(dofs)
        return dofs[order], np.asarray(vector[nz], dtype=float)[order]
