"""Finite sliding's building blocks (parsolve.contact.pairing.facet_spans, in_spans, pair_on;
parsolve.contact.rows.span_rows; parsolve.contact.sliding's spans): the spans hold the facets
within the radius of each slave, rows over a span are the node-to-segment rows with zeros on
the other span nodes, spans made again hold the facets around where the slaves are now, and a
projection on a given facet is pair_nodes' when that facet is the closest."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.contact.pairing import contains, facet_spans, in_spans, pair_nodes, pair_on
from parsolve.contact.rows import Rows, node_rows, rows_differ, span_rows
from parsolve.contact.sliding import (make_spans, near_edge, outside_spans, respan,
                                      union_spans)
from parsolve.contact.surfaces import Surfaces


def wavy_master(n: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """points (master nodes on a wavy line y = 0.05 sin(3x), then 5 slaves above it),
    master facets oriented outward (up: right to left), slave ids."""
    x = np.linspace(0.0, 3.0, n + 1)
    master = np.column_stack([x, 0.05 * np.sin(3 * x)])
    slaves = np.column_stack([np.linspace(0.3, 2.7, 5), np.full(5, 0.2)])
    points = np.vstack([master, slaves])
    facets = np.column_stack([np.arange(1, n + 1), np.arange(n)])
    return points, facets, np.arange(n + 1, n + 6)


def test_spans_hold_the_facets_within_the_radius():
    points, facets, slaves = wavy_master()
    radius = 0.6
    fptr, fids, nptr, nodes = facet_spans(points, slaves, facets, radius)
    coords = points[facets]
    lo, hi = coords.min(axis=1) - radius, coords.max(axis=1) + radius
    for i, s in enumerate(slaves):          # the definition, facet by facet
        near = np.flatnonzero(np.all((points[s] >= lo) & (points[s] <= hi), axis=1))
        assert np.array_equal(fids[fptr[i]:fptr[i + 1]], near)
        assert np.array_equal(nodes[nptr[i]:nptr[i + 1]], np.unique(facets[near]))
    p = pair_nodes(points, slaves, facets, "line", radius)
    assert np.all(in_spans(p.facet, fptr, fids))
    assert not np.any(in_spans(np.full(5, facets.shape[0] - 1), fptr, fids)[:2])  # far facet
    assert not np.any(in_spans(np.full(5, -1), fptr, fids))                     # unpaired


def test_span_rows_are_node_rows_with_zeros_elsewhere():
    points, facets, slaves = wavy_master()
    fptr, fids, nptr, nodes = facet_spans(points, slaves, facets, 0.6)
    p = pair_nodes(points, slaves, facets, "line", 0.6)
    vectors = p.normal - 0.3 * p.tangents[:, 0]
    wide, narrow = span_rows(p, vectors, nptr, nodes), node_rows(p, vectors)
    ndof = 2 * points.shape[0]

    def dense(r):
        out = np.zeros((r.nrows, ndof))
        np.add.at(out, (r.row, r.node * 2 + r.comp), r.coef)
        return out

    np.testing.assert_array_equal(dense(wide), dense(narrow))
    # one entry per (row, node, component): no duplicate, the span's size per row
    keys = wide.row * ndof + wide.node * 2 + wide.comp
    assert np.unique(keys).size == keys.size
    np.testing.assert_array_equal(np.bincount(wide.row), 2 * (1 + np.diff(nptr)))
    outside = p.subset(np.arange(5))
    outside.master = np.tile(facets[-1], (5, 1))      # the last facet: not in the first spans
    with pytest.raises(ValueError, match="outside the entry's span"):
        span_rows(outside, vectors, nptr, nodes)


def test_spans_made_again_around_the_moved_slaves():
    """Spans of radius 0.6 made at the start. A slave is near its span's edge when a facet
    within half the radius of it is not in its span, on the current positions of both
    bodies: the slaves moved along the master by 0.1 are not, by 0.4 they are, and the
    slaves and the master moved together by 0.4 are not (nothing moved relative to the
    other). Made again on the moved configuration, a span holds the facets within the radius
    of the slave there and, besides, its current facet and master nodes (a slave lifted
    above the radius keeps its facet), in input ids; the current pairing is inside it where
    the start's spans no longer hold it."""
    points, facets, slaves = wavy_master()
    master = np.setdiff1d(np.arange(points.shape[0]), slaves)
    surf = Surfaces(100 + np.arange(points.shape[0]), points)   # input ids ≠ compact
    p = pair_nodes(points, slaves, facets, "line", 0.6)
    sp = make_spans(surf, p, facets, 0.6, 1.0)
    assert not near_edge(sp, points)
    for shift, moved, together in ((0.1, False, False), (0.4, True, False),
                                   (0.4, False, True)):
        x = points.copy()
        x[slaves, 0] += shift
        if together:
            x[master, 0] += shift
        assert near_edge(sp, x) == moved
    x = points.copy()
    x[slaves, 0] += [1.0, 1.0, 1.0, 0.6, 0.2]   # (all still above the master)
    x[slaves[0], 1] += 0.7             # above the radius: no facet near it but its own
    q = pair_nodes(x, slaves, facets, "line", 1.0)
    assert q.paired.all()
    assert outside_spans(q, sp.node_ptr, surf.compact(sp.nodes)).any()
    new = respan(sp, x, q)
    fptr, fids, nptr, nodes = facet_spans(x, slaves, facets, 0.6)
    assert fptr[1] == 0                                   # the lifted slave: nothing near
    np.testing.assert_array_equal(new.facet_ids[new.facet_ptr[0]:new.facet_ptr[1]], q.facet[:1])
    np.testing.assert_array_equal(new.facet_ptr[1:] - new.facet_ptr[1], fptr[1:])
    np.testing.assert_array_equal(new.facet_ids[new.facet_ptr[1]:], fids)
    np.testing.assert_array_equal(new.nodes[:new.node_ptr[1]], surf.ids[np.sort(q.master[0])])
    np.testing.assert_array_equal(new.nodes[new.node_ptr[1]:], surf.ids[nodes])
    assert not near_edge(new, x)
    assert not outside_spans(q, new.node_ptr, surf.compact(new.nodes)).any()
    assert new.radius == sp.radius and new.slave is sp.slave and new.length == sp.length


def test_rows_compared_whatever_their_layout():
    """The same rows over two spans (one with zero entries on more nodes, in another order)
    do not differ; a coefficient changed by more than the tolerance does."""
    a = Rows(2, np.array([0, 0, 1]), np.array([3, 4, 3]), np.array([1, 1, 0]),
             np.array([1.0, -0.5, 2.0]), 0)
    b = Rows(2, np.array([1, 0, 0, 1, 0]), np.array([3, 4, 3, 7, 9]), np.array([0, 1, 1, 0, 1]),
             np.array([2.0, -0.5, 1.0, 0.0, 0.0]), 0)
    assert not rows_differ(a, b, 1e-12) and not rows_differ(a, a, 0.0)
    b.coef[0] += 1e-9
    assert rows_differ(a, b, 1e-12) and not rows_differ(a, b, 1e-8)
    c = Rows(2, a.row, a.node, a.comp, a.coef + 1e-9, 0)       # the same layout
    assert rows_differ(a, c, 1e-12) and not rows_differ(a, c, 1e-8)


def test_contains_per_entry():
    """Per entry, whether each of its ids is in that entry's list (not another entry's, even
    where the keys would alias: −1 of entry 1 against the largest id of entry 0)."""
    ptr, ids = np.array([0, 2, 2, 3]), np.array([1, 5, 0])
    sub_ptr, sub = np.array([0, 2, 4, 6]), np.array([5, 0, -1, 1, 0, -1])
    np.testing.assert_array_equal(contains(ptr, ids, sub_ptr, sub),
                                  [True, False, False, False, True, False])
    empty = np.zeros(0, dtype=np.int64)
    np.testing.assert_array_equal(contains(np.zeros(4, int), empty, sub_ptr, sub), [False] * 6)
    assert contains(ptr, ids, np.zeros(4, int), empty).size == 0
    np.testing.assert_array_equal(in_spans(np.array([5, -1, 0]), ptr, ids), [True, False, True])


def test_union_spans_adds_each_entry_s_nodes_but_no_facet():
    ptr, nodes = np.array([0, 2, 2, 3]), np.array([4, 7, 1])
    extra = np.array([[7, 2], [-1, -1], [1, 0]])      # entry 1: no facet (-1)
    new_ptr, new_nodes = union_spans(ptr, nodes, extra)
    np.testing.assert_array_equal(new_ptr, [0, 3, 3, 5])
    np.testing.assert_array_equal(new_nodes, [2, 4, 7, 0, 1])


def test_projection_on_a_given_facet():
    points, facets, slaves = wavy_master()
    p = pair_nodes(points, slaves, facets, "line", 0.6)
    q, inside = pair_on(points, slaves, facets, p.facet, "line")
    assert inside.all()
    for name in ("xi", "weights", "point", "normal", "tangents", "gap"):
        np.testing.assert_allclose(getattr(q, name), getattr(p, name), atol=1e-14)
    # on a facet three away from the closest one: outside, clipped to its end
    q, inside = pair_on(points, slaves, facets, np.where(p.facet >= 3, p.facet - 3, p.facet + 3),
                        "line")
    assert not inside.any() and np.all(np.abs(q.xi) == 1.0)
    np.testing.assert_allclose(q.weights.sum(axis=1), 1.0)
