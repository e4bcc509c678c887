"""Reference elements, quadrature and geometry helpers of parsolve.fem.elements."""

from __future__ import annotations

import itertools
from math import factorial

import numpy as np
import pytest

from parsolve.fem.elements import (
    default_degree,
    element,
    facet_measure_and_normal,
    jacobians,
    physical_gradients,
    quadrature,
)

ALL_TYPES = ["line", "line3", "triangle", "triangle6", "quad", "tetra", "tetra10", "hexahedron"]
P2_TYPES = ["line3", "triangle6", "tetra10"]
SIMPLEX = {"triangle": True, "triangle6": True, "tetra": True, "tetra10": True}  # else a cube
REF_MEASURE = {
    "line": 2.0, "line3": 2.0, "triangle": 0.5, "triangle6": 0.5, "quad": 4.0,
    "tetra": 1 / 6, "tetra10": 1 / 6, "hexahedron": 8.0,
}


def random_reference_points(cell_type: str, n: int, rng: np.random.Generator) -> np.ndarray:
    """Points strictly inside the reference cell."""
    dim = element(cell_type).dim
    if SIMPLEX.get(cell_type, False):
        bary = rng.dirichlet(np.ones(dim + 1), size=n)
        return bary[:, 1:]
    return rng.uniform(-0.95, 0.95, size=(n, dim))


def random_affine(dim: int, rng: np.random.Generator, ncells: int) -> tuple[np.ndarray, np.ndarray]:
    """ncells well-conditioned affine maps x = A xi + b with det A > 0."""
    A = np.eye(dim) + 0.3 * rng.standard_normal((ncells, dim, dim))
    neg = np.linalg.det(A) < 0
    A[neg, :, 0] *= -1.0  # flip one column: positive orientation
    b = rng.standard_normal((ncells, dim))
    return A, b


def map_nodes(cell_type: str, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    nodes = element(cell_type).nodes
    return np.einsum("cij,aj->cai", A, nodes) + b[:, None, :]


# ----------------------------------------------------------------------------------------------
# Basis functions
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("cell_type", ALL_TYPES)
def test_kronecker_property(cell_type):
    el = element(cell_type)
    assert el.nodes.shape == (el.num_nodes, el.dim)
    np.testing.assert_allclose(el.shape(el.nodes), np.eye(el.num_nodes), atol=1e-14)


@pytest.mark.parametrize("cell_type", ALL_TYPES)
def test_partition_of_unity(cell_type):
    rng = np.random.default_rng(0)
    el = element(cell_type)
    xi = random_reference_points(cell_type, 20, rng)
    np.testing.assert_allclose(el.shape(xi).sum(axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(el.grad_shape(xi).sum(axis=1), 0.0, atol=1e-13)


@pytest.mark.parametrize("cell_type", ALL_TYPES)
def test_gradients_match_central_differences(cell_type):
    rng = np.random.default_rng(1)
    el = element(cell_type)
    xi = random_reference_points(cell_type, 10, rng)
    h = 1e-6
    fd = np.empty((xi.shape[0], el.num_nodes, el.dim))
    for j in range(el.dim):
        e = np.zeros(el.dim)
        e[j] = h
        fd[:, :, j] = (el.shape(xi + e) - el.shape(xi - e)) / (2 * h)
    # every basis function is at most quadratic per variable: central differences are exact
    # up to round-off
    np.testing.assert_allclose(el.grad_shape(xi), fd, atol=1e-8)


def test_node_ordering_known_positions():
    np.testing.assert_array_equal(element("line3").nodes, [[-1.0], [1.0], [0.0]])
    np.testing.assert_array_equal(
        element("triangle6").nodes[3:], [[0.5, 0.0], [0.5, 0.5], [0.0, 0.5]]
    )
    # VTK tetra10: m01, m12, m02, m03, m13, m23
    np.testing.assert_array_equal(
        element("tetra10").nodes[4:],
        [[0.5, 0, 0], [0.5, 0.5, 0], [0, 0.5, 0], [0, 0, 0.5], [0.5, 0, 0.5], [0, 0.5, 0.5]],
    )
    np.testing.assert_array_equal(element("quad").nodes, [[-1, -1], [1, -1], [1, 1], [-1, 1]])
    hexa = element("hexahedron").nodes
    np.testing.assert_array_equal(hexa[:4], np.c_[element("quad").nodes, -np.ones(4)])
    np.testing.assert_array_equal(hexa[4:], hexa[:4] + [0, 0, 2])


def test_element_is_cached_and_read_only():
    assert element("tetra10") is element("tetra10")
    with pytest.raises(ValueError):
        element("tetra10").nodes[0, 0] = 1.0
    with pytest.raises(ValueError, match="unsupported cell type"):
        element("pyramid")
    with pytest.raises(ValueError, match="shape"):
        element("triangle").shape(np.zeros((3, 3)))


# ----------------------------------------------------------------------------------------------
# Quadrature
# ----------------------------------------------------------------------------------------------


def exact_monomial_integral(cell_type: str, powers: tuple[int, ...]) -> float:
    """Integral of prod x_k^{p_k} over the reference cell."""
    if SIMPLEX.get(cell_type, False):
        # unit simplex: prod p_k! / (sum p + dim)!
        return np.prod([factorial(p) for p in powers]) / factorial(sum(powers) + len(powers))
    # [-1, 1]^d: product of 1D integrals 2/(p+1) for even p, 0 for odd p
    return float(np.prod([2.0 / (p + 1) if p % 2 == 0 else 0.0 for p in powers]))


# (cell type, highest degree to check): triangles/tetrahedra go past the tabulated rules (5) into
# the collapsed Gauss fallback.
MAX_DEGREE = {"line": 9, "quad": 7, "hexahedron": 5, "triangle": 9, "tetra": 8}
QUAD_CASES = [(ct, d) for ct, top in MAX_DEGREE.items() for d in range(top + 1)]


@pytest.mark.parametrize("cell_type,degree", QUAD_CASES)
def test_quadrature_exact_for_monomials(cell_type, degree):
    pts, wts = quadrature(cell_type, degree)
    dim = element(cell_type).dim
    assert pts.shape == (wts.shape[0], dim)
    assert np.all(wts > 0)
    assert np.isclose(wts.sum(), REF_MEASURE[cell_type], rtol=1e-14)
    for powers in itertools.product(range(degree + 1), repeat=dim):
        if sum(powers) > degree:
            continue
        approx = wts @ np.prod(pts ** np.array(powers), axis=1)
        exact = exact_monomial_integral(cell_type, powers)
        assert approx == pytest.approx(exact, rel=1e-12, abs=1e-14), powers


def test_quadrature_known_point_counts_and_numbers():
    # symmetric rules: 1, 3, 6, 6, 7 points on triangles; 1, 4, 14 on tetrahedra
    assert [quadrature("triangle", d)[0].shape[0] for d in range(6)] == [1, 1, 3, 6, 6, 7]
    assert [quadrature("tetra", d)[0].shape[0] for d in range(6)] == [1, 1, 4, 14, 14, 14]
    assert quadrature("quad", 2)[0].shape[0] == 4  # 2x2 Gauss
    assert quadrature("hexahedron", 3)[0].shape[0] == 8  # 2x2x2 Gauss
    pts, wts = quadrature("line", 3)
    np.testing.assert_allclose(np.sort(pts[:, 0]), [-1 / np.sqrt(3), 1 / np.sqrt(3)])
    np.testing.assert_allclose(wts, [1.0, 1.0])
    # P2 element types share the rules of their geometric shape
    assert quadrature("tetra10", 2)[0].shape == quadrature("tetra", 2)[0].shape
    # integral of x^2 y over the unit triangle = 2! 1! / 5! = 1/60 (degree 3, 6-point rule)
    pts, wts = quadrature("triangle6", 3)
    assert wts @ (pts[:, 0] ** 2 * pts[:, 1]) == pytest.approx(1 / 60, rel=1e-14)


def test_quadrature_is_cached_and_rejects_bad_degree():
    assert quadrature("tetra", 4) is quadrature("tetra", 4)
    with pytest.raises(ValueError):
        quadrature("tetra", 4)[1][0] = 0.0
    with pytest.raises(ValueError):
        quadrature("triangle", -1)


def test_default_degree():
    assert default_degree("triangle", "stiffness") == 0
    assert default_degree("tetra", "stiffness") == 0
    assert quadrature("tetra", default_degree("tetra", "stiffness"))[0].shape[0] == 1
    assert default_degree("triangle6", "stiffness") == 2
    assert default_degree("tetra10", "stiffness") == 2
    assert default_degree("quad", "stiffness") == 2
    assert default_degree("hexahedron", "stiffness") == 3
    assert default_degree("tetra", "mass") == 2
    assert default_degree("tetra10", "mass") == 4
    assert default_degree("hexahedron", "load") == 2
    with pytest.raises(ValueError):
        default_degree("quad", "damping")


# ----------------------------------------------------------------------------------------------
# Geometry
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("cell_type", ALL_TYPES)
def test_volume_of_affinely_mapped_cells(cell_type):
    rng = np.random.default_rng(2)
    el = element(cell_type)
    A, b = random_affine(el.dim, rng, ncells=7)
    coords = map_nodes(cell_type, A, b)
    pts, wts = quadrature(cell_type, default_degree(cell_type, "mass"))
    dNdx, detJ = physical_gradients(coords, el.grad_shape(pts))
    assert np.all(detJ > 0)
    np.testing.assert_allclose(detJ @ wts, np.linalg.det(A) * REF_MEASURE[cell_type], rtol=1e-12)


def test_area_of_general_quad_and_volume_of_slanted_hex():
    # convex non-parallelogram quad: shoelace area = 0.5 * |sum(x_i y_{i+1} - x_{i+1} y_i)|
    quad = np.array([[[0.0, 0.0], [3.0, 0.0], [2.0, 2.0], [0.5, 1.5]]])
    x, y = quad[0, :, 0], quad[0, :, 1]
    shoelace = 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    pts, wts = quadrature("quad", 2)
    _, detJ = physical_gradients(quad, element("quad").grad_shape(pts))
    assert detJ[0] @ wts == pytest.approx(shoelace, rel=1e-14)
    # unit square base, top face the plane z = 1 + x: volume = int (1 + x) dx dy = 1.5
    hexa = np.array(
        [[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 2], [1, 1, 2], [0, 1, 1]]],
        dtype=float,
    )
    pts, wts = quadrature("hexahedron", 3)
    _, detJ = physical_gradients(hexa, element("hexahedron").grad_shape(pts))
    assert detJ[0] @ wts == pytest.approx(1.5, rel=1e-14)


@pytest.mark.parametrize("cell_type", ALL_TYPES)
def test_linear_field_interpolated_exactly(cell_type):
    rng = np.random.default_rng(3)
    el = element(cell_type)
    A, b = random_affine(el.dim, rng, ncells=3)
    coords = map_nodes(cell_type, A, b)
    g = rng.standard_normal(el.dim)
    u = coords @ g + 0.7  # nodal values of u(x) = g.x + 0.7
    xi = random_reference_points(cell_type, 5, rng)
    N, dN = el.shape(xi), el.grad_shape(xi)
    x = np.einsum("qa,cai->cqi", N, coords)
    dNdx, _ = physical_gradients(coords, dN)
    np.testing.assert_allclose(np.einsum("qa,ca->cq", N, u), x @ g + 0.7, atol=1e-12)
    grad_u = np.einsum("cqai,ca->cqi", dNdx, u)
    np.testing.assert_allclose(grad_u, np.broadcast_to(g, x.shape), atol=1e-12)


@pytest.mark.parametrize("cell_type", P2_TYPES)
def test_p2_interpolates_quadratic_field_exactly(cell_type):
    rng = np.random.default_rng(4)
    el = element(cell_type)
    d = el.dim
    A, b = random_affine(d, rng, ncells=3)
    coords = map_nodes(cell_type, A, b)
    H = rng.standard_normal((d, d))
    H = H + H.T
    g = rng.standard_normal(d)

    def f(x):  # 0.5 x.H.x + g.x + 1
        return 0.5 * np.einsum("...i,ij,...j->...", x, H, x) + x @ g + 1.0

    u = f(coords)
    xi = random_reference_points(cell_type, 6, rng)
    N, dN = el.shape(xi), el.grad_shape(xi)
    x = np.einsum("qa,cai->cqi", N, coords)
    dNdx, _ = physical_gradients(coords, dN)
    np.testing.assert_allclose(np.einsum("qa,ca->cq", N, u), f(x), atol=1e-12)
    np.testing.assert_allclose(np.einsum("cqai,ca->cqi", dNdx, u), x @ H + g, atol=1e-11)


@pytest.mark.parametrize(
    "cell_type", ["triangle", "quad", "triangle6", "tetra", "tetra10", "hexahedron"]
)
def test_physical_gradients_match_linalg_inv(cell_type):
    rng = np.random.default_rng(5)
    el = element(cell_type)
    # random perturbation of the reference nodes: curved, non-affine cells
    coords = el.nodes[None] + 0.1 * rng.standard_normal((50, el.num_nodes, el.dim))
    pts, _ = quadrature(cell_type, 2)
    dN = el.grad_shape(pts)
    J = jacobians(coords, dN)
    np.testing.assert_allclose(J, np.einsum("cai,qaj->cqij", coords, dN), atol=1e-14)
    dNdx, detJ = physical_gradients(coords, dN)
    np.testing.assert_allclose(detJ, np.linalg.det(J), rtol=1e-12)
    expected = np.einsum("qaj,cqji->cqai", dN, np.linalg.inv(J))
    np.testing.assert_allclose(dNdx, expected, rtol=1e-10, atol=1e-12)


def test_facet_normals_of_unit_square_edges():
    # counter-clockwise boundary of [0,1]^2: bottom, right, top, left
    edges = np.array(
        [[[0, 0], [1, 0]], [[1, 0], [1, 1]], [[1, 1], [0, 1]], [[0, 1], [0, 0]]], dtype=float
    )
    pts, wts = quadrature("line", 2)
    ds, normal = facet_measure_and_normal(edges, element("line").grad_shape(pts))
    np.testing.assert_allclose(ds, 0.5)  # length 1 over reference length 2
    np.testing.assert_allclose(ds @ wts, 1.0)
    expected = np.array([[0, -1], [1, 0], [0, 1], [-1, 0]], dtype=float)
    expected = np.broadcast_to(expected[:, None, :], normal.shape)
    np.testing.assert_allclose(normal, expected, atol=1e-15)


def test_facet_normals_in_3d():
    # bottom face of the unit tetrahedron ordered so the right-hand normal is -z (outward),
    # and the top face z = 1 of the unit cube (normal +z)
    tri = np.array([[[0, 0, 0], [0, 1, 0], [1, 0, 0]]], dtype=float)
    pts, wts = quadrature("triangle", 1)
    ds, normal = facet_measure_and_normal(tri, element("triangle").grad_shape(pts))
    assert ds[0] @ wts == pytest.approx(0.5)
    np.testing.assert_allclose(normal[0, 0], [0, 0, -1], atol=1e-15)

    top = np.array([[[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]], dtype=float)
    pts, wts = quadrature("quad", 2)
    ds, normal = facet_measure_and_normal(top, element("quad").grad_shape(pts))
    np.testing.assert_allclose(ds, 0.25)  # area 1 over reference area 4
    np.testing.assert_allclose(normal, np.broadcast_to([0, 0, 1.0], normal.shape), atol=1e-15)

    # a P2 edge in 2D that is a straight segment from (0,0) to (3,4): length 5, normal (4,-3)/5
    seg = np.array([[[0, 0], [3, 4], [1.5, 2]]], dtype=float)
    pts, wts = quadrature("line3", 2)
    ds, normal = facet_measure_and_normal(seg, element("line3").grad_shape(pts))
    assert ds[0] @ wts == pytest.approx(5.0)
    np.testing.assert_allclose(normal[0], np.broadcast_to([0.8, -0.6], normal[0].shape))
