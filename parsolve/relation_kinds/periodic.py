"""``periodic``: u(a) − u(b) = 0 per listed component (default: all), for each node a of the
region and its partner b, the node of the target at x_a + translation."""

from __future__ import annotations

import numpy as np

from parsolve import relations as rel
from parsolve.errors import InputError
from parsolve.relation_kinds.base import RelationSpec, Where, components


def parse(t, spec: RelationSpec, declared) -> None:
    spec.region = t.get("region", str)
    spec.components = components(t, declared, spec.field, every=True)
    spec.target = t.get("target", str)
    spec.translation = t.floats("translation", declared.dim)


def build(spec: RelationSpec, where: Where, evolution) -> rel.Relation:
    """Associated rows, node-major."""
    regions = where.regions
    a = where.nodes(spec.region, spec.key + ".region")
    b_all = where.nodes(spec.target, spec.key + ".target")
    b = partners(regions.points_of(a), b_all, regions.points_of(b_all), spec.translation,
                 regions.tol)
    lost = np.flatnonzero(b < 0)
    if lost.size:
        x = ", ".join(f"{v:g}" for v in regions.points_of(a[lost[:1]])[0])
        raise InputError(f"node {a[lost[0]]} of region {spec.region!r} (at {x}) has no node of "
                         f"region {spec.target!r} at its position + translation (within "
                         f"{regions.tol:.3g}; {lost.size} such nodes)", where.source,
                         spec.key + ".target")
    if np.any(a == b):
        raise InputError("the translation pairs a node with itself", where.source,
                         spec.key + ".translation")
    ncomp = where.fields.ncomp
    c = np.asarray([where.fields.component(spec.field, k) for k in spec.components], dtype=np.int64)
    dofs = np.stack([(a[:, None] * ncomp + c).ravel(), (b[:, None] * ncomp + c).ravel()], axis=1)
    return rel.rows(spec.name, dofs, np.tile([1.0, -1.0], (dofs.shape[0], 1)), 0.0, evolution,
                    spec.sense)


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
