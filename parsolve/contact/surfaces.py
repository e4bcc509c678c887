"""The contact surfaces as every rank holds them: slave nodes and facets as input node ids with
their coordinates, the same arrays on every rank whatever the mesh's distribution (on a
distributed mesh each rank's part of a surface is gathered once: the size of the surface,
not of the mesh).

The pairings (``pairing``, ``mortar``, ``obstacles``) index a points array by node id: they run
on the surfaces' own compact numbering (``Surfaces.points``, node ``i`` = the i-th smallest
input id), which keeps the order of the input ids, so that their results (ties broken by index,
rows sorted by node) are those of the whole mesh; ``to_input`` maps a pairing back.

Facets are put in one canonical order (their rows of input ids, sorted), on the replicated and
the distributed mesh alike: a slave node facing a master vertex at the same distance from two
facets pairs with the first, which must not depend on how the facets were found.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.contact.pairing import Pairing


def canonical_facets(ids: np.ndarray, points: np.ndarray, *extra: np.ndarray
                     ) -> tuple[np.ndarray, ...]:
    """Facets (rows of input ids, (nf, k)) and their coordinates (nf, k, dim) (and any
    ``extra`` per-facet arrays), each facet once, in increasing order of their rows
    (duplicates: the same facet seen by two ranks)."""
    if ids.shape[0] == 0:
        return (ids, points, *extra)
    rows, first = np.unique(ids, axis=0, return_index=True)
    return (rows, points[first], *(e[first] for e in extra))


@dataclass
class Surfaces:
    """Every node of the contact surfaces: sorted input ids and their coordinates."""

    ids: np.ndarray        # (m,) int64, increasing
    points: np.ndarray     # (m, dim)

    @classmethod
    def of(cls, parts: list[tuple[np.ndarray, np.ndarray]]) -> "Surfaces":
        """From (input ids (any shape), coordinates (same shape + (dim,))) pieces."""
        dim = parts[0][1].shape[-1]
        ids = np.concatenate([np.asarray(i, dtype=np.int64).ravel() for i, _ in parts])
        pts = np.concatenate([np.asarray(p, dtype=float).reshape(-1, dim) for _, p in parts])
        uniq, first = np.unique(ids, return_index=True)
        return cls(uniq, pts[first])

    def compact(self, ids: np.ndarray) -> np.ndarray:
        """The compact numbers of input ids (all of them surface nodes)."""
        return np.searchsorted(self.ids, np.asarray(ids, dtype=np.int64))

    def to_input(self, pairing: Pairing) -> Pairing:
        """A pairing of paired entries in the compact numbering → in input ids."""
        out = pairing.subset(np.arange(len(pairing)))
        out.slave = self.ids[pairing.slave]
        out.master = self.ids[pairing.master] if pairing.master.size else pairing.master
        return out
