"""``periodic``: u(a) − u(b) = 0 per listed component (default: all), for each node a of the
region and its partner b, the node of the target at x_a + translation."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve import relations as rel
from parsolve.errors import InputError
from parsolve.mesh.blocks import exchange
from parsolve.relation_kinds.base import RelationSpec, Where, components
from parsolve.relation_kinds.spread import ask


def parse(t, spec: RelationSpec, declared) -> None:
    spec.region = t.get("region", str)
    spec.components = components(t, declared, spec.field, every=True)
    spec.target = t.get("target", str)
    spec.translation = t.floats("translation", declared.dim)


def build(spec: RelationSpec, where: Where, evolution) -> rel.Relation:
    """Associated rows, node-major (nodes of the region by input id, then components), built
    per rank: the rows of the region's nodes this rank owns, each paired with its partner
    wherever the partner lives (``spread_partners``)."""
    regions, comm = where.regions, where.comm
    a, points = where.owned_nodes(spec.region, spec.key + ".region")
    b_ids, b_points = where.owned_nodes(spec.target, spec.key + ".target")
    b = spread_partners(comm, points, b_ids, b_points, spec.translation, regions.tol)
    lost = np.flatnonzero(b < 0)
    firsts = comm.allgather((int(a[lost[0]]), tuple(points[lost[0]].tolist())) if lost.size
                            else None)
    count = comm.allreduce(int(lost.size))
    if count:
        node, at = min(f for f in firsts if f is not None)
        x = ", ".join(f"{v:g}" for v in at)
        raise InputError(f"node {node} of region {spec.region!r} (at {x}) has no node of "
                         f"region {spec.target!r} at its position + translation (within "
                         f"{regions.tol:.3g}; {count} such nodes)", where.source,
                         spec.key + ".target")
    if comm.allreduce(bool(np.any(a == b)), op=MPI.LOR):
        raise InputError("the translation pairs a node with itself", where.source,
                         spec.key + ".translation")
    ncomp = where.fields.ncomp
    c = np.asarray([where.fields.component(spec.field, k) for k in spec.components], dtype=np.int64)
    dofs = np.stack([(a[:, None] * ncomp + c).ravel(), (b[:, None] * ncomp + c).ravel()], axis=1)
    r = rel.rows(spec.name, dofs, np.tile([1.0, -1.0], (dofs.shape[0], 1)), 0.0, evolution,
                 spec.sense)
    keys = (a[:, None] * c.size + np.arange(c.size)).ravel()
    return where.numbered(r, keys, where.num_nodes * c.size)


def spread_partners(comm, points: np.ndarray, ids: np.ndarray, candidates: np.ndarray,
                    translation, tol: float) -> np.ndarray:
    """``partners`` over the ranks: each rank gives its points and its candidates (ids and
    coordinates); the images (point + translation) and the candidates are sorted along a
    generic direction into one slab per rank (a candidate near a slab's edge to both sides),
    the slab's rank pairs them, and each point's partner (-1: none) comes back. No rank holds
    more than its slab of the candidates. Collective."""
    dim = candidates.shape[1] if candidates.ndim == 2 else len(translation)
    probe = _PROBE[:dim]
    images = np.asarray(points, float).reshape(-1, dim) + np.asarray(translation, float)
    candidates = np.asarray(candidates, float).reshape(-1, dim)
    key = candidates @ probe
    lo = comm.allreduce(float(key.min(initial=np.inf)), op=MPI.MIN)
    hi = comm.allreduce(float(key.max(initial=-np.inf)), op=MPI.MAX)
    width = (hi - lo) / comm.size if hi > lo else np.inf

    def slab(s: np.ndarray) -> np.ndarray:
        at = np.floor((s - lo) / width) if np.isfinite(width) else np.zeros(s.shape)
        return np.clip(np.nan_to_num(at), 0, comm.size - 1).astype(np.int64)

    first, last = slab(key - 2.0 * tol), slab(key + 2.0 * tol)
    copies = last - first + 1
    dest = np.repeat(first, copies) + np.arange(int(copies.sum())) \
        - np.repeat(np.cumsum(copies) - copies, copies)
    rows = np.concatenate([np.asarray(ids, float)[:, None], candidates], axis=1)[
        np.repeat(np.arange(key.size), copies)]
    mine, _ = exchange(comm, rows, dest)   # (ids are input ids: exact as floats)

    def answer(got: np.ndarray) -> np.ndarray:
        return partners(got, mine[:, 0].astype(np.int64), mine[:, 1:], np.zeros(dim), tol)

    return ask(comm, images, slab(images @ probe), answer)


# a generic direction: points of a mesh rarely share their projection on it, so the window
# of candidates around each image is a point or two, whatever the region's shape
_PROBE = np.array([1.0, np.sqrt(2.0), np.sqrt(3.0)]) / np.sqrt(6.0)


def partners(points: np.ndarray, ids: np.ndarray, candidates: np.ndarray, translation,
             tol: float) -> np.ndarray:
    """For each point, the id (of ``ids``, coordinates ``candidates``) of the candidate at
    point + translation within ``tol`` (the nearest; a tie to the lowest id), or -1."""
    images = np.asarray(points, float) + np.asarray(translation, float)
    ids = np.asarray(ids, dtype=np.int64)
    out = np.full(len(images), -1, dtype=np.int64)
    if len(images) == 0 or len(ids) == 0:
        return out
    probe = _PROBE[:images.shape[1]]
    key = candidates @ probe
    order = np.lexsort((ids, key))
    key, ids, candidates = key[order], ids[order], candidates[order]
    s = images @ probe
    lo = np.searchsorted(key, s - 2.0 * tol, side="left")
    hi = np.searchsorted(key, s + 2.0 * tol, side="right")
    best = np.full(len(images), np.inf)
    for k in range(int((hi - lo).max(initial=0))):   # a loop over the window, not the nodes
        at = lo + k < hi
        j = np.minimum(lo + k, len(ids) - 1)
        d = np.linalg.norm(candidates[j] - images, axis=1)
        better = at & (d <= tol) & ((d < best) | (d == best) & (ids[j] < out))
        out[better], best[better] = ids[j][better], d[better]
    return out
