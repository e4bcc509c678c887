"""Sparsity pattern of a rank's stiffness rows, built once, and the map that re-assembles into it.

The pattern is built at node level (one entry per node pair: ncomp² fewer keys to sort), then
expanded to DOFs. ``positions`` gives, for every element matrix entry, its slot in the rank's CSR
value array, so a re-assembly is one ``np.bincount`` of the element matrices into that array.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class RowPattern:
    """CSR of the owned primal rows (node-major DOFs), with room for extra entries per row."""

    row_nnz_k: np.ndarray   # (nrows,) stiffness entries of each owned DOF row
    cols_k: np.ndarray      # stiffness column of each entry, in CSR order (new DOF numbering)
    positions: np.ndarray   # (ncells, nen*ncomp, nen*ncomp) slot of each element entry (flattened order)
    row_start_k: np.ndarray  # (nrows,) start of each row's stiffness entries in the K-only CSR


def stiffness_pattern(cells: np.ndarray, node_lo: int, node_hi: int, ncomp: int,
                      nnodes: int) -> RowPattern:
    """Pattern of rows [node_lo, node_hi) for the given cells (new node numbers).

    Entries of element rows owned by another rank get position -1 (they are ignored).
    """
    nen = cells.shape[1]
    r = np.repeat(cells, nen, axis=1).ravel()
    c = np.tile(cells, (1, nen)).ravel()
    own = (r >= node_lo) & (r < node_hi)
    key = (r[own] - node_lo).astype(np.int64) * nnodes + c[own]
    ukey, inv = np.unique(key, return_inverse=True)
    urow, ucol = ukey // nnodes, ukey % nnodes
    nown = node_hi - node_lo
    nb = np.bincount(urow, minlength=nown)                 # neighbours of each owned node
    bptr = np.concatenate([[0], np.cumsum(nb)])
    rank_in_row = np.arange(ukey.size) - bptr[urow]        # place of the neighbour in its row
    # DOF rows: node i, component a has nb[i]*ncomp entries; node block start = ncomp² bptr[i]
    row_nnz = np.repeat(nb * ncomp, ncomp)
    row_start = np.concatenate([[0], np.cumsum(row_nnz)])[:-1]
    # columns in CSR order: for each node row, for each component row, neighbours × components
    cols_node = ucol.reshape(-1)
    col_block = (cols_node[:, None] * ncomp + np.arange(ncomp)[None, :]).ravel()  # per node row
    # repeat the node row's column list once per component row
    seg = np.repeat(np.arange(nown), nb * ncomp)
    starts_in_block = np.concatenate([[0], np.cumsum(nb * ncomp)])[:-1]
    local = np.arange(col_block.size) - starts_in_block[seg]
    cols = np.empty(int(row_nnz.sum()), dtype=np.int64)
    for a in range(ncomp):
        dst = ncomp * ncomp * bptr[seg] + a * (nb[seg] * ncomp) + local
        cols[dst] = col_block
    # slot of each element entry (e, i, a, j, b): rows are (node i, comp a), cols (node j, comp b)
    slot_node = np.full(r.size, -1, dtype=np.int64)
    slot_node[own] = inv
    slot_node = slot_node.reshape(-1, nen, nen)
    node_i = np.where(slot_node >= 0, urow[np.maximum(slot_node, 0)], 0)
    pos_node = ncomp * ncomp * bptr[node_i] + ncomp * rank_in_row[np.maximum(slot_node, 0)]
    a = np.arange(ncomp)[None, None, :, None, None]
    b = np.arange(ncomp)[None, None, None, None, :]
    pos = (pos_node[:, :, None, :, None] + a * (nb[node_i][:, :, None, :, None] * ncomp) + b)
    pos = np.where(slot_node[:, :, None, :, None] >= 0, pos, -1)
    dtype = np.int32 if cols.size < 2**31 - 1 else np.int64
    return RowPattern(row_nnz, cols, pos.reshape(len(cells), nen * ncomp, nen * ncomp).astype(dtype),
                      row_start)
