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
from typing import Callable

import numpy as np

from parsolve.fem.axisymmetric import is_axisymmetric, scale
from parsolve.fem.element_matrices import CellKernel, ElementMatrices
from parsolve.fem.elements import (default_degree, element, facet_measure_and_normal,
                                   physical_gradients, polynomial_order, quadrature)


FACET_BLOCK = 4096   # facets or cells integrated at once (bounded work arrays)


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


def facet_matrices(points: np.ndarray, facets: np.ndarray, facet_type: str, thickness,
                   values: Callable[[Rule, slice], np.ndarray], rows: int = 1,
                   block: int | None = None) -> ElementMatrices:
    """A facet term's element arrays (rows, nfn, nfn, k) on ``facets`` (k, nfn), computed in
    blocks of at most ``FACET_BLOCK`` facets when asked (assembly, products), never all at
    once: ``values(rule, block)`` gives a block's arrays from its quadrature rule (e.g.
    ``weighted_mass(rule, h)``)."""
    nfn = facets.shape[1]

    def compute(sl, out):
        block = facets[sl]
        rule = facet_rule(points[block], facet_type, thickness)
        v = values(rule, sl)
        if out is not None and out.shape == v.shape:
            out[...] = v
            return out
        return v

    m = ElementMatrices(kernel=CellKernel(compute, facets.shape[0], rows, nfn,
                                          block=FACET_BLOCK if block is None else block))
    m.nodes = facets
    return m


def weighted_mass(rule: Rule, c) -> np.ndarray:
    """∫ c N_a N_b over each facet or cell, cell-last as a term's values (1, nen, nen, n);
    ``c`` a number or (n, nq) values at the rule's points."""
    w = rule.weights * c
    return np.einsum("qa,qb,nq->abn", rule.N, rule.N, w)[None]
