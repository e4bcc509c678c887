"""Curved Q2 meshes written as Gmsh 2.2 files: a ring sector of nine-node (Lagrange) or
eight-node (serendipity) quadrilaterals whose every node, midside ones included, lies on its
exact circle (the corners, midside and centre nodes of cell (i, j) are the points (2i..2i+2,
2j..2j+2) of a polar grid twice as fine), and a quarter tube of hexahedron27/hexahedron20
cells on its exact cylinders."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

def q2_cells(counts: tuple[int, ...], cell: str) -> tuple[np.ndarray, np.ndarray]:
    """(cells of a structured grid of ``counts`` Q2 cells ``cell`` as ids of the fine grid
    (2 n + 1 points a direction, the first direction fastest), fine-grid ids used): the
    reference nodes (-1, 0, 1 a direction, in meshio's order) are the offsets 0, 1, 2."""
    from parsolve.fem.elements import element

    offsets = (element(cell).nodes + 1).astype(int)                  # (nen, dim)
    sizes = np.array([2 * n + 1 for n in counts])
    stride = np.concatenate([[1], np.cumprod(sizes[:-1])])
    starts = np.meshgrid(*[2 * np.arange(n) for n in counts[::-1]], indexing="ij")[::-1]
    first = sum(s.ravel() * k for s, k in zip(starts, stride))     # first direction fastest
    cells = first[:, None] + offsets @ stride
    return cells, np.unique(cells)


def q2_mesh(counts: tuple[int, ...], cell: str, place=None):
    """The Mesh of ``q2_cells`` on [0, 1]^d, its points moved by ``place(uvw (n, d))``."""
    from parsolve.mesh.mesh import Mesh

    cells, used = q2_cells(counts, cell)
    sizes = [2 * n + 1 for n in counts]
    grid = np.meshgrid(*[np.linspace(0.0, 1.0, k) for k in sizes[::-1]], indexing="ij")[::-1]
    uvw = np.column_stack([g.ravel() for g in grid])
    number = np.full(len(uvw), -1)
    number[used] = np.arange(used.size)                 # serendipity: interior ids unused
    points = uvw[used] if place is None else place(uvw[used])
    return Mesh(points, cell, number[cells])


def ring_sector_cells(nr: int, nt: int, cell: str = "quad9") -> tuple[np.ndarray, np.ndarray]:
    """``q2_cells`` of an nr × nt grid."""
    return q2_cells((nr, nt), cell)


def q2_grid(nr: int, nt: int, place, cell: str = "quad9"):
    """(mesh of nr × nt cells ``cell``, quad9 or quad8, on the fine grid (u, v) ∈ [0, 1]²
    placed at ``place(u, v)`` -> (x, y); its facets (line3) at u = 0, u = 1, v = 0, v = 1)."""
    from parsolve.mesh.mesh import Mesh

    cells, used = ring_sector_cells(nr, nt, cell)
    fine = np.arange((2 * nr + 1) * (2 * nt + 1))
    x, y = place((fine % (2 * nr + 1)) / (2 * nr), (fine // (2 * nr + 1)) / (2 * nt))
    number = np.full(fine.size, -1)
    number[used] = np.arange(used.size)          # quad8: the centres are no nodes
    cells = number[cells]
    grid = cells.reshape(nt, nr, -1)
    sides = {"u0": grid[:, 0][:, [3, 0, 7]], "u1": grid[:, -1][:, [1, 2, 5]],
             "v0": grid[0][:, [0, 1, 4]], "v1": grid[-1][:, [2, 3, 6]]}
    return Mesh(np.column_stack([x, y])[used], cell, cells), sides


def ring_sector_mesh(a: float, b: float, nr: int, nt: int, angle: float = np.pi / 2,
                     cell: str = "quad9"):
    """(mesh of the sector a ≤ r ≤ b, 0 ≤ θ ≤ angle: nr × nt cells ``cell``, quad9 or quad8,
    counter-clockwise; its "inner" (r = a) and "outer" (r = b) line3 facets)."""
    def polar(u, v):
        r, theta = a + (b - a) * u, angle * v
        return r * np.cos(theta), r * np.sin(theta)

    mesh, sides = q2_grid(nr, nt, polar, cell)
    return mesh, sides["u0"], sides["u1"]


def ring_sector(path, a: float, b: float, nr: int, nt: int, angle: float = np.pi / 2,
                cell: str = "quad9") -> None:
    """``ring_sector_mesh`` written as a Gmsh 2.2 file with the physical groups "ring",
    "inner" and "outer", on rank 0 (every rank waits for it)."""
    import meshio

    if MPI.COMM_WORLD.rank == 0:
        mesh, inner, outer = ring_sector_mesh(a, b, nr, nt, angle, cell)
        points = np.column_stack([mesh.points, np.zeros(mesh.num_points)])
        blocks = [(cell, mesh.cells), ("line3", inner), ("line3", outer)]
        phys = [np.full(len(c), tag) for (_, c), tag in zip(blocks, [1, 10, 11])]
        field = {"ring": np.array([1, 2]), "inner": np.array([10, 1]), "outer": np.array([11, 1])}
        meshio.write(str(path), meshio.Mesh(points, blocks, cell_data={
            "gmsh:physical": phys, "gmsh:geometrical": phys}, field_data=field),
            file_format="gmsh22", binary=False)
    MPI.COMM_WORLD.Barrier()


def quarter_tube_q2(path, a: float, b: float, height: float, nr: int, nt: int, nz: int,
                    cell: str = "hexahedron27") -> None:
    """A quarter of a thick tube a ≤ r ≤ b, 0 ≤ z ≤ height of nr × nt × nz cells ``cell``
    (hexahedron27 or hexahedron20) whose nodes lie on the exact cylinders, facet groups
    "inner" and "outer" (quad9 or quad8 faces), as a Gmsh 2.2 file (meshio writes Gmsh's
    node order); on rank 0, every rank waits."""
    import meshio

    from parsolve.mesh.topology import FACETS

    def tube(uvw):
        r, theta = a + (b - a) * uvw[:, 0], np.pi / 2 * uvw[:, 1]
        return np.column_stack([r * np.cos(theta), r * np.sin(theta), height * uvw[:, 2]])

    if MPI.COMM_WORLD.rank == 0:
        mesh = q2_mesh((nr, nt, nz), cell, tube)
        grid = mesh.cells.reshape(nz, nt, nr, -1)
        inner = grid[:, :, 0].reshape(-1, grid.shape[-1])[:, FACETS[cell][5]]     # x = 0 face
        outer = grid[:, :, -1].reshape(-1, grid.shape[-1])[:, FACETS[cell][3]]    # x = 1 face
        face = "quad9" if cell == "hexahedron27" else "quad8"
        blocks = [(cell, mesh.cells), (face, inner), (face, outer)]
        phys = [np.full(len(c), tag) for (_, c), tag in zip(blocks, [1, 10, 11])]
        field = {"tube": np.array([1, 3]), "inner": np.array([10, 2]), "outer": np.array([11, 2])}
        meshio.write(str(path), meshio.Mesh(mesh.points, blocks, cell_data={
            "gmsh:physical": phys, "gmsh:geometrical": phys}, field_data=field),
            file_format="gmsh22", binary=False)
    MPI.COMM_WORLD.Barrier()
