"""Relation rows: gaps of rigid motions, tangential rows, slip-direction rows, frictional dual."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.contact import obstacles
from parsolve.contact.pairing import pair_nodes
from parsolve.contact.rows import (direction_rows, friction_dual, normal_rows, normal_values,
                                   tangent_rows, tangential_components)
from parsolve.mesh.generators import box, make_quadratic, rectangle
from parsolve.mesh.topology import match_facets


def inclined_2d(cell="triangle6", angle=0.4, g0=0.02):
    master = rectangle(1.0, 0.5, 5, 2, cell, origin=(0.0, -0.5))
    slave = rectangle(1.0, 0.3, 7, 2, "quad", origin=(0.0, g0))
    pts = np.vstack([master.points, slave.points])
    c, s = np.cos(angle), np.sin(angle)
    pts = pts @ np.array([[c, -s], [s, c]]).T
    _, _, facets = match_facets(master, master.facet_groups["top"])
    slaves = slave.node_groups["bottom"] + master.num_points
    ftype = "line3" if cell == "triangle6" else "line"
    p = pair_nodes(pts, slaves, facets, ftype)
    slave_mask = np.zeros(len(pts), dtype=bool)
    slave_mask[master.num_points:] = True
    return pts, p.only_paired(), slave_mask


def curved_3d():
    master = make_quadratic(box(1.0, 1.0, 0.5, 3, 2, 1, "tetra", origin=(0, 0, -0.5)))
    z = master.points[:, 2]
    master.points[:, 2] = z + (z + 0.5) / 0.5 * 0.2 * master.points[:, 0] ** 2
    _, _, facets = match_facets(master, master.facet_groups["zmax"])
    rng = np.random.default_rng(1)
    xy = rng.uniform(0.05, 0.95, size=(25, 2))
    xs = np.column_stack([xy, 0.2 * xy[:, 0] ** 2 + rng.uniform(-0.02, 0.03, 25)])
    pts = np.vstack([master.points, xs])
    p = pair_nodes(pts, np.arange(master.num_points, len(pts)), facets, "triangle6")
    slave_mask = np.zeros(len(pts), dtype=bool)
    slave_mask[master.num_points:] = True
    return pts, p.only_paired(), slave_mask


@pytest.mark.parametrize("make", [inclined_2d, curved_3d])
def test_normal_rows_measure_translations_along_the_normal(make):
    pts, p, slave_mask = make()
    rows = normal_rows(p)
    dim = pts.shape[1]
    assert rows.nrows == len(p) and rows.width == (1 + p.master.shape[1]) * dim
    d = 0.37
    # each slave node moved by d along its own normal: Dn q = d
    u = np.zeros_like(pts)
    u[p.slave] = d * p.normal
    assert np.allclose(rows.apply(u), d, atol=1e-14)
    # any rigid translation of both bodies: Dn q = 0; of the master only: -n.v
    v = np.array([0.3, -0.8, 0.5][:dim])
    assert np.allclose(rows.apply(np.tile(v, (len(pts), 1))), 0.0, atol=1e-14)
    um = np.where(slave_mask[:, None], 0.0, v)
    assert np.allclose(rows.apply(um), -(p.normal @ v), atol=1e-14)
    # b = -g0: the relation Dn q >= b is g0 + Dn q >= 0
    assert np.allclose(normal_values(p), -p.gap)


def test_linear_gap_is_exact_under_rigid_translation():
    """Straight master: re-pairing the translated slave gives exactly g0 + Dn q."""
    pts, p, slave_mask = inclined_2d("quad")
    v = np.array([0.011, -0.004])
    u = np.where(slave_mask[:, None], v, 0.0)
    moved = pts + u
    master = rectangle(1.0, 0.5, 5, 2, "quad", origin=(0.0, -0.5))
    c, s = np.cos(0.4), np.sin(0.4)
    _, _, master_facets = match_facets(master, master.facet_groups["top"])
    q = pair_nodes(moved, p.slave, master_facets, "line")
    on = q.paired  # the last node slid past the master's end
    assert on.sum() == len(p) - 1 and not on[-1]
    assert np.allclose(q.gap[on], (p.gap + normal_rows(p).apply(u))[on], atol=1e-15)
    assert np.allclose(q.normal[on], [-s, c], atol=1e-15)


@pytest.mark.parametrize("make", [inclined_2d, curved_3d])
def test_tangent_rows_and_direction_rows(make):
    pts, p, slave_mask = make()
    dim = pts.shape[1]
    t = tangent_rows(p)
    assert t.nrows == len(p) * (dim - 1)
    for j in range(dim - 1):
        u = np.zeros_like(pts)
        u[p.slave] = 0.5 * p.tangents[:, j]
        comp = tangential_components(p, u)
        expect = np.zeros((len(p), dim - 1))
        expect[:, j] = 0.5
        assert np.allclose(comp, expect, atol=1e-14)
    # direction rows: s . (tangential components) for any slave displacement
    rng = np.random.default_rng(0)
    u = np.zeros_like(pts)
    u[p.slave] = rng.normal(size=(len(p), dim))
    if dim == 2:
        s = np.where(rng.random(len(p)) < 0.5, -1.0, 1.0)
        sv = s[:, None]
    else:
        a = rng.uniform(0, 2 * np.pi, len(p))
        sv = np.column_stack([np.cos(a), np.sin(a)])
        s = sv
    got = direction_rows(p, s).apply(u)
    assert np.allclose(got, np.einsum("nj,nj->n", tangential_components(p, u), sv), atol=1e-14)


@pytest.mark.parametrize("make", [inclined_2d, curved_3d])
def test_friction_dual_shares_the_normal_layout(make):
    pts, p, _ = make()
    dim = pts.shape[1]
    n = normal_rows(p)
    s = np.ones((len(p), dim - 1)) / np.sqrt(dim - 1)
    zero = friction_dual(p, 0.0, s)
    assert np.array_equal(zero.node, n.node) and np.array_equal(zero.comp, n.comp)
    assert np.array_equal(zero.row, n.row) and np.allclose(zero.coef, n.coef, atol=0)
    mu = np.linspace(0.1, 0.6, len(p))
    dual = friction_dual(p, mu, s)
    ds = direction_rows(p, s)
    assert np.allclose(dual.coef, n.coef - np.repeat(mu, n.width) * ds.coef, atol=1e-15)
    # acting on a slave displacement along the slip direction: -mu
    u = np.zeros_like(pts)
    u[p.slave] = np.einsum("nj,njx->nx", s, p.tangents)
    assert np.allclose(dual.apply(u), -mu, atol=1e-14)


def test_obstacle_rows_have_slave_terms_only():
    pts = np.array([[0.0, 1.0], [2.0, 1.5], [1.0, 0.9]])
    p = obstacles.plane(pts, [0, 1, 2], origin=[0.0, 0.0], normal=[0.0, 2.0])
    rows = normal_rows(p)
    assert rows.width == 2 and np.array_equal(np.unique(rows.node), [0, 1, 2])
    u = np.array([[0.1, -0.2], [0.0, 0.3], [5.0, 0.0]])
    assert np.allclose(rows.apply(u), [-0.2, 0.3, 0.0])
    # obstacle pushed up by 0.25: the relation values rise by 0.25
    assert np.allclose(normal_values(p, [0.0, 0.25]), -p.gap + 0.25)


def test_unpaired_entries_are_refused():
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.1]])
    p = pair_nodes(pts, [2], np.array([[0, 1]]), "line")
    assert not p.paired.any()
    with pytest.raises(ValueError):
        normal_rows(p)
