"""Patch tests: a linear displacement imposed on the boundary of a distorted mesh is reproduced
exactly inside, with the constant stress C ε, for every element type."""

from pathlib import Path

import meshio
import numpy as np
import pytest
from mpi4py import MPI

from parsolve.fem.materials.base import elastic_matrix
from parsolve.mesh.generators import box, rectangle

GRAD_2D = np.array([[1e-3, 2e-3], [-1.5e-3, 3e-3]])
GRAD_3D = np.array([[1e-3, 2e-3, -1e-3], [-1.5e-3, 3e-3, 0.5e-3], [0.7e-3, -2e-3, 1.2e-3]])


def distorted_mesh(cell: str, path: Path) -> None:
    """A unit square/cube mesh whose interior nodes are moved randomly (reproducibly)."""
    mesh = rectangle(1.0, 1.0, 4, 3, cell=cell) if cell in ("quad", "triangle", "triangle6") \
        else box(1.0, 1.0, 1.0, 3, 2, 2, cell=cell)
    pts = mesh.points.copy()
    interior = np.all((pts > 1e-12) & (pts < 1 - 1e-12), axis=1)
    rng = np.random.default_rng(1)
    pts[interior] += rng.uniform(-0.06, 0.06, size=(interior.sum(), pts.shape[1]))
    if cell in ("triangle6", "tetra10"):  # keep P2 edges straight: midside = mean of its ends
        from parsolve.mesh.generators import make_quadratic

        lin = rectangle(1.0, 1.0, 4, 3, cell="triangle") if cell == "triangle6" \
            else box(1.0, 1.0, 1.0, 3, 2, 2, cell="tetra")
        lp = lin.points.copy()
        inner = np.all((lp > 1e-12) & (lp < 1 - 1e-12), axis=1)
        lp[inner] += rng.uniform(-0.06, 0.06, size=(inner.sum(), lp.shape[1]))
        lin.points = lp
        mesh = make_quadratic(lin)
        pts = mesh.points
    if MPI.COMM_WORLD.rank == 0:
        meshio.write(str(path), meshio.Mesh(pts, [(mesh.cell_type, mesh.cells)]))
    MPI.COMM_WORLD.Barrier()


def scene(mesh_file: Path, dim: int) -> str:
    grad = GRAD_2D if dim == 2 else GRAD_3D
    xyz = "xyz"[:dim]
    boundary = " or ".join(f"{c} == 0 or {c} == 1" for c in xyz)
    rels = ""
    for i, c in enumerate(xyz):
        expr = " + ".join(f"{grad[i, j]!r} * {xyz[j]}" for j in range(dim))
        rels += f'''
[[relations]]
name = "u{c}"
type = "dirichlet"
region = "boundary"
components = ["{c}"]
value = "{expr}"
'''
    return f'''
[mesh]
file = "{mesh_file}"
[model]
hypothesis = "{'plane_strain' if dim == 2 else '3d'}"
[regions]
boundary = "{boundary}"
[[materials]]
E = 200.0
nu = 0.3
{rels}'''


@pytest.mark.parametrize("cell", ["triangle", "triangle6", "quad", "tetra", "tetra10", "hexahedron"])
def test_patch(cell, run, shared_tmp):
    dim = 2 if cell in ("quad", "triangle", "triangle6") else 3
    mesh_file = shared_tmp / f"patch_{cell}.vtu"
    distorted_mesh(cell, mesh_file)
    res = run(scene(mesh_file, dim), name=f"patch_{cell}")
    grad = GRAD_2D if dim == 2 else GRAD_3D
    pts = res["mesh/points"]
    u = res["fields/displacement"][-1]
    np.testing.assert_allclose(u, pts @ grad.T, rtol=0, atol=1e-13)
    eps = 0.5 * (grad + grad.T)
    voigt = [eps[0, 0], eps[1, 1], 2 * eps[0, 1]] if dim == 2 else \
        [eps[0, 0], eps[1, 1], eps[2, 2], 2 * eps[1, 2], 2 * eps[0, 2], 2 * eps[0, 1]]
    sigma = elastic_matrix(200.0, 0.3, "plane_strain" if dim == 2 else "3d") @ voigt
    stress = res["cell_fields/stress"][-1]
    np.testing.assert_allclose(stress, np.tile(sigma, (len(stress), 1)), rtol=0,
                               atol=1e-11 * np.abs(sigma).max())
