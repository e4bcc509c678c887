"""Relations are kept whole on every rank, in input numbering (they are the size of the
boundaries and regions they constrain, not of the mesh). ``RelationDofs`` maps the input nodes
they name to the global numbering, to this rank's local DOFs, and to their coordinates, each
found once by a reduction over the relation nodes."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI


class RelationDofs:
    """The input nodes of every relation, their global numbers, local positions (-1: not on
    this rank) and coordinates."""

    def __init__(self, comm, mesh, ncomp: int, dofs: list[np.ndarray]):
        self.ncomp = ncomp
        nodes = np.unique(np.concatenate([np.asarray(d, dtype=np.int64) // ncomp for d in dofs])
                          if dofs else np.zeros(0, dtype=np.int64))
        self.nodes = nodes
        order = np.argsort(mesh.global_nodes, kind="stable")
        sorted_ids = mesh.global_nodes[order]
        pos = np.minimum(np.searchsorted(sorted_ids, nodes), max(sorted_ids.size - 1, 0))
        here = sorted_ids[pos] == nodes if sorted_ids.size else np.zeros(nodes.size, dtype=bool)
        self.local_node = np.where(here, order[pos], -1) if order.size else np.full(nodes.size, -1)
        owned = here & (self.local_node < mesh.n_owned)
        # each node's owner contributes its global number and coordinates; one reduction
        packed = np.zeros((nodes.size, 1 + mesh.points.shape[1]))
        packed[owned, 0] = mesh.node_new[self.local_node[owned]] + 1
        packed[owned, 1:] = mesh.points[self.local_node[owned]]
        comm.Allreduce(MPI.IN_PLACE, packed, op=MPI.SUM)
        self.new_node = packed[:, 0].astype(np.int64) - 1
        self.coords = packed[:, 1:]

    def _pos(self, nodes: np.ndarray) -> np.ndarray:
        return np.searchsorted(self.nodes, nodes)

    def new_dof(self, dofs: np.ndarray) -> np.ndarray:
        node, comp = np.divmod(np.asarray(dofs, dtype=np.int64), self.ncomp)
        return self.new_node[self._pos(node)] * self.ncomp + comp

    def local(self, dofs: np.ndarray) -> np.ndarray:
        """Local DOF of each input DOF, -1 where the node is not on this rank."""
        node, comp = np.divmod(np.asarray(dofs, dtype=np.int64), self.ncomp)
        ln = self.local_node[self._pos(node)]
        return np.where(ln >= 0, ln * self.ncomp + comp, -1)

    def points_of(self, nodes: np.ndarray) -> np.ndarray:
        return self.coords[self._pos(np.asarray(nodes, dtype=np.int64))]
