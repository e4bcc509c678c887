"""Find the cell that contains a point and its reference coordinates, vectorised over cells.

Candidates are the cells whose bounding box holds the point; for all of them at once the
isoparametric map x(ξ) = Σ N_a(ξ) X_a is inverted by Newton's method (exact in one step for
affine cells, a few steps for curved P2 cells, bilinear or curved Q2 quadrilaterals and
hexahedra)."""

from __future__ import annotations

import numpy as np

from parsolve.fem.elements import element

SIMPLICES = ("triangle", "triangle6", "tetra", "tetra10")


def _inside(cell_type: str, xi: np.ndarray, tol: float) -> np.ndarray:
    if cell_type in SIMPLICES:
        return (xi >= -tol).all(axis=1) & (xi.sum(axis=1) <= 1.0 + tol)
    return (np.abs(xi) <= 1.0 + tol).all(axis=1)


def _start(cell_type: str, n: int, dim: int) -> np.ndarray:
    return np.full((n, dim), 1.0 / (dim + 1) if cell_type in SIMPLICES else 0.0)


def locate(points: np.ndarray, cells: np.ndarray, cell_type: str, x, tol: float = 1e-9
           ) -> tuple[int, np.ndarray] | None:
    """(cell index, ξ (dim,)) of a cell containing x, or None if x is outside the mesh.

    On a shared face any of the cells is returned (the first in mesh order), which is enough
    for continuous (nodal) fields."""
    x = np.asarray(x, dtype=float)
    ref = element(cell_type)
    coords = points[cells]                                    # (nc, nen, dim)
    extent = np.ptp(points, axis=0).max()
    slack = tol * extent + 1e-14
    box = (coords.min(axis=1) - slack <= x).all(axis=1) & (x <= coords.max(axis=1) + slack).all(axis=1)
    candidates = np.flatnonzero(box)
    if candidates.size == 0:
        return None
    X = coords[candidates]
    xi = _start(cell_type, len(candidates), ref.dim)
    for _ in range(20):
        N = ref.shape(xi)                                     # one reference point per cell
        dN = ref.grad_shape(xi)
        r = x - np.einsum("ca,cad->cd", N, X)
        J = np.einsum("cad,cak->cdk", X, dN)
        ok = np.abs(np.linalg.det(J)) > 0
        step = np.zeros_like(xi)
        step[ok] = np.linalg.solve(J[ok], r[ok][..., None])[..., 0]
        xi = xi + step
        if np.abs(step).max() < 1e-14:
            break
    inside = np.flatnonzero(_inside(cell_type, xi, tol))
    if inside.size == 0:
        return None
    k = inside[0]
    return int(candidates[k]), xi[k]


def interpolate(values: np.ndarray, points: np.ndarray, cells: np.ndarray, cell_type: str,
                x) -> np.ndarray | None:
    """Nodal values (..., npoints, ncomp) interpolated at x with the element's shape functions:
    (..., ncomp), or None if x is outside the mesh."""
    found = locate(points, cells, cell_type, x)
    if found is None:
        return None
    cell, xi = found
    N = element(cell_type).shape(xi[None, :])[0]              # (nen,)
    return np.einsum("a,...ac->...c", N, values[..., cells[cell], :])
