"""Integrals at quadrature points on boundary facets (curved second-order ones included) and on
cells: the points, the weights (w |J| × the out-of-plane measure: thickness or 2π r) and the
facets' unit normals, for loads whose value varies over the element (an expression of the
coordinates, a pressure along the normal of a curved face) and for facet terms of an operator
(an exchange condition's h ∫ N Nᵀ, a term on the facets' nodes).

The facet normal is the one of ``elements.facet_measure_and_normal``: outward for the facets
of a region (``FACETS`` order on positively oriented cells), evaluated at each quadrature point
of the facet's own geometry (a six-node triangle or three-node line follows the curve).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.fem.axisymmetric import is_axisymmetric, scale
from parsolve.fem.elements import (default_degree, element, facet_measure_and_normal,
                                   physical_gradients, polynomial_order, quadrature)


@dataclass
class Rule:
    """Quadrature on a set of facets or cells: shape functions N (nq, nen), weights (n, nq)
    with the measure, points (n, nq, gdim) and, on facets, unit normals (n, nq, gdim)."""

    N: np.ndarray
    weights: np.ndarray
    points: np.ndarray
    normals: np.ndarray | None = None


def _degree(cell_type: str) -> int:
    """Exact for a polynomial value of the element's order on a curved facet, the 2π r
    factor included (N of order p, n ds of order p - 1, r of order p, value of order p)."""
    return 4 * polynomial_order(cell_type)


def facet_rule(coords: np.ndarray, facet_type: str, thickness=1.0) -> Rule:
    """The rule on facets ``coords`` (nf, nfn, gdim)."""
    ref = element(facet_type)
    xi, w = quadrature(facet_type, _degree(facet_type))
    N = ref.shape(xi)
    ds, normals = facet_measure_and_normal(coords, ref.grad_shape(xi))
    points = np.einsum("qa,fad->fqd", N, coords)
    r = points[:, :, 0] if is_axisymmetric(thickness) else None
    return Rule(N, scale(ds * w, r, thickness), points, normals)


def cell_rule(coords: np.ndarray, cell_type: str, thickness=1.0) -> Rule:
    """The rule on cells ``coords`` (nc, nen, dim) (the load degree of the cell type)."""
    ref = element(cell_type)
    xi, w = quadrature(cell_type, default_degree(cell_type, "load") + 2)
    N = ref.shape(xi)
    _, det = physical_gradients(coords, ref.grad_shape(xi))
    points = np.einsum("qa,cad->cqd", N, coords)
    r = points[:, :, 0] if is_axisymmetric(thickness) else None
    return Rule(N, scale(np.abs(det) * w, r, thickness), points)


def integrate(rule: Rule, values: np.ndarray) -> np.ndarray:
    """∫ N_a v over each facet or cell: (n, nen, ncomp) of values (n, nq, ncomp)."""
    return np.einsum("qa,nq,nqc->nac", rule.N, rule.weights, values)


def mass(rule: Rule) -> np.ndarray:
    """∫ N_a N_b over each facet or cell: (n, nen, nen)."""
    return np.einsum("qa,qb,nq->nab", rule.N, rule.N, rule.weights)
