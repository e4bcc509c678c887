"""Curved second-order meshes written as Gmsh 2.2 files: a quarter annulus a ≤ r ≤ b,
0 ≤ θ ≤ π/2 of six-node triangles whose nodes (mid-edge ones included) lie on the exact
circles, with line3 facet groups "inner" (r = a) and "outer" (r = b)."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve.mesh.generators import rectangle


def quarter_annulus(path, a: float, b: float, nr: int, nt: int) -> None:
    """Write the mesh on rank 0 (every rank waits for it)."""
    import meshio

    if MPI.COMM_WORLD.rank == 0:
        flat = rectangle(b - a, np.pi / 2, nr, nt, cell="triangle6", origin=(a, 0.0))
        r, theta = flat.points[:, 0], flat.points[:, 1]
        points = np.column_stack([r * np.cos(theta), r * np.sin(theta), np.zeros(len(r))])
        groups = [("inner", flat.facet_groups["left"]), ("outer", flat.facet_groups["right"])]
        blocks = [("triangle6", flat.cells)] + [("line3", f) for _, f in groups]
        tags = [1, 10, 11]
        phys = [np.full(len(c), tag) for (_, c), tag in zip(blocks, tags)]
        field = {"ring": np.array([1, 2]), "inner": np.array([10, 1]), "outer": np.array([11, 1])}
        meshio.write(str(path), meshio.Mesh(points, blocks, cell_data={
            "gmsh:physical": phys, "gmsh:geometrical": phys}, field_data=field),
            file_format="gmsh22", binary=False)
    MPI.COMM_WORLD.Barrier()


def quarter_tube(path, a: float, b: float, height: float, nr: int, nt: int, nz: int) -> None:
    """A quarter of a thick tube a ≤ r ≤ b, 0 ≤ z ≤ height of ten-node tetrahedra whose nodes
    lie on the exact cylinders, facet groups "inner" and "outer" (six-node triangles)."""
    import meshio

    from parsolve.mesh.generators import box

    if MPI.COMM_WORLD.rank == 0:
        flat = box(b - a, np.pi / 2, height, nr, nt, nz, cell="tetra10", origin=(a, 0.0, 0.0))
        r, theta, z = flat.points.T
        points = np.column_stack([r * np.cos(theta), r * np.sin(theta), z])
        groups = [("inner", flat.facet_groups["xmin"]), ("outer", flat.facet_groups["xmax"])]
        blocks = [("tetra10", flat.cells)] + [("triangle6", f) for _, f in groups]
        phys = [np.full(len(c), tag) for (_, c), tag in zip(blocks, [1, 10, 11])]
        field = {"tube": np.array([1, 3]), "inner": np.array([10, 2]), "outer": np.array([11, 2])}
        meshio.write(str(path), meshio.Mesh(points, blocks, cell_data={
            "gmsh:physical": phys, "gmsh:geometrical": phys}, field_data=field),
            file_format="gmsh22", binary=False)
    MPI.COMM_WORLD.Barrier()
