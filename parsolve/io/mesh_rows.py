"""The result file's mesh from the ranks' parts: every rank hands the writers the rows it
owns (its owned nodes' coordinates, its owned cells' connectivity in input ids), never the
whole; the writers place them in input order (``slabs``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.io.slabs import OwnedRows, Rows
from parsolve.mesh.mesh import CELL_INFO


@dataclass
class OutputMesh:
    """What the writers read of a mesh: sizes and types, and the rows as ``OwnedRows``."""

    cell_type: str
    num_points: int
    num_cells: int
    nodes_per_cell: int
    points: OwnedRows
    cells: OwnedRows

    @property
    def dim(self) -> int:
        return CELL_INFO[self.cell_type][0]


def output_mesh(comm, mesh, part) -> tuple[OutputMesh, tuple[Rows, Rows]]:
    """(the mesh the writers take, (node rows, cell rows) of this rank) for a ``LocalMesh``."""
    owned_cells = part.owned_cells(comm.rank, mesh.cells)
    n_owned = mesh.n_owned
    written = OutputMesh(mesh.cell_type, mesh.num_global_points, mesh.num_global_cells,
                         mesh.nodes_per_cell, OwnedRows(mesh.points[:n_owned]),
                         # the file's connectivity stays int64 (the HDF5 layout's)
                         OwnedRows(mesh.global_nodes[mesh.cells[owned_cells]].astype(np.int64)))
    rows = (Rows.from_ids(comm, mesh.global_nodes[:n_owned], mesh.num_global_points),
            Rows.from_ids(comm, mesh.global_cells[owned_cells], mesh.num_global_cells))
    return written, rows
