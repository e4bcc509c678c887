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
    from parsolve.scene import MaterialSpec

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
