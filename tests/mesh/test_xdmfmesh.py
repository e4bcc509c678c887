"""XDMF + HDF5 meshes read by slices (``mesh.xdmfmesh``): the mesh meshio's reading of the same
file gives (cells, points in input order, orientation, cell tags as groups), DOLFINx's mesh
tags as cell and facet groups, and the same answers as the parallel mesh file."""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.errors import InputError
from parsolve.mesh import slices
from parsolve.mesh.generators import box, rectangle
from parsolve.mesh.h5mesh import write_mesh
from parsolve.mesh.reader import read_mesh
from parsolve.mesh.topology import FACETS
from parsolve.mesh.regions import allgather_rows
from parsolve.mesh.xdmfmesh import open_xdmf


def _tagged_box():
    """A 4 × 3 × 5 box of tetrahedra, tag 1 for x < 0.5, 2 beyond; every 7th cell's nodes
    given clockwise (meshio's reading orients them)."""
    whole = box(1.0, 1.0, 1.0, 4, 3, 5, cell="tetra")
    cells = whole.cells.copy()
    cells[::7, [1, 2]] = cells[::7, [2, 1]]
    tags = np.where(whole.points[whole.cells].mean(axis=1)[:, 0] < 0.5, 1, 2)
    return whole.points, cells, tags


def _tagged_square():
    """A 6 × 4 square of triangles, its points with z = 0 (meshio writes XYZ), tags 3 and 5."""
    whole = rectangle(1.5, 1.0, 6, 4, cell="triangle")
    points = np.column_stack([whole.points, np.zeros(whole.num_points)])
    tags = np.where(whole.points[whole.cells].mean(axis=1)[:, 1] < 0.5, 3, 5)
    return points, whole.cells, tags


MESHES = {"tetra": ("tetra", _tagged_box), "triangle": ("triangle", _tagged_square)}


def _write_meshio(comm, tmp: Path, name: str) -> Path:
    import meshio

    cell_type, make = MESHES[name]
    points, cells, tags = make()
    path = tmp / f"{name}.xdmf"
    if comm.rank == 0:
        meshio.write(str(path), meshio.Mesh(points, [(cell_type, cells)],
                                            cell_data={"gmsh:physical": [tags]}))
    comm.Barrier()
    return path


def _gathered(comm, local):
    """The whole mesh from every rank's part: points by input id, cells (input node ids) by
    input id, each cell group's input ids."""
    n_owned = local.n_owned
    pts = allgather_rows(comm, np.column_stack([local.global_nodes[:n_owned].astype(float),
                                                local.points[:n_owned]]))
    points = np.empty((local.num_global_points, local.dim))
    points[pts[:, 0].astype(np.int64)] = pts[:, 1:]
    rows = allgather_rows(comm, np.column_stack([local.global_cells.astype(np.int64),
                                                 local.global_nodes[local.cells]]))
    cells = np.empty((local.num_global_cells, local.cells.shape[1]), np.int64)
    cells[rows[:, 0]] = rows[:, 1:]
    groups = {name: np.unique(np.concatenate(comm.allgather(
        local.global_cells[ids].astype(np.int64)))) for name, ids in local.cell_groups.items()}
    return points, cells, groups


@pytest.mark.parametrize("name", sorted(MESHES))
def test_slices_read_the_mesh_meshio_reads(name, comm, shared_tmp):
    """Every rank's part from the XDMF slices, gathered: meshio's reading of the same file
    (``reader.read_mesh``) point for point and cell for cell in input order, the clockwise
    cells oriented alike, the cell tags the same groups."""
    path = _write_meshio(comm, shared_tmp, name)
    whole = read_mesh(str(path))
    src = open_xdmf(comm, str(path))
    assert (src.num_cells, src.num_points, src.cell_type) == (whole.num_cells,
                                                               whole.num_points, MESHES[name][0])
    local = slices.distribute_slices(comm, src, "scotch", str(path), "mesh.file")
    points, cells, groups = _gathered(comm, local)
    assert np.array_equal(points, whole.points)
    assert np.array_equal(cells, whole.cells)
    assert sorted(groups) == sorted(whole.cell_groups) and len(groups) == 2
    for group, ids in whole.cell_groups.items():
        assert np.array_equal(groups[group], ids)


def _write_dolfinx(comm, tmp: Path) -> tuple[Path, np.ndarray, np.ndarray]:
    """A DOLFINx-style file (grids "mesh", "cell_tags", "facet_tags") of a 3 × 2 × 2 box:
    cells 5, 9 and 30 tagged 4 (their nodes given in another order), 7 tagged 6; the facets of
    the x = 0 side tagged 1, in reverse order. Returns the path, the tagged cells of 4 and the
    facets of 1."""
    import h5py

    whole = box(1.0, 1.0, 1.0, 3, 2, 2, cell="tetra")
    tagged = np.array([5, 9, 30, 7])
    values = np.array([4, 4, 4, 6])
    left = np.flatnonzero(np.isclose(whole.points[:, 0], 0.0))
    faces = np.concatenate([whole.cells[:, list(f)] for f in FACETS["tetra"]])
    facets = faces[np.isin(faces, left).all(axis=1)][::-1]
    path, data = tmp / "dolfinx.xdmf", tmp / "dolfinx.h5"
    if comm.rank == 0:
        with h5py.File(data, "w") as f:
            f["Mesh/mesh/geometry"] = whole.points
            f["Mesh/mesh/topology"] = whole.cells
            f["MeshTags/cell_tags/topology"] = whole.cells[tagged][:, [2, 0, 3, 1]]
            f["MeshTags/cell_tags/Values"] = values.astype(np.int32)
            f["MeshTags/facet_tags/topology"] = facets
            f["MeshTags/facet_tags/Values"] = np.ones(len(facets), np.int32)

        def item(where, shape, kind="Int"):
            return (f'<DataItem Dimensions="{" ".join(map(str, shape))}" NumberType="{kind}" '
                    f'Format="HDF">dolfinx.h5:/{where}</DataItem>')

        def tags(name, kind, top):
            return (f'<Grid Name="{name}" GridType="Uniform">'
                    '<xi:include xpointer="xpointer(/Xdmf/Domain/Grid[@GridType=\'Uniform\'][1]'
                    '/Geometry)" />'
                    f'<Topology TopologyType="{kind}" NumberOfElements="{len(top)}" '
                    f'NodesPerElement="{top.shape[1]}">'
                    + item(f"MeshTags/{name}/topology", top.shape) + "</Topology>"
                    f'<Attribute Name="{name}" AttributeType="Scalar" Center="Cell">'
                    + item(f"MeshTags/{name}/Values", (len(top),)) + "</Attribute></Grid>")

        path.write_text(
            '<?xml version="1.0"?><Xdmf Version="3.0" '
            'xmlns:xi="http://www.w3.org/2001/XInclude"><Domain>'
            '<Grid Name="mesh" GridType="Uniform"><Topology TopologyType="Tetrahedron" '
            f'NumberOfElements="{whole.num_cells}" NodesPerElement="4">'
            + item("Mesh/mesh/topology", whole.cells.shape) + '</Topology>'
            '<Geometry GeometryType="XYZ">'
            + item("Mesh/mesh/geometry", whole.points.shape, "Float") + "</Geometry></Grid>"
            + tags("cell_tags", "Tetrahedron", whole.cells[tagged])
            + tags("facet_tags", "Triangle", facets) + "</Domain></Xdmf>")
    comm.Barrier()
    return path, tagged[:3], facets


def test_dolfinx_mesh_tags_are_groups(comm, shared_tmp):
    """DOLFINx's cell tags (cells given by their nodes, in any order) are the cell groups of
    the cells they name; its facet tags the facet groups, each facet on the ranks owning one
    of its nodes, the whole group the tagged facets."""
    path, four, facets = _write_dolfinx(comm, shared_tmp)
    src = open_xdmf(comm, str(path))
    assert src.cell_groups == ("4", "6") and src.facet_groups == ("1",)
    local = slices.distribute_slices(comm, src, "scotch", str(path), "mesh.file")
    _, _, groups = _gathered(comm, local)
    assert np.array_equal(groups["4"], four) and np.array_equal(groups["6"], [7])
    mine = local.global_nodes[local.facet_groups["1"]].astype(np.int64)
    got = np.unique(np.concatenate(comm.allgather(np.sort(mine, axis=1))), axis=0)
    assert len(facets) == 8   # (the 2 × 2 squares of the side, 2 triangles each)
    assert np.array_equal(got, np.unique(np.sort(facets, axis=1), axis=0))


def test_files_the_slices_cannot_read_go_to_rank_0(comm, shared_tmp):
    """A "Mixed" topology (meshio's file of tetrahedra and triangles) is left to meshio on
    rank 0 (None); a missing HDF5 file is an input error on every rank."""
    import meshio

    whole = box(1.0, 1.0, 1.0, 2, 2, 2, cell="tetra")
    mixed, lost = shared_tmp / "mixed.xdmf", shared_tmp / "lost.xdmf"
    if comm.rank == 0:
        meshio.write(str(mixed), meshio.Mesh(whole.points, [("tetra", whole.cells),
                                                            ("triangle", whole.cells[:3, :3])]))
        meshio.write(str(lost), meshio.Mesh(whole.points, [("tetra", whole.cells)]))
        lost.with_suffix(".h5").rename(shared_tmp / "elsewhere.h5")
    comm.Barrier()
    assert open_xdmf(comm, str(mixed)) is None
    with pytest.raises(InputError, match="cannot read the mesh's HDF5 file"):
        open_xdmf(comm, str(lost))


@pytest.mark.parametrize("bad", [-1, 27])
def test_cells_beyond_the_points_are_an_input_error(comm, shared_tmp, bad):
    """A cell naming a point the geometry does not have (the 2 × 2 × 2 box has 27: id 27, or
    -1) is an input error on every rank, raised before any rank asks for its coordinates."""
    import h5py
    import meshio

    whole = box(1.0, 1.0, 1.0, 2, 2, 2, cell="tetra")
    path = shared_tmp / f"beyond{bad}.xdmf"
    if comm.rank == 0:
        meshio.write(str(path), meshio.Mesh(whole.points, [("tetra", whole.cells)]))
        with h5py.File(path.with_suffix(".h5"), "r+") as f:
            topology = [k for k in f if f[k].ndim == 2 and f[k].dtype.kind in "iu"]
            assert len(topology) == 1 and whole.num_points == 27
            f[topology[0]][whole.num_cells - 1, 2] = bad   # (the last rank's slice)
    comm.Barrier()
    with pytest.raises(InputError, match="cells refer to points that do not exist"):
        open_xdmf(comm, str(path))


SCENE = """
[mesh]
file = "{file}"

[model]
hypothesis = "3d"

[regions]
left = "x == 0"
right = "x == 1"

[[materials]]
E = 1000.0
nu = 0.3

[[loads]]
name = "pull"
region = "right"
total_force = [0.0, 0.0, -1.0]

[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x", "y", "z"]
"""


def test_scene_from_xdmf_is_the_parallel_files(comm, run, shared_tmp):
    """A clamped box pulled at its end from the XDMF file and from its parallel mesh file
    (meshio's reading converted): the same mesh, displacements and reaction."""
    path = _write_meshio(comm, shared_tmp, "tetra")
    h5 = shared_tmp / "tetra_parallel.h5"   # (tetra.h5 holds the XDMF's data)
    if comm.rank == 0:
        write_mesh(read_mesh(str(path)), str(h5))
    comm.Barrier()
    a = run(SCENE.format(file=path), "from_xdmf")
    b = run(SCENE.format(file=h5), "from_h5")
    for key in ("mesh/points", "mesh/cells/tetra"):
        assert np.array_equal(a[key], b[key])
    u, w = a["fields/displacement"], b["fields/displacement"]
    assert np.abs(w).max() > 1e-3
    np.testing.assert_allclose(u, w, rtol=0, atol=1e-12 * np.abs(w).max())
    np.testing.assert_allclose(a["relations/clamp/resultant"][0, :3], [0.0, 0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(a["relations/clamp/resultant"], b["relations/clamp/resultant"],
                               rtol=0, atol=1e-12)
