"""Reading meshes with meshio: Gmsh physical groups, VTU, generic sets, errors."""

import meshio
import numpy as np
import pytest

from parsolve.errors import InputError
from parsolve.mesh.generators import box, rectangle
from parsolve.mesh.reader import mesh_from_meshio, read_mesh
from parsolve.mesh.topology import cell_measures

# 2 x 2 mesh of [0, 2]^2; gmsh node n sits at (i, j) with n = 1 + i + 3 j, plus an
# orphan node 10 that no element uses.
NODES = "\n".join(f"{1 + i + 3 * j} {i} {j} 0" for j in range(3) for i in range(3))
QUADS = [(1, 2, 5, 4), (2, 3, 6, 5), (4, 5, 8, 7), (5, 8, 9, 6)]  # the last is clockwise
TRIANGLES = [t for a, b, c, d in QUADS for t in ((a, b, c), (a, c, d))]


def msh22(cells, cell_code, extra=()):
    """A Gmsh MSH 2.2 ASCII file: physical 'corner' (point), 'left'/'right' (lines),
    'domain' (the cells) and an unnamed physical 5 on the top lines."""
    elements = [
        (15, 3, [1]),  # point at the origin
        (1, 1, [1, 4]), (1, 1, [4, 7]),  # left
        (1, 2, [3, 6]), (1, 2, [6, 9]),  # right
        (1, 5, [7, 8]), (1, 5, [8, 9]),  # top, unnamed
    ]  # fmt: skip
    elements += [(cell_code, 4, list(c)) for c in cells] + list(extra)
    lines = [
        f"{n} {code} 2 {phys} {phys} {' '.join(map(str, nodes))}"
        for n, (code, phys, nodes) in enumerate(elements, start=1)
    ]
    return (
        "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n"
        '$PhysicalNames\n4\n0 3 "corner"\n1 1 "left"\n1 2 "right"\n2 4 "domain"\n'
        "$EndPhysicalNames\n"
        f"$Nodes\n10\n{NODES}\n10 5 5 0\n$EndNodes\n"
        f"$Elements\n{len(lines)}\n" + "\n".join(lines) + "\n$EndElements\n"
    )


@pytest.mark.parametrize("cell_type, code, cells", [("quad", 3, QUADS), ("triangle", 2, TRIANGLES)])
def test_gmsh_physical_groups(tmp_path, cell_type, code, cells):
    path = tmp_path / "square.msh"
    path.write_text(msh22(cells, code))
    m = read_mesh(str(path))
    assert m.cell_type == cell_type and m.dim == 2
    assert m.points.shape == (10, 2)  # z dropped, orphan point kept, input order kept
    assert np.array_equal(m.points[9], [5.0, 5.0])
    assert np.array_equal(m.points[4], [1.0, 1.0])
    assert m.num_cells == len(cells)
    # the clockwise cell(s) were reoriented; the area is right
    assert np.all(cell_measures(m) > 0)
    assert cell_measures(m).sum() == pytest.approx(4.0)
    assert np.array_equal(m.cell_groups["domain"], np.arange(len(cells)))
    assert m.facet_groups["left"].shape == (2, 2)
    assert np.all(m.points[m.facet_groups["left"], 0] == 0.0)
    assert np.all(m.points[m.facet_groups["right"], 0] == 2.0)
    assert np.all(m.points[m.facet_groups["5"], 1] == 2.0)  # unnamed: named by tag
    assert np.array_equal(m.node_groups["corner"], [0])


def test_mixed_volume_types_are_rejected(tmp_path):
    path = tmp_path / "mixed.msh"
    path.write_text(msh22(QUADS[:2], 3, extra=[(2, 4, [4, 5, 8]), (2, 4, [4, 8, 7])]))
    with pytest.raises(InputError, match="mixed volume cell types quad, triangle") as info:
        read_mesh(str(path))
    assert info.value.source == str(path) and info.value.key == "mesh.file"


def test_missing_and_broken_files(tmp_path, capsys):
    missing = str(tmp_path / "nope.msh")
    with pytest.raises(InputError, match="not found") as info:
        read_mesh(missing)
    assert info.value.source == missing
    broken = tmp_path / "broken.msh"
    broken.write_text("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n3\n1 0 0\n")
    with pytest.raises(InputError, match="the file ends 2 line") as info:   # ours (MSH 2.2)
        read_mesh(str(broken))
    assert (info.value.source, info.value.key) == (str(broken), "$Nodes")
    # meshio prints and calls sys.exit() for this one: still a clean InputError
    garbage = tmp_path / "garbage.vtu"
    garbage.write_text("<not xml")
    with pytest.raises(InputError, match="cannot read mesh"):
        read_mesh(str(garbage))
    assert capsys.readouterr().out == ""
    with pytest.raises(InputError, match="not a file"):
        read_mesh(str(tmp_path))
    unknown = tmp_path / "mesh.unknownformat"
    unknown.write_text("hello")
    with pytest.raises(InputError, match="cannot read mesh"):
        read_mesh(str(unknown))


@pytest.mark.parametrize(
    "make",
    [
        lambda: rectangle(2.0, 1.0, 3, 2, cell="triangle6"),
        lambda: rectangle(2.0, 1.0, 3, 2, cell="quad"),
        lambda: box(1.0, 1.0, 2.0, 2, 1, 2, cell="tetra10"),
        lambda: box(1.0, 1.0, 2.0, 2, 1, 2, cell="hexahedron"),
    ],
)
@pytest.mark.parametrize("suffix", [".vtu", ".xdmf"])
def test_vtu_and_xdmf_roundtrip(tmp_path, make, suffix):
    src = make()
    path = str(tmp_path / f"mesh{suffix}")
    meshio.write(path, meshio.Mesh(src.points, [(src.cell_type, src.cells)]))
    m = read_mesh(path)
    assert m.cell_type == src.cell_type
    assert m.points.shape == src.points.shape  # 2D points come back 2D
    assert np.allclose(m.points, src.points)
    assert np.array_equal(m.cells, src.cells)


def test_2d_mesh_must_be_flat(tmp_path):
    src = rectangle(1.0, 1.0, 2, 2, cell="triangle")
    pts = np.column_stack([src.points, src.points[:, 0]])  # z = x: not a plane z = c
    path = str(tmp_path / "tilted.vtu")
    meshio.write(path, meshio.Mesh(pts, [("triangle", src.cells)]))
    with pytest.raises(InputError, match="non-constant z"):
        read_mesh(path)
    flat = np.column_stack([src.points, np.full(src.num_points, 3.0)])
    meshio.write(path, meshio.Mesh(flat, [("triangle", src.cells)]))
    assert read_mesh(path).points.shape == (9, 2)


def test_generic_cell_and_point_sets():
    src = box(1.0, 1.0, 1.0, 1, 1, 2, cell="tetra")
    faces = src.facet_groups["zmin"]
    m = meshio.Mesh(
        src.points,
        [
            ("tetra", src.cells),
            ("triangle", faces),
            ("line", np.array([[0, 1]])),
            ("vertex", np.array([[7]])),
        ],
        cell_sets={
            "lower": [np.arange(6), None, None, None],
            "bottom": [None, np.arange(len(faces)), None, None],
            "edge": [None, None, np.array([0]), None],
            "tip": [None, None, None, np.array([0])],
        },
        point_sets={"origin": np.array([0])},
    )
    mesh = mesh_from_meshio(m, source="sets.xdmf")
    assert mesh.cell_type == "tetra" and mesh.num_cells == 12
    assert np.array_equal(mesh.cell_groups["lower"], np.arange(6))
    assert np.array_equal(mesh.facet_groups["bottom"], faces)
    assert np.array_equal(mesh.node_groups["edge"], [0, 1])  # edges in 3D -> nodes
    assert np.array_equal(mesh.node_groups["tip"], [7])
    assert np.array_equal(mesh.node_groups["origin"], [0])


def test_facet_group_of_wrong_type_is_rejected():
    src = rectangle(1.0, 1.0, 2, 2, cell="triangle6")
    m = meshio.Mesh(
        src.points,
        [("triangle6", src.cells), ("line", src.facet_groups["left"][:, :2])],
        cell_sets={"left": [None, np.arange(2)]},
    )
    with pytest.raises(InputError, match="'left' has line elements, expected .* line3 facets"):
        mesh_from_meshio(m, source="bad.vtu")


def test_unsupported_volume_type():
    m = meshio.Mesh(np.zeros((6, 3)), [("wedge", np.arange(6)[None, :])])
    with pytest.raises(InputError, match="unsupported cell type 'wedge'"):
        mesh_from_meshio(m, source="w.msh")
