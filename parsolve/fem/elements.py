"""Reference elements, quadrature rules and vectorised geometry helpers.

Node ordering is meshio/VTK's. Reference cells:

* ``line`` / ``line3``: [-1, 1] (length 2), nodes -1, 1 (and 0 for the midside node of line3),
  so that line facets share the [-1, 1] convention of quadrilaterals and Gauss rules.
* ``triangle`` / ``triangle6``: (0,0), (1,0), (0,1) (area 1/2); P2 midside order m01, m12, m20.
* ``quad`` / ``quad9`` / ``quad8``: [-1, 1]^2 (area 4), corners counter-clockwise from (-1,-1);
  Q2 midside order m01, m12, m23, m30, then (quad9, biquadratic Lagrange) the centre (0, 0);
  quad8 is the serendipity element (no centre node). Gmsh's and VTK's orders are the same.
* ``tetra`` / ``tetra10``: (0,0,0), (1,0,0), (0,1,0), (0,0,1) (volume 1/6); P2 midside order
  m01, m12, m02, m03, m13, m23 (VTK).
* ``hexahedron`` / ``hexahedron27`` / ``hexahedron20``: [-1, 1]^3 (volume 8), bottom face z=-1
  counter-clockwise seen from above, then the top face z=1 in the same order; Q2 midside order
  (VTK) m01, m12, m23, m30, m45, m56, m67, m74, m04, m15, m26, m37, then (hexahedron27,
  triquadratic Lagrange) the face centres x=-1, x=1, y=-1, y=1, z=-1, z=1 and the centre;
  hexahedron20 is the serendipity element. Gmsh's order differs (``mesh.gmsh.ORDER``).

Array conventions used throughout: ``xi`` (nq, dim), ``N`` (nq, num_nodes),
``dN`` (nq, num_nodes, dim), cell coordinates (ncells, num_nodes, gdim).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from itertools import permutations

import numpy as np

# cell type -> (reference shape, polynomial order)
_CELLS: dict[str, tuple[str, int]] = {
    "line": ("line", 1),
    "line3": ("line", 2),
    "triangle": ("triangle", 1),
    "triangle6": ("triangle", 2),
    "quad": ("quad", 1),
    "quad9": ("quad", 2),
    "quad8": ("quad", 2),
    "tetra": ("tetra", 1),
    "tetra10": ("tetra", 2),
    "hexahedron": ("hexahedron", 1),
    "hexahedron27": ("hexahedron", 2),
    "hexahedron20": ("hexahedron", 2),
}

_DIM = {"line": 1, "triangle": 2, "quad": 2, "tetra": 3, "hexahedron": 3}

REFERENCE_MEASURE: dict[str, float] = {
    "line": 2.0,
    "triangle": 0.5,
    "quad": 4.0,
    "tetra": 1.0 / 6.0,
    "hexahedron": 8.0,
}

# Simplices are described by their barycentric coordinates L = b0 + G @ xi (affine in xi):
# the P1 basis is L itself and the P2 basis is built from products of L, so one code path
# serves line, triangle and tetrahedron. The line uses [-1, 1]: L0 = (1 - xi)/2, L1 = (1 + xi)/2.
_BARY: dict[str, tuple[np.ndarray, np.ndarray]] = {
    "line": (np.array([0.5, 0.5]), np.array([[-0.5], [0.5]])),
    "triangle": (np.array([1.0, 0.0, 0.0]), np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])),
    "tetra": (
        np.array([1.0, 0.0, 0.0, 0.0]),
        np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
    ),
}

# P2 midside nodes as vertex pairs, in meshio/VTK order.
_EDGES: dict[str, list[tuple[int, int]]] = {
    "line": [(0, 1)],
    "triangle": [(0, 1), (1, 2), (2, 0)],
    "tetra": [(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)],
    "quad": [(0, 1), (1, 2), (2, 3), (3, 0)],
    "hexahedron": [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4),
                   (0, 4), (1, 5), (2, 6), (3, 7)],
}
# Lagrange Q2 cells' nodes after the midside ones: face centres (as their corners), then the
# cell's centre (all the corners)
_INTERIOR: dict[str, list[tuple[int, ...]]] = {
    "quad9": [(0, 1, 2, 3)],
    "hexahedron27": [(0, 3, 7, 4), (1, 2, 6, 5), (0, 1, 5, 4), (3, 2, 6, 7), (0, 1, 2, 3),
                     (4, 5, 6, 7), tuple(range(8))],
}
# second-order tensor cells without interior nodes: serendipity basis
_SERENDIPITY = ("quad8", "hexahedron20")

_VERTICES: dict[str, np.ndarray] = {
    "line": np.array([[-1.0], [1.0]]),
    "triangle": np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]),
    "quad": np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]),
    "tetra": np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
    "hexahedron": np.array(
        [
            [-1.0, -1.0, -1.0],
            [1.0, -1.0, -1.0],
            [1.0, 1.0, -1.0],
            [-1.0, 1.0, -1.0],
            [-1.0, -1.0, 1.0],
            [1.0, -1.0, 1.0],
            [1.0, 1.0, 1.0],
            [-1.0, 1.0, 1.0],
        ]
    ),
}


def _check_cell_type(cell_type: str) -> tuple[str, int]:
    try:
        return _CELLS[cell_type]
    except KeyError:
        raise ValueError(
            f"unsupported cell type {cell_type!r}; expected one of {', '.join(_CELLS)}"
        ) from None


def _readonly(a: np.ndarray) -> np.ndarray:
    # Cached arrays are shared by every caller: make accidental in-place edits fail loudly.
    a = np.ascontiguousarray(a, dtype=np.float64)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class ReferenceElement:
    """A Lagrange reference element (nodal basis) in meshio/VTK node order."""

    cell_type: str
    dim: int
    num_nodes: int
    # Excluded from eq/hash: arrays are unhashable, and the cell type identifies the element.
    nodes: np.ndarray = field(compare=False, repr=False)

    def _points(self, xi: np.ndarray) -> np.ndarray:
        xi = np.asarray(xi, dtype=np.float64)
        if xi.ndim != 2 or xi.shape[1] != self.dim:
            raise ValueError(
                f"{self.cell_type}: xi must have shape (nq, {self.dim}), got {xi.shape}"
            )
        return xi

    def shape(self, xi: np.ndarray) -> np.ndarray:
        """Shape function values N (nq, num_nodes) at reference points xi (nq, dim)."""
        xi = self._points(xi)
        ref, order = _CELLS[self.cell_type]
        if ref in _BARY:
            return _simplex_shape(ref, order, xi)
        if order == 2:
            return _quadratic_shape(self.cell_type, self.nodes, xi)
        return _tensor_shape(self.nodes, xi)

    def grad_shape(self, xi: np.ndarray) -> np.ndarray:
        """Reference gradients dN/dxi (nq, num_nodes, dim) at reference points xi (nq, dim)."""
        xi = self._points(xi)
        ref, order = _CELLS[self.cell_type]
        if ref in _BARY:
            return _simplex_grad(ref, order, xi)
        if order == 2:
            return _quadratic_grad(self.cell_type, self.nodes, xi)
        return _tensor_grad(self.nodes, xi)


def _simplex_shape(ref: str, order: int, xi: np.ndarray) -> np.ndarray:
    b0, G = _BARY[ref]
    L = b0 + xi @ G.T  # (nq, dim+1)
    if order == 1:
        return L
    vertex = L * (2.0 * L - 1.0)
    edge = np.stack([4.0 * L[:, i] * L[:, j] for i, j in _EDGES[ref]], axis=1)
    return np.concatenate([vertex, edge], axis=1)


def _simplex_grad(ref: str, order: int, xi: np.ndarray) -> np.ndarray:
    b0, G = _BARY[ref]
    nq = xi.shape[0]
    if order == 1:
        return np.broadcast_to(G, (nq,) + G.shape).copy()
    L = b0 + xi @ G.T
    # d/dxi [L_i (2 L_i - 1)] = (4 L_i - 1) G_i ; d/dxi [4 L_i L_j] = 4 (L_j G_i + L_i G_j)
    vertex = (4.0 * L - 1.0)[:, :, None] * G[None, :, :]
    edge = np.stack(
        [4.0 * (L[:, j, None] * G[i] + L[:, i, None] * G[j]) for i, j in _EDGES[ref]], axis=1
    )
    return np.concatenate([vertex, edge], axis=1)


def _tensor_shape(nodes: np.ndarray, xi: np.ndarray) -> np.ndarray:
    # Multilinear basis on [-1, 1]^d: N_a = prod_k (1 + xi_k * node_a,k) / 2
    factors = 0.5 * (1.0 + xi[:, None, :] * nodes[None, :, :])  # (nq, nn, dim)
    return np.prod(factors, axis=2)


def _tensor_grad(nodes: np.ndarray, xi: np.ndarray) -> np.ndarray:
    factors = 0.5 * (1.0 + xi[:, None, :] * nodes[None, :, :])
    dim = nodes.shape[1]
    grad = np.empty(factors.shape)
    for j in range(dim):  # dim <= 3: product over the other directions, derivative in j
        others = [k for k in range(dim) if k != j]
        grad[:, :, j] = 0.5 * nodes[None, :, j] * np.prod(factors[:, :, others], axis=2)
    return grad


def _lagrange2(nodes: np.ndarray, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    # 1D quadratic Lagrange factors on the nodes -1, 0, 1 of each direction, and their
    # derivatives: (nq, nn, dim) each. Node c = ±1: x (x + c) / 2; node c = 0: 1 - x².
    x, c = xi[:, None, :], nodes[None, :, :]
    mid = c == 0.0
    value = np.where(mid, 1.0 - x * x, 0.5 * x * (x + c))
    slope = np.where(mid, -2.0 * x, x + 0.5 * c)
    return value, slope


def _serendipity_parts(nodes: np.ndarray, xi: np.ndarray):
    # Serendipity Q2 (quad8, hexahedron20) in dimension d: corner a: 2^-d Π(1 + ξ_k c_k)
    # (Σ ξ_k c_k - (d - 1)); midside node with c_j = 0: 2^(1-d) (1 - ξ_j²) Π_{k≠j}(1 + ξ_k c_k).
    # Written as a product P (nq, nn) of the linear factors times a factor S (nq, nn).
    x, c = xi[:, None, :], nodes[None, :, :]
    d = nodes.shape[1]
    mid = c == 0.0
    lin = np.where(mid, 1.0, 1.0 + x * c)                       # (nq, nn, dim)
    dlin = np.where(mid, 0.0, c)
    corner = ~mid.any(axis=2)                                   # (1, nn)
    s = np.where(corner, 0.5 ** d * ((x * c).sum(axis=2) - (d - 1)),
                 0.5 ** (d - 1) * (1.0 - (x * x * mid).sum(axis=2)))
    ds = np.where(corner[..., None], 0.5 ** d * c, -2.0 * 0.5 ** (d - 1) * x * mid)
    return lin, dlin, s, ds


def _quadratic_shape(cell_type: str, nodes: np.ndarray, xi: np.ndarray) -> np.ndarray:
    if cell_type in _SERENDIPITY:
        lin, _, s, _ = _serendipity_parts(nodes, xi)
        return np.prod(lin, axis=2) * s
    return np.prod(_lagrange2(nodes, xi)[0], axis=2)


def _quadratic_grad(cell_type: str, nodes: np.ndarray, xi: np.ndarray) -> np.ndarray:
    dim = nodes.shape[1]
    if cell_type in _SERENDIPITY:
        lin, dlin, s, ds = _serendipity_parts(nodes, xi)
        p = np.prod(lin, axis=2)
        grad = ds * p[..., None]
        for j in range(dim):  # d/dξ_j of the product: the other directions' factors
            others = [k for k in range(dim) if k != j]
            grad[:, :, j] += dlin[:, :, j] * np.prod(lin[:, :, others], axis=2) * s
        return grad
    value, slope = _lagrange2(nodes, xi)
    grad = np.empty(value.shape)
    for j in range(dim):
        others = [k for k in range(dim) if k != j]
        grad[:, :, j] = slope[:, :, j] * np.prod(value[:, :, others], axis=2)
    return grad


@lru_cache(maxsize=None)
def element(cell_type: str) -> ReferenceElement:
    """The (cached) reference element for a meshio cell type."""
    ref, order = _check_cell_type(cell_type)
    vertices = _VERTICES[ref]
    if order == 2:
        mids = [0.5 * (vertices[i] + vertices[j]) for i, j in _EDGES[ref]]
        inner = [vertices[list(f)].mean(axis=0) for f in _INTERIOR.get(cell_type, [])]
        nodes = np.concatenate([vertices, np.array(mids + inner)], axis=0)
    else:
        nodes = vertices
    return ReferenceElement(cell_type, _DIM[ref], nodes.shape[0], _readonly(nodes))


def reference_measure(cell_type: str) -> float:
    """Length/area/volume of the reference cell."""
    return REFERENCE_MEASURE[_check_cell_type(cell_type)[0]]


def polynomial_order(cell_type: str) -> int:
    """Polynomial order of the element's basis (1 or 2)."""
    return _check_cell_type(cell_type)[1]


# ---------------------------------------------------------------------------------------------
# Quadrature
# ---------------------------------------------------------------------------------------------


def _orbit(bary: tuple[float, ...]) -> np.ndarray:
    """All distinct permutations of a barycentric point, as rows (npts, dim+1)."""
    return np.array(sorted(set(permutations(bary))))


def _symmetric_rule(
    classes: list[tuple[tuple[float, ...], float]],
) -> tuple[np.ndarray, np.ndarray]:
    """Points (Cartesian = barycentric coordinates 1..d) and weights from symmetry orbits."""
    pts, wts = [], []
    for bary, w in classes:
        orbit = _orbit(bary)
        pts.append(orbit[:, 1:])  # xi_k = L_k for k >= 1 on the reference simplex
        wts.append(np.full(orbit.shape[0], w))
    return np.concatenate(pts), np.concatenate(wts)


def _triangle_table(degree: int) -> tuple[np.ndarray, np.ndarray] | None:
    # Symmetric rules with positive weights, weights scaled to the reference area 1/2.
    if degree <= 1:  # centroid
        return _symmetric_rule([((1 / 3, 1 / 3, 1 / 3), 0.5)])
    if degree == 2:  # Strang-Fix 3-point interior rule
        return _symmetric_rule([((2 / 3, 1 / 6, 1 / 6), 1 / 6)])
    if degree <= 4:
        # Dunavant/Strang-Fix 6-point degree-4 rule (also used for degree 3: the classical
        # 4-point degree-3 rule has a negative weight). Values re-derived to 25 digits.
        a, wa = 0.4459484909159648863183293, 0.1116907948390057328475035
        b, wb = 0.09157621350977074345957146, 0.05497587182766093381916316
        return _symmetric_rule([((a, a, 1 - 2 * a), wa), ((b, b, 1 - 2 * b), wb)])
    if degree == 5:  # Radon's 7-point degree-5 rule (closed form)
        s = math.sqrt(15.0)
        a, b = (6 - s) / 21, (6 + s) / 21
        return _symmetric_rule(
            [
                ((1 / 3, 1 / 3, 1 / 3), 9 / 80),
                ((a, a, 1 - 2 * a), (155 - s) / 2400),
                ((b, b, 1 - 2 * b), (155 + s) / 2400),
            ]
        )
    return None


def _tetra_table(degree: int) -> tuple[np.ndarray, np.ndarray] | None:
    # Weights scaled to the reference volume 1/6.
    if degree <= 1:  # centroid
        return _symmetric_rule([((0.25, 0.25, 0.25, 0.25), 1 / 6)])
    if degree == 2:  # Keast 4-point rule
        a = (5 - math.sqrt(5.0)) / 20
        return _symmetric_rule([((a, a, a, 1 - 3 * a), 1 / 24)])
    if degree <= 5:
        # Walkington/Keast 14-point degree-5 rule with positive weights (used for degree 3 and 4
        # too: the 5-point degree-3 and 11-point degree-4 Keast rules have a negative weight).
        a1, w1 = 0.09273525031089122640232391, 0.01224884051939365825728503
        a2, w2 = 0.3108859192633006097973457, 0.01878132095300264179986428
        b, w3 = 0.04550370412564964949188053, 0.007091003462846911073011571
        return _symmetric_rule(
            [
                ((a1, a1, a1, 1 - 3 * a1), w1),
                ((a2, a2, a2, 1 - 3 * a2), w2),
                ((b, b, 0.5 - b, 0.5 - b), w3),
            ]
        )
    return None


def _gauss01(n: int) -> tuple[np.ndarray, np.ndarray]:
    """n-point Gauss-Legendre rule on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def _gauss_points(degree: int) -> int:
    # n Gauss points integrate degree 2n-1 exactly
    return max(1, (degree + 2) // 2)


def _duffy(ref: str, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Collapsed Gauss rule on a simplex, exact for total degree ``degree``.

    The unit cube (u, v[, w]) maps onto the simplex by x = u, y = v (1-u)[, z = w (1-u)(1-v)];
    the Jacobian (1-u)^(d-1) (1-v)^(d-2) raises the degree in u (and v), so those directions get
    more Gauss points (a Gauss-Jacobi rule would absorb the weight, but numpy has none).
    """
    if ref == "triangle":
        (u, wu), (v, wv) = _gauss01(_gauss_points(degree + 1)), _gauss01(_gauss_points(degree))
        U, V = np.meshgrid(u, v, indexing="ij")
        W = np.outer(wu * (1 - u), wv)
        pts = np.stack([U, V * (1 - U)], axis=-1).reshape(-1, 2)
        return pts, W.ravel()
    (u, wu), (v, wv), (w, ww) = (
        _gauss01(_gauss_points(degree + 2)),
        _gauss01(_gauss_points(degree + 1)),
        _gauss01(_gauss_points(degree)),
    )
    U, V, Wc = np.meshgrid(u, v, w, indexing="ij")
    weights = (wu * (1 - u) ** 2)[:, None, None] * (wv * (1 - v))[None, :, None] * ww[None, None, :]
    pts = np.stack([U, V * (1 - U), Wc * (1 - U) * (1 - V)], axis=-1).reshape(-1, 3)
    return pts, weights.ravel()


def _tensor_gauss(dim: int, degree: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(_gauss_points(degree))
    grids = np.meshgrid(*([x] * dim), indexing="ij")
    pts = np.stack([g.ravel() for g in grids[::-1]], axis=-1)  # first coordinate varies fastest
    wgrid = np.meshgrid(*([w] * dim), indexing="ij")
    weights = np.prod(np.stack([g.ravel() for g in wgrid]), axis=0)
    return pts, weights


@lru_cache(maxsize=None)
def quadrature(cell_type: str, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature (points (nq, dim), weights (nq,)) on the reference cell, cached.

    Exact for polynomials of total degree ``degree``. Line/quad/hexahedron use tensor-product
    Gauss-Legendre rules with ceil((degree+1)/2) points per direction (so they are exact for
    degree ``degree`` in each variable separately). Triangles use symmetric rules up to degree 5
    and tetrahedra up to degree 5; higher degrees fall back to a collapsed (Duffy) Gauss rule.
    All weights are positive and sum to the reference measure. Returned arrays are read-only.
    """
    ref, _ = _check_cell_type(cell_type)
    if int(degree) != degree or degree < 0:
        raise ValueError(f"quadrature degree must be a non-negative integer, got {degree!r}")
    degree = int(degree)
    if ref in ("line", "quad", "hexahedron"):
        pts, wts = _tensor_gauss(_DIM[ref], degree)
    else:
        table = _triangle_table(degree) if ref == "triangle" else _tetra_table(degree)
        pts, wts = table if table is not None else _duffy(ref, degree)
    return _readonly(pts), _readonly(wts)


def default_degree(cell_type: str, purpose: str) -> int:
    """Quadrature degree for an integrand kind on affine cells.

    ``"stiffness"`` (B^T D B): 2*(order-1) for simplices (0, i.e. one point, for P1; 2 for P2),
    2 for quad (2x2 Gauss), 3 for hexahedron (2x2x2 Gauss) and 4 for their Q2 cells (3 Gauss
    points a direction: full integration, the serendipity cells' 2 have spurious modes).
    ``"mass"``/``"load"``: 2*order.
    """
    ref, order = _check_cell_type(cell_type)
    if purpose == "stiffness":
        if ref == "quad":
            return 2 * order
        if ref == "hexahedron":
            return 3 if order == 1 else 4
        return 2 * (order - 1)
    if purpose in ("mass", "load"):
        return 2 * order
    raise ValueError(f"unknown quadrature purpose {purpose!r}; expected stiffness, mass or load")


# ---------------------------------------------------------------------------------------------
# Vectorised geometry (hot path: no Python loops over cells)
# ---------------------------------------------------------------------------------------------


def jacobians(coords: np.ndarray, dN: np.ndarray) -> np.ndarray:
    """J (ncells, nq, gdim, dim), J[c,q,i,j] = sum_a coords[c,a,i] dN[q,a,j].

    coords: (ncells, num_nodes, gdim); dN: (nq, num_nodes, dim).

    Elementwise products summed node by node in a fixed order, never BLAS: a BLAS kernel's
    summation order depends on the batch (its size, its alignment), so the same cell evaluated
    in two ranks' batches would differ in the last bits, and a material branch test on the
    result (yield, damage threshold) could go two ways. Here each cell's value is one fixed
    sequence of IEEE operations whatever the batch it sits in.
    """
    coords = np.asarray(coords, dtype=np.float64)
    J = np.zeros((coords.shape[0], dN.shape[0], coords.shape[2], dN.shape[2]))
    for a in range(coords.shape[1]):
        J += coords[:, None, a, :, None] * dN[None, :, a, None, :]
    return J


def _det_inv(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Determinant and inverse of a stack of 1x1, 2x2 or 3x3 matrices by cofactors."""
    d = J.shape[-1]
    if d == 1:
        det = J[..., 0, 0].copy()
        return det, 1.0 / J
    if d == 2:
        a, b, c, e = J[..., 0, 0], J[..., 0, 1], J[..., 1, 0], J[..., 1, 1]
        det = a * e - b * c
        inv = np.empty_like(J)
        inv[..., 0, 0], inv[..., 0, 1] = e, -b
        inv[..., 1, 0], inv[..., 1, 1] = -c, a
        inv /= det[..., None, None]
        return det, inv
    if d == 3:
        m = J
        cof = np.empty_like(J)  # cof[..., i, j] = cofactor C_ji, i.e. the adjugate
        cof[..., 0, 0] = m[..., 1, 1] * m[..., 2, 2] - m[..., 1, 2] * m[..., 2, 1]
        cof[..., 0, 1] = m[..., 0, 2] * m[..., 2, 1] - m[..., 0, 1] * m[..., 2, 2]
        cof[..., 0, 2] = m[..., 0, 1] * m[..., 1, 2] - m[..., 0, 2] * m[..., 1, 1]
        cof[..., 1, 0] = m[..., 1, 2] * m[..., 2, 0] - m[..., 1, 0] * m[..., 2, 2]
        cof[..., 1, 1] = m[..., 0, 0] * m[..., 2, 2] - m[..., 0, 2] * m[..., 2, 0]
        cof[..., 1, 2] = m[..., 0, 2] * m[..., 1, 0] - m[..., 0, 0] * m[..., 1, 2]
        cof[..., 2, 0] = m[..., 1, 0] * m[..., 2, 1] - m[..., 1, 1] * m[..., 2, 0]
        cof[..., 2, 1] = m[..., 0, 1] * m[..., 2, 0] - m[..., 0, 0] * m[..., 2, 1]
        cof[..., 2, 2] = m[..., 0, 0] * m[..., 1, 1] - m[..., 0, 1] * m[..., 1, 0]
        det = (
            m[..., 0, 0] * cof[..., 0, 0]
            + m[..., 0, 1] * cof[..., 1, 0]
            + m[..., 0, 2] * cof[..., 2, 0]
        )
        cof /= det[..., None, None]
        return det, cof
    raise ValueError(f"unsupported Jacobian size {d}x{d}")


def physical_gradients(coords: np.ndarray, dN: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Physical shape gradients and Jacobian determinants for cells with gdim == dim.

    Returns dNdx (ncells, nq, num_nodes, dim) with dNdx = dN J^{-1}, and the *signed* detJ
    (ncells, nq): callers multiply |detJ| (or check detJ > 0 for orientation) themselves.
    Degenerate cells (detJ == 0) give inf/nan with a numpy warning rather than an exception.
    """
    J = jacobians(coords, dN)
    if J.shape[2] != J.shape[3]:
        raise ValueError(f"physical_gradients needs square Jacobians, got {J.shape[2:]}")
    detJ, Jinv = _det_inv(J)
    # dN J^{-1} summed over j in a fixed order (batch-independent, see ``jacobians``)
    dNdx = np.zeros(J.shape[:2] + dN.shape[1:])
    for j in range(dN.shape[2]):
        dNdx += dN[None, :, :, j, None] * Jinv[:, :, None, j, :]
    return dNdx, detJ


def facet_measure_and_normal(coords: np.ndarray, dN: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Surface Jacobian ds (nf, nq) and unit normal (nf, nq, gdim) of facets with gdim == dim + 1.

    In 2D a line from a to b has normal (dy, -dx)/|.| (outward for a counter-clockwise boundary);
    in 3D the normal is cross(J[:, :, :, 0], J[:, :, :, 1]) normalised (right-hand rule on the
    facet's node order).
    """
    J = jacobians(coords, dN)
    gdim, dim = J.shape[2], J.shape[3]
    if gdim != dim + 1 or dim not in (1, 2):
        raise ValueError(f"facet geometry needs gdim == dim + 1 with dim 1 or 2, got {J.shape[2:]}")
    if dim == 1:
        t = J[..., 0]
        n = np.stack([t[..., 1], -t[..., 0]], axis=-1)
    else:
        n = np.cross(J[..., 0], J[..., 1])
    ds = np.sqrt(np.einsum("...i,...i->...", n, n))
    return ds, n / ds[..., None]
