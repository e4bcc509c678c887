"""``total_force`` (``total_flux`` on a scalar field): a resultant spread uniformly over a
boundary region (the traction is the force over the region's whole measure, every rank's
facets counted once)."""

from __future__ import annotations

from typing import Iterable

import numpy as np

from parsolve.fem.element_matrices import NodeForces
from parsolve.fem.integrals import facet_rule
from parsolve.loads.base import Instant, LoadSpec, Where, need_facets
from parsolve.loads.traction import facet_forces


def measure(where: Where) -> float:
    """The region's facets' total measure (collective)."""
    facets = where.region.facets
    rule = facet_rule(where.mesh.points[facets], where.mesh.facet_type, where.thickness)
    return where.regions.facet_total(facets, rule.weights.sum(axis=1))


def forces(spec: LoadSpec, where: Where, at: Instant) -> Iterable[NodeForces]:
    need_facets(spec, where)
    traction = np.asarray(spec.vector, dtype=float) / measure(where)
    return facet_forces(where, lambda rule: np.broadcast_to(
        traction, rule.weights.shape + traction.shape))
