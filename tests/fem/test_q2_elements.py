"""Q2 cells: the nine-node Lagrange (quad9) and eight-node serendipity (quad8) quadrilaterals
and their hexahedra (hexahedron27, hexahedron20) as reference elements (against VTK's), the
quadrilaterals' integration on curved cells, their facets and orientation, the
Jacobian checks and point location on a ring sector whose every node lies on its circle.
Nothing here depends on the number of ranks (each rank checks the same numbers)."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.curved_q2 import ring_sector_mesh
from parsolve.errors import InputError
from parsolve.fem.elements import (default_degree, element, facet_measure_and_normal,
                                   polynomial_order, quadrature)
from parsolve.fem.integrals import cell_rule, facet_rule
from parsolve.mesh import checks
from parsolve.mesh.topology import FACETS, FLIP, boundary_facets, cell_measures, orient_cells
from parsolve.post.locate import interpolate, locate

Q2 = ["quad9", "quad8"]
Q2_3D = ["hexahedron27", "hexahedron20"]
# the reference nodes in Gmsh's (= VTK's) order: corners, midsides m01 m12 m23 m30, centre
NODES = [(-1, -1), (1, -1), (1, 1), (-1, 1), (0, -1), (1, 0), (0, 1), (-1, 0), (0, 0)]
VTK_CELL = {"quad9": "vtkBiQuadraticQuad", "quad8": "vtkQuadraticQuad",
            "hexahedron27": "vtkTriQuadraticHexahedron", "hexahedron20": "vtkQuadraticHexahedron"}


def inside(n: int, seed: int = 0, dim: int = 2) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-0.95, 0.95, size=(n, dim))


@pytest.mark.parametrize("cell", Q2 + Q2_3D)
def test_nodes_kronecker_and_partition_of_unity(cell):
    ref = element(cell)
    assert (ref.num_nodes, polynomial_order(cell)) == ({"quad9": 9, "quad8": 8,
                                                        "hexahedron27": 27,
                                                        "hexahedron20": 20}[cell], 2)
    if ref.dim == 2:
        np.testing.assert_array_equal(ref.nodes, NODES[:ref.num_nodes])
    np.testing.assert_allclose(ref.shape(ref.nodes), np.eye(ref.num_nodes), atol=1e-15)
    xi = inside(50, dim=ref.dim)
    np.testing.assert_allclose(ref.shape(xi).sum(axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(ref.grad_shape(xi).sum(axis=1), 0.0, atol=1e-14)


@pytest.mark.parametrize("cell", Q2 + Q2_3D)
def test_gradients_by_finite_differences(cell):
    ref, h = element(cell), 1e-6
    xi = inside(20, 1, ref.dim)
    fd = np.stack([(ref.shape(xi + h * e) - ref.shape(xi - h * e)) / (2 * h)
                   for e in np.eye(ref.dim)], axis=-1)
    np.testing.assert_allclose(ref.grad_shape(xi), fd, atol=1e-9)


@pytest.mark.parametrize("cell", Q2 + Q2_3D)
def test_nodes_and_shape_functions_are_vtks(cell):
    """VTK's own element (its parametric coordinates on [0, 1]^d, its interpolation functions):
    the same nodes in the same order, the same functions (an independent implementation)."""
    vtk = pytest.importorskip("vtk")
    ref, other = element(cell), getattr(vtk, VTK_CELL[cell])()
    n, dim = other.GetNumberOfPoints(), ref.dim
    p = other.GetParametricCoords()
    nodes = np.array([p[k] for k in range(3 * n)]).reshape(n, 3)[:, :dim] * 2 - 1
    np.testing.assert_array_equal(nodes, ref.nodes)
    interpolate = getattr(other, "InterpolationFunctions", None) or other.InterpolateFunctions
    xi = inside(10, 4, dim)
    theirs = []
    for q in xi:
        out = [0.0] * n
        interpolate(tuple((q + 1) / 2) + (0.0,) * (3 - dim), out)
        theirs.append(out)
    np.testing.assert_allclose(ref.shape(xi), theirs, atol=1e-14)


@pytest.mark.parametrize("cell", sorted(FLIP))
def test_flip_is_the_mirror_of_the_first_two_reference_coordinates(cell):
    """``FLIP`` reorders the nodes as the reference cell mirrored by ξ <-> η (triangles and
    tetrahedra: their vertex 1 <-> 2), so that flipped cells stay valid cells of their type."""
    nodes = element(cell).nodes
    if cell.startswith(("quad", "hexahedron")):
        np.testing.assert_array_equal(nodes[FLIP[cell]], nodes[:, [1, 0, 2][:nodes.shape[1]]])
    else:
        np.testing.assert_array_equal(nodes[FLIP[cell]][:, [1, 0, 2][:nodes.shape[1]]], nodes)


@pytest.mark.parametrize("cell, monomials", [
    ("quad9", [(i, j) for i in range(3) for j in range(3)]),            # every ξ^i η^j, i, j ≤ 2
    ("quad8", [(i, j) for i in range(3) for j in range(3) if i + j <= 3])])  # not ξ² η²
def test_reproduces_its_polynomial_space(cell, monomials):
    ref, xi = element(cell), inside(30, 2)
    for i, j in monomials:
        f = lambda p: p[:, 0] ** i * p[:, 1] ** j                        # noqa: E731
        np.testing.assert_allclose(ref.shape(xi) @ f(ref.nodes), f(xi), atol=1e-14)
        grad = np.einsum("qad,a->qd", ref.grad_shape(xi), f(ref.nodes))
        np.testing.assert_allclose(grad[:, 0], i * xi[:, 0] ** max(i - 1, 0) * xi[:, 1] ** j,
                                   atol=1e-13)
    if cell == "quad8":   # the serendipity space lacks ξ² η²
        f = (ref.nodes ** 2).prod(axis=1)
        assert np.abs(ref.shape(xi) @ f - (xi ** 2).prod(axis=1)).max() > 0.1


def test_stiffness_is_fully_integrated():
    """3 Gauss points a direction (degree 4, exact to 5 in each variable): B^T D B of a
    straight Q2 cell is of degree 4 in each variable (the serendipity cells' 2 points leave a
    spurious mode)."""
    for cell in Q2 + Q2_3D:
        assert default_degree(cell, "stiffness") == 4 and default_degree(cell, "mass") == 4
        assert len(quadrature(cell, 4)[1]) == 3 ** element(cell).dim


def curved_cell(cell: str) -> np.ndarray:
    """One cell (1, nen, 2) with curved edges: the biquadratic map x = ξ + 0.15 η², y = η +
    0.1 ξ² + 0.05 ξ η of the reference nodes (quad8: the same nodes without the centre)."""
    xi = element(cell).nodes
    return np.column_stack([1.0 + xi[:, 0] + 0.15 * xi[:, 1] ** 2,
                            2.0 + xi[:, 1] + 0.1 * xi[:, 0] ** 2
                            + 0.05 * xi[:, 0] * xi[:, 1]])[None]


@pytest.mark.parametrize("cell", Q2)
@pytest.mark.parametrize("i, j", [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)])
def test_exact_integration_on_a_curved_cell(cell, i, j):
    """∫ x^i y^j over a curved cell by its cell rule equals the boundary integral
    ∮ x^(i+1) y^j / (i+1) n_x ds by its four three-node edges' rule (divergence theorem, an
    independent quadrature): both integrands are polynomials of the reference coordinates."""
    coords = curved_cell(cell)
    rule = cell_rule(coords, cell)
    x, y = rule.points[..., 0], rule.points[..., 1]
    inside_value = float((rule.weights * x ** i * y ** j).sum())
    edges = coords[0][np.array(FACETS[cell])]                              # (4, 3, 2)
    edge = facet_rule(edges, "line3")
    x, y = edge.points[..., 0], edge.points[..., 1]
    boundary = float((edge.weights * x ** (i + 1) * y ** j / (i + 1) * edge.normals[..., 0]).sum())
    assert inside_value == pytest.approx(boundary, rel=1e-13, abs=1e-13)
    if (i, j) == (0, 0):   # both elements hold the map exactly: det J = (1 + 0.05 ξ)
        # - 0.3 η (0.2 ξ + 0.05 η), whose integral over [-1, 1]² is 4 - 0.015 · 4/3
        assert inside_value == pytest.approx(4.0 - 0.02, rel=1e-14)


@pytest.mark.parametrize("cell", Q2)
def test_ring_sector_facets_orientation_and_checks(cell):
    """A ring sector 1 ≤ r ≤ 2 of Q2 cells whose nodes lie on the circles: positive Jacobians
    (the checks pass), boundary facets three-node lines with the outward normal (towards the
    centre on the bore), area within the isoparametric circles' error of 3π/4, and
    ``orient_cells`` repairs flipped cells with ``FLIP``."""
    mesh, inner, outer = ring_sector_mesh(1.0, 2.0, 4, 8, cell=cell)
    lo, _, scale = checks.jacobian_range_of(mesh.points[mesh.cells], cell, 2)
    assert np.all(lo > checks.RELATIVE_JACOBIAN * scale)
    assert cell_measures(mesh).sum() == pytest.approx(0.75 * np.pi, rel=1e-5)
    facets, _, _ = boundary_facets(mesh)
    assert facets.shape == (2 * 8 + 2 * 4, 3)
    ref = element("line3")
    for group, sign in ((inner, -1.0), (outer, 1.0)):
        on = facets[np.isin(facets[:, 2], group[:, 2])]
        np.testing.assert_array_equal(np.sort(on, axis=0), np.sort(group, axis=0))
        _, n = facet_measure_and_normal(mesh.points[on], ref.grad_shape(quadrature("line3", 4)[0]))
        pts = np.einsum("qa,fad->fqd", ref.shape(quadrature("line3", 4)[0]), mesh.points[on])
        radial = np.einsum("fqd,fqd->fq", n, pts / np.linalg.norm(pts, axis=-1, keepdims=True))
        assert np.all(sign * radial > 0.999)
    bad = mesh.cells.copy()
    bad[::3] = bad[::3][:, FLIP[cell]]
    fixed, flipped = orient_cells(mesh.points, cell, bad)
    assert flipped == len(bad[::3]) and np.array_equal(fixed, mesh.cells)


def test_a_folded_quad9_is_refused():
    """The centre node pushed beyond an edge folds the cell: the Jacobian check names it."""
    coords = curved_cell("quad9").copy()
    coords[0, 8] = coords[0, 4] + [0.0, -0.6]
    lo, hi, scale = checks.jacobian_range_of(coords, "quad9", 2)
    assert lo[0] < 0 < hi[0]
    with pytest.raises(InputError, match="1 invalid quad9 cell.*folded"):
        checks.raise_jacobians(np.array([0]), lo, hi, checks.RELATIVE_JACOBIAN * scale,
                               "quad9", "m.msh", "mesh.file")


@pytest.mark.parametrize("cell", Q2)
def test_locate_and_interpolate_in_curved_cells(cell):
    """Points of the ring sector found in their curved cell (Newton on the biquadratic map);
    a field linear in x, y is interpolated exactly (isoparametric)."""
    mesh, _, _ = ring_sector_mesh(1.0, 2.0, 3, 5, cell=cell)
    rng = np.random.default_rng(3)
    r, t = rng.uniform(1.05, 1.95, 10), rng.uniform(0.05, np.pi / 2 - 0.05, 10)
    field = (mesh.points @ [2.0, -3.0] + 1.0)[:, None]
    for x in np.column_stack([r * np.cos(t), r * np.sin(t)]):
        c, xi = locate(mesh.points, mesh.cells, cell, x)
        back = element(cell).shape(xi[None]) @ mesh.points[mesh.cells[c]]
        np.testing.assert_allclose(back[0], x, atol=1e-13)
        got = interpolate(field, mesh.points, mesh.cells, cell, x)
        assert got[0] == pytest.approx(x @ [2.0, -3.0] + 1.0, abs=1e-12)
    assert locate(mesh.points, mesh.cells, cell, [0.5, 0.5]) is None
