"""The solution as a rank holds it: its owned rows of the saddle vector, the values of its
ghost nodes fetched from their owners, and every multiplier (a relation's size).

``GhostExchange`` is planned once (who needs which saddle rows from whom) and then moves the
values with two buffer ``Alltoallv`` calls; ``SaddleValues`` holds what a rank knows of the
saddle vector and answers ``x[saddle indices]`` for those indices, as the whole vector would,
without being as long as it.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI


def _displacements(counts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)


class SaddleValues:
    """Values at a fixed set of saddle indices: the local primal DOFs (``q``, local order) and
    every multiplier (``lam``, scaled, global multiplier order)."""

    def __init__(self, keys: np.ndarray, q: np.ndarray, lam: np.ndarray):
        self.q, self.lam = q, lam
        self._keys = keys   # (order, sorted keys), shared by the copies

    def _where(self, idx) -> np.ndarray:
        order, sorted_keys = self._keys
        idx = np.asarray(idx, dtype=np.int64)
        if idx.size == 0:   # (a rank with no cell asks for nothing)
            return np.zeros(idx.shape, dtype=np.int64)
        pos = np.minimum(np.searchsorted(sorted_keys, idx), max(sorted_keys.size - 1, 0))
        if sorted_keys.size == 0 or not np.array_equal(sorted_keys[pos], idx):
            miss = idx[sorted_keys[pos] != idx] if sorted_keys.size else idx
            raise IndexError(f"saddle indices not held by this rank: {miss[:5]} "
                             f"({miss.size} of {idx.size})")
        return order[pos]

    def __getitem__(self, idx) -> np.ndarray:
        # each value from q or lam directly: no concatenation of both at every lookup
        where = self._where(idx)
        nq = self.q.size
        in_q = where < nq
        out = np.empty(where.shape)
        out[in_q] = self.q[where[in_q]]
        out[~in_q] = self.lam[where[~in_q] - nq]
        return out

    def copy(self) -> "SaddleValues":
        return SaddleValues(self._keys, self.q.copy(), self.lam.copy())


def value_keys(primal: np.ndarray, mult: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(order, sorted keys) of the saddle indices of [local primal DOFs, multipliers]."""
    keys = np.concatenate([primal, mult]).astype(np.int64)
    order = np.argsort(keys, kind="stable")
    return order, keys[order]


class GhostExchange:
    """Fetches the saddle rows ``wanted`` (global indices, owned by ``owner``) from their
    owners: ``fetch(x_owned)`` returns their values in the order of ``wanted``."""

    def __init__(self, comm, wanted: np.ndarray, owner: np.ndarray, offset: int):
        self.comm = comm
        order = np.argsort(owner, kind="stable")
        self.order = order
        self.recv_counts = np.bincount(owner, minlength=comm.size).astype(np.int64)
        self.send_counts = np.empty_like(self.recv_counts)
        comm.Alltoall(self.recv_counts, self.send_counts)
        asked = np.ascontiguousarray(wanted[order], dtype=np.int64)
        self.asked_of_me = np.empty(int(self.send_counts.sum()), dtype=np.int64)
        comm.Alltoallv([asked, self.recv_counts, _displacements(self.recv_counts), MPI.INT64_T],
                       [self.asked_of_me, self.send_counts, _displacements(self.send_counts),
                        MPI.INT64_T])
        self.asked_of_me -= offset   # rows of this rank's block

    def fetch(self, x_owned: np.ndarray) -> np.ndarray:
        send = np.ascontiguousarray(x_owned[self.asked_of_me], dtype=np.float64)
        got = np.empty(int(self.recv_counts.sum()), dtype=np.float64)
        self.comm.Alltoallv([send, self.send_counts, _displacements(self.send_counts), MPI.DOUBLE],
                            [got, self.recv_counts, _displacements(self.recv_counts), MPI.DOUBLE])
        out = np.empty_like(got)
        out[self.order] = got
        return out
