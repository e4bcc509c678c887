"""``nodal``: a force on each node of a region (the whole ring's in an axisymmetric model),
numbers or expressions of (x, y, z, t) evaluated at the nodes."""

from __future__ import annotations

import numpy as np

from parsolve.loads.base import Instant, LoadSpec, Where, field_dofs, scatter, values_at


def assemble(spec: LoadSpec, where: Where, at: Instant) -> np.ndarray:
    nodes = where.region.nodes
    values = values_at(spec, where.mesh.points[nodes], at, where.source)
    return scatter(where.ndof, field_dofs(where.fields, spec.field, nodes[:, None]), values)
