"""Regions: named sets of nodes, boundary facets and cells, resolved on the mesh."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.errors import InputError
from parsolve.mesh import selectors
from parsolve.mesh.mesh import Mesh
from parsolve.mesh.topology import boundary_facets, facets_from_nodes, match_facets


@dataclass
class Region:
    name: str
    nodes: np.ndarray        # node ids
    facets: np.ndarray       # (nf, nfn) outward-oriented boundary facets all of whose nodes are in the region
    cells: np.ndarray        # cell ids


class RegionResolver:
    """Resolves region names (scene selectors, file or generator groups, 'all') lazily, once."""

    def __init__(self, mesh: Mesh, specs: dict, source: str):
        self.mesh, self.specs, self.source = mesh, specs, source
        extent = np.ptp(mesh.points, axis=0).max() if mesh.num_points else 1.0
        self.tol = 1e-8 * max(extent, 1e-300)
        self.cache: dict[str, Region] = {}
        self._centroids = None

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

    # ------------------------------------------------ what a distributed mesh changes (below)
    def _local(self, fn, *args):
        """A check on this rank's points (raises InputError)."""
        return fn(*args)

    def _kept(self, facets: np.ndarray) -> np.ndarray:
        """The boundary facets this mesh really has (all of them here)."""
        return facets

    def _closest(self, spec) -> np.ndarray:
        """Mask of the node closest to a point region's point."""
        mask = np.zeros(self.mesh.num_points, dtype=bool)
        mask[selectors.closest_point(spec.value, self.mesh.points, self.source, spec.key)] = True
        return mask

    def _empty(self, region: Region) -> bool:
        return region.nodes.size == 0 and region.cells.size == 0

    def points_of(self, nodes: np.ndarray) -> np.ndarray:
        """Coordinates of nodes given by the ids relations use (here: the mesh's own)."""
        return self.mesh.points[nodes]

    def relation_nodes(self, name: str, key: str) -> np.ndarray:
        """A region's nodes as the ids relations use (here: the mesh's own)."""
        return self(name, key).nodes

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

    def owned_cell_rows(self, cells: np.ndarray, ncomp: int, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
        """Per-cell rows as relations number them: (cell ids, DOFs, the other arrays)."""
        return (cells,) + arrays

    def cell_count(self, cells: np.ndarray) -> int:
        return int(cells.size)

    def facet_count(self, facets: np.ndarray) -> int:
        """Whether any rank has facets (their number here)."""
        return int(facets.shape[0])

    def facet_total(self, facets: np.ndarray, values: np.ndarray) -> float:
        """Σ of per-facet values over the region's facets, each facet once."""
        return float(np.sum(values))

    def relation_vector(self, vector: np.ndarray, ncomp: int) -> tuple[np.ndarray, np.ndarray]:
        """A nodal vector (DOFs of this mesh) as relations take it: (DOFs, nonzero values)."""
        nz = np.flatnonzero(vector)
        return nz, vector[nz]
