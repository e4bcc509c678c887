"""The Gmsh MSH 4.1 and 2.2 reader (``mesh.gmsh``, ``mesh.gmshmesh``): every rank's slices of
points, cells (oriented), cell/node/facet groups equal meshio's whole reading cut at the same rows,
for ASCII and binary files, node tags 1..N or scattered, with chunks and line marks small enough
to cut every block; a 2.2 file and its 4.1 conversion give the same mesh; ``parsolve mesh convert`` writes what
meshio's reading would; a shipped scene gives the same answers from the .msh read by slices, by
meshio on rank 0 and from the converted file, and so does every shipped .msh scene (2.2); broken files exit 2 naming the file and the
section."""

import re
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

from conftest import CONFIGS
from helpers.msh22 import write_msh22
from helpers.msh41 import blocks_of, write_msh41
from parsolve.errors import InputError
from parsolve.mesh import cli as mesh_cli
from parsolve.mesh import gmsh, gmshmesh
from parsolve.mesh.generators import box, rectangle
from parsolve.mesh.gmshmesh import open_gmsh
from parsolve.mesh.h5mesh import read_whole
from parsolve.mesh.partition import block_starts
from parsolve.mesh.reader import mesh_from_meshio
from parsolve.model import build_model
from parsolve.scene import load_scene


def shipped(name: str):
    m = meshio.read(CONFIGS / f"{name}.msh")
    names = {(int(v[1]), int(v[0])): k for k, v in m.field_data.items()}
    return m.points, blocks_of(m), names


def tets():
    """tetra10 cells in two entities (the second with an unnamed first tag and a named
    second one), facets with a named and an unnamed group, an edge and a corner (node
    groups)."""
    m = box(2.0, 1.0, 1.0, 3, 2, 2, "tetra10")
    half = m.num_cells // 2
    xmin, zmax = m.facet_groups["xmin"], m.facet_groups["zmax"]
    blocks = [("tetra10", m.cells[:half], [1]), ("triangle6", xmin, [3]),
              ("tetra10", m.cells[half:], [5, 2]), ("triangle6", zmax, [4]),
              ("line3", np.array([[0, 2, 1]]), [7]), ("vertex", np.array([[0]]), [8])]
    names = {(3, 1): "left", (3, 2): "right", (2, 3): "xmin", (1, 7): "edge", (0, 8): "corner"}
    return m.points, blocks, names


def flipped():
    """Triangles, every other one clockwise (oriented on reading), two line facet groups."""
    m = rectangle(2.0, 1.0, 4, 3, "triangle")
    cells = m.cells.copy()
    cells[::2] = cells[::2, ::-1]
    blocks = [("triangle", cells, [1]), ("line", m.facet_groups["left"], [2]),
              ("line", m.facet_groups["top"], [3])]
    return m.points, blocks, {(2, 1): "plate", (1, 2): "left"}


MESHES = {"ironing_2d": lambda: shipped("contact_ironing_2d"),
          "ironing_3d": lambda: shipped("contact_ironing_3d"),
          "cylinder_p2": lambda: shipped("thick_cylinder_p2"), "tets": tets, "flipped": flipped}


def written(comm, tmp: Path, name: str, binary: bool, scattered: bool,
            version: str = "4.1") -> Path:
    path = tmp / (f"{name}_{'bin' if binary else 'ascii'}{'_scattered' if scattered else ''}"
                  f"_{version}.msh")
    if comm.rank == 0:
        points, blocks, names = MESHES[name]()
        tags = None   # scattered: a permutation of every third number from 7
        if scattered:
            tags = np.random.default_rng(1).permutation(len(points)) * 3 + 7
        if version == "2.2":
            write_msh22(path, points, blocks, names, binary, node_tags=tags)
        else:
            write_msh41(path, points, blocks, names, binary, node_tags=tags, node_blocks=3)
    comm.Barrier()
    return path


def meshio_mesh(path: Path):
    return mesh_from_meshio(meshio.read(path), str(path))


def reference(comm, tmp: Path, name: str, binary: bool, scattered: bool, version: str):
    """meshio's reading of the file (of its ASCII twin for a binary 2.2 file with scattered
    tags: meshio refuses those)."""
    return meshio_mesh(written(comm, tmp, name, binary and not (scattered and version == "2.2"),
                               scattered, version))


@pytest.mark.parametrize("version", ["4.1", "2.2"])
@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("scattered", [False, True])
@pytest.mark.parametrize("name", sorted(MESHES))
def test_slices_are_meshio_reading_cut(name, binary, scattered, version, comm, shared_tmp):
    path = written(comm, shared_tmp, name, binary, scattered, version)
    assert_cut(comm, path, reference(comm, shared_tmp, name, binary, scattered, version))


@pytest.mark.parametrize("version", ["4.1", "2.2"])
@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("name", ["tets", "ironing_3d"])
def test_small_chunks_and_marks(name, binary, version, comm, shared_tmp, monkeypatch):
    """Lines marked every 5th and files read 300 bytes at a time: every block and slice starts
    between marks, runs of MSH 2 elements span chunks."""
    path = written(comm, shared_tmp, name, binary, True, version)
    ref = reference(comm, shared_tmp, name, binary, True, version)
    monkeypatch.setattr(gmsh, "MARK", 5)
    monkeypatch.setattr(gmsh, "CHUNK", 300)
    assert_cut(comm, path, ref)


def assert_cut(comm, path: Path, ref) -> None:
    """This rank's slices of ``path`` are ``ref`` (the whole mesh) cut at its rows."""
    src = open_gmsh(comm, str(path))
    size, rank = comm.size, comm.rank
    cs, ps = block_starts(ref.num_cells, size), block_starts(ref.num_points, size)
    c0, c1, p0, p1 = int(cs[rank]), int(cs[rank + 1]), int(ps[rank]), int(ps[rank + 1])
    assert (src.cell_type, src.num_cells, src.num_points) == (ref.cell_type, ref.num_cells,
                                                               ref.num_points)
    np.testing.assert_array_equal(src.cells(c0, c1), ref.cells[c0:c1])
    np.testing.assert_array_equal(src.points(p0, p1), ref.points[p0:p1])
    assert src.cell_groups == tuple(sorted(ref.cell_groups))
    assert src.node_groups == tuple(sorted(ref.node_groups))
    assert src.facet_groups == tuple(sorted(ref.facet_groups))
    flags = src.cell_flags(c0, c1)
    for k, group in enumerate(src.cell_groups):
        np.testing.assert_array_equal(np.flatnonzero(flags[:, k]) + c0,
                                      ref.cell_groups[group][(ref.cell_groups[group] >= c0)
                                                             & (ref.cell_groups[group] < c1)])
    flags = src.node_flags(p0, p1)
    for k, group in enumerate(src.node_groups):
        ids = ref.node_groups[group]
        np.testing.assert_array_equal(np.flatnonzero(flags[:, k]) + p0,
                                      ids[(ids >= p0) & (ids < p1)])
    for group in src.facet_groups:
        facets, rows = src.facet_slice(group, rank, size)
        whole = ref.facet_groups[group]
        # the ranks' rows, in rank order, number the group's rows once each in order
        np.testing.assert_array_equal(np.concatenate(comm.allgather(rows)),
                                      np.arange(len(whole)))
        np.testing.assert_array_equal(facets, whole[rows])


def test_the_meshes_have_what_is_tested(comm, shared_tmp):
    """The cases above cover groups of each kind, a flipped cell, an unnamed tag; the 2.2
    layouts have runs of several physical tags in one binary block and tag counts that vary."""
    ref = meshio_mesh(written(comm, shared_tmp, "tets", True, False))
    assert sorted(ref.cell_groups) == ["5", "left", "right"]
    assert sorted(ref.facet_groups) == ["4", "xmin"] and sorted(ref.node_groups) == ["corner",
                                                                                     "edge"]
    raw = meshio.read(written(comm, shared_tmp, "flipped", False, False))
    assert not np.array_equal(raw.cells[0].data, meshio_mesh(
        shared_tmp / "flipped_ascii_4.1.msh").cells)
    ref = meshio_mesh(written(comm, shared_tmp, "tets", True, False, "2.2"))
    assert sorted(ref.cell_groups) == ["5", "left"] and sorted(ref.facet_groups) == ["4", "xmin"]
    lay = gmsh.scan(written(comm, shared_tmp, "ironing_3d", True, False, "2.2"))
    # 2 binary blocks (hexahedra, quads) of 14 physical tags in all: a block each
    assert [kind for _, _, kind, _ in lay.element_blocks] == ["hexahedron", "quad"]
    assert sum(len(tags) for tags in lay.row_tags.values()) == 14
    lay = gmsh.scan(written(comm, shared_tmp, "tets", False, False, "2.2"))
    assert sorted({rows.lead for *_, rows in lay.element_blocks}) == [5, 6]   # 2 or 3 tags


@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("cell", ["tetra", "tetra10", "triangle", "triangle6"])
def test_msh41_as_meshio_writes_it(cell, binary, comm, shared_tmp):
    """MSH 4.1 (Gmsh's default format) written by meshio, linear and quadratic: the slices are
    meshio's reading cut, the converted file is meshio's reading."""
    path = shared_tmp / f"meshio41_{cell}_{int(binary)}.msh"
    if comm.rank == 0:
        m = (box(2.0, 1.0, 1.0, 3, 2, 2, cell) if cell.startswith("tetra")
             else rectangle(2.0, 1.0, 4, 3, cell))
        meshio.write(path, meshio.Mesh(m.points, [(cell, m.cells)]), file_format="gmsh",
                     binary=binary)
    comm.Barrier()
    assert gmsh.version_of(str(path)) == "4.1"
    ref = meshio_mesh(path)
    assert_cut(comm, path, ref)
    out = shared_tmp / f"{path.stem}.h5"
    assert mesh_cli.main(["convert", str(path), str(out), "--force"]) == 0
    assert_same_mesh(read_whole(str(out)), ref)


def alternating(comm, tmp: Path, binary: bool) -> Path:
    """MSH 2.2 as meshio writes it, every element's physical tag alternating: cells of "left"
    (1) and "right" (2), facets of "xmin" (3) and of an unnamed tag (4)."""
    path = tmp / f"alternating_{int(binary)}.msh"
    if comm.rank == 0:
        m = box(2.0, 1.0, 1.0, 3, 2, 2, "tetra10")
        xmin = m.facet_groups["xmin"]
        phys = [np.arange(m.num_cells) % 2 + 1, np.arange(len(xmin)) % 2 + 3]
        meshio.write(path, meshio.Mesh(
            m.points, [("tetra10", m.cells), ("triangle6", xmin)],
            cell_data={"gmsh:physical": phys, "gmsh:geometrical": phys},
            field_data={"left": np.array([1, 3]), "right": np.array([2, 3]),
                        "xmin": np.array([3, 2])}), file_format="gmsh22", binary=binary)
    comm.Barrier()
    return path


@pytest.mark.parametrize("binary", [False, True])
def test_alternating_tags_are_few_blocks(binary, comm, shared_tmp):
    """Elements alternating physical tags: a block per (type, tag count) with its rows' tags
    counted, not a block per element; the slices, the whole mesh and the converted file are
    meshio's reading (cells in the file's order, groups by tag)."""
    path = alternating(comm, shared_tmp, binary)
    lay = gmsh.scan(str(path))
    assert [kind for _, _, kind, _ in lay.element_blocks] == ["tetra10", "triangle6"]
    assert lay.row_tags == {0: {1: 36, 2: 36}, 1: {3: 4, 4: 4}}
    ref = meshio_mesh(path)
    np.testing.assert_array_equal(ref.cell_groups["left"], np.arange(0, 72, 2))
    assert sorted(ref.facet_groups) == ["4", "xmin"] and len(ref.facet_groups["xmin"]) == 4
    assert_cut(comm, path, ref)
    assert_same_mesh(gmshmesh.read_whole(str(path)), ref)
    out = shared_tmp / f"{path.stem}.h5"
    assert mesh_cli.main(["convert", str(path), str(out), "--force"]) == 0
    assert_same_mesh(read_whole(str(out)), ref)


@pytest.mark.parametrize("version", ["4.1", "2.2"])
@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("name", ["tets", "ironing_3d", "flipped"])
def test_convert_writes_what_meshio_reads(name, binary, version, comm, shared_tmp):
    path = written(comm, shared_tmp, name, binary, binary, version)
    out = shared_tmp / f"{path.stem}.h5"
    assert mesh_cli.main(["convert", str(path), str(out), "--force"]) == 0
    assert_same_mesh(read_whole(str(out)),
                     reference(comm, shared_tmp, name, binary, binary, version))


def assert_same_mesh(got, ref) -> None:
    assert (got.cell_type, got.dim) == (ref.cell_type, ref.dim)
    np.testing.assert_array_equal(got.points, ref.points)
    np.testing.assert_array_equal(got.cells, ref.cells)
    for kind in ("cell_groups", "facet_groups", "node_groups"):
        a, b = getattr(ref, kind), getattr(got, kind)
        assert sorted(a) == sorted(b), kind
        for group in a:
            np.testing.assert_array_equal(b[group], a[group], err_msg=f"{kind} {group}")


@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("name", ["contact_ironing_2d", "contact_ironing_3d",
                                  "thick_cylinder_p2"])
def test_shipped_msh22_and_its_41_conversion_same_mesh(name, binary, comm, shared_tmp):
    """A shipped MSH 2.2 file (ASCII as shipped, or rewritten binary) and the same mesh written
    as MSH 4.1 (one entity per physical group): the same points, cells and regions, whole, by
    slices and converted."""
    m = meshio.read(CONFIGS / f"{name}.msh")
    names = {(int(v[1]), int(v[0])): k for k, v in m.field_data.items()}
    v41, v22 = (shared_tmp / f"{name}_{int(binary)}_{v}.msh" for v in ("41", "22"))
    if comm.rank == 0:
        write_msh41(v41, m.points, blocks_of(m), names, binary)
        if binary:
            write_msh22(v22, m.points, blocks_of(m), names, binary)
        else:
            v22.write_bytes((CONFIGS / f"{name}.msh").read_bytes())
    comm.Barrier()
    assert gmsh.version_of(str(v22)) == "2.2" and gmsh.version_of(str(v41)) == "4.1"
    whole = gmshmesh.read_whole(str(v22))
    assert whole.cell_groups and whole.facet_groups
    assert_same_mesh(whole, gmshmesh.read_whole(str(v41)))
    assert_cut(comm, v41, whole)
    assert_cut(comm, v22, whole)
    out = shared_tmp / f"{name}_{int(binary)}_22.h5"
    assert mesh_cli.main(["convert", str(v22), str(out), "--force"]) == 0
    assert_same_mesh(read_whole(str(out)), whole)


def scene_with(tmp: Path, mesh_file: Path, tag: str, comm) -> Path:
    text = (CONFIGS / "contact_ironing_2d.toml").read_text()
    path = tmp / f"ironing_{tag}.toml"
    if comm.rank == 0:
        path.write_text(text.replace('file = "contact_ironing_2d.msh"', f'file = "{mesh_file}"'))
    comm.Barrier()
    return path


def test_shipped_scene_same_answers_by_slices_meshio_and_converted(comm, shared_tmp, run,
                                                                     monkeypatch):
    """The 2D ironing from its MSH 4.1 file read by slices, the same file read by meshio on
    rank 0, and its converted .h5: the mesh, steps and iterations to the bit; the fields to the
    bit on one rank, to round-off on several (the reductions' order)."""
    msh = written(comm, shared_tmp, "ironing_2d", True, True)
    h5 = shared_tmp / "ironing41.h5"
    assert mesh_cli.main(["convert", str(msh), str(h5), "--force"]) == 0
    sliced = run(scene_with(shared_tmp, msh, "msh", comm), "sliced")
    converted = run(scene_with(shared_tmp, h5, "h5", comm), "converted")
    monkeypatch.setattr(gmsh, "ours", lambda path: False)   # meshio, whole on rank 0
    whole = run(scene_with(shared_tmp, msh, "msh", comm), "meshio")
    assert_same_results(comm, sliced, converted, whole)


# the shipped scenes on .msh files (MSH 2.2); the 3D ironing's first 6 steps (press, drag starts)
SHIPPED = {"contact_ironing_2d": "contact_ironing_2d.msh",
           "contact_ironing_3d": "contact_ironing_3d.msh",
           "thick_cylinder_pressure": "thick_cylinder_p2.msh"}


@pytest.mark.parametrize("scene", sorted(SHIPPED))
def test_shipped_msh_scenes_same_answers_by_slices_and_meshio(scene, comm, shared_tmp, run,
                                                              monkeypatch):
    """Each shipped scene on a .msh file: read by slices (every rank its rows) and read whole
    by meshio on rank 0 (the former path): the same answers, fields in the input's order."""
    text = (CONFIGS / f"{scene}.toml").read_text()
    text = text.replace(f'file = "{SHIPPED[scene]}"', f'file = "{CONFIGS / SHIPPED[scene]}"')
    text = re.sub(r"(?m)^times = \[0\.05, .*$", "times = [0.05, 0.1, 0.15, 0.2, 0.2125, 0.225]",
                  text)
    assert str(CONFIGS / SHIPPED[scene]) in text
    sliced = run(text, f"{scene}_sliced")
    monkeypatch.setattr(gmsh, "ours", lambda path: False)
    whole = run(text, f"{scene}_meshio")
    assert_same_results(comm, sliced, whole)


def assert_same_results(comm, sliced: dict, *others: dict) -> None:
    """The mesh, steps and iterations to the bit; the fields to the bit on one rank, to
    round-off on several (the reductions' order; a resultant that is round-off itself, such as
    a fixed die's, against the largest resultant)."""
    assert sliced["attrs"]["status"] == "complete"
    keys = [k for k in sliced if k.startswith(("fields/", "cell_fields/", "relations/",
                                               "mesh/", "steps/")) and k != "steps/residual"]
    assert "fields/displacement" in keys and np.abs(sliced["fields/displacement"]).max() > 1e-5
    forces = max([float(np.abs(sliced[k]).max()) for k in keys if k.endswith("/resultant")],
                 default=0.0)
    for other in others:
        assert sorted(k for k in other if k in keys) == sorted(keys)
        for key in keys:
            if key.startswith(("mesh/", "steps/iterations")) or comm.size == 1:
                np.testing.assert_array_equal(other[key], sliced[key], err_msg=key)
            else:
                scale = max(float(np.abs(sliced[key]).max(initial=0.0)), 1e-300,
                            forces if key.endswith("/resultant") else 0.0)
                np.testing.assert_allclose(other[key], sliced[key], rtol=0,
                                           atol=1e-9 * scale + 1e-14, err_msg=key)


def broken(comm, tmp: Path, how: str, binary: bool, version: str = "4.1") -> Path:
    src = written(comm, tmp, "tets", binary, False, version)
    path = tmp / f"broken_{how}_{int(binary)}_{version}.msh"
    if comm.rank == 0:
        data = src.read_bytes()
        if how == "truncated":
            data = data[:data.index(b"$Elements") + (len(data) - data.index(b"$Elements")) // 2]
        elif how == "version":
            data = data.replace(f"{version} ".encode(), b"5.0 ", 1)
        else:   # no $Nodes section
            data = data[:data.index(b"\n$Nodes\n") + 1] + data[data.index(b"$EndNodes\n") + 10:]
        path.write_bytes(data)
    comm.Barrier()
    return path


SECTION = {"truncated": "$Elements", "version": "$MeshFormat", "missing": "$Nodes"}


@pytest.mark.parametrize("version", ["4.1", "2.2"])
@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("how", sorted(SECTION))
def test_broken_files_exit_2_naming_file_and_section(how, binary, version, comm, shared_tmp,
                                                     capsys):
    path = broken(comm, shared_tmp, how, binary, version)
    out = shared_tmp / f"{path.stem}.h5"
    assert mesh_cli.main(["convert", str(path), str(out)]) == 2
    if comm.rank == 0:
        line = capsys.readouterr().err.strip().splitlines()[-1]
        assert f"{path}: {SECTION[how]}: " in line, line
    comm.Barrier()
    assert not out.exists() and not out.with_name(out.name + ".part").exists()
    scene = load_scene(scene_with(shared_tmp, path, f"{how}_{int(binary)}", comm))
    with pytest.raises(InputError) as err:   # the run: every rank the same one-line error
        build_model(scene, comm)
    assert (err.value.source, err.value.key) == (str(path), SECTION[how])


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__]))
