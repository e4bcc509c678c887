"""Vectorised element kernels: every function works on a stack of cells at once."""

from __future__ import annotations

import numpy as np

from parsolve.fem.axisymmetric import is_axisymmetric, scale
from parsolve.fem.elements import default_degree, element, physical_gradients, quadrature

# ``thickness`` below is the out-of-plane measure of a 2D model: a float (plane) or an
# ``Axisymmetric`` (2π r at each point, see fem/axisymmetric.py).


def stiffness_degree(cell_type: str, thickness=1.0) -> int:
    """Quadrature degree of the stiffness: ``default_degree``'s, and for an axisymmetric
    simplex 2·order (the weight r and the hoop terms N_a N_b make the integrand of degree
    2·order: one point on a P1 triangle loses the rate, O(h) instead of O(h²))."""
    deg = default_degree(cell_type, "stiffness")
    if is_axisymmetric(thickness) and cell_type.startswith("triangle"):
        return default_degree(cell_type, "mass")
    return deg


class CellGeometry:
    """Shape-function gradients and quadrature weights of a stack of cells."""

    def __init__(self, coords: np.ndarray, cell_type: str, degree: int | None = None,
                 thickness: float = 1.0, points: np.ndarray | None = None):
        """``points``: evaluate at these reference points (unit weights) instead of quadrature.
        Axisymmetric ``thickness``: ``r`` (nc, nq) the radius at the points, and the strain
        operator has the hoop row."""
        ref = element(cell_type)
        deg = stiffness_degree(cell_type, thickness) if degree is None else degree
        xi, w = quadrature(cell_type, deg) if points is None else (points, np.ones(len(points)))
        self.N = ref.shape(xi)                              # (nq, nen)
        self.dNdx, det = physical_gradients(coords, ref.grad_shape(xi))
        self.axisymmetric = is_axisymmetric(thickness)
        self.r = coords[:, :, 0] @ self.N.T if self.axisymmetric else None
        self.wdet = scale(np.abs(det) * w[None, :], self.r, thickness)   # (nc, nq)
        self.nq = len(w)

    def strain_operator(self) -> np.ndarray:
        """B (nc, nq, nvoigt, nen*dim), engineering shear, Voigt order xx yy (zz) (yz xz) xy;
        axisymmetric: rr zz rz θθ, the hoop row N_a / r on u_r (a point on the axis, r = 0,
        takes the limit θθ = rr there: u_r vanishes on the axis)."""
        g = self.dNdx
        nc, nq, nen, dim = g.shape
        if dim == 2:
            B = np.zeros((nc, nq, 4 if self.axisymmetric else 3, nen, 2))
            B[:, :, 0, :, 0] = g[..., 0]
            B[:, :, 1, :, 1] = g[..., 1]
            B[:, :, 2, :, 0] = g[..., 1]
            B[:, :, 2, :, 1] = g[..., 0]
            if self.axisymmetric:
                r = self.r[:, :, None]
                on_axis = r == 0.0
                B[:, :, 3, :, 0] = np.where(on_axis, g[..., 0],
                                            self.N[None] / np.where(on_axis, 1.0, r))
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
    """ε at quadrature points (nc, nq, nvoigt) from element DOF values ue (nc, ndof).

    Summed DOF by DOF in a fixed order, not by a BLAS matmul, so that a cell's strain has the
    same bits whatever the batch of cells it is evaluated in (material branches depend on it).
    """
    eps = np.zeros(B.shape[:3])
    for k in range(B.shape[3]):
        eps += B[..., k] * ue[:, None, None, k]
    return eps


def voigt_strain(dNdx: np.ndarray, ue: np.ndarray) -> np.ndarray:
    """ε (nc, nq, nvoigt), engineering shear, straight from the shape gradients dNdx
    (nc, nq, nen, d) and the element displacements ue (nc, nen, d): the displacement gradient
    without the strain operator B (nv × nen·d numbers per point) that ``strains`` needs."""
    g = np.zeros(dNdx.shape[:2] + (ue.shape[2], dNdx.shape[3]))   # ∂u_i/∂x_j
    for a in range(ue.shape[1]):  # node by node: elementwise, in a fixed order
        g += ue[:, None, a, :, None] * dNdx[:, :, a, None, :]
    if g.shape[-1] == 2:
        return np.stack([g[..., 0, 0], g[..., 1, 1], g[..., 0, 1] + g[..., 1, 0]], axis=-1)
    return np.stack([g[..., 0, 0], g[..., 1, 1], g[..., 2, 2], g[..., 1, 2] + g[..., 2, 1],
                     g[..., 0, 2] + g[..., 2, 0], g[..., 0, 1] + g[..., 1, 0]], axis=-1)


def internal_forces(B: np.ndarray, wdet: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """fe = Σ_q w |J| Bᵀ σ, (nc, ndof)."""
    return np.einsum("cqvd,cqv->cd", B, sigma * wdet[:, :, None])


def cell_dofs(cells: np.ndarray, ncomp: int) -> np.ndarray:
    """Element DOF numbers (nc, nen*ncomp), node-major, from node numbers."""
    return (cells[:, :, None] * ncomp + np.arange(ncomp)).reshape(len(cells), cells.shape[1] * ncomp)


# ---------------------------------------------------------------- cell-last stiffness (hot path)
#
# Assembly speed is set by memory traffic, and numpy is only fast on long vectors: these
# kernels keep the cell index last, so every operation runs over all cells at once and the
# output comes in the (i, j, a, b, cell) layout that the CSR scatter map is built for.


def gradients_cell_last(coords: np.ndarray, cell_type: str, degree: int | None = None,
                        thickness: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Physical shape gradients G (dim, nq, nen, nc) and weights w|J| (nq, nc)."""
    ref = element(cell_type)
    xi, w = quadrature(cell_type, stiffness_degree(cell_type, thickness) if degree is None else degree)
    dN = ref.grad_shape(xi)                                   # (nq, nen, d)
    nc, nen, d = coords.shape
    nq = len(w)
    det, inv = _det_inv_cell_last(_jacobians_cell_last(coords, dN))
    G = np.empty((d, nq, nen, nc))
    for q in range(nq):  # dN/dx_k = sum_j dN/dxi_j dxi_j/dx_k
        G[:, q] = np.tensordot(dN[q], inv[:, :, q], axes=([1], [0])).transpose(1, 0, 2)
    return G, scale(np.abs(det) * w[:, None], _radius_cell_last(coords, ref.shape(xi), thickness),
                    thickness)


def _radius_cell_last(coords: np.ndarray, N: np.ndarray, thickness) -> np.ndarray | None:
    """r (nq, nc) at the points of N (nq, nen) for an axisymmetric measure, else None."""
    return N @ coords[:, :, 0].T if is_axisymmetric(thickness) else None


def axisymmetric_gradients(coords: np.ndarray, cell_type: str,
                           thickness) -> tuple[np.ndarray, np.ndarray]:
    """The gradients of ``gradients_cell_last`` extended by a third "direction" N_a / r
    (3, nq, nen, nc) and the weights 2π r w|J| (nq, nc): with ``axisymmetric_tensor`` the
    factored stiffness then carries the hoop strain θθ = u_r / r. Quadrature points are
    inside the cells, so r > 0 there for a mesh with r ≥ 0."""
    G, wdet = gradients_cell_last(coords, cell_type, thickness=thickness)
    xi, _ = quadrature(cell_type, stiffness_degree(cell_type, thickness))
    N = element(cell_type).shape(xi)                              # (nq, nen)
    r = N @ coords[:, :, 0].T                                     # (nq, nc)
    return np.concatenate([G, (N[:, :, None] / r[:, None, :])[None]]), wdet


def _jacobians_cell_last(coords: np.ndarray, dN: np.ndarray) -> np.ndarray:
    """J[i, j, q, c] = dx_i/dxi_j of cells coords (nc, nen, d) at the points of dN (nq, nen, d)."""
    nc, nen, d = coords.shape
    nq = dN.shape[0]
    X = coords.transpose(2, 0, 1).reshape(d * nc, nen)        # rows (i, c)
    J = (X @ dN.transpose(1, 0, 2).reshape(nen, nq * d)).reshape(d, nc, nq, d)
    return np.ascontiguousarray(J.transpose(0, 3, 2, 1))


def weights_cell_last(coords: np.ndarray, cell_type: str, thickness: float = 1.0) -> np.ndarray:
    """Quadrature weights w|J| (nq, nc) of the stiffness rule, without the gradients."""
    xi, w = quadrature(cell_type, stiffness_degree(cell_type, thickness))
    J = _jacobians_cell_last(coords, element(cell_type).grad_shape(xi))
    r = _radius_cell_last(coords, element(cell_type).shape(xi), thickness)
    if J.shape[0] == 2:
        det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
    else:
        det = (J[0, 0] * (J[1, 1] * J[2, 2] - J[1, 2] * J[2, 1])
               - J[0, 1] * (J[1, 0] * J[2, 2] - J[1, 2] * J[2, 0])
               + J[0, 2] * (J[1, 0] * J[2, 1] - J[1, 1] * J[2, 0]))
    return scale(np.abs(det) * w[:, None], r, thickness)


def _det_inv_cell_last(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Determinant and inverse of J[i, j, ...] for 2×2 and 3×3, elementwise."""
    if J.shape[0] == 2:
        det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
        inv = np.array([[J[1, 1], -J[0, 1]], [-J[1, 0], J[0, 0]]]) / det
        return det, inv
    cof = np.empty_like(J)
    for i in range(3):
        for j in range(3):
            i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
            cof[i, j] = J[i1, j1] * J[i2, j2] - J[i1, j2] * J[i2, j1]
    det = (J[0] * cof[0]).sum(axis=0)
    return det, cof.transpose(1, 0, *range(2, J.ndim)) / det


def voigt_to_tensor(C: np.ndarray, dim: int) -> np.ndarray:
    """Voigt matrix (engineering shear) → M[(k, l), (i, j)] with K_ai,bj = Σ G_ak M G_bl."""
    pairs = [(0, 0), (1, 1), (0, 1)] if dim == 2 else \
        [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    index = {}
    for v, (i, k) in enumerate(pairs):
        index[(i, k)] = index[(k, i)] = v
    M = np.empty((dim, dim, dim, dim))  # [k, l, i, j] = C[(i,k), (j,l)]
    for i in range(dim):
        for k in range(dim):
            for j in range(dim):
                for l in range(dim):
                    M[k, l, i, j] = C[index[(i, k)], index[(j, l)]]
    return M.reshape(dim * dim, dim * dim)


def axisymmetric_tensor(C: np.ndarray) -> np.ndarray:
    """Axisymmetric Voigt matrix (rr, zz, rz, θθ) → M[(k, l), (i, j)] (9, 4) with
    K_ai,bj = Σ G_ak M G_bl over the extended gradients (∂_r, ∂_z, 1/r) of
    ``axisymmetric_gradients``: strain row of (component i, direction k) is rr (0, 0), zz
    (1, 1), rz (0, 1) and (1, 0), θθ (0, 2); (1, 2) is no strain (u_z / r does not appear)."""
    index = {(0, 0): 0, (1, 1): 1, (0, 1): 2, (1, 0): 2, (0, 2): 3}
    M = np.zeros((3, 3, 2, 2))  # [k, l, i, j] = C[(i,k), (j,l)]
    for (i, k), a in index.items():
        for (j, l), b in index.items():
            M[k, l, i, j] = C[a, b]
    return M.reshape(9, 4)


def geometric_part(G: np.ndarray, wdet: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """P[(k, l), a, b, c] = Σ_q w|J| G[k, q, a, c] G[l, q, b, c], (d², nen, nen, nc)."""
    d, nq, nen, nc = G.shape
    Gw = G * wdet[None, :, None, :]
    if out is None or out.shape != (d * d, nen, nen, nc):
        out = np.empty((d * d, nen, nen, nc))
    tmp = np.empty((nen, nen, nc)) if nq > 1 else None
    for k in range(d):
        for l in range(d):
            target = out[k * d + l]
            np.multiply(Gw[k, 0][:, None, :], G[l, 0][None, :, :], out=target)
            for q in range(1, nq):
                np.multiply(Gw[k, q][:, None, :], G[l, q][None, :, :], out=tmp)
                target += tmp
    return out


# ---------------------------------------------------------------- cell-last outputs (post-processing)
#
# Cell means and nodal averages of a field's gradient (stress, flux) over all cells at once,
# cell index last like the stiffness kernels above: every operation is one long vector.


def cell_rows(points: np.ndarray, values: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Coordinates and node values of the cells (nc, nen), cell-last in one array:
    rows[a, i, c] = x_i of node a of cell c (i < d), then the k values (npoints, k) there:
    (nen, d + k, nc), the right-hand side of one product with the reference gradients."""
    nc, nen = cells.shape
    d = points.shape[1]
    idx = np.ascontiguousarray(cells.T)
    rows = np.empty((nen, d + values.shape[1], nc))
    for i in range(d):
        np.take(points[:, i], idx, out=rows[:, i], mode="clip")
    for i in range(values.shape[1]):
        np.take(values[:, i], idx, out=rows[:, d + i], mode="clip")
    return rows


def _reference_derivatives(rows: np.ndarray, dN: np.ndarray) -> np.ndarray:
    """R[p, j, i, c] = ∂(x, v)_i/∂ξ_j at the points of dN (np, nen, d): one product of the
    reference gradients with the rows gives the Jacobian and the values' derivatives together."""
    nen, dk, nc = rows.shape
    npts, _, d = dN.shape
    A = dN.transpose(0, 2, 1).reshape(npts * d, nen)
    B = rows.reshape(nen, dk * nc)
    R = np.empty((npts * d, dk * nc))
    for s in range(0, npts * d, 12):  # Debian's OpenBLAS: 24 rows at once take 2× two 12s
        np.matmul(A[s:s + 12], B, out=R[s:s + 12])
    return R.reshape(npts, d, dk, nc)


def _det_adj(R: np.ndarray, d: int) -> tuple[np.ndarray, list]:
    """det J and adj(J) (adj[j][l]: (np, nc)), J[i][j] = R[:, j, i]."""
    J = [[R[:, j, i] for j in range(d)] for i in range(d)]
    if d == 2:
        return J[0][0] * J[1][1] - J[0][1] * J[1][0], [[J[1][1], -J[0][1]], [-J[1][0], J[0][0]]]
    # adj[j][l] = cofactor (l, j), cyclic indices carry the signs
    cof = [[J[(l + 1) % 3][(j + 1) % 3] * J[(l + 2) % 3][(j + 2) % 3]
            - J[(l + 1) % 3][(j + 2) % 3] * J[(l + 2) % 3][(j + 1) % 3]
            for j in range(3)] for l in range(3)]
    det = J[0][0] * cof[0][0] + J[0][1] * cof[0][1] + J[0][2] * cof[0][2]
    return det, [[cof[l][j] for l in range(3)] for j in range(3)]


def _gradients_at(rows: np.ndarray, dN: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(det J (np, nc), M = (∂v/∂ξ) adj(J) (k, d, np, nc)) at the points of dN (np, nen, d):
    the values' physical gradient there is M / det J (no shape-gradient array is formed)."""
    nen, dk, nc = rows.shape
    npts, _, d = dN.shape
    R = _reference_derivatives(rows, dN)
    det, adj = _det_adj(R, d)
    k = dk - d
    M = np.empty((k, d, npts, nc))
    tmp = np.empty((npts, nc))
    for m in range(k):  # in place: no temporaries of the cells' size per term
        for l in range(d):
            np.multiply(R[:, 0, d + m], adj[0][l], out=M[m, l])
            for j in range(1, d):
                np.multiply(R[:, j, d + m], adj[j][l], out=tmp)
                M[m, l] += tmp
    return det, M


def mean_gradient(rows: np.ndarray, cell_type: str, degree: int | None = None,
                  thickness: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Cell means of the values' gradient, Σ_q w|J| ∇v / Σ_q w|J| (k, d, nc), and the cells'
    measures Σ_q w|J| (nc,), over the quadrature rule of ``degree`` (default: the stiffness')."""
    xi, w = quadrature(cell_type, default_degree(cell_type, "stiffness") if degree is None else degree)
    dN = element(cell_type).grad_shape(xi)
    if len(w) == 1:  # one point (P1): the gradient is the mean
        det, M = _gradients_at(rows, dN)
        return M[:, :, 0] / det[0], np.abs(det[0]) * (w[0] * thickness)
    # Several points: the mean is linear in the values, Σ_a v_a ⊗ Ḡ_a with the cells' mean
    # shape gradients Ḡ_a = Σ_q w sign(J) dN_a adj(J) / Σ_q w|J|: the Jacobians at the points,
    # one small product for Ḡ, then k·d·nen products over the cells (not k·d·d·nq).
    nen, dk, nc = rows.shape
    nq, _, d = dN.shape
    det, adj = _det_adj(_reference_derivatives(rows[:, :d], dN), d)
    wq = w[:, None] * thickness
    vol = (np.abs(det) * wq).sum(axis=0)
    s = np.sign(det) * wq / vol                         # w|J|/vol ∇N_a = w sign(J)/vol dN_a adj
    W = np.empty((nq, d, d, nc))
    for j in range(d):
        for l in range(d):
            np.multiply(adj[j][l], s, out=W[:, j, l])
    Gm = (dN.transpose(1, 0, 2).reshape(nen, nq * d) @ W.reshape(nq * d, d * nc))
    Gm = Gm.reshape(nen, d, nc)                         # Ḡ[a, l, c]
    g = np.empty((dk - d, d, nc))
    tmp = np.empty((d, nc))
    for m in range(dk - d):
        np.multiply(rows[0, d + m], Gm[0], out=g[m])
        for a in range(1, nen):
            np.multiply(rows[a, d + m], Gm[a], out=tmp)
            g[m] += tmp
    return g, vol


def cell_measures(rows: np.ndarray, cell_type: str, thickness: float = 1.0) -> np.ndarray:
    """Σ_q w|J| (nc,) over the stiffness rule, from the coordinate rows of ``cell_rows``."""
    xi, w = quadrature(cell_type, default_degree(cell_type, "stiffness"))
    dN = element(cell_type).grad_shape(xi)
    d = dN.shape[2]
    det, _ = _det_adj(_reference_derivatives(rows[:, :d], dN), d)
    return (np.abs(det) * (w[:, None] * thickness)).sum(axis=0)


def gradient_at_nodes(rows: np.ndarray, cell_type: str) -> np.ndarray:
    """The values' gradient at each cell's nodes, (k, d, nen, nc)."""
    det, M = _gradients_at(rows, element(cell_type).grad_shape(element(cell_type).nodes))
    M /= det
    return M


def voigt_of_gradient(g: np.ndarray) -> np.ndarray:
    """Strain (nv, ..., nc), engineering shear, Voigt order xx yy (zz) (yz xz) xy, from a
    displacement gradient g[i, j, ..., c] = ∂u_i/∂x_j."""
    if g.shape[0] == 2:
        return np.stack([g[0, 0], g[1, 1], g[0, 1] + g[1, 0]])
    return np.stack([g[0, 0], g[1, 1], g[2, 2], g[1, 2] + g[2, 1], g[0, 2] + g[2, 0],
                     g[0, 1] + g[1, 0]])


def nodal_sums(cells: np.ndarray, values: np.ndarray, vol: np.ndarray,
               npoints: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell-volume weighted sums per node: (Σ vol·value (npoints, k), Σ vol (npoints,)) over the
    cells (nc, nen), of values at the cells' nodes (k, nen, nc) or constant per cell (k, nc)."""
    nc, nen = cells.shape
    idx = cells.T.ravel()                                     # (nen, nc) order, as the values
    sums = np.empty((npoints, len(values)))
    for m, v in enumerate(values):
        wv = np.broadcast_to(v * vol, (nen, nc)).ravel()
        sums[:, m] = np.bincount(idx, weights=wv, minlength=npoints)
    weights = np.bincount(idx, weights=np.tile(vol, nen), minlength=npoints)
    return sums, weights


def add_nodal_sums(sums: np.ndarray, weights: np.ndarray, cells: np.ndarray, values: np.ndarray,
                   vol: np.ndarray) -> None:
    """``nodal_sums`` of one block of cells added into ``sums`` (npoints, k) and ``weights``
    (npoints,): counted over the block's range of nodes (the nodes of consecutive cells are
    close in a numbering that follows the mesh), or over the nodes present when it is wide."""
    nc, nen = cells.shape
    if nc == 0:
        return
    idx = cells.T.astype(np.intp).ravel()                      # (nen, nc) order, as the values
    lo, hi = int(idx.min()), int(idx.max()) + 1
    if hi - lo <= 8 * idx.size:
        idx -= lo
        dest, n = slice(lo, hi), hi - lo
    else:
        dest, idx = np.unique(idx, return_inverse=True)
        n = dest.size
    for m, v in enumerate(values):
        wv = np.broadcast_to(v * vol, (nen, nc)).ravel()
        sums[dest, m] += np.bincount(idx, weights=wv, minlength=n)
    weights[dest] += np.bincount(idx, weights=np.tile(vol, nen), minlength=n)
