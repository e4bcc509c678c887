"""Which rows of a node or cell dataset each rank writes, and how it gets them.

A result file keeps the input order of nodes and cells (DESIGN §5). In the parallel output mode
each rank writes the rows of the nodes and cells it owns (the partition's ``node_part`` and the
reporting rule of ``Partition.owned_cells``); in input numbering they are a sorted set of ids,
not one block. Two ways to put them in the file, both collective:

* ``runs``: the rank's rows as they are, selected in the file as one hyperslab per contiguous
  run of ids (no communication; as many selections as runs).
* ``blocks``: the rows are first exchanged (one ``Alltoallv``) so that rank r holds input rows
  ``[N r / P, N (r+1) / P)``, then written as one hyperslab (one contiguous request per rank).

A value handed to the writer is, on each rank, either the whole array (every row, input order:
the rank takes its own rows), ``None`` on ranks other than 0 (rank 0 holds the whole array and
scatters the rows), or :class:`OwnedRows` (only this rank's rows, in increasing id order: no
whole array anywhere).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI


@dataclass
class OwnedRows:
    """A dataset's rows for this rank's owned nodes / cells only, in increasing input id."""

    values: np.ndarray


def split_owners(n: int, size: int) -> np.ndarray:
    """Rank of each of ``n`` rows when no partition is given: near-equal contiguous blocks."""
    return np.minimum(np.arange(n) * size // max(n, 1), size - 1).astype(np.int64)


def block_bounds(n: int, size: int) -> np.ndarray:
    """Rows [bounds[r], bounds[r+1]) of rank r in the ``blocks`` layout."""
    return np.arange(size + 1, dtype=np.int64) * n // size


def runs(ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(starts, lengths) of the contiguous runs of sorted ids."""
    if ids.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cut = np.flatnonzero(np.diff(ids) != 1) + 1
    starts = ids[np.concatenate([[0], cut])]
    lengths = np.diff(np.concatenate([[0], cut, [ids.size]]))
    return starts.astype(np.int64), lengths.astype(np.int64)


class Rows:
    """One kind of row (nodes or cells): who owns what, and the exchanges that move rows."""

    def __init__(self, comm: MPI.Comm, owner: np.ndarray):
        self.comm = comm
        self.n = int(owner.size)
        self.owner = np.asarray(owner, dtype=np.int64)
        self.ids = np.flatnonzero(self.owner == comm.rank)   # this rank's rows, sorted
        self.counts = np.bincount(self.owner, minlength=comm.size)
        self.starts, self.lengths = runs(self.ids)
        self._exchange = None

    @classmethod
    def from_ids(cls, comm: MPI.Comm, ids: np.ndarray, n: int) -> "Rows":
        """Rows of a distributed mesh: each rank knows only its own (sorted input ids); rank 0
        learns every rank's once, to place gathered rows (``owner`` is None elsewhere)."""
        rows = cls.__new__(cls)
        rows.comm, rows.n = comm, int(n)
        rows.ids = np.sort(np.asarray(ids, dtype=np.int64))
        rows.counts = np.array(comm.allgather(int(rows.ids.size)), dtype=np.int64)
        rows.starts, rows.lengths = runs(rows.ids)
        rows._exchange = None
        everyone = np.empty(int(rows.counts.sum()) if comm.rank == 0 else 0, dtype=np.int64)
        comm.Gatherv(rows.ids, [everyone, rows.counts, _displacements(rows.counts), MPI.INT64_T]
                     if comm.rank == 0 else None, root=0)
        rows.owner = None
        if comm.rank == 0:
            rows.owner = np.empty(rows.n, dtype=np.int64)
            rows.owner[everyone] = np.repeat(np.arange(comm.size), rows.counts)
        return rows

    # ---------------------------------------------------------------- this rank's rows
    def local(self, value) -> np.ndarray | None:
        """This rank's owned rows of ``value`` (see the module's doc); collective when rank 0
        has to scatter (every rank passes None but rank 0)."""
        if isinstance(value, OwnedRows):
            return np.asarray(value.values)
        if value is not None:
            return np.asarray(value)[self.ids]
        return None

    def scatter(self, full: np.ndarray | None, row_shape: tuple, dtype) -> np.ndarray:
        """Rank 0's whole array -> every rank's owned rows (Scatterv, rows grouped by owner)."""
        comm = self.comm
        width = int(np.prod(row_shape, dtype=np.int64))
        out = np.empty((self.ids.size,) + tuple(row_shape), dtype=dtype)
        send = None
        if comm.rank == 0:
            order = np.argsort(self.owner, kind="stable")   # by owner, input order inside
            data = np.ascontiguousarray(np.asarray(full, dtype=dtype)[order])
            send = [data, self.counts * width, _displacements(self.counts * width),
                    MPI._typedict[np.dtype(dtype).char]]
        comm.Scatterv(send, out, root=0)
        return out

    def gather(self, local: np.ndarray) -> np.ndarray | None:
        """Every rank's owned rows -> the whole array on rank 0 (None elsewhere)."""
        comm = self.comm
        local = np.ascontiguousarray(local)
        row_shape, dtype = local.shape[1:], local.dtype
        width = int(np.prod(row_shape, dtype=np.int64))
        recv = None
        if comm.rank == 0:
            grouped = np.empty((self.n,) + row_shape, dtype=dtype)
            recv = [grouped, self.counts * width, _displacements(self.counts * width),
                    MPI._typedict[dtype.char]]
        comm.Gatherv(local, recv, root=0)
        if comm.rank != 0:
            return None
        full = np.empty_like(grouped)
        full[np.argsort(self.owner, kind="stable")] = grouped
        return full

    # ---------------------------------------------------------------- blocks layout
    def to_block(self, local: np.ndarray) -> tuple[int, np.ndarray]:
        """(first row, rows) of this rank's contiguous block of the input order, made from every
        rank's owned rows by one Alltoallv."""
        ex = self._exchange or self._plan()
        local = np.ascontiguousarray(local)
        row_shape, dtype = local.shape[1:], local.dtype
        width = int(np.prod(row_shape, dtype=np.int64))
        recv = np.empty((ex["recv_total"],) + row_shape, dtype=dtype)
        kind = MPI._typedict[dtype.char]
        self.comm.Alltoallv([local, ex["send"] * width, _displacements(ex["send"] * width), kind],
                            [recv, ex["recv"] * width, _displacements(ex["recv"] * width), kind])
        block = np.empty_like(recv)
        block[ex["position"]] = recv
        return ex["first"], block

    def _plan(self) -> dict:
        """Once: how many rows go to which rank, and where the received rows sit in the block."""
        comm = self.comm
        bounds = block_bounds(self.n, comm.size)
        dest = np.searchsorted(bounds, self.ids, side="right") - 1
        send = np.bincount(dest, minlength=comm.size).astype(np.int64)
        recv = np.empty_like(send)
        comm.Alltoall(send, recv)
        ids = np.empty(int(recv.sum()), dtype=np.int64)
        comm.Alltoallv([self.ids, send, _displacements(send), MPI.INT64_T],
                       [ids, recv, _displacements(recv), MPI.INT64_T])
        first = int(bounds[comm.rank])
        self._exchange = {"send": send, "recv": recv, "recv_total": int(recv.sum()),
                          "position": ids - first, "first": first}
        return self._exchange


def _displacements(counts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
