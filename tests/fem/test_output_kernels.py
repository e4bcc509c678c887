"""Cell-last output kernels (cell means and nodal values of a field's gradient, nodal sums)
against the cell-first geometry (``CellGeometry``, summed node by node) and exact fields."""

import numpy as np
import pytest

from parsolve.fem import kernels
from parsolve.fem.elements import element
from parsolve.mesh.generators import box, rectangle

MESHES = {"triangle": lambda: rectangle(1.0, 0.5, 5, 3, cell="triangle"),
          "triangle6": lambda: rectangle(1.0, 0.5, 5, 3, cell="triangle6"),
          "quad": lambda: rectangle(1.0, 0.5, 5, 3, cell="quad"),
          "tetra": lambda: box(1.0, 0.5, 0.4, 3, 2, 2, cell="tetra"),
          "tetra10": lambda: box(1.0, 0.5, 0.4, 3, 2, 2, cell="tetra10"),
          "hexahedron": lambda: box(1.0, 0.5, 0.4, 3, 2, 2, cell="hexahedron")}


def distorted(name: str, amount: float = 0.02):
    mesh = MESHES[name]()
    rng = np.random.default_rng(7)
    mesh.points[:] += amount * rng.standard_normal(mesh.points.shape)
    return mesh


@pytest.mark.parametrize("name", list(MESHES))
def test_mean_gradient_matches_cell_geometry(name):
    """Σ w|J| ∇v / Σ w|J| and Σ w|J| as the cell-first CellGeometry gives them, on distorted
    cells, for several fields at once."""
    mesh = distorted(name)
    rng = np.random.default_rng(2)
    v = rng.standard_normal((mesh.num_points, 4))
    cells = mesh.cells[::2]
    geo = kernels.CellGeometry(mesh.points[cells], mesh.cell_type, thickness=0.3)
    grad = np.einsum("cqaj,cak->cqkj", geo.dNdx, v[cells])              # (nc, nq, k, d)
    expected = (grad * geo.wdet[:, :, None, None]).sum(axis=1) / geo.wdet.sum(axis=1)[:, None, None]
    g, vol = kernels.mean_gradient(kernels.cell_rows(mesh.points, v, cells), mesh.cell_type,
                                   thickness=0.3)
    assert g.shape == (4, mesh.dim, len(cells))
    np.testing.assert_allclose(g.transpose(2, 0, 1), expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    np.testing.assert_allclose(vol, geo.wdet.sum(axis=1), rtol=1e-13)
    np.testing.assert_allclose(kernels.cell_measures(kernels.cell_rows(mesh.points, v, cells),
                                                     mesh.cell_type, 0.3), vol, rtol=1e-13)


@pytest.mark.parametrize("name", list(MESHES))
def test_gradient_at_nodes_matches_cell_geometry(name):
    mesh = distorted(name)
    rng = np.random.default_rng(4)
    v = rng.standard_normal((mesh.num_points, 2))
    cells = mesh.cells
    geo = kernels.CellGeometry(mesh.points[cells], mesh.cell_type,
                               points=element(mesh.cell_type).nodes)
    expected = np.einsum("cpaj,cak->kjpc", geo.dNdx, v[cells])          # (k, d, nen, nc)
    g = kernels.gradient_at_nodes(kernels.cell_rows(mesh.points, v, cells), mesh.cell_type)
    np.testing.assert_allclose(g, expected, rtol=0, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize("name", ["triangle6", "tetra10"])
def test_gradient_of_a_quadratic_field_is_exact_at_the_nodes(name):
    """P2 cells hold v = x² + 3xy − z exactly: its gradient at every node is (2x + 3y, 3x, −1)."""
    mesh = distorted(name, 0.0)
    x = mesh.points
    v = x[:, 0] ** 2 + 3 * x[:, 0] * x[:, 1] - (x[:, 2] if mesh.dim == 3 else 0.0)
    g = kernels.gradient_at_nodes(kernels.cell_rows(mesh.points, v[:, None], mesh.cells),
                                  mesh.cell_type)[0]                     # (d, nen, nc)
    xn = x[mesh.cells].transpose(2, 1, 0)                               # (d, nen, nc)
    np.testing.assert_allclose(g[0], 2 * xn[0] + 3 * xn[1], atol=1e-12)
    np.testing.assert_allclose(g[1], 3 * xn[0], atol=1e-12)
    if mesh.dim == 3:
        np.testing.assert_allclose(g[2], -1.0, atol=1e-12)


@pytest.mark.parametrize("name", list(MESHES))
def test_linear_field_and_measures_on_reversed_cells(name):
    """v = A x + b: every mean gradient is A; cells listed with the opposite orientation
    (det J < 0) give the same gradients and positive measures that add up to the domain's."""
    mesh = distorted(name, 0.0)
    rng = np.random.default_rng(5)
    A = rng.standard_normal((3, mesh.dim))
    v = mesh.points @ A.T + 1.0
    lx = {2: 0.5, 3: 0.5 * 0.4}[mesh.dim]
    for cells in (mesh.cells, mesh.cells[:, _reversal(mesh.cell_type)]):
        g, vol = kernels.mean_gradient(kernels.cell_rows(mesh.points, v, cells), mesh.cell_type)
        np.testing.assert_allclose(g, np.broadcast_to(A[:, :, None], g.shape), atol=1e-12)
        assert np.all(vol > 0) and abs(vol.sum() - lx) < 1e-13


def _reversal(cell_type: str) -> list[int]:
    """A node permutation of the same cell with the opposite orientation (a mirror)."""
    return {"triangle": [0, 2, 1], "triangle6": [0, 2, 1, 5, 4, 3], "quad": [0, 3, 2, 1],
            "tetra": [0, 2, 1, 3], "tetra10": [0, 2, 1, 3, 6, 5, 4, 7, 9, 8],
            "hexahedron": [0, 3, 2, 1, 4, 7, 6, 5]}[cell_type]


def test_nodal_sums_against_add_at():
    rng = np.random.default_rng(6)
    cells = rng.integers(0, 30, size=(50, 4))
    vol = rng.random(50)
    at_nodes = rng.standard_normal((3, 4, 50))
    per_cell = rng.standard_normal((3, 50))
    for values, nodal in ((at_nodes, at_nodes.transpose(2, 1, 0)),
                          (per_cell, np.repeat(per_cell.T[:, None, :], 4, axis=1))):
        sums, weights = kernels.nodal_sums(cells, values, vol, 32)
        expected = np.zeros((32, 3))
        np.add.at(expected, cells, nodal * vol[:, None, None])
        w = np.zeros(32)
        np.add.at(w, cells, np.broadcast_to(vol[:, None], cells.shape))
        np.testing.assert_allclose(sums, expected, rtol=1e-14, atol=1e-14)
        np.testing.assert_allclose(weights, w, rtol=1e-14)
        assert np.all(weights[30:] == 0) and np.all(sums[30:] == 0)
