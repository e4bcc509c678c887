"""Contact pairing per rank: each rank pairs the slave nodes it owns against the master facets
near them, and numbers its entries as the whole pairing would.

* ``update_near``: the master facets every rank needs, by a bounded exchange: each rank's
  slave nodes span a box (grown by the search radius); the boxes are gathered (one per rank)
  and each rank sends its master facets to the ranks whose box meets the facet's. A rank
  receives the facets near its slaves only (and its own), not the whole master surface.
  Finite sliding does it again on the current configuration, sending only the facets new
  to a rank (none: no exchange).
* ``global_positions``: the place of each of a rank's entries among every rank's (entries
  sorted by input id, each id on one rank): the relation rows' own numbering
  (``relation_kinds.spread.places``), never the whole pairing on a rank.

The facets received are put in the canonical order (``surfaces.canonical_facets``): a subset
of the whole surface's canonical facets in the same relative order, so that the pairing's ties
(smallest distance, then the first facet) are decided as on the whole surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsolve.contact.surfaces import canonical_facets
from parsolve.mesh.blocks import exchange
from parsolve.relation_kinds.spread import places


def facet_extent(comm, facet_pts: np.ndarray) -> float:
    """The largest facet extent over every rank's facets (the default search radius)."""
    mine = float(np.max(facet_pts.max(axis=1) - facet_pts.min(axis=1))) if facet_pts.size else 0.0
    return comm.allreduce(mine, op=MPI.MAX)


def grown_boxes(comm, pts: np.ndarray, radius: float) -> np.ndarray:
    """Every rank's box (lo, hi) of its points grown by ``radius`` (a rank with none: a box
    that meets nothing), (ranks, 2 dim). Collective."""
    dim = pts.shape[-1]
    if pts.shape[0]:
        margin = radius * (1.0 + 1e-9) + 1e-12 * float(np.abs(pts).max())
        box = np.concatenate([pts.min(axis=0) - margin, pts.max(axis=0) + margin])
    else:
        box = np.concatenate([np.full(dim, np.inf), np.full(dim, -np.inf)])
    boxes = np.empty((comm.size, 2 * dim))
    comm.Allgather(box, boxes)
    return boxes


def meeting(facet_pts: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """(nf, ranks): whether each facet's box meets each rank's box."""
    dim = facet_pts.shape[-1]
    lo, hi = facet_pts.min(axis=1), facet_pts.max(axis=1)          # (nf, dim)
    return np.all((lo[:, None, :] <= boxes[None, :, dim:])
                  & (hi[:, None, :] >= boxes[None, :, :dim]), axis=2)


def global_positions(comm, ids: np.ndarray) -> tuple[np.ndarray, int]:
    """(The place of each of this rank's ids (each id on one rank only) among every rank's
    ids sorted, their total): ``relation_kinds.spread.places`` over the ids' range.
    Collective."""
    ids = np.asarray(ids, dtype=np.int64)
    space = comm.allreduce(int(ids.max()) + 1 if ids.size else 0, op=MPI.MAX)
    return places(comm, ids, space), comm.allreduce(int(ids.size))


@dataclass
class NearFacets:
    """The master facets near this rank's slaves as they move (finite sliding): ``ids``,
    ``pts`` (reference coordinates) and ``new`` (global numbers), canonical; ``sent`` the
    (rank · nf + facet) pairs of this rank's own facets already sent. Facets are added, never
    dropped (a slave's state names them)."""

    ids: np.ndarray
    pts: np.ndarray
    new: np.ndarray
    sent: np.ndarray


def start_near(nfn: int, dim: int) -> NearFacets:
    """No facet yet."""
    return NearFacets(np.zeros((0, nfn), np.int64), np.zeros((0, nfn, dim)),
                      np.zeros((0, nfn), np.int64), np.zeros(0, np.int64))


def update_near(comm, near: NearFacets, slave_x: np.ndarray, mine: tuple, mine_x: np.ndarray,
                reach: float) -> tuple[NearFacets, bool]:
    """The near facets with those of every rank's own (``mine``: ids, reference points, global
    numbers; ``mine_x`` their current points) whose current box now meets a rank's current
    slave box (``slave_x``) grown by ``reach`` and were not sent to it yet: (the facets, whether
    any rank received some). One box per rank gathered; the exchange only when a facet is new
    to a rank. Collective."""
    ids, pts, new = mine
    nf = ids.shape[0]
    rank, facet = np.nonzero(meeting(mine_x, grown_boxes(comm, slave_x, reach)).T)
    key = rank * max(nf, 1) + facet
    fresh = ~np.isin(key, near.sent)
    if not comm.allreduce(bool(fresh.any()), op=MPI.LOR):
        return near, False
    rank, facet = rank[fresh], facet[fresh]
    got_ids, _ = exchange(comm, ids[facet].astype(np.int64), rank)
    got_pts, _ = exchange(comm, pts[facet].astype(float), rank)
    got_new, _ = exchange(comm, new[facet].astype(np.int64), rank)
    k = ids.shape[1]
    all_ids, all_pts, all_new = canonical_facets(
        np.concatenate([near.ids, got_ids.reshape(-1, k)]),
        np.concatenate([near.pts, got_pts.reshape((-1,) + pts.shape[1:])]),
        np.concatenate([near.new, got_new.reshape(-1, k)]))
    return NearFacets(all_ids, all_pts, all_new, np.union1d(near.sent, key[fresh])), True


def facet_index(facets: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The index in ``facets`` (canonical rows of input ids) of each row of ``rows`` (all
    present)."""
    if rows.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    both = np.concatenate([facets, rows])
    _, inverse = np.unique(both, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    where = np.empty(inverse.max() + 1, dtype=np.int64)
    where[inverse[:facets.shape[0]]] = np.arange(facets.shape[0])
    return where[inverse[facets.shape[0]:]]
