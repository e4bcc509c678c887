"""Stress outputs straight from the shape gradients agree with the strain-operator form."""

import numpy as np
import pytest

from parsolve.fem import kernels
from parsolve.mesh.generators import box, rectangle


@pytest.mark.parametrize("mesh", [rectangle(1.0, 0.5, 5, 3, cell="triangle6"),
                                  rectangle(1.0, 0.5, 5, 3, cell="quad"),
                                  box(1.0, 0.5, 0.4, 3, 2, 2, cell="tetra10"),
                                  box(1.0, 0.5, 0.4, 3, 2, 2, cell="hexahedron")],
                         ids=["triangle6", "quad", "tetra10", "hexahedron"])
def test_voigt_strain_is_B_times_u(mesh):
    rng = np.random.default_rng(1)
    coords = mesh.points[mesh.cells] + 0.02 * rng.standard_normal(mesh.cells.shape + (mesh.dim,))
    ue = rng.standard_normal(mesh.cells.shape + (mesh.dim,))
    geo = kernels.CellGeometry(coords, mesh.cell_type)
    by_B = kernels.strains(geo.strain_operator(), ue.reshape(len(ue), -1))
    np.testing.assert_allclose(kernels.voigt_strain(geo.dNdx, ue), by_B, atol=1e-12 * np.abs(by_B).max())


def test_cell_and_nodal_stress_of_a_linear_field():
    """u = A x: uniform strain, so every cell and every node carries σ = C ε exactly."""
    from parsolve.effects.elasticity import Elasticity
    from parsolve.mesh.regions import RegionResolver
    from parsolve.effects.elasticity import MaterialSpec

    mesh = rectangle(2.0, 1.0, 6, 4, cell="triangle6")
    regions = RegionResolver(mesh, {}, "test")
    mech = Elasticity(mesh, "plane_strain", 1.0,
                      [MaterialSpec("all", "elastic", {"E": 100.0, "nu": 0.3}, "materials[0]")],
                      regions, "test")
    A = np.array([[1e-3, 2e-3], [-1e-3, 4e-3]])
    u = mesh.points @ A.T
    eps = np.array([A[0, 0], A[1, 1], A[0, 1] + A[1, 0]])
    sigma = mech.C[0] @ eps
    cells = np.arange(mesh.num_cells)
    np.testing.assert_allclose(mech.cell_stress(cells, u), np.tile(sigma, (mesh.num_cells, 1)), rtol=1e-12)
    sums, weights = mech.nodal_stress_sums(cells, u)
    np.testing.assert_allclose(sums / weights[:, None], np.tile(sigma, (mesh.num_points, 1)), rtol=1e-12)


CELL_MESHES = {"triangle": lambda: rectangle(2.0, 1.0, 6, 4, cell="triangle"),
               "quad": lambda: rectangle(2.0, 1.0, 6, 4, cell="quad"),
               "tetra": lambda: box(2.0, 1.0, 0.5, 4, 2, 2, cell="tetra"),
               "hexahedron": lambda: box(2.0, 1.0, 0.5, 4, 2, 2, cell="hexahedron"),
               "tetra10": lambda: box(2.0, 1.0, 0.5, 2, 2, 1, cell="tetra10")}


def two_materials(mesh):
    """Elasticity with E = 100, ν = 0.3 everywhere but x < 1 (E = 7, ν = 0.2)."""
    from parsolve.effects.elasticity import Elasticity
    from parsolve.mesh.regions import RegionResolver
    from parsolve.effects.elasticity import MaterialSpec
    from parsolve.scene import RegionSpec

    regions = RegionResolver(mesh, {"left": RegionSpec("left", "expr", "x < 1.0", "regions.left")},
                             "test")
    hyp = "3d" if mesh.dim == 3 else "plane_stress"
    return Elasticity(mesh, hyp, 0.5,
                      [MaterialSpec("all", "elastic", {"E": 100.0, "nu": 0.3}, "materials[0]"),
                       MaterialSpec("left", "elastic", {"E": 7.0, "nu": 0.2}, "materials[1]")],
                      regions, "test")


@pytest.mark.parametrize("name", list(CELL_MESHES))
def test_stress_of_a_linear_field_with_two_materials(name):
    """u = A x: every cell carries its own material's σ = C ε; a node inside one material
    averages to that σ; outputs() gives the same as cell_stress and nodal_stress_sums."""
    mesh = CELL_MESHES[name]()
    mech = two_materials(mesh)
    d = mesh.dim
    A = np.random.default_rng(3).standard_normal((d, d)) * 1e-3
    u = mesh.points @ A.T
    if d == 2:
        eps = np.array([A[0, 0], A[1, 1], A[0, 1] + A[1, 0]])
    else:
        eps = np.array([A[0, 0], A[1, 1], A[2, 2], A[1, 2] + A[2, 1], A[0, 2] + A[2, 0],
                        A[0, 1] + A[1, 0]])
    sigma = np.array([C @ eps for C in mech.C])                      # per material
    cells = np.arange(mesh.num_cells)[1:]                            # not all: any subset
    cell_sig = mech.cell_stress(cells, u)
    np.testing.assert_allclose(cell_sig, sigma[mech.cell_model[cells]], rtol=1e-11, atol=1e-15)
    sums, weights = mech.nodal_stress_sums(cells, u)
    used = np.zeros(mesh.num_points, dtype=bool)
    used[mesh.cells[cells]] = True
    for m in (0, 1):  # nodes whose every cell has material m
        other = np.zeros(mesh.num_points, dtype=bool)
        other[mesh.cells[cells[mech.cell_model[cells] != m]]] = True
        inside = used & ~other
        assert inside.sum() > 0
        np.testing.assert_allclose(sums[inside] / weights[inside, None],
                                   np.tile(sigma[m], (inside.sum(), 1)), rtol=1e-11)
    assert np.all(weights[~used] == 0)
    nodal, per_cell = mech.outputs(cells, {"u": u}, None, cells)
    np.testing.assert_array_equal(per_cell["stress"], cell_sig)
    np.testing.assert_array_equal(nodal["stress"][0], sums)
    np.testing.assert_array_equal(nodal["stress"][1], weights)
    # the weights: each cell's measure (× thickness 0.5 in 2D) once per node of the cell
    geo = kernels.CellGeometry(mesh.points[mesh.cells[cells]], mesh.cell_type,
                               thickness=mech.thickness)
    np.testing.assert_allclose(weights.sum(), mesh.cells.shape[1] * geo.wdet.sum(), rtol=1e-13)


@pytest.mark.parametrize("name", ["quad", "hexahedron"])
def test_outputs_of_quadrature_stresses(name):
    """A nonlinear run's outputs: the cell mean of given quadrature-point stresses, weighted
    by w|J|, and its volume-weighted nodal average, against the cell-first geometry."""
    mesh = CELL_MESHES[name]()
    rng = np.random.default_rng(9)
    mesh.points[:] += 0.03 * rng.standard_normal(mesh.points.shape)
    mech = two_materials(mesh)
    local = np.arange(mesh.num_cells)
    owned = local[::3]
    geo = kernels.CellGeometry(mesh.points[mesh.cells[local]], mesh.cell_type,
                               thickness=mech.thickness)
    nv = 3 if mesh.dim == 2 else 6
    stress_qp = rng.standard_normal((len(local), geo.nq, nv))
    nodal, cells = mech.outputs(owned, {"u": np.zeros((mesh.num_points, mesh.dim))},
                                (stress_qp, mech.init_state(local)), local)
    w = geo.wdet[owned]
    mean = (stress_qp[owned] * w[:, :, None]).sum(axis=1) / w.sum(axis=1)[:, None]
    np.testing.assert_allclose(cells["stress"], mean, rtol=1e-12, atol=1e-14)
    sums, weights = nodal["stress"]
    vol = w.sum(axis=1)
    expected = np.zeros((mesh.num_points, nv))
    np.add.at(expected, mesh.cells[owned], (mean * vol[:, None])[:, None, :])
    np.testing.assert_allclose(sums, expected, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(weights.sum(), vol.sum() * mesh.cells.shape[1], rtol=1e-13)


def test_stiffness_holds_no_element_arrays():
    """The stiffness is blocked: the effect and its ElementMatrices hold no array of the
    mesh's size (the geometric part is computed block by block when it is reduced, or whole
    on demand), and the whole geometric part is the same at every call."""
    mesh = CELL_MESHES["hexahedron"]()
    mech = two_materials(mesh)
    cells = np.arange(mesh.num_cells)
    m = mech.stiffness(cells)
    first = m.geometric
    assert first.shape == (9, 8, 8, mesh.num_cells)
    held = [v for v in list(vars(m).values()) + list(vars(mech).values())
            if isinstance(v, np.ndarray) and v.size >= first.size // 8]
    assert held == []
    np.testing.assert_array_equal(mech.stiffness(cells).geometric, first)


@pytest.mark.parametrize("budget", [None, 1])
def test_increment_size_of_a_linear_field_over_cell_blocks(monkeypatch, budget):
    """u = A x: every cell has ε = (A₀₀, A₁₁, A₀₁ + A₁₀), so the largest strain component is
    max |ε| (1e-12), whatever the cell blocks (one block of every cell, or one cell a block)."""
    from parsolve.effects.elasticity import Elasticity, MaterialSpec
    from parsolve.fem import element_matrices
    from parsolve.mesh.regions import RegionResolver

    if budget is not None:   # one cell a block
        monkeypatch.setattr(element_matrices, "BLOCK_BYTES", budget)
    mesh = rectangle(2.0, 1.0, 6, 4, cell="quad")
    mech = Elasticity(mesh, "plane_strain", 1.0,
                      [MaterialSpec("all", "elastic", {"E": 100.0, "nu": 0.3}, "materials[0]")],
                      RegionResolver(mesh, {}, "test"), "test")
    A = np.array([[1e-3, 2e-3], [-1e-3, -7e-3]])
    size = mech.increment_size(np.arange(mesh.num_cells), {"u": mesh.points @ A.T})
    np.testing.assert_allclose(size, 7e-3, rtol=1e-12)
    assert mech.increment_size(np.zeros(0, dtype=np.int64), {"u": mesh.points @ A.T}) == 0.0
