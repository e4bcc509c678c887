"""Values of the contact rows from the primal vector a solver holds, on a replicated or a
distributed mesh.

Contact rows name input DOFs (``node_input_id * ncomp + comp``). On a replicated mesh the
primal vector is in input numbering and a row's value is a dot product. On a distributed mesh
(``LocalMesh``) the vector holds this rank's local DOFs (owned nodes first, then ghosts): a
row's value is the sum over the ranks of its entries on their owned DOFs, one reduction of the
rows' size — what ``SaddleSystem.relation_primal`` does, which the effect's hooks cannot reach
(Newton hands them the primal vector only). Every rank then holds the same row values, so the
contact decisions made from them agree.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve.io.slabs import OwnedRows
from parsolve.mesh.distribute import LocalMesh


class PartValues:
    def __init__(self, mesh, ncomp: int, comm=None):
        self.mesh, self.ncomp = mesh, ncomp
        self.distributed = isinstance(mesh, LocalMesh)
        self.comm = comm if self.distributed else None
        if self.distributed:
            self._order = np.argsort(mesh.global_nodes, kind="stable")
            self._sorted = mesh.global_nodes[self._order]

    def local_nodes(self, nodes: np.ndarray) -> np.ndarray:
        """Local node of each input node id, -1 where the node is not on this rank."""
        nodes = np.asarray(nodes, dtype=np.int64)
        if not self.distributed:
            return nodes
        if self._sorted.size == 0:
            return np.full(nodes.shape, -1, dtype=np.int64)
        pos = np.minimum(np.searchsorted(self._sorted, nodes), self._sorted.size - 1)
        return np.where(self._sorted[pos] == nodes, self._order[pos], -1)

    def owned_nodes(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(mask of the input node ids owned here, their local nodes)."""
        local = self.local_nodes(nodes)
        if not self.distributed:
            return np.ones(local.shape, dtype=bool), local
        own = (local >= 0) & (local < self.mesh.n_owned)
        return own, local[own]

    def rows(self, dofs: np.ndarray, rows: np.ndarray, coefs: np.ndarray, nrows: int,
             q: np.ndarray) -> np.ndarray:
        """A q of rows given as COO entries over input DOFs (the same on every rank;
        collective on a distributed mesh)."""
        if not self.distributed:
            return np.bincount(rows, weights=coefs * q[dofs], minlength=nrows)
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
        return self.comm.allreduce(local, op=MPI.MAX) if self.distributed else local

    def nodal(self, nodes: np.ndarray, values: np.ndarray, fill: float = 0.0):
        """A nodal output (k columns) with ``values`` at input ``nodes`` and ``fill`` elsewhere:
        on a replicated mesh over every node; on a distributed one this rank's owned rows
        (``OwnedRows``, increasing input id: owned nodes come first, in that order)."""
        values = np.asarray(values, dtype=float).reshape(len(nodes), -1)
        if not self.distributed:
            out = np.full((self.mesh.num_points, values.shape[1]), fill)
            out[nodes] = values
            return out
        own, local = self.owned_nodes(nodes)
        out = np.full((self.mesh.n_owned, values.shape[1]), fill)
        out[local] = values[own]
        return OwnedRows(out)

    def node_rows(self, rows: list, u: np.ndarray) -> list[np.ndarray]:
        """Values of ``Rows`` (``parsolve.contact.rows``, nodes as input ids) for a nodal field
        u (npoints, k) of this rank's nodes, every rank the same: on a replicated mesh
        ``rows.apply(u)``; on a distributed one the entries on owned nodes, summed over the
        ranks in one reduction of the rows' total size (each entry counted once)."""
        if not self.distributed:
            return [r.apply(u) for r in rows]
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
        if not self.distributed:
            return values
        own, _ = self.owned_nodes(nodes)
        out = np.where(own.reshape(own.shape + (1,) * (values.ndim - 1)), values, 0.0)
        self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return out
