"""Closest-point pairing: matched and non-matching meshes, inclined, curved, quadratic faces."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.contact.pairing import candidate_pairs, pair_nodes
from parsolve.mesh.generators import box, make_quadratic, rectangle
from parsolve.mesh.mesh import Mesh
from parsolve.mesh.topology import boundary_facets, match_facets, orient_cells


def two_bodies(master: Mesh, slave: Mesh, master_side: str, slave_side: str):
    """Concatenated points, master facets (outward from the master), slave node ids."""
    pts = np.vstack([master.points, slave.points])
    _, _, facets = match_facets(master, master.facet_groups[master_side])
    return pts, facets, slave.node_groups[slave_side] + master.num_points


def rotate2(points: np.ndarray, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return points @ np.array([[c, -s], [s, c]]).T


def check_frame(p, dim):
    assert np.allclose(np.linalg.norm(p.normal, axis=1), 1.0, atol=1e-14)
    t = p.tangents
    gram = np.einsum("nix,njx->nij", t, t)
    assert np.allclose(gram, np.eye(dim - 1), atol=1e-14)
    assert np.allclose(np.einsum("nix,nx->ni", t, p.normal), 0.0, atol=1e-14)
    if dim == 3:  # right-handed (t1, t2, n)
        assert np.allclose(np.cross(t[:, 0], t[:, 1]), p.normal, atol=1e-14)
    else:  # t = (-n_y, n_x)
        assert np.allclose(t[:, 0], np.column_stack([-p.normal[:, 1], p.normal[:, 0]]), atol=1e-15)


@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_matched_2d_gap_zero_and_nodal_weights(cell):
    master = rectangle(2.0, 1.0, 8, 2, cell, origin=(0.0, -1.0))
    slave = rectangle(2.0, 0.5, 8, 2, cell)
    pts, facets, slaves = two_bodies(master, slave, "top", "bottom")
    p = pair_nodes(pts, slaves, facets, "line")
    assert p.paired.all()
    assert np.abs(p.gap).max() == 0.0
    assert np.allclose(p.normal, [0.0, 1.0]) and np.allclose(p.tangents[:, 0], [-1.0, 0.0])
    # each slave node coincides with one master node: weights are 0/1 on that node
    mx = pts[p.master]
    w_node = (np.abs(mx - pts[slaves][:, None, :]).sum(axis=2) == 0.0)
    assert np.allclose(p.weights, w_node, atol=1e-15)
    check_frame(p, 2)


@pytest.mark.parametrize("angle", [0.0, 0.3, -1.1])
@pytest.mark.parametrize("cell", ["quad", "triangle", "triangle6"])
def test_non_matching_inclined_2d(angle, cell):
    g0 = 0.013
    master = rectangle(1.0, 0.5, 7, 3, cell, origin=(0.0, -0.5))
    slave = rectangle(1.0, 0.3, 5, 2, "quad", origin=(0.0, g0))
    pts, facets, slaves = two_bodies(master, slave, "top", "bottom")
    pts = rotate2(pts, angle)
    ftype = "line3" if cell == "triangle6" else "line"
    p = pair_nodes(pts, slaves, facets, ftype)
    assert p.paired.all()
    assert np.allclose(p.gap, g0, rtol=0, atol=1e-14)
    n = np.array([-np.sin(angle), np.cos(angle)])
    assert np.allclose(p.normal, n, atol=1e-14)
    # the projection is the slave point moved back along n, and the weights interpolate it
    assert np.allclose(p.point, pts[slaves] - g0 * n, atol=1e-14)
    assert np.allclose(np.einsum("nk,nkx->nx", p.weights, pts[p.master]), p.point, atol=1e-14)
    assert np.allclose(p.weights.sum(axis=1), 1.0, atol=1e-14)
    check_frame(p, 2)


def test_penetration_is_negative_gap_and_orientation_follows_the_master():
    # master above the slave: its bottom facets point down, towards the slave
    master = rectangle(1.0, 0.5, 4, 2, "quad", origin=(0.0, 0.0))
    slave = rectangle(1.0, 0.5, 3, 2, "triangle", origin=(0.0, -0.48))  # 0.02 overlap
    pts, facets, slaves = two_bodies(master, slave, "bottom", "top")
    p = pair_nodes(pts, slaves, facets, "line")
    assert p.paired.all()
    assert np.allclose(p.gap, -0.02, atol=1e-14)
    assert np.allclose(p.normal, [0.0, -1.0])


def test_outside_nodes_are_unpaired():
    master = rectangle(1.0, 0.5, 4, 1, "quad", origin=(0.0, -0.5))
    slave = rectangle(1.6, 0.3, 8, 1, "quad", origin=(-0.3, 0.01))
    pts, facets, slaves = two_bodies(master, slave, "top", "bottom")
    p = pair_nodes(pts, slaves, facets, "line")
    x = pts[slaves, 0]
    inside = (x >= -1e-12) & (x <= 1.0 + 1e-12)
    assert np.array_equal(p.paired, inside)
    assert np.all(p.facet[~inside] == -1) and np.all(np.isinf(p.gap[~inside]))
    # a node beyond the search radius is unpaired too
    far = pair_nodes(pts, slaves, facets, "line", search_radius=0.005)
    # 1 % of a facet beyond the master's end: paired with the end vertex (default tol 1e-2)
    pts_end = np.vstack([pts, [[1.0 + 0.001, 0.01]]])  # xi = 1.008
    end = pair_nodes(pts_end, [len(pts)], facets, "line")
    assert end.paired.all() and np.allclose(end.point, [[1.0, 0.0]]) and end.gap[0] == 0.01
    assert not pair_nodes(pts_end, [len(pts)], facets, "line", tol=1e-3).paired.any()
    assert not far.paired.any()


def annulus(r_in: float, r_out: float, nt: int, nr: int, cell: str) -> Mesh:
    """Half annulus y >= 0, with the outer circle's nodes (and P2 midside nodes) on it."""
    base = rectangle(np.pi, r_out - r_in, nt, nr, "triangle" if cell == "triangle6" else cell,
                     origin=(0.0, r_in))
    th, r = base.points[:, 0], base.points[:, 1]
    points = np.column_stack([r * np.cos(th), r * np.sin(th)])
    cells, _ = orient_cells(points, base.cell_type, base.cells)
    mesh = Mesh(points, base.cell_type, cells)
    if cell == "triangle6":
        mesh = make_quadratic(mesh)
    rad = np.linalg.norm(mesh.points, axis=1)
    ring = np.abs(rad - r_out) < 1e-9 * r_out
    if cell == "triangle6":  # midside nodes of outer edges: move onto the circle
        bnodes = boundary_facets(mesh)[0]
        outer = np.isclose(np.linalg.norm(mesh.points[bnodes[:, 0]], axis=1), r_out) & \
            np.isclose(np.linalg.norm(mesh.points[bnodes[:, 1]], axis=1), r_out)
        mid = bnodes[outer, 2]
        mesh.points[mid] *= r_out / np.linalg.norm(mesh.points[mid], axis=1)[:, None]
        ring[mid] = True
    mesh.node_groups["outer"] = np.flatnonzero(ring)
    mask = np.zeros(mesh.num_points, dtype=bool)
    mask[ring] = True
    from parsolve.mesh.topology import facets_from_nodes
    mesh.facet_groups["outer"] = facets_from_nodes(mesh, mask)[0]
    return mesh


def brute_force_distance(xs: np.ndarray, curve: np.ndarray) -> np.ndarray:
    """Distance from points (n, 2) to a densely sampled polyline (m, 2), refined by the
    exact distance to each sample segment (independent of the Newton projection)."""
    a, b = curve[:-1], curve[1:]
    ab = b - a
    t = np.clip(np.einsum("nmx,mx->nm", xs[:, None, :] - a[None], ab) / (ab**2).sum(1), 0, 1)
    d = xs[:, None, :] - (a[None] + t[..., None] * ab[None])
    return np.sqrt((d**2).sum(axis=2)).min(axis=1)


@pytest.mark.parametrize("cell", ["quad", "triangle6"])
def test_curved_circular_master(cell):
    radius, nt = 1.0, 12
    master = annulus(0.5, radius, nt, 2, cell)
    _, _, facets = match_facets(master, master.facet_groups["outer"])
    ftype = "line3" if cell == "triangle6" else "line"
    # slave points off the circle at known radii, angles avoiding the ends
    phi = np.linspace(0.2, np.pi - 0.2, 23) + 0.01  # away from the chords' vertices
    rr = radius + np.linspace(-0.01, 0.02, 23)
    xs = np.column_stack([rr * np.cos(phi), rr * np.sin(phi)])
    pts = np.vstack([master.points, xs])
    slaves = np.arange(master.num_points, pts.shape[0])
    p = pair_nodes(pts, slaves, facets, ftype)
    assert p.paired.all()
    check_frame(p, 2)
    if cell == "quad":
        # straight chords: the distance to the chord of half-angle h is r cos(phi - mid) - R cos h
        h = np.pi / nt / 2
        mid = (np.floor(phi / (2 * h)) + 0.5) * 2 * h
        exact = rr * np.cos(phi - mid) - radius * np.cos(h)
        assert np.allclose(p.gap, exact, atol=1e-14)
        assert np.allclose(p.normal, np.column_stack([np.cos(mid), np.sin(mid)]), atol=1e-14)
    else:
        # parabolic arcs: compare with a dense sampling of the same arcs
        from parsolve.fem.elements import element
        s = np.linspace(-1, 1, 4001)[:, None]
        arcs = np.einsum("qk,fkx->fqx", element("line3").shape(s), master.points[facets])
        dist = np.array([brute_force_distance(xs[i:i + 1], arcs[p.facet[i]])[0] for i in range(23)])
        assert np.allclose(np.abs(p.gap), dist, atol=1e-9)
        # the arcs are within O(h^3) of the circle: the gap is close to r - R
        assert np.allclose(p.gap, rr - radius, atol=2e-4)
        # sign: outside the circle is open
        assert np.all(np.sign(p.gap) == np.sign(rr - radius + 1e-5))


def test_matched_3d_hex_and_tet_faces():
    for cell, ftype in (("hexahedron", "quad"), ("tetra", "triangle")):
        master = box(1.0, 1.0, 0.5, 3, 3, 1, cell, origin=(0.0, 0.0, -0.5))
        slave = box(1.0, 1.0, 0.5, 3, 3, 1, cell)
        pts, facets, slaves = two_bodies(master, slave, "zmax", "zmin")
        p = pair_nodes(pts, slaves, facets, ftype)
        assert p.paired.all()
        assert np.abs(p.gap).max() < 1e-15
        assert np.allclose(p.normal, [0, 0, 1], atol=1e-15)
        assert np.allclose(np.einsum("nk,nkx->nx", p.weights, pts[p.master]), pts[slaves], atol=1e-15)
        check_frame(p, 3)


@pytest.mark.parametrize("cell,ftype", [("hexahedron", "quad"), ("tetra", "triangle"),
                                        ("tetra10", "triangle6")])
def test_non_matching_3d_with_gap(cell, ftype):
    g0 = 0.021
    base = "tetra" if cell == "tetra10" else cell
    master = box(1.0, 1.0, 0.4, 4, 3, 1, base, origin=(0.0, 0.0, -0.4))
    if cell == "tetra10":
        master = make_quadratic(master)
    slave = box(1.0, 1.0, 0.3, 5, 7, 1, "hexahedron", origin=(0.0, 0.0, g0))
    pts, facets, slaves = two_bodies(master, slave, "zmax", "zmin")
    p = pair_nodes(pts, slaves, facets, ftype)
    assert p.paired.all()
    assert np.allclose(p.gap, g0, atol=1e-14)
    assert np.allclose(p.point, pts[slaves] - [0, 0, g0], atol=1e-14)
    check_frame(p, 3)


def closest_on_graph(xs: np.ndarray, f, fx, fy) -> np.ndarray:
    """Closest points on z = f(x, y) from the optimality conditions
    (X - x) + (Z - f) f_x = 0, (Y - y) + (Z - f) f_y = 0, solved by Newton with
    finite-difference Jacobians (a different route from the facet parametrisation)."""
    x, y = xs[:, 0].copy(), xs[:, 1].copy()

    def res(x, y):
        d = xs[:, 2] - f(x, y)
        return np.stack([xs[:, 0] - x + d * fx(x, y), xs[:, 1] - y + d * fy(x, y)], 1)

    for _ in range(40):
        r = res(x, y)
        h = 1e-7
        jx = (res(x + h, y) - res(x - h, y)) / (2 * h)
        jy = (res(x, y + h) - res(x, y - h)) / (2 * h)
        jac = np.stack([jx, jy], axis=2)
        step = np.linalg.solve(jac, r[:, :, None])[:, :, 0]
        x, y = x - step[:, 0], y - step[:, 1]
    return np.column_stack([x, y, f(x, y)])


@pytest.mark.parametrize("cell,ftype,c", [("tetra10", "triangle6", 0.3), ("hexahedron", "quad", 0.4)])
def test_curved_quadratic_and_warped_faces(cell, ftype, c):
    """triangle6 faces reproduce z = c x^2 exactly; quad faces reproduce z = c x y exactly:
    the pairing must find the closest point of that exact surface."""
    if cell == "tetra10":
        master = make_quadratic(box(1.0, 1.0, 0.5, 3, 3, 1, "tetra", origin=(0, 0, -0.5)))
        f = lambda x, y: c * x**2  # noqa: E731
        fx, fy = (lambda x, y: 2 * c * x), (lambda x, y: 0 * x)
    else:
        master = box(1.0, 1.0, 0.5, 3, 3, 1, "hexahedron", origin=(0, 0, -0.5))
        f = lambda x, y: c * x * y  # noqa: E731
        fx, fy = (lambda x, y: c * y), (lambda x, y: c * x)
    # bend the top surface (and scale the body below it) so that top nodes lie on z = f
    z = master.points[:, 2]
    master.points[:, 2] = z + (z + 0.5) / 0.5 * f(master.points[:, 0], master.points[:, 1])
    _, _, facets = match_facets(master, master.facet_groups["zmax"])
    rng = np.random.default_rng(7)
    xy = rng.uniform(0.1, 0.9, size=(40, 2))
    xs = np.column_stack([xy, f(xy[:, 0], xy[:, 1]) + rng.uniform(-0.03, 0.05, 40)])
    pts = np.vstack([master.points, xs])
    p = pair_nodes(pts, np.arange(master.num_points, pts.shape[0]), facets, ftype)
    assert p.paired.all()
    cp = closest_on_graph(xs, f, fx, fy)
    assert np.allclose(p.point, cp, atol=1e-9)
    assert np.allclose(np.abs(p.gap), np.linalg.norm(xs - cp, axis=1), atol=1e-12)
    # upward unit normal of the graph (-f_x, -f_y, 1)/|.|
    ng = np.column_stack([-fx(cp[:, 0], cp[:, 1]), -fy(cp[:, 0], cp[:, 1]), np.ones(40)])
    ng /= np.linalg.norm(ng, axis=1)[:, None]
    assert np.allclose(p.normal, ng, atol=1e-8)
    assert np.all(np.sign(p.gap) == np.sign(xs[:, 2] - f(xs[:, 0], xs[:, 1])))
    check_frame(p, 3)


def test_candidate_search_matches_all_pairs():
    rng = np.random.default_rng(3)
    lo = rng.uniform(0, 10, size=(300, 2))
    hi = lo + rng.uniform(0, 0.8, size=(300, 2))
    xs = rng.uniform(0, 11, size=(500, 2))
    s, f = candidate_pairs(xs, lo, hi)
    inside = np.all((xs[:, None] >= lo[None]) & (xs[:, None] <= hi[None]), axis=2)
    ref = set(zip(*np.nonzero(inside)))
    got = set(zip(s.tolist(), f.tolist()))
    assert got == {(int(a), int(b)) for a, b in ref}
    assert len(s) == len(got)  # no duplicates


def test_bad_facet_type():
    with pytest.raises(ValueError):
        pair_nodes(np.zeros((3, 2)), [0], np.array([[1, 2]]), "triangle")


def test_convex_corner_dead_zone_needs_a_tolerance():
    """A point outside a convex polygonal master, exactly facing a vertex, projects beyond
    both adjacent chords: unpaired with a strict tolerance, paired with the vertex (gap along
    the chosen chord's normal) with a larger one."""
    radius, nt = 1.0, 12
    master = annulus(0.5, radius, nt, 1, "quad")
    _, _, facets = match_facets(master, master.facet_groups["outer"])
    rr = 1.005
    pts = np.vstack([master.points, [[0.0, rr]]])  # the vertex at angle pi/2
    strict = pair_nodes(pts, [master.num_points], facets, "line", tol=1e-8)
    assert not strict.paired.any()
    loose = pair_nodes(pts, [master.num_points], facets, "line", tol=0.05)
    assert loose.paired.all()
    assert np.allclose(loose.point, [[0.0, radius]], atol=1e-15)
    h = np.pi / nt / 2
    assert np.isclose(loose.gap[0], (rr - radius) * np.cos(h), atol=1e-15)
    assert np.isclose(abs(loose.xi[0, 0]), 1.0)
