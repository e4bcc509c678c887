"""Mortar rows (parsolve/contact/mortar.py) at the algebra level: matching meshes give the
node-to-segment rows times the nodal weights, constant jumps give jump × ∫φ_i, linear fields
are reproduced exactly on non-matching meshes (line and line3), the clipping against an
independent brute-force quadrature, partially covered ends, the facing test and curved
interfaces converging at second order."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.contact.mortar import mortar_pairing, mortar_rows
from parsolve.contact.pairing import pair_nodes
from parsolve.contact.rows import normal_rows, normal_values, tangent_rows

ANGLE = 0.37   # an inclined interface: nothing aligned with the axes


def frame(angle: float) -> tuple[np.ndarray, np.ndarray]:
    """Direction d of the interface and the normal n from master to slave, t = (−n_y, n_x)."""
    d = np.array([np.cos(angle), np.sin(angle)])
    return d, np.array([-d[1], d[0]])


def interface(sm, ss, facet_type="line", angle=ANGLE, gap=0.0, origin=(0.3, -0.2)):
    """Straight master and slave surfaces along d, the slave shifted by gap·n. Master nodes at
    arc lengths sm, slave nodes at ss. Master facets run backwards (outward normal +n), slave
    facets forwards (outward −n); line3 facets get their midside node at the middle.
    Returns (points, slave facets, master facets, slave node ids)."""
    d, n = frame(angle)
    o = np.asarray(origin, dtype=float)
    xm = o + np.outer(sm, d)
    xs = o + np.outer(ss, d) + gap * n
    nm, ns = len(sm), len(ss)
    mf = np.column_stack([np.arange(1, nm), np.arange(nm - 1)])
    sf = np.column_stack([np.arange(ns - 1), np.arange(1, ns)]) + nm
    points = np.vstack([xm, xs])
    if facet_type == "line3":
        mids = 0.5 * (points[mf[:, 0]] + points[mf[:, 1]]), 0.5 * (points[sf[:, 0]] + points[sf[:, 1]])
        first = len(points)
        mf = np.column_stack([mf, first + np.arange(len(mf))])
        sf = np.column_stack([sf, first + len(mf) + np.arange(len(sf))])
        points = np.vstack([points, mids[0], mids[1]])
    return points, sf, mf, np.unique(sf)


def nodal_weights(points, sf, facet_type="line") -> np.ndarray:
    """∫φ_i ds on straight facets, by hand: L/2 per end (line), L/6 per end and 2L/3 for the
    midside node (line3). Over all points (0 off the slave surface)."""
    length = np.linalg.norm(points[sf[:, 1]] - points[sf[:, 0]], axis=1)
    per = [0.5, 0.5] if facet_type == "line" else [1 / 6, 1 / 6, 2 / 3]
    w = np.zeros(len(points))
    for a, c in enumerate(per):
        np.add.at(w, sf[:, a], c * length)
    return w


def dense(rows, npts: int) -> np.ndarray:
    out = np.zeros((rows.nrows, 2 * npts))
    np.add.at(out, (rows.row, rows.node * 2 + rows.comp), rows.coef)
    return out


def random_positions(rng, count: int, length: float = 1.0) -> np.ndarray:
    """count + 1 positions on [0, length], ends fixed, interior random (not uniform)."""
    h = rng.uniform(0.5, 1.5, count)
    return np.concatenate([[0.0], np.cumsum(h) / h.sum() * length])


@pytest.mark.parametrize("facet_type", ["line", "line3"])
def test_matching_meshes_give_node_to_segment_rows_times_weights(facet_type):
    rng = np.random.default_rng(1)
    s = random_positions(rng, 6)
    points, sf, mf, slave = interface(s, s, facet_type)
    mortar = mortar_pairing(points, sf, mf, facet_type)
    np.testing.assert_array_equal(mortar.pairing.slave, slave)
    nts = pair_nodes(points, slave, mf, facet_type)
    assert np.all(nts.paired)
    w = nodal_weights(points, sf, facet_type)[slave]
    np.testing.assert_allclose(mortar.weight, w, rtol=1e-13)
    rn, rt, b = mortar_rows(mortar)
    npts = len(points)
    scale = np.abs(dense(normal_rows(nts), npts)).max()
    np.testing.assert_allclose(dense(rn, npts), w[:, None] * dense(normal_rows(nts), npts),
                               rtol=0, atol=1e-14 * scale)
    np.testing.assert_allclose(dense(rt, npts), w[:, None] * dense(tangent_rows(nts), npts),
                               rtol=0, atol=1e-14 * scale)
    np.testing.assert_allclose(b, w * normal_values(nts), atol=1e-15)
    # the normalised form is the node-to-segment pairing itself
    np.testing.assert_allclose(dense(normal_rows(mortar.pairing), npts),
                               dense(normal_rows(nts), npts), atol=1e-14)


@pytest.mark.parametrize("facet_type", ["line", "line3"])
@pytest.mark.parametrize("nm, ns", [(3, 5), (5, 3), (4, 11)])
def test_constant_jump_gives_jump_times_nodal_weight(facet_type, nm, ns):
    rng = np.random.default_rng(nm * 100 + ns)
    points, sf, mf, slave = interface(random_positions(rng, nm), random_positions(rng, ns),
                                      facet_type, gap=0.01)
    mortar = mortar_pairing(points, sf, mf, facet_type)
    np.testing.assert_array_equal(mortar.pairing.slave, slave)
    w = nodal_weights(points, sf, facet_type)[slave]
    np.testing.assert_allclose(mortar.weight, w, rtol=1e-13)
    np.testing.assert_allclose(mortar.pairing.weights.sum(axis=1), 1.0, atol=1e-14)
    rn, rt, b = mortar_rows(mortar)
    _, n = frame(ANGLE)
    t = np.array([-n[1], n[0]])
    c_n, c_t = -0.7, 0.25
    u = np.zeros_like(points)
    u[slave] = c_n * n + c_t * t
    np.testing.assert_allclose(rn.apply(u), c_n * w, rtol=1e-13)
    np.testing.assert_allclose(rt.apply(u), c_t * w, rtol=1e-13)
    # a rigid translation of both sides changes nothing; the weighted gap is 0.01 ∫φ_i
    np.testing.assert_allclose(rn.apply(np.tile([0.4, -1.3], (len(points), 1))), 0.0, atol=1e-15)
    np.testing.assert_allclose(-b, 0.01 * w, rtol=1e-11)
    np.testing.assert_allclose(mortar.weighted_gap, 0.01 * w, rtol=1e-11)


@pytest.mark.parametrize("facet_type", ["line", "line3"])
@pytest.mark.parametrize("nm, ns", [(3, 5), (7, 4)])
def test_linear_master_field_is_reproduced_exactly(facet_type, nm, ns):
    """On coincident straight sides: Σ_a M_ia ℓ(x_a) = w_i ℓ(x_i) for any linear ℓ, so a linear
    displacement of both sides (no gap change) leaves every row at zero."""
    rng = np.random.default_rng(7 * nm + ns)
    points, sf, mf, slave = interface(random_positions(rng, nm), random_positions(rng, ns),
                                      facet_type)
    mortar = mortar_pairing(points, sf, mf, facet_type)
    rn, rt, _ = mortar_rows(mortar)
    grad = np.array([[0.3, -1.1], [0.8, 0.45]])
    field = np.array([0.2, -0.5]) + points @ grad.T
    on_master = np.zeros_like(field)
    master = np.unique(mf)
    on_master[master] = field[master]
    p, w = mortar.pairing, mortar.weight
    # master part alone: −n_i · w_i ℓ(x_i) (and −t_i · w_i ℓ(x_i))
    np.testing.assert_allclose(rn.apply(on_master), -w * np.einsum("mx,mx->m", p.normal, field[slave]),
                               atol=1e-14)
    np.testing.assert_allclose(rt.apply(on_master), -w * np.einsum("mx,mx->m", p.tangents[:, 0], field[slave]),
                               atol=1e-14)
    np.testing.assert_allclose(rn.apply(field), 0.0, atol=1e-14)
    np.testing.assert_allclose(rt.apply(field), 0.0, atol=1e-14)


def test_clipping_against_brute_force_quadrature():
    """M_ia = ∫ψ_i N_a ds with the textbook dual functions ψ = (1 ∓ 3ξ)/2 of fully covered
    line facets, by a midpoint rule on 20000 points per slave facet with the master facet
    found by position (no clipping): agrees to the midpoint rule's accuracy."""
    rng = np.random.default_rng(3)
    sm, ss = random_positions(rng, 4), random_positions(rng, 6)
    points, sf, mf, slave = interface(sm, ss, "line", angle=0.0, origin=(0.0, 0.0))
    mortar = mortar_pairing(points, sf, mf, "line")
    got = np.zeros((len(points), len(points)))
    p = mortar.pairing
    np.add.at(got, (np.repeat(p.slave, p.master.shape[1]), p.master.ravel()),
              (mortar.weight[:, None] * p.weights).ravel())
    expected = np.zeros_like(got)
    k = 20000
    xi = -1 + (2 * np.arange(k) + 1) / k
    psi = np.column_stack([(1 - 3 * xi) / 2, (1 + 3 * xi) / 2])
    for e in range(len(sf)):                                      # a few facets: fine in a test
        x0, x1 = points[sf[e], 0]
        x = x0 + (xi + 1) / 2 * (x1 - x0)
        seg = np.clip(np.searchsorted(sm, x) - 1, 0, len(sm) - 2)  # master segment [sm_j, sm_j+1]
        r = (x - sm[seg]) / (sm[seg + 1] - sm[seg])
        ds = (x1 - x0) / k
        for i in range(2):
            np.add.at(expected[sf[e, i]], seg, psi[:, i] * (1 - r) * ds)
            np.add.at(expected[sf[e, i]], seg + 1, psi[:, i] * r * ds)
    np.testing.assert_allclose(got, expected, atol=1e-8)
    assert np.abs(expected).max() > 0.1


def test_partially_covered_ends():
    """A master shorter than the slave: slave nodes whose facets see no master are left out,
    the others weigh ∫φ_i over the covered part only, and still reproduce constant and linear
    fields (dual basis biorthogonal on the covered part)."""
    ss = np.array([0.0, 0.1, 0.35, 0.6, 0.8, 1.0])
    sm = np.array([0.2, 0.45, 0.7])
    points, sf, mf, slave = interface(sm, ss, "line")
    mortar = mortar_pairing(points, sf, mf, "line")
    p = mortar.pairing
    # covered part: s in [0.2, 0.7]; the nodes at 0.0 and 1.0 see nothing (their facets end
    # at 0.1 and start at 0.8)
    np.testing.assert_array_equal(p.slave, slave[1:5])

    def hat_integral(i, lo, hi):   # ∫ of the hat of node i over [lo, hi]
        s = np.linspace(lo, hi, 200001)
        hat = np.interp(s, ss, np.eye(len(ss))[i])
        return float(np.sum((hat[1:] + hat[:-1]) / 2 * np.diff(s)))

    w = np.array([hat_integral(i, 0.2, 0.7) for i in range(1, 5)])
    np.testing.assert_allclose(mortar.weight, w, rtol=1e-8)
    np.testing.assert_allclose(p.weights.sum(axis=1), 1.0, atol=1e-13)
    grad = np.array([[0.3, -1.1], [0.8, 0.45]])
    field = points @ grad.T + 1.0
    rn, rt, _ = mortar_rows(mortar)
    np.testing.assert_allclose(rn.apply(field), 0.0, atol=1e-13)
    np.testing.assert_allclose(rt.apply(field), 0.0, atol=1e-13)


def test_only_facing_master_facets_pair():
    """A thin master strip given by both its faces: only the face turned to the slave counts."""
    sm = np.linspace(0, 1, 4)
    points, sf, mf, slave = interface(sm, np.linspace(0, 1, 6), "line", gap=0.05)
    d, n = frame(ANGLE)
    back = points[:4] - 0.02 * n                      # the strip's other face, outward −n
    points = np.vstack([points, back])
    mf_back = np.column_stack([np.arange(3), np.arange(1, 4)]) + len(points) - 4
    both = mortar_pairing(points, sf, np.vstack([mf, mf_back]), "line")
    alone = mortar_pairing(points, sf, mf, "line")
    np.testing.assert_array_equal(both.pairing.master, alone.pairing.master)
    np.testing.assert_allclose(both.pairing.weights, alone.pairing.weights, atol=1e-15)
    np.testing.assert_allclose(both.pairing.gap, 0.05, rtol=1e-12)
    # beyond the search radius nothing pairs
    none = mortar_pairing(points, sf, mf, "line", search_radius=0.01)
    assert len(none.pairing) == 0


def arcs(nm: int, ns: int, facet_type: str, g0: float, rng):
    """Master: the outer surface of a disk of radius 1 (angles 0.2..1.3); slave: the inner
    surface of a ring of radius 1 + g0 over the same angles, non-matching random nodes."""
    def arc(count, radius, reverse):
        th = 0.2 + 1.1 * random_positions(rng, count)
        if facet_type == "line3":
            th = np.concatenate([th, 0.5 * (th[1:] + th[:-1])])
        return radius * np.column_stack([np.cos(th), np.sin(th)])
    xm, xs = arc(nm, 1.0, True), arc(ns, 1.0 + g0, False)
    km, ks = nm + 1, ns + 1
    # counter-clockwise along the disk's boundary: outward; the ring's inner surface: clockwise
    mf = np.column_stack([np.arange(km - 1), np.arange(1, km)])
    sf = np.column_stack([np.arange(1, ks), np.arange(ks - 1)])
    if facet_type == "line3":
        mf = np.column_stack([mf, km + np.arange(nm)])
        sf = np.column_stack([sf, ks + np.arange(ns)])
    points = np.vstack([xm, xs])
    return points, sf + len(xm), mf


@pytest.mark.parametrize("facet_type, order", [("line", 2), ("line3", 3)])
def test_curved_interface_gap_converges(facet_type, order):
    """Concentric arcs at distance g0: the averaged gaps converge to g0 at the geometric
    order of the facets (h² for line, h³ or better for line3), a rigid translation is
    annihilated, the weights partition unity."""
    g0 = 0.01
    errors = []
    for level in range(4):
        rng = np.random.default_rng(level)
        points, sf, mf = arcs(6 * 2 ** level, 10 * 2 ** level, facet_type, g0, rng)
        mortar = mortar_pairing(points, sf, mf, facet_type)
        p = mortar.pairing
        np.testing.assert_allclose(p.weights.sum(axis=1), 1.0, atol=1e-13)
        rn, _, _ = mortar_rows(mortar)
        np.testing.assert_allclose(rn.apply(np.tile([0.3, 0.7], (len(points), 1))), 0.0,
                                   atol=1e-15)
        errors.append(np.abs(p.gap - g0).max())
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(rates[1:] > order - 0.3), (errors, rates)
