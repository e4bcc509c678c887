"""The previous node-pair pattern builder (sorting every (row node, column node) key of every
element), kept as the baseline of scripts/bench_setup.py's "old" column. The same code as
tests/la/test_pattern.py's reference (which checks the current builder against it); a copy here
because benchmarks import nothing from tests/."""

from __future__ import annotations

import numpy as np

from parsolve.la.pattern import NodePattern


def reference_pattern(cells: np.ndarray, lo: int, hi: int, ncomp: int, nnodes: int) -> NodePattern:
    """The previous builder: sorts every (row node, column node) key of every element."""
    ct = np.ascontiguousarray(cells.T)
    nen, ncells = ct.shape
    rows = np.broadcast_to(ct[:, None, :], (nen, nen, ncells))
    cols = np.broadcast_to(ct[None, :, :], (nen, nen, ncells))
    own_row = (ct >= lo) & (ct < hi)
    own = np.broadcast_to(own_row[:, None, :], rows.shape)
    key = (rows[own] - lo).astype(np.int64) * nnodes + cols[own]
    ukey, inv = np.unique(key, return_inverse=True)
    urow = ukey // nnodes
    nown = hi - lo
    nb = np.bincount(urow, minlength=nown)
    bptr = np.concatenate([[0], np.cumsum(nb)])
    pair_slot = np.full((nen, nen, ncells), ukey.size, dtype=np.intp)
    pair_slot[own] = inv
    diag = np.searchsorted(ukey, np.arange(nown, dtype=np.int64) * nnodes + lo + np.arange(nown))
    return NodePattern(lo, nown, ncomp, nb, ukey % nnodes, pair_slot,
                       (np.minimum(diag, ukey.size - 1) - bptr[:-1]).astype(np.int64))


def reference_block_positions(p: NodePattern, row_start: np.ndarray) -> np.ndarray:
    nc = p.ncomp
    bptr = np.concatenate([[0], np.cumsum(p.nb)])
    row = np.repeat(np.arange(p.nown), p.nb)
    rank = np.arange(p.nnzb) - bptr[row]
    starts = row_start.reshape(-1, nc)[row].T
    return starts[:, None, :] + nc * rank[None, None, :] + np.arange(nc)[None, :, None]
