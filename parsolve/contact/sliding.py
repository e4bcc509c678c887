"""Finite sliding: the spans the rows live on, and the pairings made again on the current
configuration fitted to them.

A finite-sliding row couples its slave node to a superset of master nodes, its *span*
(``rows.span_rows``): the nodes of every master facet within the search radius of the slave
when the span was made, zeros where a node is not in the current pairing. Pairing again is
then a value update of the same entries. When a slave is about to leave its span (a facet
within half the radius of it now is not in its span: ``near_edge``) or has left it, the spans
are made again around the current configuration (``respan``): the rows' sparsity changes,
and the system builds its operator again on it.

Node-to-segment (node-to-face) pairs a slave with one facet: its span is the master nodes of
the facets near it (``pairing.facet_spans``). A mortar row integrates over the slave facets
around its node: its span adds the slave facets' reach to the radius, and keeps the nodes of
its current row (a triangle6 midside's row holds its edge's corners).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from parsolve.contact.pairing import Pairing, contains, facet_spans, pair_on
from parsolve.contact.surfaces import Surfaces


@dataclass
class Spans:
    """The surfaces (compact numbering), the paired slaves' compact ids, the master facets
    (compact) and, per paired slave, the facets and master nodes (input ids) of its span,
    until made again (``respan``): the rows' sparsity. Mortar: the slave facets (compact) too."""
    surf: Surfaces
    slave: np.ndarray
    facets: np.ndarray
    radius: float
    facet_ptr: np.ndarray
    facet_ids: np.ndarray
    node_ptr: np.ndarray
    nodes: np.ndarray
    reference: np.ndarray | None = None   # 3D: per slave, the vector its t1 follows
    slave_facets: np.ndarray | None = None   # mortar only
    # the length the rows' tolerances are relative to: the largest master facet (an
    # obstacle: the mesh's size), not the radius, so that the answer does not depend on it
    length: float = 1.0
    slave_reach: float = 0.0   # mortar: the slave facets' largest extent (spans reach it)
    _repeated: dict = field(default_factory=dict)   # per repetition: the spans repeated

    def ptr_for(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The spans (node_ptr, nodes) of n entries: one per slave, or (3D tangential rows)
        several per slave (3D tangential rows: two; geometric rows: 2 (dim − 1)), each the
        slave's span (the same entries for all its rows)."""
        if n == self.slave.size:
            return self.node_ptr, self.nodes
        times = n // self.slave.size
        if times not in self._repeated:
            self._repeated[times] = repeat_spans(self.node_ptr, self.nodes, times)
        return self._repeated[times]


def make_spans(surf: Surfaces, p: Pairing, facets: np.ndarray, radius: float, length: float,
               slave_facets: np.ndarray | None = None, slave_reach: float = 0.0) -> Spans:
    """The spans of the paired slaves of p (compact numbering): the master facets within
    ``radius`` of each slave's start; mortar (``slave_facets`` given): within the radius plus
    ``slave_reach`` (the slave facets' largest extent), and the nodes of the slave's initial
    row besides. ``length``: the largest master facet (the rows' tolerances). The numbers are
    the whole surfaces' (a rank holds a part of them)."""
    fptr, fids, nptr, nodes = facet_spans(surf.points, p.slave, facets, radius + slave_reach)
    if slave_facets is not None:
        nptr, nodes = union_spans(nptr, nodes, p.master)
    return Spans(surf, p.slave.copy(), facets, radius, fptr, fids, nptr, surf.ids[nodes],
                 _reference(p), slave_facets, length, slave_reach)


def respan(sp: Spans, x: np.ndarray, p: Pairing) -> Spans:
    """The spans of ``sp`` made again around the current configuration x (compact numbering,
    as p, the current pairing of sp's slaves): the facets within the search radius (mortar:
    plus the slave facets' reach) of each slave now, and the facet and master nodes of its
    current row besides (a slave farther than the radius from every facet keeps what it
    holds). The same slaves, radius and reference frame."""
    fptr, fids, nptr, nodes = facet_spans(x, p.slave, sp.facets, sp.radius + sp.slave_reach)
    fptr, fids = union_spans(fptr, fids, p.facet[:, None])
    nptr, nodes = union_spans(nptr, nodes, p.master)
    return Spans(sp.surf, sp.slave, sp.facets, sp.radius, fptr, fids, nptr, sp.surf.ids[nodes],
                 sp.reference, sp.slave_facets, sp.length, sp.slave_reach)


def near_edge(sp: Spans, x: np.ndarray) -> bool:
    """Whether a slave is near its span's edge on the configuration x: a master facet within
    half the search radius of it (mortar: plus its slave facets' reach), on the current
    positions of both bodies, is not in its span (the next step could carry it out). False
    for empty spans (a rigid obstacle's: nothing to make again)."""
    if sp.nodes.size == 0:
        return False
    fptr, fids, _, _ = facet_spans(x, sp.slave, sp.facets, 0.5 * sp.radius + sp.slave_reach)
    return not bool(np.all(contains(sp.facet_ptr, sp.facet_ids, fptr, fids)))


def _reference(p: Pairing) -> np.ndarray | None:
    """3D: the vector each slave's t1 follows, its initial one (the pairing's own frame at
    the start, unchanged)."""
    return p.tangents[:, 0].copy() if p.dim == 3 else None


def extent(points: np.ndarray, facets: np.ndarray) -> float:
    """The largest extent of the facets (along any axis)."""
    coords = points[facets]
    return float(np.max(coords.max(axis=1) - coords.min(axis=1))) if coords.size else 0.0


def mortar_waiting(surf: Surfaces, p: Pairing, facets: np.ndarray, facet_type: str,
                   reach: float, slaves: np.ndarray) -> Pairing:
    """The slave-surface nodes ``slaves`` that no mortar row holds at the start (p: the rows)
    but whose span (the facets within ``reach``) is not empty, as placeholder rows (compact
    numbering): one master node of their span (weight 0), no normal, their point their own,
    the tangents of the first facet of their span (what a 3D row's reference frame follows);
    sorted by slave like p."""
    missing = np.setdiff1d(slaves, p.slave)
    fptr, fids, nptr, nodes = facet_spans(surf.points, missing, facets, reach)
    has = np.diff(nptr) > 0
    missing, first, facet = missing[has], nodes[nptr[:-1][has]], fids[fptr[:-1][has]]
    n, k, dim = missing.size, p.master.shape[1], surf.points.shape[1]
    tangents = pair_on(surf.points, missing, facets, facet, facet_type)[0].tangents
    return Pairing(missing, np.ones(n, dtype=bool), np.full(n, -1, dtype=np.int64),
                   np.zeros((n, dim - 1)), np.repeat(first[:, None], k, axis=1),
                   np.zeros((n, k)), surf.points[missing].copy(), np.zeros((n, dim)),
                   tangents, np.zeros(n))


def merged(a: Pairing, b: Pairing) -> Pairing:
    """The entries of a and b (same master width), sorted by slave."""
    both = Pairing(*(np.concatenate([getattr(a, f), getattr(b, f)])
                     for f in a.__dataclass_fields__))
    return both.subset(np.argsort(both.slave, kind="stable"))


def obstacle_spans(surf: Surfaces, p: Pairing, size: float) -> Spans:
    """Finite sliding against a rigid obstacle: rows on the slave alone, every span empty;
    ``size`` (the mesh's) scales the rows' tolerances."""
    ptr, none = np.zeros(len(p) + 1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return Spans(surf, p.slave.copy(), np.zeros((0, 0), dtype=np.int64), size, ptr, none, ptr,
                 none, _reference(p), length=size)


def union_spans(ptr: np.ndarray, nodes: np.ndarray, extra: np.ndarray) -> tuple[np.ndarray,
                                                                                np.ndarray]:
    """CSR spans (increasing nodes per entry) with each entry's ``extra[i]`` nodes added (a
    negative one, no facet, is not)."""
    n = ptr.size - 1
    owner = np.concatenate([np.repeat(np.arange(n, dtype=np.int64), np.diff(ptr)),
                            np.repeat(np.arange(n, dtype=np.int64), extra.shape[1])])
    values = np.concatenate([nodes, extra.ravel()])
    pairs = np.unique(np.column_stack([owner, values])[values >= 0], axis=0).reshape(-1, 2)
    new_ptr = np.concatenate([[0], np.cumsum(np.bincount(pairs[:, 0], minlength=n))])
    return new_ptr.astype(np.int64), pairs[:, 1].copy()


def repeat_spans(ptr: np.ndarray, nodes: np.ndarray, times: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR spans with each entry repeated ``times`` times in a row (entry i → times·i + j)."""
    counts = np.repeat(np.diff(ptr), times)
    new_ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    owner = np.repeat(np.arange(counts.size, dtype=np.int64), counts)
    offset = np.arange(new_ptr[-1], dtype=np.int64) - new_ptr[owner]
    return new_ptr, nodes[ptr[owner // times] + offset]


def outside_spans(p: Pairing, ptr: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """True where an entry of p (compact numbering, as the spans' ``nodes``) has a master node
    outside its span (``nodes[ptr[i]:ptr[i+1]]``, increasing), whatever its weight: the rows
    over the span (``rows.span_combination``) hold every node of the entry."""
    n, k = p.master.shape
    inside = contains(ptr, nodes, np.arange(n + 1, dtype=np.int64) * k, p.master.ravel())
    return ~inside.reshape(n, k).all(axis=1)


def fit_mortar(new: Pairing, last: Pairing, x: np.ndarray) -> tuple[Pairing, np.ndarray]:
    """The mortar rows made on the current configuration x, on the slaves of ``last`` (the
    fixed set of rows, compact numbering): a slave that the new rows no longer hold (its
    facets uncovered: past the master's end) keeps its last row, its master combination and
    normal, with its point and gap measured on x (as a node-to-segment slave past the master's
    end stays on its last facet). Slaves the new rows hold beyond the set are left out.
    Returns (the rows, which of them the new rows hold)."""
    at = np.minimum(np.searchsorted(new.slave, last.slave), max(len(new) - 1, 0))
    found = (new.slave[at] == last.slave) if len(new) else np.zeros(len(last), dtype=bool)
    width = max(new.master.shape[1], last.master.shape[1])
    out = last.subset(np.arange(len(last)))
    out.master, out.weights = pad(last.master, last.weights, width)
    master, weights = pad(new.master, new.weights, width)
    out.master[found], out.weights[found] = master[at[found]], weights[at[found]]
    for name in ("normal", "tangents", "xi", "facet"):
        getattr(out, name)[found] = getattr(new, name)[at[found]]
    out.point = np.einsum("mk,mkx->mx", out.weights, x[out.master])
    out.gap = np.einsum("mx,mx->m", out.normal, x[out.slave] - out.point)
    return out, found


def pad(master: np.ndarray, weights: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows padded to ``width`` entries with zero weights on their first master node."""
    extra = width - master.shape[1]
    if extra == 0:
        return master.copy(), weights.copy()
    return (np.concatenate([master, np.repeat(master[:, :1], extra, axis=1)], axis=1),
            np.concatenate([weights, np.zeros((weights.shape[0], extra))], axis=1))


def reference_frame(p: Pairing, reference: np.ndarray) -> None:
    """Finite sliding in 3D: the tangents of the pairing p set, in place, from the normal and
    a per-entry reference vector (t1 = the reference projected on the tangent plane, t2 =
    n × t1) rather than from the facet's parametrisation: the basis the slip direction and
    the slip are written in then does not jump when a slave crosses to a facet oriented
    otherwise (a triangle's first edge, a quad numbered from another corner); on a flat
    master it is the same on every facet, on a curved one it turns with the normal."""
    p.tangents[:] = frame_of(p.normal, reference)


def frame_of(normal: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The tangents (m, 2, 3) of ``reference_frame`` for unit normals (m, 3)."""
    t1 = reference - np.einsum("mx,mx->m", reference, normal)[:, None] * normal
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    return np.stack([t1, np.cross(normal, t1)], axis=1)
