"""The mesh container: one volume cell type, meshio (VTK) node ordering (the whole mesh as
read or generated; a rank's part is a ``distribute.LocalMesh``)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# meshio cell type -> (topological dimension, facet cell type)
CELL_INFO = {
    "triangle": (2, "line"),
    "triangle6": (2, "line3"),
    "quad": (2, "line"),
    "quad9": (2, "line3"),
    "quad8": (2, "line3"),
    "tetra": (3, "triangle"),
    "tetra10": (3, "triangle6"),
    "hexahedron": (3, "quad"),
    "hexahedron27": (3, "quad9"),
    "hexahedron20": (3, "quad8"),
}
# the second-order cell types (read as they are; ``order = 2`` adds midside nodes to the others)
SECOND_ORDER = ("triangle6", "quad9", "quad8", "tetra10", "hexahedron27", "hexahedron20")


@dataclass
class Mesh:
    """A mesh with a single volume cell type.

    points: (npoints, gdim) float64, gdim equals the cell's topological dimension.
    cells: (ncells, nodes_per_cell) int64 node ids in meshio/VTK order.
    cell_groups: name -> volume cell indices (from the file's physical groups).
    facet_groups: name -> (nfacets, nodes_per_facet) node ids (lower-dimensional groups).
    node_groups: name -> node ids (point groups).
    warnings: messages about the mesh that are not errors (see ``mesh.checks``).
    """

    points: np.ndarray
    cell_type: str
    cells: np.ndarray
    cell_groups: dict[str, np.ndarray] = field(default_factory=dict)
    facet_groups: dict[str, np.ndarray] = field(default_factory=dict)
    node_groups: dict[str, np.ndarray] = field(default_factory=dict)
    # what is legitimate but worth saying (unused points, duplicate points): the command line
    # prints each as "parsolve: warning: ..." on rank 0
    warnings: list[str] = field(default_factory=list)

    def unused_points(self) -> np.ndarray:
        """Ids of the points used by no cell (to be kept out of the linear system)."""
        used = np.zeros(self.num_points, dtype=bool)
        used[self.cells.ravel()] = True
        return np.flatnonzero(~used)

    @property
    def dim(self) -> int:
        return CELL_INFO[self.cell_type][0]

    @property
    def facet_type(self) -> str:
        return CELL_INFO[self.cell_type][1]

    @property
    def num_points(self) -> int:
        return self.points.shape[0]

    @property
    def nodes_per_cell(self) -> int:
        return self.cells.shape[1]

    @property
    def num_cells(self) -> int:
        return self.cells.shape[0]


def volume_type(kinds: list[str], dims: list, fail) -> tuple[str, str, int]:
    """The volume cell type of a mesh's blocks (``kinds``, of dimension ``dims``: None for a
    type parsolve does not know), its facet type and its dimension: one volume type per mesh,
    one of ``CELL_INFO``; ``fail(message)`` makes the error raised otherwise."""
    if not kinds or all(d is None for d in dims):
        raise fail("the mesh has no cells")
    vdim = max(d for d in dims if d is not None)
    vtypes = sorted({t for t, d in zip(kinds, dims) if d == vdim})
    if len(vtypes) > 1:
        raise fail(f"mixed volume cell types {', '.join(vtypes)} (one type per mesh)")
    if vtypes[0] not in CELL_INFO:
        raise fail(f"unsupported cell type {vtypes[0]!r} (supported: {', '.join(CELL_INFO)})")
    return vtypes[0], CELL_INFO[vtypes[0]][1], vdim
