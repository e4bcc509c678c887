"""``pressure``: a pressure p on a boundary region, acting against the outward normal of the
body (t = -p n), the normal taken at each quadrature point of the facet's own geometry (a
curved second-order face follows its curve). A number or an expression of (x, y, z, t);
2D (per unit thickness × thickness), axisymmetric (over the revolved surface) and 3D."""

from __future__ import annotations

from typing import Iterable

from parsolve.fem.element_matrices import NodeForces
from parsolve.loads.base import Instant, LoadSpec, Where, need_facets, values_at
from parsolve.loads.traction import facet_forces


def forces(spec: LoadSpec, where: Where, at: Instant) -> Iterable[NodeForces]:
    need_facets(spec, where)
    return facet_forces(where, lambda rule: -values_at(spec, rule.points, at, where.source)
                        * rule.normals)
