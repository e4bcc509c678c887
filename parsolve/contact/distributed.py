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
from parsolve.mesh.blocks import exchange


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
    ids, _ = exchange(comm, facet_ids[facet].astype(np.int64), rank)
    pts, _ = exchange(comm, facet_pts[facet].astype(float), rank)
    return canonical_facets(ids.reshape(-1, facet_ids.shape[1]), pts)


def global_positions(comm, ids: np.ndarray) -> tuple[np.ndarray, int]:
    """(The place of each of this rank's ids (increasing, each id on one rank only) among
    every rank's ids sorted, their total). Collective."""
    ids = np.asarray(ids, dtype=np.int64)
    top = comm.allreduce(int(ids.max()) + 1 if ids.size else 0, op=MPI.MAX)
    width = max(-(-top // comm.size), 1)
    dest = ids // width                          # increasing: grouped by destination
    got, got_counts = exchange(comm, ids, dest)
    order = np.argsort(got, kind="stable")
    place = np.empty(got.size, dtype=np.int64)
    place[order] = np.arange(got.size)
    first = comm.exscan(int(got.size)) or 0     # (rank 0: None)
    total = comm.allreduce(int(got.size))
    back, _ = exchange(comm, place + first, np.repeat(np.arange(comm.size), got_counts))
    return back, total
