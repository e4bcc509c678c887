"""Facet tables, boundary facets, facet matching and cell orientation."""

import numpy as np
import pytest

from helpers.curved_q2 import q2_mesh, ring_sector_mesh
from parsolve.errors import InputError
from parsolve.fem.elements import element
from parsolve.mesh.generators import box, plate_with_hole, rectangle
from parsolve.mesh.mesh import CELL_INFO, SECOND_ORDER, Mesh
from parsolve.mesh.topology import (
    FACETS,
    FLIP,
    boundary_facets,
    cell_measures,
    facets_from_nodes,
    match_facets,
    orient_cells,
)

FACET_NODES = {"line": 2, "line3": 3, "triangle": 3, "triangle6": 6, "quad": 4, "quad9": 9,
               "quad8": 8}


def single_cell(cell_type):
    """The first cell of a tiny generated mesh, as a one-cell mesh (Q2 quadrilaterals, which
    no generator makes: the reference cell mapped onto the unit square)."""
    if cell_type in SECOND_ORDER and cell_type not in ("triangle6", "tetra10"):
        nodes = 0.5 * (element(cell_type).nodes + 1.0)
        return Mesh(nodes, cell_type, np.arange(len(nodes))[None, :])
    if CELL_INFO[cell_type][0] == 2:
        m = rectangle(1.0, 1.0, 1, 1, cell=cell_type)
    else:
        m = box(1.0, 1.0, 1.0, 1, 1, 1, cell=cell_type)
    return Mesh(m.points, cell_type, m.cells[:1])


def area_vectors(points, facets, facet_type):
    """(measure * outward normal, centroid) of straight facets, from their corners."""
    p = points[facets]
    if facet_type in ("line", "line3"):
        d = p[:, 1] - p[:, 0]
        return np.column_stack([d[:, 1], -d[:, 0]]), 0.5 * (p[:, 0] + p[:, 1])
    if facet_type in ("triangle", "triangle6"):
        return 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, :3].mean(axis=1)
    return 0.5 * np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1]), p.mean(axis=1)  # quad


@pytest.mark.parametrize("cell_type", sorted(FACETS))
def test_facet_table_is_outward_and_well_ordered(cell_type):
    m = single_cell(cell_type)
    ftype = m.facet_type
    local = np.array(FACETS[cell_type])
    assert local.shape[1] == FACET_NODES[ftype]
    facets = m.cells[0][local]
    vec, centroid = area_vectors(m.points, facets, ftype)
    outward = centroid - m.points[m.cells[0]].mean(axis=0)
    assert np.all(np.einsum("ij,ij->i", vec, outward) > 0)
    # quadratic facets: midside nodes in meshio order (line3: v0, v1, m01)
    quad = [(0, 1, 4), (1, 2, 5), (2, 3, 6), (3, 0, 7)]
    mids = {"line3": [(0, 1, 2)], "triangle6": [(0, 1, 3), (1, 2, 4), (2, 0, 5)],
            "quad8": quad, "quad9": quad}
    p = m.points[facets]
    for a, b, mid in mids.get(ftype, []):
        assert np.allclose(p[:, mid], 0.5 * (p[:, a] + p[:, b]))
    if ftype == "quad9":   # then the face's centre
        assert np.allclose(p[:, 8], p[:, :4].mean(axis=1))


MESHES = {
    "quad": lambda: rectangle(2.0, 1.0, 4, 3),
    "triangle": lambda: rectangle(2.0, 1.0, 4, 3, cell="triangle"),
    "triangle6": lambda: rectangle(2.0, 1.0, 4, 3, cell="triangle6"),
    "plate": lambda: plate_with_hole(2.0, 1.5, 0.5, 3, 6),
    "hexahedron": lambda: box(1.0, 2.0, 3.0, 2, 3, 2),
    "tetra": lambda: box(1.0, 2.0, 3.0, 2, 3, 2, cell="tetra"),
    "tetra10": lambda: box(1.0, 2.0, 3.0, 2, 3, 2, cell="tetra10"),
}


@pytest.mark.parametrize("name", sorted(MESHES))
def test_boundary_normals_close_and_give_volume(name):
    m = MESHES[name]()
    facets, owner, local = boundary_facets(m)
    # the returned nodes are the owner's local facet
    table = np.array(FACETS[m.cell_type])
    assert np.array_equal(facets, m.cells[owner[:, None], table[local]])
    vec, centroid = area_vectors(m.points, facets, m.facet_type)
    # closed surface: integral of n is 0; divergence theorem with the field (x, 0, 0)
    assert np.allclose(vec.sum(axis=0), 0.0, atol=1e-12)
    assert np.sum(centroid[:, 0] * vec[:, 0]) == pytest.approx(cell_measures(m).sum(), rel=1e-12)


def test_boundary_facet_counts():
    assert len(boundary_facets(rectangle(1.0, 1.0, 5, 7))[0]) == 2 * (5 + 7)
    assert len(boundary_facets(rectangle(1.0, 1.0, 5, 7, cell="triangle"))[0]) == 2 * (5 + 7)
    assert len(boundary_facets(box(1.0, 1.0, 1.0, 2, 3, 4))[0]) == 2 * (6 + 12 + 8)


def test_facets_from_nodes():
    m = rectangle(2.0, 1.0, 4, 3, cell="triangle")
    facets, owner, local = facets_from_nodes(m, np.isclose(m.points[:, 0], 0.0))
    assert facets.shape == (3, 2) and np.allclose(m.points[facets, 0], 0.0)
    # outward on x = 0: normal (dy, -dx) has negative x component
    d = m.points[facets[:, 1]] - m.points[facets[:, 0]]
    assert np.all(d[:, 1] < 0)
    # selecting every node gives the boundary only, never interior facets
    every = facets_from_nodes(m, np.ones(m.num_points, dtype=bool))
    assert all(np.array_equal(a, b) for a, b in zip(every, boundary_facets(m)))
    # a single node supports no facet
    one = np.zeros(m.num_points, dtype=bool)
    one[0] = True
    assert facets_from_nodes(m, one)[0].shape == (0, 2)


def test_facets_from_nodes_quadratic_needs_all_nodes():
    m = rectangle(1.0, 1.0, 2, 2, cell="triangle6")
    on_left = np.isclose(m.points[:, 0], 0.0)
    assert len(facets_from_nodes(m, on_left)[0]) == 2
    vertices_only = on_left.copy()
    vertices_only[np.unique(m.cells[:, 3:])] = False  # drop the midside nodes
    assert len(facets_from_nodes(m, vertices_only)[0]) == 0


@pytest.mark.parametrize("name", ["triangle", "triangle6", "hexahedron", "tetra10"])
def test_match_facets_any_order(name):
    m = MESHES[name]()
    facets, owner, local = boundary_facets(m)
    rng = np.random.default_rng(0)
    pick = rng.permutation(len(facets))[:7]
    nv = {"line": 2, "line3": 2, "triangle": 3, "triangle6": 3, "quad": 4}[m.facet_type]
    scrambled = facets[pick].copy()
    scrambled[:, :nv] = scrambled[:, :nv][:, ::-1]  # reversed corners (inward)
    o, lf, oriented = match_facets(m, scrambled)
    assert np.array_equal(o, owner[pick]) and np.array_equal(lf, local[pick])
    assert np.array_equal(oriented, facets[pick])
    # corners only are enough to identify a quadratic facet
    o2, _, oriented2 = match_facets(m, facets[pick, :nv])
    assert np.array_equal(o2, owner[pick]) and np.array_equal(oriented2, facets[pick])


def test_match_facets_rejects_interior_facet():
    m = rectangle(1.0, 1.0, 2, 2)
    interior = np.array([[1, 4]])  # vertical edge between cells 0 and 1
    with pytest.raises(InputError, match="not boundary facets"):
        match_facets(m, interior, source="mesh.msh", key="groups.left")
    with pytest.raises(InputError, match="mesh.msh: groups.left"):
        match_facets(m, interior, source="mesh.msh", key="groups.left")


@pytest.mark.parametrize("cell_type", sorted(FACETS))
def test_orient_cells_repairs_flipped_cells(cell_type):
    dim = CELL_INFO[cell_type][0]
    if cell_type in ("quad9", "quad8"):
        m = ring_sector_mesh(1.0, 2.0, 2, 2, cell=cell_type)[0]
    elif cell_type in ("hexahedron27", "hexahedron20"):
        m = q2_mesh((2, 1, 1), cell_type)
    elif dim == 2:
        m = rectangle(1.0, 1.0, 2, 2, cell=cell_type)
    else:
        m = box(1.0, 1.0, 1.0, 2, 1, 1, cell=cell_type)
    bad = m.cells.copy()
    bad[::2] = bad[::2][:, FLIP[cell_type]]
    flipped = Mesh(m.points, cell_type, bad)
    vol = cell_measures(flipped)
    assert np.all(vol[::2] < 0) and np.all(vol[1::2] > 0)
    fixed, n = orient_cells(m.points, cell_type, bad)
    assert n == len(bad[::2])
    assert np.array_equal(fixed, m.cells)


@pytest.mark.parametrize("high", [3, 1000, 2**20, 2**40])
@pytest.mark.parametrize("width", [1, 2, 3, 4])
def test_row_groups_is_unique_rows(high, width):
    """One packed key, two packed keys (ids too large for every column in one int64) or one
    column per key: the groups of np.unique(axis=0), numbered in the rows' order."""
    from parsolve.mesh.topology import _row_groups

    rng = np.random.default_rng(width)
    rows = rng.integers(0, high, size=(3000, width))
    rows = np.concatenate([rows, rows[rng.integers(0, 3000, 1000)]])   # repeats
    group, counts = _row_groups(rows)
    unique, inverse, ucounts = np.unique(rows, axis=0, return_inverse=True, return_counts=True)
    assert np.array_equal(group, inverse.ravel()) and np.array_equal(counts, ucounts)


@pytest.mark.parametrize("nv, facet", [(2, "line"), (3, "triangle"), (4, "quad")])
def test_sorted_vertex_keys_and_facet_direction(nv, facet):
    """The sorting network sorts the corners (midside nodes after them ignored); the facet's
    direction is read at its first smallest corner."""
    from parsolve.mesh.checks import facet_direction
    from parsolve.mesh.topology import _sorted_vertex_keys

    rng = np.random.default_rng(nv)
    nodes = rng.integers(0, 6, size=(5000, nv + 2))
    assert np.array_equal(_sorted_vertex_keys(nodes, facet), np.sort(nodes[:, :nv], axis=1))
    corners = nodes[:, :nv]
    i = corners.argmin(axis=1)
    rows = np.arange(corners.shape[0])
    expected = (corners[:, 0] < corners[:, 1] if nv == 2 else
                corners[rows, (i + 1) % nv] < corners[rows, (i - 1) % nv])
    assert np.array_equal(facet_direction(corners), expected)
    assert facet_direction(np.array([[4, 1, 7, 2]])).tolist() == [False]   # 1 → 7, back to 4
    assert facet_direction(np.array([[4, 1, 2, 7]])).tolist() == [True]    # 1 → 2
