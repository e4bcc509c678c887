"""Terms on the tuples of contact rows built per rank (``effects.row_terms``): a slave's rows
live on its owner, their master nodes on any rank; the tuple is sent once to the owners of
its other nodes (``contact.distributed.SharedTuples``), which declare it too, and its values
follow it at each evaluation: no rank holds another's tuples but those touching its nodes."""

from __future__ import annotations

from typing import Callable

import numpy as np
from mpi4py import MPI

from parsolve.contact.distributed import SharedTuples
from parsolve.contact.rows import Rows
from parsolve.effects.row_terms import RowTerm, RowTuples, outer_blocks
from parsolve.fem.element_matrices import Term, TermMatrices


class SharedRowTerm(RowTerm):
    """A ``RowTerm`` on this rank's own rows: its tuples shared with their nodes' owners;
    ``new_of`` gives input node ids' global numbers (this rank's rows' nodes)."""

    def __init__(self, field: str, symmetric: bool, new_of: Callable[[np.ndarray], np.ndarray]):
        super().__init__(field, symmetric)
        self.new_of = new_of
        self.shared: SharedTuples | None = None

    def lay(self, rows: Rows, per: int, dim: int, values, mesh, whole: bool = False) -> None:
        """Its tuples from the rows' layout (this rank's rows: ``whole`` is not). Collective."""
        self.layout = RowTuples(rows, per, dim)
        nodes = self.layout.nodes
        width = values.comm.allreduce(nodes.shape[1], op=MPI.MAX)
        if width > nodes.shape[1]:   # (the same width everywhere: first nodes repeated)
            pad = np.repeat(nodes[:, :1], width - nodes.shape[1], axis=1)
            self.layout.nodes = nodes = np.concatenate([nodes, pad], axis=1)
        self.shared = SharedTuples(values.comm, self.new_of(nodes).reshape(nodes.shape),
                                   values.node_ranges)
        self.declared = np.arange(nodes.shape[0])
        self.term.nodes = self.shared.nodes

    def matrices(self, u: np.ndarray, w: np.ndarray) -> tuple[Term, TermMatrices]:
        """(the term, Σ_r u_r w_rᵀ) from (k, r, m, d) arrays over this rank's tuples, with
        the values of the tuples sent to it. Collective."""
        blocks = np.moveaxis(outer_blocks(u, w), -1, 0)
        return self.term, TermMatrices(self.term, np.moveaxis(self.shared.share(blocks), 0, -1))
