"""Contact between bodies of Q2 quadrilaterals (quad9, quad8) in 2D: their faces are the
three-node lines of six-node triangles, and the contact works on them unchanged — the mortar
patch test on non-matching meshes transmits a uniform pressure to round-off."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from helpers.contact import PATCH
from helpers.curved_q2 import q2_grid


def two_q2_blocks(path, cell: str, nx_low: int, nx_up: int) -> None:
    """[0, 1] × [0, ½] and [0, 1] × [½, 1] of ``cell`` (2 rows each), not connected, with the
    groups of ``helpers.contact.PATCH``; written on rank 0 (every rank waits)."""
    import meshio

    if MPI.COMM_WORLD.rank == 0:
        low, ls = q2_grid(nx_low, 2, lambda u, v: (u, 0.5 * v), cell)
        up, us = q2_grid(nx_up, 2, lambda u, v: (u, 0.5 + 0.5 * v), cell)
        off = low.num_points
        points = np.vstack([low.points, up.points])
        lines = [("lower_top", ls["v1"]), ("lower_bottom", ls["v0"]), ("lower_left", ls["u0"]),
                 ("upper_top", us["v1"] + off), ("upper_bottom", us["v0"] + off),
                 ("upper_left", us["u0"] + off)]
        blocks = [(cell, low.cells), (cell, up.cells + off)] + [("line3", f) for _, f in lines]
        tags = [1, 2] + [10 + i for i in range(len(lines))]
        phys = [np.full(len(b[1]), tag) for b, tag in zip(blocks, tags)]
        field = {"lower": np.array([1, 2]), "upper": np.array([2, 2])}
        field.update({name: np.array([10 + i, 1]) for i, (name, _) in enumerate(lines)})
        meshio.write(str(path), meshio.Mesh(np.column_stack([points, np.zeros(len(points))]),
                     blocks, cell_data={"gmsh:physical": phys, "gmsh:geometrical": phys},
                     field_data=field), file_format="gmsh22", binary=False)
    MPI.COMM_WORLD.Barrier()


@pytest.mark.parametrize("cell", ["quad9", "quad8"])
def test_mortar_patch_on_q2_faces(run, shared_tmp, cell):
    """3 against 5 cells across the interface: σ_yy = −p everywhere to round-off, the normal
    force p per unit width (p/2 at the first step), one iteration per step."""
    mesh = shared_tmp / f"patch_{cell}.msh"
    two_q2_blocks(mesh, cell, 3, 5)
    p = 10.0
    res = run(PATCH.format(mesh=mesh, traction=-p, extra='discretization = "mortar"'))
    stress = res["fields/stress"][-1]
    np.testing.assert_allclose(stress[:, 1], -p, atol=1e-12 * p)
    np.testing.assert_allclose(stress[:, [0, 2]], 0.0, atol=1e-12 * p)
    np.testing.assert_allclose(res["relations/joint_normal/normal_force"][:, 0], [p / 2, p],
                               rtol=1e-12)
    assert np.all(res["steps/iterations"] == 1)
