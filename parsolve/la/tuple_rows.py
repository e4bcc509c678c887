"""The rows another rank owns of node tuples declared on this one (``Term.global_ids``: a
contact pair's tuple, held and computed by the rank of its slave node only): their entries
sent to the rows' owners, once as node pairs (the owner's pattern holds them) and at each
assembly as values, each entry (row, column) summed over this rank's tuples first. A rank
owning the master surface of every pair then receives a few entries per pair in its rows
(its operator's own), not every pair's tuple and its dense block."""

from __future__ import annotations

import numpy as np

from parsolve.mesh.blocks import exchange


class TupleRows:
    """For tuples (k, m) of global node numbers declared here, the entries (row, column)
    of the rows owned elsewhere: sent to the rows' owners (``received``: the (row, column)
    pairs other ranks sent here, this rank's rows); ``send`` sums their values per entry and
    exchanges them. Collective."""

    def __init__(self, comm, tuples: np.ndarray, node_ranges: np.ndarray):
        self.comm = comm
        ranges = np.asarray(node_ranges, dtype=np.int64)
        lo, hi = ranges[comm.rank], ranges[comm.rank + 1]
        k, m = tuples.shape
        # (m, m, k) as the term's values: entry (row p, column q) of tuple i
        rows = np.broadcast_to(tuples.T[:, None, :], (m, m, k))
        cols = np.broadcast_to(tuples.T[None, :, :], (m, m, k))
        away = (rows < lo) | (rows >= hi)
        self.at = np.flatnonzero(away)                        # in the values' (m·m·k) order
        pairs = np.column_stack([rows[away], cols[away]]).astype(np.int64)
        pairs, self.inverse = np.unique(pairs.reshape(-1, 2), axis=0, return_inverse=True)
        self.inverse = self.inverse.ravel()
        self.dest = np.searchsorted(ranges, pairs[:, 0], side="right") - 1   # (sorted by row)
        self.n_pairs = len(pairs)
        got, _ = exchange(comm, pairs, self.dest)
        self.received = got.reshape(-1, 2)

    def cells(self, nen: int) -> np.ndarray:
        """The received entries as pseudo-cells [row, column, column, ...] of ``nen`` nodes."""
        return np.concatenate([self.received[:, :1],
                               np.repeat(self.received[:, 1:], nen - 1, axis=1)], axis=1)

    def send(self, values: np.ndarray | None, width: int, factor: float = 1.0) -> np.ndarray:
        """The term's values (width, m, m, k) × ``factor`` (None: this rank's evaluation gave
        none: zeros) summed per entry of a row owned elsewhere and sent there: the received
        entries' values (len(received), width). Collective."""
        sums = np.zeros((self.n_pairs, width))
        if values is not None and self.at.size:
            flat = values.reshape(width, -1)[:, self.at]
            for c in range(width):
                sums[:, c] = factor * np.bincount(self.inverse, weights=flat[c],
                                                  minlength=self.n_pairs)
        got, _ = exchange(self.comm, sums, self.dest)
        return got.reshape(-1, width)
