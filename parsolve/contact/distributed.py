"""Contact pairing per rank: each rank pairs the slave nodes it owns against the master facets
near them, and numbers its entries as the whole pairing would.

* ``near_facets``: the master facets every rank needs, by a bounded exchange: each rank's
  slave nodes span a box (grown by the search radius); the boxes are gathered (one per rank)
  and each rank sends its master facets to the ranks whose box meets the facet's. A rank
  receives the facets near its slaves only (and its own), not the whole master surface.
* ``global_positions``: the place of each of a rank's entries among every rank's (entries
  sorted by input id, each id on one rank): ids are sent to the rank of their id range, which
  counts and sorts them, and the places come back. Its arrays are the rank's share of the
  entries, never the whole pairing.

The facets received are put in the canonical order (``surfaces.canonical_facets``): a subset
of the whole surface's canonical facets in the same relative order, so that the pairing's ties
(smallest distance, then the first facet) are decided as on the whole surface.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve.contact.surfaces import canonical_facets


def _displ(counts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)


def _alltoallv(comm, send: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``send`` (grouped by destination, ``counts`` per rank) to their ranks: (the rows
    received, grouped by source; the counts received). Collective."""
    send = np.ascontiguousarray(send)
    width = int(np.prod(send.shape[1:], dtype=np.int64))
    got_counts = np.empty_like(counts)
    comm.Alltoall(counts, got_counts)
    kind = MPI.INT64_T if send.dtype == np.int64 else MPI.DOUBLE
    got = np.empty((int(got_counts.sum()),) + send.shape[1:], dtype=send.dtype)
    comm.Alltoallv([send, counts * width, _displ(counts) * width, kind],
                   [got, got_counts * width, _displ(got_counts) * width, kind])
    return got, got_counts


def facet_extent(comm, facet_pts: np.ndarray) -> float:
    """The largest facet extent over every rank's facets (the default search radius)."""
    mine = float(np.max(facet_pts.max(axis=1) - facet_pts.min(axis=1))) if facet_pts.size else 0.0
    return comm.allreduce(mine, op=MPI.MAX)


def near_facets(comm, slave_pts: np.ndarray, facet_ids: np.ndarray, facet_pts: np.ndarray,
                radius: float) -> tuple[np.ndarray, np.ndarray]:
    """The master facets (input ids (nf, k), coordinates (nf, k, dim)) whose box meets this
    rank's slave box grown by ``radius``, from every rank's facets (``facet_ids``,
    ``facet_pts``: this rank's), each once, in the canonical order. Collective."""
    dim = facet_pts.shape[-1]
    if slave_pts.shape[0]:
        margin = radius * (1.0 + 1e-9) + 1e-12 * float(np.abs(slave_pts).max())
        box = np.concatenate([slave_pts.min(axis=0) - margin, slave_pts.max(axis=0) + margin])
    else:   # no slave here: a box that meets nothing
        box = np.concatenate([np.full(dim, np.inf), np.full(dim, -np.inf)])
    boxes = np.empty((comm.size, 2 * dim))
    comm.Allgather(box, boxes)
    lo, hi = facet_pts.min(axis=1), facet_pts.max(axis=1)          # (nf, dim)
    meets = np.all((lo[:, None, :] <= boxes[None, :, dim:])
                   & (hi[:, None, :] >= boxes[None, :, :dim]), axis=2)   # (nf, ranks)
    rank, facet = np.nonzero(meets.T)            # grouped by destination rank
    counts = np.bincount(rank, minlength=comm.size).astype(np.int64)
    ids, _ = _alltoallv(comm, facet_ids[facet].astype(np.int64), counts)
    pts, _ = _alltoallv(comm, facet_pts[facet].astype(float), counts)
    return canonical_facets(ids.reshape(-1, facet_ids.shape[1]), pts)


def global_positions(comm, ids: np.ndarray) -> tuple[np.ndarray, int]:
    """(The place of each of this rank's ids (increasing, each id on one rank only) among
    every rank's ids sorted, their total). Collective."""
    ids = np.asarray(ids, dtype=np.int64)
    top = comm.allreduce(int(ids.max()) + 1 if ids.size else 0, op=MPI.MAX)
    width = max(-(-top // comm.size), 1)
    dest = ids // width                          # increasing: grouped by destination
    counts = np.bincount(dest, minlength=comm.size).astype(np.int64)
    got, got_counts = _alltoallv(comm, ids, counts)
    order = np.argsort(got, kind="stable")
    place = np.empty(got.size, dtype=np.int64)
    place[order] = np.arange(got.size)
    first = comm.exscan(int(got.size)) or 0     # (rank 0: None)
    total = comm.allreduce(int(got.size))
    back, _ = _alltoallv(comm, place + first, got_counts)
    return back, total
