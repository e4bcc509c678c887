"""``nodal``: a force on each node of a region (the whole ring's in an axisymmetric model),
numbers or expressions of (x, y, z, t) evaluated at the nodes."""

from __future__ import annotations

from typing import Iterable

from parsolve.fem.element_matrices import NodeForces
from parsolve.loads.base import Instant, LoadSpec, Where, values_at


def forces(spec: LoadSpec, where: Where, at: Instant) -> Iterable[NodeForces]:
    nodes = where.region.nodes
    values = values_at(spec, where.mesh.points[nodes], at, where.source)
    return [NodeForces(nodes[:, None], values[:, None, :])]
