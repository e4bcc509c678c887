"""Load patterns: named force vectors (tractions, resultant-normalised tractions, body and
nodal forces), each part following its evolution. A pattern named as the dual of a relation is
that relation's reaction direction and is not applied as a known load."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from parsolve.errors import InputError
from parsolve.fem import kernels
from parsolve.mesh.mesh import Mesh


@dataclass
class LoadPattern:
    name: str
    parts: list = field(default_factory=list)   # (vector, evolution)

    def vector(self) -> np.ndarray:
        """The pattern at unit intensity (evolutions ignored): a relation's dual direction."""
        return np.sum([v for v, _ in self.parts], axis=0)

    def at(self, t: float) -> np.ndarray:
        return np.sum([v * evol(t) for v, evol in self.parts], axis=0)


def _scatter(ndof: int, dofs: np.ndarray, values: np.ndarray) -> np.ndarray:
    return np.bincount(dofs.ravel(), weights=values.ravel(), minlength=ndof).astype(float, copy=False)


def _field_dofs(fields, field: str, nodes: np.ndarray) -> np.ndarray:
    """(n, nen·ncomp) DOFs of a field at (n, nen) nodes, node-major (n may be 0: a rank's
    part that holds none of the region, so the width is given, not inferred)."""
    nodes = np.asarray(nodes)
    width = nodes.shape[1] * fields[field].ncomp
    return fields.dofs(field, nodes.ravel()).reshape(nodes.shape[0], width)


def part_vector(mesh: Mesh, spec, region, thickness: float, source: str, fields,
                regions=None) -> np.ndarray:
    """Force vector (the mesh's DOF numbering) of one load entry, on its field. ``regions``
    (the resolver) counts and sums over the whole mesh when the mesh is one rank's part."""
    ndof = mesh.num_points * fields.ncomp
    vec = np.asarray(spec.vector)
    if spec.kind == "nodal":
        dofs = _field_dofs(fields, spec.field, region.nodes[:, None])
        return _scatter(ndof, dofs, np.tile(vec, (len(region.nodes), 1)))
    if spec.kind == "body":
        if (region.cells.size if regions is None else regions.cell_count(region.cells)) == 0:
            raise InputError(f"region {spec.region!r} contains no cell", source, spec.key + ".region")
        if region.cells.size == 0:
            return np.zeros(ndof)
        cells = mesh.cells[region.cells]
        fe = kernels.body_load(mesh.points[cells], mesh.cell_type, vec, thickness)
        return _scatter(ndof, _field_dofs(fields, spec.field, cells), fe)
    if (region.facets.shape[0] if regions is None else regions.facet_count(region.facets)) == 0:
        raise InputError(f"region {spec.region!r} contains no boundary facet", source,
                         spec.key + ".region")
    coords = mesh.points[region.facets]
    if spec.kind == "total_force":   # (collective on a distributed mesh)
        vec = vec / _measure(coords, mesh.facet_type, thickness, region.facets, regions)
    if region.facets.shape[0] == 0:   # none on this rank's part of a distributed mesh
        return np.zeros(ndof)
    fe = kernels.facet_load(coords, mesh.facet_type, vec, thickness)
    return _scatter(ndof, _field_dofs(fields, spec.field, region.facets), fe)


def _measure(coords, facet_type: str, thickness: float, facets, regions) -> float:
    """Total measure of a region's facets (over every rank's part, each facet once)."""
    if regions is None:
        return kernels.facet_measure(coords, facet_type, thickness)
    if coords.shape[0] == 0:
        return regions.facet_total(facets, np.zeros(0))
    return regions.facet_total(facets, kernels.facet_weights(coords, facet_type,
                                                             thickness).sum(axis=1))


def load_patterns(mesh: Mesh, specs: list, regions, evolutions: dict, thickness: float,
                  source: str, fields) -> dict[str, LoadPattern]:
    patterns: dict[str, LoadPattern] = {}
    for spec in specs:
        region = regions(spec.region, spec.key + ".region")
        vec = part_vector(mesh, spec, region, thickness if mesh.dim == 2 else 1.0, source, fields,
                          regions)
        patterns.setdefault(spec.pattern, LoadPattern(spec.pattern)).parts.append(
            (vec, evolutions[spec.evolution]))
    return patterns
