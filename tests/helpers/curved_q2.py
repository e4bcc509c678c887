"""Curved Q2 meshes written as Gmsh 2.2 files: a ring sector of nine-node (Lagrange) or
eight-node (serendipity) quadrilaterals whose every node, midside ones included, lies on its
exact circle (the corners, midside and centre nodes of cell (i, j) are the points (2i..2i+2,
2j..2j+2) of a polar grid twice as fine)."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

# a Q2 cell's nodes as (di, dj) offsets on the fine grid, in Gmsh's (= VTK's) order
QUAD9 = [(0, 0), (2, 0), (2, 2), (0, 2), (1, 0), (2, 1), (1, 2), (0, 1), (1, 1)]


def ring_sector_cells(nr: int, nt: int, cell: str = "quad9") -> tuple[np.ndarray, np.ndarray]:
    """(cells (nr nt, 9 or 8) of fine-grid ids i + j (2 nr + 1), fine-grid ids used)."""
    j, i = np.meshgrid(2 * np.arange(nt), 2 * np.arange(nr), indexing="ij")   # i fastest
    offsets = QUAD9 if cell == "quad9" else QUAD9[:8]
    cells = np.stack([(i + di) + (j + dj) * (2 * nr + 1) for di, dj in offsets], axis=-1)
    return cells.reshape(-1, len(offsets)), np.unique(cells)


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
