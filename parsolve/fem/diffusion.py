"""Vectorised kernels of a scalar diffusion field (heat, Darcy head, concentration).

Weak form of  c ∂h/∂t − div(k ∇h) = f  in Ω,  −(−k ∇h)·n = q  on Γ_q (q: flux *into* Ω):

    ∫ c N_a N_b ḣ_b + ∫ ∇N_a · k ∇N_b h_b = ∫ f N_a + ∫_Γq q N_a

so the conductivity matrix is ``K_ab = ∫ ∇N_aᵀ k ∇N_b``, the capacity (mass) matrix
``M_ab = ∫ c N_a N_b``, the source vector ``∫ f N_a`` and the boundary flux vector
``∫ q N_a``; the flux is ``−k ∇h``. Every kernel works on a stack of cells at once; element
matrices come cell-last, shape (1, nen, nen, nc), the ``ElementMatrices(values=...)`` layout
of a field with one component (d² = 1).

Lumping: row sums for linear cells (triangle, quad, tetra, hexahedron): positive weights
that add up to the cell's capacity. For quadratic cells (triangle6, tetra10) the row sums of
the vertices are zero (triangle6) or negative (tetra10), so the diagonal is *scaled* instead
(Hinton-Rock-Zienkiewicz): m_a = M_aa · (Σ_b ∫ c N_b) / Σ_b M_bb, positive and summing to the
capacity. With HRZ the consistent source ∫ f N_a is no longer proportional to the lumped
weights (it vanishes at the triangle6 vertices), so a uniform source does not keep a uniform
field uniform: use ``source_vector(..., lumped=True)`` (f · m_a) together with a lumped mass.
"""

from __future__ import annotations

import numpy as np

from parsolve.fem.element_matrices import CellKernel, ElementMatrices
from parsolve.fem.elements import default_degree, element, jacobians, polynomial_order, \
    quadrature
from parsolve.fem import kernels
from parsolve.fem.axisymmetric import is_axisymmetric, scale
from parsolve.fem.kernels import geometric_part, gradients_cell_last


def conductivity_tensor(k, nc: int, dim: int) -> np.ndarray:
    """Per-cell conductivity tensors (nc, dim, dim) from a scalar, a per-cell scalar (nc,),
    one tensor (dim, dim) or per-cell tensors (nc, dim, dim)."""
    k = np.asarray(k, dtype=float)
    if k.ndim == 0:
        return np.broadcast_to(k * np.eye(dim), (nc, dim, dim))
    if k.shape == (nc,):
        return k[:, None, None] * np.eye(dim)[None]
    if k.shape == (dim, dim):
        return np.broadcast_to(k, (nc, dim, dim))
    if k.shape == (nc, dim, dim):
        return k
    raise ValueError(f"conductivity must be a scalar, ({nc},), ({dim}, {dim}) or "
                     f"({nc}, {dim}, {dim}); got shape {k.shape}")


def _per_cell(value, nc: int, name: str) -> np.ndarray:
    v = np.asarray(value, dtype=float)
    if v.ndim == 0:
        return np.full(nc, float(v))
    if v.shape == (nc,):
        return v
    raise ValueError(f"{name} must be a scalar or one value per cell ({nc},); got shape {v.shape}")


def conductivity(coords: np.ndarray, cell_type: str, k, thickness: float = 1.0) -> ElementMatrices:
    """Conductivity matrices K_ab = ∫ ∇N_a · k ∇N_b, full values (1, nen, nen, nc)."""
    G, wdet = gradients_cell_last(coords, cell_type, thickness=thickness)  # (d, nq, nen, nc)
    d, nq, nen, nc = G.shape
    k = np.asarray(k, dtype=float)
    iso = k.ndim == 0 or k.shape == (nc,)
    kt = None if iso else conductivity_tensor(k, nc, d).transpose(1, 2, 0)  # (d, d, nc)
    # Σ_q Σ_i (w G_i)_a (k G)_i,b: d·nq products of (nen, nen, nc), cell index last (numpy is
    # fast on long vectors); an isotropic k multiplies the weights, a tensor mixes the G_l
    out = np.zeros((nen, nen, nc))
    tmp = np.empty((nen, nen, nc))
    for q in range(nq):
        w = wdet[q] * k if iso else wdet[q]
        for i in range(d):
            kg = G[i, q] if iso else np.einsum("lc,lbc->bc", kt[i], G[:, q])
            np.multiply((G[i, q] * w)[:, None, :], kg[None, :, :], out=tmp)
            out += tmp
    return ElementMatrices(values=out[None])


def conductivity_factored(coords: np.ndarray, cell_type: str, tensors: np.ndarray,
                          cell_material: np.ndarray, thickness: float = 1.0) -> ElementMatrices:
    """Conductivity as ``ElementMatrices`` in factored form: geometry P (d², nen, nen, nc) and one
    constant tensor per region. ``tensors`` (nmat, d, d) is stored as (nmat, d², 1) so that
    ``reduce`` returns one row (a scalar field's single component pair)."""
    G, wdet = gradients_cell_last(coords, cell_type, thickness=thickness)
    d = G.shape[0]
    t = np.asarray(tensors, dtype=float).reshape(-1, d * d, 1)
    return ElementMatrices(geometric=geometric_part(G, wdet), tensors=t,
                           cell_material=np.asarray(cell_material))


def conductivity_blocks(points: np.ndarray, cell_nodes: np.ndarray, cell_type: str,
                        tensors: np.ndarray, cell_material: np.ndarray,
                        thickness: float = 1.0) -> ElementMatrices:
    """``conductivity_factored`` of the cells ``cell_nodes`` (nc, nen), blocked: the geometric
    part is computed a block of cells at a time when it is reduced or applied."""
    d = points.shape[1]

    def geometric(sel, out):
        G, wdet = gradients_cell_last(points[cell_nodes[sel]], cell_type, thickness=thickness)
        return geometric_part(G, wdet, out=out)

    t = np.asarray(tensors, dtype=float).reshape(-1, d * d, 1)
    kernel = CellKernel(geometric, len(cell_nodes), d * d, cell_nodes.shape[1])
    return ElementMatrices(tensors=t, cell_material=np.asarray(cell_material), kernel=kernel)


def _mass_rule(cell_type: str, thickness: float, coords: np.ndarray):
    ref = element(cell_type)
    xi, w = quadrature(cell_type, default_degree(cell_type, "mass"))
    N = ref.shape(xi)                                         # (nq, nen)
    J = jacobians(coords, ref.grad_shape(xi))                 # (nc, nq, d, d): only |J| needed
    if J.shape[-1] == 2:
        det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
    else:
        det = (J[..., 0, 0] * (J[..., 1, 1] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 1])
               - J[..., 0, 1] * (J[..., 1, 0] * J[..., 2, 2] - J[..., 1, 2] * J[..., 2, 0])
               + J[..., 0, 2] * (J[..., 1, 0] * J[..., 2, 1] - J[..., 1, 1] * J[..., 2, 0]))
    r = coords[:, :, 0] @ N.T if is_axisymmetric(thickness) else None
    return N, scale(np.abs(det) * w[None, :], r, thickness)   # (nc, nq)


def mass(coords: np.ndarray, cell_type: str, capacity=1.0, thickness: float = 1.0) -> np.ndarray:
    """Consistent capacity matrices M_ab = ∫ c N_a N_b, (1, nen, nen, nc); c per cell."""
    N, wdet = _mass_rule(cell_type, thickness, coords)
    c = _per_cell(capacity, coords.shape[0], "capacity")
    # Σ_q N_qa N_qb (c w|J|)_cq as one gemm over (nen², nq) x (nq, nc)
    NN = (N[:, :, None] * N[:, None, :]).reshape(len(N), -1)  # (nq, nen²)
    nen = N.shape[1]
    return (NN.T @ (wdet * c[:, None]).T).reshape(1, nen, nen, -1)


def lumped_mass(coords: np.ndarray, cell_type: str, capacity=1.0, thickness: float = 1.0) -> np.ndarray:
    """Lumped capacity per cell node (nen, nc): row sums ∫ c N_a (linear cells) or HRZ
    (quadratic: the consistent diagonal ∫ c N_a², scaled to the cell's capacity ∫ c)."""
    N, wdet = _mass_rule(cell_type, thickness, coords)
    cw = wdet * _per_cell(capacity, coords.shape[0], "capacity")[:, None]   # (nc, nq)
    if polynomial_order(cell_type) == 1:
        return (cw @ N).T
    diag = cw @ (N * N)                                                     # (nc, nen)
    return (diag * (cw.sum(axis=1) / diag.sum(axis=1))[:, None]).T


def lumped_as_matrices(lumped: np.ndarray) -> np.ndarray:
    """Lumped weights (nen, nc) as diagonal element matrices (1, nen, nen, nc)."""
    nen, nc = lumped.shape
    out = np.zeros((1, nen, nen, nc))
    out[0, np.arange(nen), np.arange(nen)] = lumped
    return out


def source_vector(coords: np.ndarray, cell_type: str, f, thickness: float = 1.0,
                  lumped: bool = False) -> np.ndarray:
    """Element source vectors (nc, nen) of ∫ f N_a.

    ``f``: a scalar, one value per cell (nc,), or node values (nc, nen) interpolated at the
    quadrature points. ``lumped``: f_a · m_a with the lumped weights instead (what keeps a
    uniform field uniform with HRZ lumping; identical to the consistent vector on linear cells
    for a per-cell constant f).
    """
    nc = coords.shape[0]
    f = np.asarray(f, dtype=float)
    if lumped:
        m = lumped_mass(coords, cell_type, 1.0, thickness).T   # (nc, nen)
        return m * (f if f.ndim == 2 else _per_cell(f, nc, "source")[:, None])
    N, wdet = _mass_rule(cell_type, thickness, coords)
    if f.ndim == 2:
        if f.shape != (nc, N.shape[1]):
            raise ValueError(f"node values of the source must be ({nc}, {N.shape[1]}), got {f.shape}")
        fq = f @ N.T                                          # (nc, nq)
    else:
        fq = _per_cell(f, nc, "source")[:, None]
    return (fq * wdet) @ N


def _flux_of(kt: np.ndarray, g: np.ndarray) -> np.ndarray:
    """−k ∇h cell-last: kt (nc, d, d), g (d, ..., nc) → (d, ..., nc)."""
    K = kt.transpose(1, 2, 0)                                  # (d, d, nc)
    d = K.shape[0]
    flux = np.zeros_like(g)
    for i in range(d):
        for j in range(d):
            flux[i] -= K[i, j] * g[j]
    return flux


def _rows_of(coords: np.ndarray, he: np.ndarray) -> np.ndarray:
    """``kernels.cell_rows`` from element coordinates (nc, nen, d) and node values (nc, nen)."""
    return np.concatenate([coords.transpose(1, 2, 0), he.T[:, None, :]], axis=1)


def _cell_flux(rows: np.ndarray, cell_type: str, kt: np.ndarray) -> np.ndarray:
    g, _ = kernels.mean_gradient(rows, cell_type, degree=default_degree(cell_type, "mass"))
    return np.ascontiguousarray(_flux_of(kt, g[0]).T)


def _nodal_flux_sums(rows: np.ndarray, cells: np.ndarray, cell_type: str, kt: np.ndarray,
                     npoints: int) -> tuple[np.ndarray, np.ndarray]:
    flux = _flux_of(kt, kernels.gradient_at_nodes(rows, cell_type)[0])   # (d, nen, nc)
    return kernels.nodal_sums(cells, flux, kernels.cell_measures(rows, cell_type), npoints)


def cell_flux(coords: np.ndarray, cell_type: str, k, he: np.ndarray) -> np.ndarray:
    """Mean flux −k ∇h over each cell (nc, d), from element node values he (nc, nen)."""
    kt = conductivity_tensor(k, coords.shape[0], coords.shape[2])
    return _cell_flux(_rows_of(coords, he), cell_type, kt)


def nodal_flux_sums(points: np.ndarray, cells: np.ndarray, cell_type: str, k,
                    h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flux −k ∇h evaluated at each cell's nodes, summed per node with cell-volume weights.

    ``cells`` (nc, nen) node numbers of the cells to use (e.g. the owned ones), ``h`` the field
    on all points. Returns (sums (npoints, d), weights (npoints,)): the caller adds the ranks'
    sums and divides, as ``Elasticity.nodal_stress_sums``.
    """
    kt = conductivity_tensor(k, len(cells), points.shape[1])
    rows = kernels.cell_rows(points, np.asarray(h, dtype=float).reshape(-1, 1), cells)
    return _nodal_flux_sums(rows, cells, cell_type, kt, len(points))


def flux_outputs(points: np.ndarray, cells: np.ndarray, cell_type: str, k, h: np.ndarray):
    """(cell_flux, nodal_flux_sums) of the same cells, the cells' data gathered once."""
    kt = conductivity_tensor(k, len(cells), points.shape[1])
    rows = kernels.cell_rows(points, np.asarray(h, dtype=float).reshape(-1, 1), cells)
    return _cell_flux(rows, cell_type, kt), _nodal_flux_sums(rows, cells, cell_type, kt,
                                                             len(points))
