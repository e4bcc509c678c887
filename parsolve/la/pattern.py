"""Sparsity pattern of a rank's stiffness rows, built once, and the map that re-assembles into it.

The pattern is built at node level (one key per node pair: ncomp² fewer keys to sort), then
expanded to DOFs. Element values come cell-last, ``(ncomp², nen, nen, ncells)``, and ``pair_slot`` maps each
(row node, column node, cell) to its node pair: a re-assembly sums element blocks into node
pairs with ``np.bincount`` (one per component pair), then places the blocks in the CSR value
array through ``block_positions``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class NodePattern:
    """Node-level CSR of the owned rows [lo, hi) for a set of cells."""

    lo: int
    nown: int
    ncomp: int
    nb: np.ndarray          # (nown,) neighbour nodes of each owned node
    ucol: np.ndarray        # neighbour node numbers, row by row (sorted within a row)
    pair_slot: np.ndarray   # (nen, nen, ncells) node pair of each element block; nnzb if row owned elsewhere
    diag_rank: np.ndarray   # (nown,) place of node i in its own row

    @property
    def nnzb(self) -> int:
        return int(self.ucol.size)

    def row_nnz(self) -> np.ndarray:
        """Stiffness entries of each owned DOF row (node-major DOFs)."""
        return np.repeat(self.nb * self.ncomp, self.ncomp)

    def block_positions(self, row_start: np.ndarray) -> np.ndarray:
        """(ncomp, ncomp, nnzb) slot of entry (i, j) of each node-pair block in a CSR whose owned
        DOF row r starts at row_start[r] with its stiffness entries first."""
        nc = self.ncomp
        bptr = np.concatenate([[0], np.cumsum(self.nb)])
        row = np.repeat(np.arange(self.nown), self.nb)
        rank = np.arange(self.nnzb) - bptr[row]
        starts = row_start.reshape(-1, nc)[row].T                            # (nc, nnzb)
        return starts[:, None, :] + nc * rank[None, None, :] + np.arange(nc)[None, :, None]

    def diagonal_positions(self, row_start: np.ndarray) -> np.ndarray:
        """Slot of each owned DOF row's diagonal entry."""
        nc = self.ncomp
        rows = np.arange(self.nown * nc)
        return row_start[rows] + nc * self.diag_rank[rows // nc] + rows % nc


def node_pattern(cells: np.ndarray, lo: int, hi: int, ncomp: int, nnodes: int) -> NodePattern:
    """Pattern of node rows [lo, hi) for cells given as (ncells, nen) new node numbers."""
    ct = np.ascontiguousarray(cells.T)                                      # (nen, ncells)
    nen, ncells = ct.shape
    rows = np.broadcast_to(ct[:, None, :], (nen, nen, ncells))
    cols = np.broadcast_to(ct[None, :, :], (nen, nen, ncells))
    own_row = (ct >= lo) & (ct < hi)                                        # (nen, ncells)
    own = np.broadcast_to(own_row[:, None, :], rows.shape)
    key = (rows[own] - lo).astype(np.int64) * nnodes + cols[own]
    ukey, inv = np.unique(key, return_inverse=True)
    urow = ukey // nnodes
    nown = hi - lo
    nb = np.bincount(urow, minlength=nown)
    bptr = np.concatenate([[0], np.cumsum(nb)])
    pair_slot = np.full((nen, nen, ncells), ukey.size, dtype=np.intp)  # bincount's own type
    pair_slot[own] = inv
    diag = np.searchsorted(ukey, np.arange(nown, dtype=np.int64) * nnodes + lo + np.arange(nown))
    return NodePattern(lo, nown, ncomp, nb, ukey % nnodes, pair_slot,
                       (np.minimum(diag, ukey.size - 1) - bptr[:-1]).astype(np.int64))
