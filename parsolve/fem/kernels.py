"""Vectorised element kernels: every function works on a stack of cells at once."""

from __future__ import annotations

import numpy as np

from parsolve.fem.elements import default_degree, element, facet_measure_and_normal, \
    physical_gradients, quadrature


class CellGeometry:
    """Shape-function gradients and quadrature weights of a stack of cells."""

    def __init__(self, coords: np.ndarray, cell_type: str, degree: int | None = None,
                 thickness: float = 1.0, points: np.ndarray | None = None):
        """``points``: evaluate at these reference points (unit weights) instead of quadrature."""
        ref = element(cell_type)
        deg = default_degree(cell_type, "stiffness") if degree is None else degree
        xi, w = quadrature(cell_type, deg) if points is None else (points, np.ones(len(points)))
        self.N = ref.shape(xi)                              # (nq, nen)
        self.dNdx, det = physical_gradients(coords, ref.grad_shape(xi))
        self.wdet = np.abs(det) * w[None, :] * thickness    # (nc, nq)
        self.nq = len(w)

    def strain_operator(self) -> np.ndarray:
        """B (nc, nq, nvoigt, nen*dim), engineering shear, Voigt order xx yy (zz) (yz xz) xy."""
        g = self.dNdx
        nc, nq, nen, dim = g.shape
        if dim == 2:
            B = np.zeros((nc, nq, 3, nen, 2))
            B[:, :, 0, :, 0] = g[..., 0]
            B[:, :, 1, :, 1] = g[..., 1]
            B[:, :, 2, :, 0] = g[..., 1]
            B[:, :, 2, :, 1] = g[..., 0]
        else:
            B = np.zeros((nc, nq, 6, nen, 3))
            for i in range(3):
                B[:, :, i, :, i] = g[..., i]
            for row, (i, j) in zip((3, 4, 5), ((1, 2), (0, 2), (0, 1))):
                B[:, :, row, :, i] = g[..., j]
                B[:, :, row, :, j] = g[..., i]
        return B.reshape(nc, nq, B.shape[2], nen * dim)


def stiffness(B: np.ndarray, wdet: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Ke = Σ_q w |J| Bᵀ C B; C is (nvoigt, nvoigt), per cell (nc, 1, nv, nv) or per point."""
    CB = np.matmul(C, B)                                   # (nc, nq, nv, ndof)
    Bw = B * wdet[:, :, None, None]
    ke = np.matmul(Bw.transpose(0, 1, 3, 2), CB)           # (nc, nq, ndof, ndof)
    return ke.sum(axis=1) if ke.shape[1] > 1 else ke[:, 0]


def strains(B: np.ndarray, ue: np.ndarray) -> np.ndarray:
    """ε at quadrature points (nc, nq, nvoigt) from element DOF values ue (nc, ndof)."""
    return np.matmul(B, ue[:, None, :, None])[..., 0]


def internal_forces(B: np.ndarray, wdet: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """fe = Σ_q w |J| Bᵀ σ, (nc, ndof)."""
    return np.einsum("cqvd,cqv->cd", B, sigma * wdet[:, :, None])


def body_load(coords: np.ndarray, cell_type: str, force: np.ndarray, thickness: float = 1.0):
    """Element load vectors (nc, nen*dim) of a constant body force per unit volume."""
    ref = element(cell_type)
    xi, w = quadrature(cell_type, default_degree(cell_type, "load"))
    N = ref.shape(xi)
    _, det = physical_gradients(coords, ref.grad_shape(xi))
    wn = (np.abs(det) * w * thickness) @ N                 # (nc, nen): ∫ N_a
    return (wn[:, :, None] * force[None, None, :]).reshape(len(coords), -1)


def facet_load(coords: np.ndarray, facet_type: str, traction: np.ndarray,
               thickness: float = 1.0) -> np.ndarray:
    """Facet load vectors (nf, nfn*gdim) of a constant traction (force per unit area)."""
    ref = element(facet_type)
    xi, w = quadrature(facet_type, default_degree(facet_type, "load"))
    N = ref.shape(xi)
    ds, _ = facet_measure_and_normal(coords, ref.grad_shape(xi))
    wn = (ds * w * thickness) @ N
    return (wn[:, :, None] * traction[None, None, :]).reshape(len(coords), -1)


def facet_measure(coords: np.ndarray, facet_type: str, thickness: float = 1.0) -> float:
    """Total measure (length × thickness in 2D, area in 3D) of a set of facets."""
    ref = element(facet_type)
    xi, w = quadrature(facet_type, default_degree(facet_type, "load"))
    ds, _ = facet_measure_and_normal(coords, ref.grad_shape(xi))
    return float((ds * w).sum() * thickness)


def cell_dofs(cells: np.ndarray, ncomp: int) -> np.ndarray:
    """Element DOF numbers (nc, nen*ncomp), node-major, from node numbers."""
    return (cells[:, :, None] * ncomp + np.arange(ncomp)).reshape(len(cells), -1)
