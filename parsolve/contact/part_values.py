"""Values of the contact rows from the primal vector a solver holds, on a rank's part of the
mesh.

Contact rows name input DOFs (``node_input_id * ncomp + comp``). The primal vector holds this
rank's local DOFs (``LocalMesh``: owned nodes first, then ghosts): a row's value is the sum over the ranks of its entries on their owned DOFs, one reduction of the
rows' size — what ``SaddleSystem.relation_primal`` does, which the effect's hooks cannot reach
(Newton hands them the primal vector only). Every rank then holds the same row values, so the
contact decisions made from them agree.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve.io.slabs import OwnedRows


class PartValues:
    def __init__(self, mesh, ncomp: int, comm=None):
        self.mesh, self.ncomp, self.comm = mesh, ncomp, comm
        self._order = np.argsort(mesh.global_nodes, kind="stable")
        self._sorted = mesh.global_nodes[self._order]

    def local_nodes(self, nodes: np.ndarray) -> np.ndarray:
        """Local node of each input node id, -1 where the node is not on this rank."""
        nodes = np.asarray(nodes, dtype=np.int64)
        if self._sorted.size == 0:
            return np.full(nodes.shape, -1, dtype=np.int64)
        pos = np.minimum(np.searchsorted(self._sorted, nodes), self._sorted.size - 1)
        return np.where(self._sorted[pos] == nodes, self._order[pos], -1)

    def owned_nodes(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(mask of the input node ids owned here, their local nodes)."""
        local = self.local_nodes(nodes)
        own = (local >= 0) & (local < self.mesh.n_owned)
        return own, local[own]

    def rows(self, dofs: np.ndarray, rows: np.ndarray, coefs: np.ndarray, nrows: int,
             q: np.ndarray) -> np.ndarray:
        """A q of rows given as COO entries over input DOFs (the same on every rank;
        collective)."""
        node, comp = np.divmod(np.asarray(dofs, dtype=np.int64), self.ncomp)
        own, local = self.owned_nodes(node)
        out = np.bincount(rows[own], weights=coefs[own] * q[local * self.ncomp + comp[own]],
                          minlength=nrows).astype(float, copy=False)
        self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return out

    def relation(self, r, q: np.ndarray) -> np.ndarray:
        """A q of a relation's rows."""
        return self.rows(r.a_dofs, r.a_rows, r.a_vals, r.nrows, q)

    def max_abs(self, v: np.ndarray) -> float:
        """max |v| over the whole mesh (every rank's local DOFs)."""
        local = float(np.abs(v).max()) if v.size else 0.0
        return self.comm.allreduce(local, op=MPI.MAX)

    def nodal(self, nodes: np.ndarray, values: np.ndarray, fill: float = 0.0):
        """A nodal output (k columns) with ``values`` at input ``nodes`` and ``fill`` elsewhere:
        this rank's owned rows (``OwnedRows``, increasing input id: owned nodes come first,
        in that order)."""
        values = np.asarray(values, dtype=float).reshape(len(nodes), -1)
        own, local = self.owned_nodes(nodes)
        out = np.full((self.mesh.n_owned, values.shape[1]), fill)
        out[local] = values[own]
        return OwnedRows(out)

    def node_rows(self, rows: list, u: np.ndarray) -> list[np.ndarray]:
        """Values of ``Rows`` (``parsolve.contact.rows``, nodes as input ids) for a nodal field
        u (npoints, k) of this rank's nodes, every rank the same: the entries on owned nodes,
        summed over the ranks in one reduction of the rows' total size (each entry counted
        once)."""
        parts = []
        for r in rows:
            own, local = self.owned_nodes(r.node)
            parts.append(np.bincount(r.row[own], weights=r.coef[own] * u[local, r.comp[own]],
                                     minlength=r.nrows).astype(float, copy=False))
        out = np.concatenate(parts) if parts else np.zeros(0)
        self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return np.split(out, np.cumsum([r.nrows for r in rows])[:-1])

    def node_sum(self, nodes: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Per input node of ``nodes``, ``values`` (one per node, computed on this rank's
        nodes) taken where the node is owned and summed over the ranks: each node's value from
        its owner, the same on every rank (one reduction of the nodes' size)."""
        values = np.asarray(values, dtype=float)
        own, _ = self.owned_nodes(nodes)
        out = np.where(own.reshape(own.shape + (1,) * (values.ndim - 1)), values, 0.0)
        self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return out
