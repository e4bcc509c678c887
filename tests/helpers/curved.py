"""Curved second-order meshes written as Gmsh 2.2 files, every node (mid-edge ones included)
on its exact circle, cylinder or sphere: a quarter annulus of six-node triangles, a quarter
tube and an eighth of a spherical shell of ten-node tetrahedra."""

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


def _triangle_grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The flat triangle u, v ≥ 0, u + v ≤ 1 cut in n² triangles: (points (u, v), triangles)."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    index = np.full((n + 1, n + 1), -1)
    index[keep] = np.arange(np.count_nonzero(keep))
    uv = np.column_stack([i[keep], j[keep]]) / n
    a, b = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    up = (a + b) <= n - 1
    down = (a + b) <= n - 2
    tri = [np.column_stack([index[a[up], b[up]], index[a[up] + 1, b[up]], index[a[up], b[up] + 1]]),
           np.column_stack([index[a[down] + 1, b[down]], index[a[down] + 1, b[down] + 1],
                            index[a[down], b[down] + 1]])]
    return uv, np.vstack(tri)


def sphere_octant(path, a: float, b: float, n: int, nr: int) -> None:
    """An eighth of a thick spherical shell a ≤ r ≤ b (x, y, z ≥ 0) of ten-node tetrahedra
    with every node on its exact sphere: the flat triangle x + y + z = 1 cut in n² triangles,
    extruded in nr layers of prisms (each cut in three tetrahedra by the diagonals from each
    quad face's lowest node id, so that neighbours agree), made quadratic in the parameters
    and mapped to the shell (the direction normalised, the radius a + ρ (b - a))."""
    import meshio

    from parsolve.mesh.generators import make_quadratic
    from parsolve.mesh.mesh import Mesh

    if MPI.COMM_WORLD.rank == 0:
        uv, tri = _triangle_grid(n)
        tri = np.sort(tri, axis=1)   # p < q < s: the prism's diagonals from the lower ids
        layer = len(uv)
        params = np.vstack([np.column_stack([uv, np.full(layer, k / nr)]) for k in range(nr + 1)])
        tets = []
        for k in range(nr):
            p, q, s = (tri + k * layer).T
            pt, qt, st = p + layer, q + layer, s + layer
            tets += [np.column_stack(c) for c in ((p, q, s, st), (p, q, qt, st), (p, pt, qt, st))]
        flat = make_quadratic(Mesh(params, "tetra", np.vstack(tets)))
        u, v, rho = flat.points.T
        d = np.column_stack([u, v, 1.0 - u - v])
        points = (a + rho * (b - a))[:, None] * d / np.linalg.norm(d, axis=1)[:, None]
        tags = [np.ones(len(flat.cells), dtype=int)]
        meshio.write(str(path), meshio.Mesh(points, [("tetra10", flat.cells)], cell_data={
            "gmsh:physical": tags, "gmsh:geometrical": tags}, field_data={
            "shell": np.array([1, 3])}), file_format="gmsh22", binary=False)
    MPI.COMM_WORLD.Barrier()
