"""Sparsity pattern of a rank's stiffness rows, built once, and the map that re-assembles into it.

The pattern is built at node level (one key per unordered node pair of a cell: ncomp² fewer keys
than DOF pairs, and about half the node pairs since the pattern is symmetric), then expanded to
DOFs. Element values come cell-last, ``(ncomp², nen, nen, ncells)``, and ``pair_slot`` maps each
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

    def block_positions(self, row_start: np.ndarray, dtype: type | None = None) -> np.ndarray:
        """(ncomp, ncomp, nnzb) slot of entry (i, j) of each node-pair block in a CSR whose owned
        DOF row r starts at row_start[r] with its stiffness entries first.

        dtype: of the result (default: row_start's, at least int64); np.int32 halves the memory
        of a map kept for every re-assembly when the CSR has fewer than 2³¹ entries."""
        # entry (i, j) of pair p in node row n: row_start[n nc + i] + nc (p - bptr[n]) + j; the
        # per-row part is repeated once per component, the rest is a ramp: no (nc, nnzb) gather
        nc = self.ncomp
        bptr = np.concatenate([[0], np.cumsum(self.nb)])
        first = row_start.reshape(-1, nc) - nc * bptr[:-1, None]                # (nown, nc)
        ramp = nc * np.arange(self.nnzb, dtype=np.int64)
        out = np.empty((nc, nc, self.nnzb), dtype=dtype or np.result_type(row_start, np.int64))
        for i in range(nc):
            start = np.repeat(first[:, i], self.nb)
            start += ramp
            for j in range(nc):
                np.add(start, j, out=out[i, j], casting="unsafe")
        return out

    def diagonal_positions(self, row_start: np.ndarray) -> np.ndarray:
        """Slot of each owned DOF row's diagonal entry."""
        nc = self.ncomp
        rows = np.arange(self.nown * nc)
        return row_start[rows] + nc * self.diag_rank[rows // nc] + rows % nc


def _unique_inverse(key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """np.unique(key, return_inverse=True) by a stable sort: keys taken cell after cell for one
    pair of element nodes come in long nearly sorted runs when the numbering follows the mesh,
    which timsort merges several times faster than np.unique's quicksort sorts them."""
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    new = np.empty(key.size, dtype=bool)
    new[:1] = True
    np.not_equal(sorted_key[1:], sorted_key[:-1], out=new[1:])
    inv = np.empty(key.size, dtype=np.intp)
    inv[order] = np.cumsum(new) - 1
    return sorted_key[new], inv


def node_pattern(cells: np.ndarray, lo: int, hi: int, ncomp: int, nnodes: int) -> NodePattern:
    """Pattern of node rows [lo, hi) for cells given as (ncells, nen) new node numbers.

    The pattern is symmetric, so only the unordered node pairs (edges) of each cell are sorted:
    nen(nen-1)/2 keys per cell instead of nen². A row's columns are its lower neighbours, then
    itself, then its upper neighbours; the upper ones come sorted with the edges, the lower ones
    from one stable sort by their other end."""
    ct = np.ascontiguousarray(cells.T, dtype=np.int64)                      # (nen, ncells)
    nen, ncells = ct.shape
    nown = hi - lo
    iu, ju = np.triu_indices(nen, 1)
    a, b = ct[iu], ct[ju]                                                   # (npairs, ncells)
    forward = a < b
    small, large = np.where(forward, a, b), np.where(forward, b, a)
    ct_own = (ct >= lo) & (ct < hi)
    same = a == b                                   # a repeated node: a diagonal entry
    touches = ct_own[iu] | ct_own[ju]
    if same.any():
        touches &= ~same
    key = small * nnodes + large
    if not touches.all():
        key = key[touches]
    ukey, inv = _unique_inverse(key.ravel())
    e_small, e_large = ukey // nnodes - lo, ukey % nnodes - lo               # local rows
    up = (e_small >= 0) & (e_small < nown)          # entry (small, large) in an owned row
    down = (e_large >= 0) & (e_large < nown)        # entry (large, small) in an owned row
    has_diag = np.bincount(ct[ct_own] - lo, minlength=nown) > 0
    n_up = np.bincount(e_small[up], minlength=nown)
    n_down = np.bincount(e_large[down], minlength=nown)
    nb = n_down + has_diag + n_up
    bptr = np.concatenate([[0], np.cumsum(nb)])
    nnzb = int(bptr[-1])
    # place of each entry: its row's start, then its rank among the row's lower / upper entries
    up_idx = np.flatnonzero(up)
    up_rows = e_small[up_idx]
    up_rank = np.arange(up_idx.size) - np.concatenate([[0], np.cumsum(n_up)])[up_rows]
    up_slot = np.full(ukey.size + 1, nnzb, dtype=np.intp)
    up_slot[up_idx] = bptr[up_rows] + n_down[up_rows] + has_diag[up_rows] + up_rank
    down_idx = np.flatnonzero(down)
    down_idx = down_idx[np.argsort(e_large[down_idx], kind="stable")]  # stable: small ascending
    down_rows = e_large[down_idx]
    down_rank = np.arange(down_idx.size) - np.concatenate([[0], np.cumsum(n_down)])[down_rows]
    down_slot = np.full(ukey.size + 1, nnzb, dtype=np.intp)
    down_slot[down_idx] = bptr[down_rows] + down_rank
    ucol = np.empty(nnzb, dtype=np.int64)
    ucol[up_slot[up_idx]] = e_large[up_idx] + lo
    ucol[down_slot[down_idx]] = e_small[down_idx] + lo
    diag_slot = np.append(bptr[:-1] + n_down, nnzb)                        # dump slot last
    ucol[diag_slot[:-1][has_diag]] = np.flatnonzero(has_diag) + lo
    # element pairs: edge id (ukey.size = dump: no owned end), then which side of the edge
    if touches.all():
        edge = inv.reshape(a.shape)
    else:
        edge = np.full(a.shape, ukey.size, dtype=np.intp)
        edge[touches] = inv
    s_up, s_down = up_slot[edge], down_slot[edge]
    pair_slot = np.empty((nen, nen, ncells), dtype=np.intp)
    pair_slot[iu, ju] = np.where(forward, s_up, s_down)
    pair_slot[ju, iu] = np.where(forward, s_down, s_up)
    if same.any():                                   # degenerate cells: both are the diagonal
        d = diag_slot[np.where((a >= lo) & (a < hi), a - lo, nown)]
        pair_slot[iu, ju] = np.where(same, d, pair_slot[iu, ju])
        pair_slot[ju, iu] = np.where(same, d, pair_slot[ju, iu])
    dn = np.arange(nen)
    pair_slot[dn, dn] = diag_slot[np.where(ct_own, ct - lo, nown)]
    # an owned node in no local cell has an empty row: keep the old convention for its diagonal
    diag_rank = np.where(has_diag, n_down, np.minimum(bptr[:-1], nnzb - 1) - bptr[:-1])
    return NodePattern(lo, nown, ncomp, nb, ucol, pair_slot, diag_rank.astype(np.int64))
