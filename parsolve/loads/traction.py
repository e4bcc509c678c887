"""``traction`` (``flux`` on a scalar field): a force per unit area of a boundary region,
numbers or expressions of (x, y, z, t), integrated at the facets' quadrature points."""

from __future__ import annotations

import numpy as np

from parsolve.fem.integrals import facet_rule, integrate
from parsolve.loads.base import (Instant, LoadSpec, Where, blocks, field_dofs, need_facets,
                                 scatter, values_at)


def facet_forces(spec: LoadSpec, where: Where, value) -> np.ndarray:
    """Σ ∫ N_a v ds over the region's facets as a full vector; ``value(rule)`` gives the
    force per unit area (nf, nq, ncomp) at the rule's points."""
    facets = where.region.facets
    out = np.zeros(where.ndof)
    for sl in blocks(facets.shape[0]):
        rule = facet_rule(where.mesh.points[facets[sl]], where.mesh.facet_type, where.thickness)
        fe = integrate(rule, value(rule))
        out += scatter(where.ndof, field_dofs(where.fields, spec.field, facets[sl]),
                       fe.reshape(fe.shape[0], -1))
    return out


def assemble(spec: LoadSpec, where: Where, at: Instant) -> np.ndarray:
    need_facets(spec, where)
    return facet_forces(spec, where, lambda rule: values_at(spec, rule.points, at, where.source))
