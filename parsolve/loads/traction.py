"""``traction`` (``flux`` on a scalar field): a force per unit area of a boundary region,
numbers or expressions of (x, y, z, t), integrated at the facets' quadrature points."""

from __future__ import annotations

from typing import Iterator

import numpy as np

from parsolve.fem.element_matrices import NodeForces
from parsolve.fem.integrals import facet_rule, integrate
from parsolve.loads.base import Instant, LoadSpec, Where, blocks, need_facets, values_at


def facet_forces(where: Where, value) -> Iterator[NodeForces]:
    """∫ N_a v ds on the region's facets, facet block after facet block (a generator: one
    block's arrays at a time); ``value(rule)`` gives the force per unit area (nf, nq, ncomp)
    at the rule's points."""
    facets = where.region.facets
    for sl in blocks(facets.shape[0]):
        rule = facet_rule(where.mesh.points[facets[sl]], where.mesh.facet_type, where.thickness)
        yield NodeForces(facets[sl], integrate(rule, value(rule)))


def forces(spec: LoadSpec, where: Where, at: Instant) -> Iterator[NodeForces]:
    need_facets(spec, where)
    return facet_forces(where, lambda rule: values_at(spec, rule.points, at, where.source))
