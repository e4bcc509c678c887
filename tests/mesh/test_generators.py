"""Structured generators: sizes, measures, orientation, conformity, quadratic upgrade."""


import numpy as np
import pytest

from parsolve.errors import InputError
from parsolve.mesh.generators import (
    GENERATOR_GROUPS,
    GENERATORS,
    box,
    make_quadratic,
    plate_with_hole,
    rectangle,
)
from parsolve.mesh.topology import boundary_facets, cell_measures, jacobian_dets


def assert_valid(mesh):
    """Positive Jacobians everywhere we look, no duplicate points, all points used."""
    assert np.all(jacobian_dets(mesh.points, mesh.cell_type, mesh.cells) > 0)
    assert len(np.unique(np.round(mesh.points, 12), axis=0)) == mesh.num_points
    assert np.array_equal(np.unique(mesh.cells), np.arange(mesh.num_points))


def face_counts(mesh, faces):
    """How many cells share each distinct face (by sorted vertex ids)."""
    keys = np.concatenate([np.sort(mesh.cells[:, f], axis=1) for f in faces])
    return np.unique(keys, axis=0, return_counts=True)[1]


# ---------------------------------------------------------------- rectangle


@pytest.mark.parametrize("cell", ["quad", "triangle", "triangle6"])
def test_rectangle_area_orientation_boundary(cell):
    nx, ny = 4, 3
    m = rectangle(2.0, 1.5, nx, ny, cell=cell, origin=(1.0, -1.0))
    assert m.cell_type == cell and m.dim == 2 and m.points.shape[1] == 2
    assert m.num_cells == nx * ny * (1 if cell == "quad" else 2)
    assert cell_measures(m).sum() == pytest.approx(3.0, rel=1e-13)
    assert_valid(m)
    assert m.points.min(axis=0) == pytest.approx([1.0, -1.0])
    assert m.points.max(axis=0) == pytest.approx([3.0, 0.5])
    assert len(boundary_facets(m)[0]) == 2 * (nx + ny)


def test_rectangle_side_groups():
    m = rectangle(2.0, 1.0, 4, 3, cell="triangle6")
    sizes = {name: len(f) for name, f in m.facet_groups.items()}
    assert sizes == {"left": 3, "right": 3, "bottom": 4, "top": 4}
    assert m.facet_groups["left"].shape[1] == 3  # line3
    assert np.allclose(m.points[m.facet_groups["right"].ravel(), 0], 2.0)
    # node groups contain the midside nodes too: 2*ny+1 nodes on the left side
    assert len(m.node_groups["left"]) == 7
    assert np.allclose(m.points[m.node_groups["top"], 1], 1.0)


def test_rectangle_quadratic_node_count():
    nx, ny = 5, 3
    m = rectangle(1.0, 1.0, nx, ny, cell="triangle6")
    assert m.num_points == (2 * nx + 1) * (2 * ny + 1)


def test_rectangle_of_a_million_cells():
    # its speed belongs in scripts/bench_assembly.py, not in a timed unit test (3 ranks on 2
    # cores made the former 2 s bound fail)
    m = rectangle(1.0, 1.0, 1000, 1000)
    assert m.num_cells == 10**6 and m.num_points == 1001**2


def test_bad_arguments():
    # ValueError: the scene layer turns it into an InputError with source and key
    with pytest.raises(ValueError, match="unsupported cell"):
        rectangle(1, 1, 2, 2, cell="hexahedron")
    with pytest.raises(ValueError, match="nx must be a positive integer"):
        rectangle(1, 1, 0, 2)
    with pytest.raises(ValueError, match="ny must be a positive integer"):
        rectangle(1, 1, 2, 2.5)
    with pytest.raises(ValueError):
        box(1, 1, 1, 1, 1, 1, cell="quad")
    with pytest.raises(ValueError, match="radius"):
        plate_with_hole(1, 1, 2.0, 2, 4)
    with pytest.raises(ValueError, match="lz must be positive"):
        box(1, 1, -1, 1, 1, 1)
    with pytest.raises(ValueError, match="origin must have 2"):
        rectangle(1, 1, 1, 1, origin=(0, 0, 0))
    assert rectangle(1, 1, 2.0, 2).num_cells == 4  # integral floats are fine


# ---------------------------------------------------------------- box

TET_FACES = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)]


@pytest.mark.parametrize("cell", ["hexahedron", "tetra", "tetra10"])
def test_box_volume_orientation(cell):
    nx, ny, nz = 3, 2, 4
    m = box(1.0, 2.0, 3.0, nx, ny, nz, cell=cell, origin=(0.0, 1.0, -1.0))
    assert m.dim == 3 and m.points.shape[1] == 3
    assert m.num_cells == nx * ny * nz * (1 if cell == "hexahedron" else 6)
    assert cell_measures(m).sum() == pytest.approx(6.0, rel=1e-13)
    assert_valid(m)
    assert m.points.max(axis=0) == pytest.approx([1.0, 3.0, 2.0])


@pytest.mark.parametrize("cell", ["tetra", "tetra10"])
def test_box_tet_split_is_conforming(cell):
    nx, ny, nz = 3, 2, 4
    m = box(1.0, 1.0, 1.0, nx, ny, nz, cell=cell)
    counts = face_counts(m, TET_FACES)
    # every face is shared by at most 2 tets, and exactly the outer ones by one
    assert counts.max() == 2
    assert np.count_nonzero(counts == 1) == 2 * (2 * nx * ny + 2 * ny * nz + 2 * nx * nz)
    assert len(boundary_facets(m)[0]) == 2 * (2 * nx * ny + 2 * ny * nz + 2 * nx * nz)


def test_box_hex_boundary_and_groups():
    nx, ny, nz = 3, 2, 4
    m = box(1.0, 2.0, 3.0, nx, ny, nz)
    assert len(boundary_facets(m)[0]) == 2 * (nx * ny + ny * nz + nx * nz)
    sizes = {name: len(f) for name, f in m.facet_groups.items()}
    assert sizes == {"xmin": 8, "xmax": 8, "ymin": 12, "ymax": 12, "zmin": 6, "zmax": 6}
    assert np.allclose(m.points[m.facet_groups["zmax"].ravel(), 2], 3.0)


def test_box_tetra10_nodes_and_groups():
    nx, ny, nz = 2, 3, 1
    m = box(1.0, 1.0, 1.0, nx, ny, nz, cell="tetra10")
    vertices = (nx + 1) * (ny + 1) * (nz + 1)
    grid_edges = nx * (ny + 1) * (nz + 1) + ny * (nx + 1) * (nz + 1) + nz * (nx + 1) * (ny + 1)
    face_diagonals = nx * ny * (nz + 1) + ny * nz * (nx + 1) + nx * nz * (ny + 1)
    body_diagonals = nx * ny * nz
    assert m.num_points == vertices + grid_edges + face_diagonals + body_diagonals
    assert m.facet_groups["xmin"].shape == (2 * ny * nz, 6)
    assert np.allclose(m.points[m.node_groups["xmin"], 0], 0.0)
    assert len(m.node_groups["xmin"]) == (2 * ny + 1) * (2 * nz + 1)


# ---------------------------------------------------------------- plate with hole


def polygon_hole_area(mesh, radius):
    """Area cut out by the straight chords between consecutive hole nodes."""
    p = mesh.points[mesh.facet_groups["hole"][:, :2]]
    dtheta = np.abs(np.arctan2(p[:, 1, 1], p[:, 1, 0]) - np.arctan2(p[:, 0, 1], p[:, 0, 0]))
    return np.sum(0.5 * radius**2 * np.sin(dtheta))


@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_plate_with_hole_linear_area(cell):
    w, h, r = 2.0, 2.0, 0.5
    exact = w * h - np.pi * r**2 / 4
    errors = []
    for n in (4, 8, 16):
        m = plate_with_hole(w, h, r, n, 2 * n, cell=cell)
        assert_valid(m)
        area = cell_measures(m).sum()
        # the mesh is exactly the plate minus the inscribed polygon
        assert area == pytest.approx(w * h - polygon_hole_area(m, r), rel=1e-12)
        errors.append(area - exact)
    assert errors[0] > errors[1] > errors[2] > 0
    assert errors[1] / errors[2] == pytest.approx(4.0, rel=0.05)  # O(h^2) chords


def test_plate_with_hole_triangle6_is_almost_exact():
    w, h, r = 2.0, 2.0, 0.5
    exact = w * h - np.pi * r**2 / 4
    errors = []
    for n in (4, 8):
        m = plate_with_hole(w, h, r, n, 2 * n, cell="triangle6", grading=3.0)
        assert_valid(m)
        errors.append(abs(cell_measures(m).sum() - exact))
    assert errors[0] < 1e-6 * exact
    assert errors[1] < errors[0] / 10  # ~ h^4
    # every node on the hole (midside ones included) is on the circle
    hole = np.unique(m.facet_groups["hole"])
    assert len(hole) == 2 * 16 + 1
    assert np.allclose(np.linalg.norm(m.points[hole], axis=1), r, rtol=1e-14)


def test_plate_with_hole_groups_and_counts():
    w, h, r, nr, na = 3.0, 1.5, 0.5, 5, 7
    m = plate_with_hole(w, h, r, nr, na)
    assert m.num_points == (nr + 1) * (na + 1) and m.num_cells == nr * na
    assert_valid(m)
    assert cell_measures(m).sum() == pytest.approx(w * h - polygon_hole_area(m, r), rel=1e-12)
    fg = m.facet_groups
    assert len(fg["hole"]) == na and len(fg["left"]) == nr and len(fg["bottom"]) == nr
    assert len(fg["right"]) + len(fg["top"]) == na
    assert len(boundary_facets(m)[0]) == 2 * (nr + na)
    pts = m.points
    assert np.all(pts[fg["left"].ravel(), 0] == 0.0)
    assert np.all(pts[fg["bottom"].ravel(), 1] == 0.0)
    assert np.allclose(pts[fg["right"].ravel(), 0], w)
    assert np.allclose(pts[fg["top"].ravel(), 1], h)
    assert np.allclose(np.linalg.norm(pts[fg["hole"].ravel()], axis=1), r)


def test_plate_with_hole_grading():
    r, w = 1.0, 5.0
    m = plate_with_hole(w, w, r, 10, 8, grading=4.0)
    bottom = np.sort(m.points[m.node_groups["bottom"], 0])  # nodes along y = 0
    sizes = np.diff(bottom)
    assert sizes[0] == pytest.approx(sizes[-1] / 4.0)
    assert np.all(np.diff(sizes) > 0)
    uniform = plate_with_hole(w, w, r, 10, 8, grading=1.0)
    assert np.allclose(np.diff(np.sort(uniform.points[uniform.node_groups["bottom"], 0])), 0.4)


# ---------------------------------------------------------------- make_quadratic


def test_make_quadratic_triangle():
    lin = rectangle(1.0, 1.0, 2, 2, cell="triangle")
    lin.cell_groups["all"] = np.arange(lin.num_cells)
    lin.node_groups["corner"] = np.array([0])
    quad = make_quadratic(lin)
    assert quad.cell_type == "triangle6" and quad.cells.shape == (8, 6)
    assert np.array_equal(quad.cells[:, :3], lin.cells)
    assert np.array_equal(quad.points[: lin.num_points], lin.points)
    # midside nodes: m01, m12, m20
    c, p = quad.cells, quad.points
    for a, b, mid in ((0, 1, 3), (1, 2, 4), (2, 0, 5)):
        assert np.allclose(p[c[:, mid]], 0.5 * (p[c[:, a]] + p[c[:, b]]))
    assert np.array_equal(quad.cell_groups["all"], lin.cell_groups["all"])
    assert np.array_equal(quad.node_groups["corner"], [0])
    left = quad.facet_groups["left"]
    assert left.shape == (2, 3)
    assert np.allclose(p[left[:, 2]], 0.5 * (p[left[:, 0]] + p[left[:, 1]]))


def test_make_quadratic_tetra_ordering():
    lin = box(1.0, 1.0, 1.0, 1, 1, 1, cell="tetra")
    quad = make_quadratic(lin)
    assert quad.cell_type == "tetra10" and quad.num_points == 8 + 19
    c, p = quad.cells, quad.points
    for mid, (a, b) in enumerate([(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)], start=4):
        assert np.allclose(p[c[:, mid]], 0.5 * (p[c[:, a]] + p[c[:, b]]))
    f = quad.facet_groups["zmin"]  # triangle6: v0, v1, v2, m01, m12, m20
    for mid, (a, b) in zip((3, 4, 5), ((0, 1), (1, 2), (2, 0))):
        assert np.allclose(p[f[:, mid]], 0.5 * (p[f[:, a]] + p[f[:, b]]))


def test_make_quadratic_rejects_quads():
    with pytest.raises(InputError):
        make_quadratic(rectangle(1.0, 1.0, 1, 1))


def test_registry_keywords():
    assert set(GENERATORS) == {"rectangle", "box", "plate_with_hole", "sphere_on_block"} \
        == set(GENERATOR_GROUPS)
    m = GENERATORS["rectangle"](lx=1.0, ly=1.0, nx=1, ny=1, cell="triangle", origin=(0, 0))
    assert m.num_cells == 2
    m = GENERATORS["box"](lx=1, ly=1, lz=1, nx=1, ny=1, nz=1, cell="tetra", origin=(0, 0, 0))
    assert m.num_cells == 6
    m = GENERATORS["plate_with_hole"](
        width=1, height=1, radius=0.3, n_radial=2, n_angular=4, cell="triangle6", grading=2.0
    )
    assert m.cell_type == "triangle6"
    for name, kwargs in [
        ("rectangle", dict(lx=1, ly=1, nx=2, ny=2)),
        ("box", dict(lx=1, ly=1, lz=1, nx=1, ny=1, nz=1)),
        ("plate_with_hole", dict(width=1, height=1, radius=0.3, n_radial=2, n_angular=4)),
    ]:
        m = GENERATORS[name](**kwargs)
        assert set(m.facet_groups) == set(m.node_groups) == set(GENERATOR_GROUPS[name])
    m = GENERATORS["sphere_on_block"](radius=10, width=5, depth=5, height=5, fine=1, n_fine=2,
                                      n_coarse=1, n_depth=1)
    assert set(m.cell_groups) | set(m.facet_groups) == set(GENERATOR_GROUPS["sphere_on_block"])
    assert set(m.facet_groups) == set(m.node_groups)


# ---------------------------------------------------------------- sphere on a block


@pytest.mark.parametrize("profile", ["paraboloid", "sphere"])
@pytest.mark.parametrize("cell", ["hexahedron", "tetra"])
def test_sphere_on_block_bodies_and_faces(profile, cell):
    """Two bodies, positively oriented, each conforming (the faces between cells shared by
    two), meeting only at the tip: the block [0, 5]² × [−5, 0] (volume 125 exactly), the
    sphere body above the profile; the block top flat at z = 0, the sphere body's contact
    nodes on the profile above the tip by the gap; the fine zone's cells of the block h =
    0.8 / 4, the sphere body's 0.8 / 3 (¾ of the block's count: non-matching); counts as
    memory.cell_counts says."""
    from parsolve.mesh import memory
    from parsolve.mesh.generators import sphere_on_block

    params = dict(radius=10.0, width=5.0, depth=5.0, height=5.0, fine=0.8, n_fine=4,
                  n_coarse=2, n_depth=3, gap=1e-3, profile=profile, cell=cell)
    m = sphere_on_block(**params)
    assert_valid(m)
    assert memory.cell_counts("sphere_on_block", params) == (m.num_points, m.num_cells, 3)
    vol = cell_measures(m)
    assert vol[m.cell_groups["block"]].sum() == pytest.approx(125.0, rel=1e-13)
    assert m.cell_groups["block"].size + m.cell_groups["sphere"].size == m.num_cells
    x = m.points
    top, face = np.unique(m.facet_groups["block_top"]), np.unique(m.facet_groups["sphere_surface"])
    assert np.all(x[top, 2] == 0.0) and np.all(x[np.unique(m.facet_groups["block_bottom"]), 2] == -5.0)
    assert np.all(x[np.unique(m.facet_groups["sphere_top"]), 2] == 5.0)
    r = np.hypot(x[face, 0], x[face, 1])
    f = r * r / 20.0 if profile == "paraboloid" else 10.0 - np.sqrt(100.0 - r * r)
    np.testing.assert_allclose(x[face, 2], 1e-3 + f, rtol=1e-14, atol=1e-15)
    assert top.size == 7 * 7 and face.size == 6 * 6
    assert np.unique(x[top, 0])[1] == pytest.approx(0.2) and np.unique(x[face, 0])[1] == pytest.approx(0.8 / 3)
    assert np.all(x[np.unique(m.facet_groups["xmin"]), 0] == 0.0)
    assert np.all(x[np.unique(m.facet_groups["ymin"]), 1] == 0.0)
    faces = [f for f in ([0, 1, 2, 3], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6],
                         [3, 0, 4, 7])] if cell == "hexahedron" else [[0, 1, 2], [0, 1, 3], [1, 2, 3], [0, 2, 3]]
    assert face_counts(m, faces).max() == 2
    if cell == "tetra":   # order = 2: the counts of the upgraded mesh
        assert memory.cell_counts("sphere_on_block", params, order=2)[0] == make_quadratic(m).num_points


def test_sphere_on_block_bad_arguments():
    """Each refusal names its parameter first (the scene's key: mesh.<name>)."""
    from parsolve.mesh.generators import sphere_on_block

    good = dict(radius=10.0, width=5.0, depth=5.0, height=5.0, fine=0.8, n_fine=4, n_coarse=2,
                n_depth=3)
    for change, first in [({"fine": 6.0}, "fine"), ({"n_fine": 0}, "n_fine"),
                          ({"gap": -1.0}, "gap"), ({"profile": "cone"}, "profile"),
                          ({"height": 2.0}, "height"), ({"cell": "tetra10"}, "unsupported"),
                          ({"profile": "sphere", "radius": 7.0}, "radius"),
                          ({"depth": 0.0}, "depth"), ({"n_fine_sphere": 1.5}, "n_fine_sphere")]:
        with pytest.raises(ValueError) as err:
            sphere_on_block(**{**good, **change})
        assert str(err.value).split()[0] == first, (change, str(err.value))
