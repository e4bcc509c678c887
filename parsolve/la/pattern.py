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

    def block_starts(self, row_start: np.ndarray, dtype: type | None = None) -> np.ndarray:
        """(ncomp, nnzb) slot of entry (i, 0) of each node-pair block in a CSR whose owned DOF
        row r starts at row_start[r] with its stiffness entries first; entry (i, j) is j
        further (a block row's entries are consecutive).

        dtype: of the result (default: row_start's, at least int64); np.int32 halves the memory
        of a map kept for every re-assembly when the CSR has fewer than 2³¹ entries."""
        # entry (i, 0) of pair p in node row n: row_start[n nc + i] + nc (p - bptr[n]); the
        # per-row part is repeated once per pair, the rest is a ramp
        nc = self.ncomp
        bptr = np.concatenate([[0], np.cumsum(self.nb)])
        first = row_start.reshape(-1, nc) - nc * bptr[:-1, None]                # (nown, nc)
        out = np.empty((nc, self.nnzb), dtype=dtype or np.result_type(row_start, np.int64))
        # in the result's type (every slot fits it), the row of each pair and the ramp made
        # once for all components: no temporary of int64 per pair and component (fresh
        # memory costs the kernel as much time as the arithmetic here)
        row = np.repeat(np.arange(self.nown, dtype=_index_type(self.nown)), self.nb)
        ramp = np.arange(0, nc * self.nnzb, nc, dtype=out.dtype)
        for i in range(nc):
            np.take(first[:, i].astype(out.dtype), row, out=out[i])
            out[i] += ramp
        return out

    def block_positions(self, row_start: np.ndarray, dtype: type | None = None) -> np.ndarray:
        """(ncomp, ncomp, nnzb) slot of entry (i, j) of each node-pair block (see block_starts)."""
        starts = self.block_starts(row_start, dtype)
        out = np.empty((self.ncomp,) + starts.shape, dtype=starts.dtype)
        for j in range(self.ncomp):
            np.add(starts, j, out=out[:, j], casting="unsafe")
        return out

    def diagonal_positions(self, row_start: np.ndarray) -> np.ndarray:
        """Slot of each owned DOF row's diagonal entry."""
        nc = self.ncomp
        rows = np.arange(self.nown * nc)
        return row_start[rows] + nc * self.diag_rank[rows // nc] + rows % nc


def _unique_inverse(key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """np.unique(key, return_inverse=True) of non-negative keys by a stable sort: keys taken
    cell after cell for one pair of element nodes come in long nearly sorted runs when the
    numbering follows the mesh, which timsort merges several times faster than np.unique's
    quicksort sorts them. When key and position fit in 63 bits together, the values
    key << bits | position are sorted instead of the positions by key (an argsort): the sorted
    keys and their order then come out in sequence, with no gather through the order."""
    n = key.size
    shift = max(int(n - 1).bit_length(), 1)
    if n and int(key.max()).bit_length() + shift <= 62:
        packed = np.left_shift(key, shift)
        for start in range(0, n, _RAMP):            # bounded temporaries (see block_starts)
            packed[start:start + _RAMP] |= np.arange(start, min(start + _RAMP, n))
        packed.sort(kind="stable")
        order = packed & ((1 << shift) - 1)
        sorted_key = np.right_shift(packed, shift, out=packed)
    else:
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
    new = np.empty(n, dtype=bool)
    new[:1] = True
    np.not_equal(sorted_key[1:], sorted_key[:-1], out=new[1:])
    ukey = sorted_key[new]
    rank = np.cumsum(new, out=sorted_key if sorted_key.dtype == np.int64 else None)
    rank -= 1                                       # (the sorted keys' memory, no longer used)
    inv = np.empty(n, dtype=np.intp)
    inv[order] = rank
    return ukey, inv


_RAMP = 1 << 20   # entries per piece of a ramp added in place


def _index_type(bound: int) -> type:
    """int32 for numbers below 2³¹ (half the memory and traffic), else int64."""
    return np.int32 if bound < 2**31 else np.int64


def node_pattern(cells: np.ndarray, lo: int, hi: int, ncomp: int, nnodes: int) -> NodePattern:
    """Pattern of node rows [lo, hi) for cells given as (ncells, nen) new node numbers.

    The pattern is symmetric, so only the unordered node pairs (edges) of each cell are sorted:
    nen(nen-1)/2 keys per cell instead of nen². A row's columns are its lower neighbours, then
    itself, then its upper neighbours; the upper ones come sorted with the edges, the lower ones
    from one stable sort by their other end. Node numbers are int32 when they fit (their DOF
    numbers too), and so are ``ucol`` and ``pair_slot`` (kept for every re-assembly)."""
    ct = np.ascontiguousarray(cells.T, dtype=_index_type(nnodes))            # (nen, ncells)
    nen, ncells = ct.shape
    nown = hi - lo
    iu, ju = np.triu_indices(nen, 1)
    a, b = ct[iu], ct[ju]                                                   # (npairs, ncells)
    forward = a < b
    small, large = np.minimum(a, b), np.maximum(a, b)
    same = a == b                                   # a repeated node: a diagonal entry
    del a, b
    any_same = bool(same.any())
    all_own = ncells == 0 or (int(ct.min()) >= lo and int(ct.max()) < hi)
    if all_own:                                     # one rank, or a rank with no ghost node
        ct_own = touches = None
    else:
        ct_own = (ct >= lo) & (ct < hi)
        touches = ct_own[iu] | ct_own[ju]
    if any_same:
        touches = ~same if touches is None else touches & ~same
    key = small.astype(np.int64)
    key *= nnodes
    key += large
    del small, large
    if touches is not None:
        key = key[touches]
    ukey, inv = _unique_inverse(key.ravel())
    del key
    e_small, e_large = ukey // nnodes - lo, ukey % nnodes - lo               # local rows
    up = (e_small >= 0) & (e_small < nown)          # entry (small, large) in an owned row
    down = (e_large >= 0) & (e_large < nown)        # entry (large, small) in an owned row
    own_nodes = ct.ravel() - lo if all_own else ct[ct_own] - lo
    has_diag = np.bincount(own_nodes, minlength=nown) > 0
    del own_nodes
    n_up = np.bincount(e_small[up], minlength=nown)
    n_down = np.bincount(e_large[down], minlength=nown)
    nb = n_down + has_diag + n_up
    bptr = np.concatenate([[0], np.cumsum(nb)])
    nnzb = int(bptr[-1])
    stype = _index_type(nnzb + 1)
    # place of each entry: its row's start, then its rank among the row's lower / upper entries
    # (slots of edges with no owned end, and the dump slot last, are nnzb)
    up_idx = np.flatnonzero(up)
    up_rows = e_small[up_idx]
    up_rank = np.arange(up_idx.size) - np.concatenate([[0], np.cumsum(n_up)])[up_rows]
    nedge = ukey.size + 1                            # edges, then the dump
    slots = np.full(2 * nedge, nnzb, dtype=stype)    # [down slot of each edge, up slot of each]
    up_slot = slots[nedge:]
    up_slot[up_idx] = bptr[up_rows] + n_down[up_rows] + has_diag[up_rows] + up_rank
    down_idx = np.flatnonzero(down)
    down_idx = down_idx[np.argsort(e_large[down_idx], kind="stable")]  # stable: small ascending
    down_rows = e_large[down_idx]
    down_rank = np.arange(down_idx.size) - np.concatenate([[0], np.cumsum(n_down)])[down_rows]
    down_slot = slots[:nedge]
    down_slot[down_idx] = bptr[down_rows] + down_rank
    ucol = np.empty(nnzb, dtype=_index_type(nnodes * max(ncomp, 1)))   # DOF numbers fit too
    ucol[up_slot[up_idx]] = e_large[up_idx] + lo
    ucol[down_slot[down_idx]] = e_small[down_idx] + lo
    diag_slot = np.append(bptr[:-1] + n_down, nnzb).astype(stype)          # dump slot last
    ucol[diag_slot[:-1][has_diag]] = np.flatnonzero(has_diag) + lo
    # element pairs: edge id (ukey.size = dump: no owned end), then which side of the edge: the
    # pair (i, j) of a cell is the edge's up entry when its node i is the smaller
    if touches is None:
        edge = inv.reshape(forward.shape)
    else:
        edge = np.full(forward.shape, ukey.size, dtype=np.intp)
        edge[touches] = inv
    del inv
    pair_slot = np.empty((nen, nen, ncells), dtype=stype)
    pick = np.empty(ncells, dtype=np.intp)
    for k, (i, j) in enumerate(zip(iu, ju)):        # nen(nen-1)/2 pairs of element nodes
        np.multiply(forward[k], nedge, out=pick)
        pick += edge[k]
        np.take(slots, pick, out=pair_slot[i, j])                         # (i, j): up if forward
        np.subtract(edge[k], pick, out=pick)
        pick += edge[k] + nedge
        np.take(slots, pick, out=pair_slot[j, i])                         # (j, i): the other side
    del edge, pick
    if any_same:                                     # degenerate cells: both are the diagonal
        in_rows = (ct[iu] >= lo) & (ct[iu] < hi)
        d = diag_slot[np.where(in_rows, ct[iu] - lo, nown)]
        pair_slot[iu, ju] = np.where(same, d, pair_slot[iu, ju])
        pair_slot[ju, iu] = np.where(same, d, pair_slot[ju, iu])
    for i in range(nen):
        node = ct[i] - lo if all_own else np.where(ct_own[i], ct[i] - lo, nown)
        np.take(diag_slot, node, out=pair_slot[i, i])
    # an owned node in no local cell has an empty row: keep the old convention for its diagonal
    diag_rank = np.where(has_diag, n_down, np.minimum(bptr[:-1], nnzb - 1) - bptr[:-1])
    return NodePattern(lo, nown, ncomp, nb, ucol, pair_slot, diag_rank.astype(np.int64))
