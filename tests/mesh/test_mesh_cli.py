"""``parsolve mesh convert``, and scenes run from its parallel mesh file: the same results as
from the Gmsh file at every rank count, the same regions; bad input exits 2 on every rank with
one line naming the file and the key, nothing written, the input never overwritten."""

import os
from pathlib import Path

import h5py
import numpy as np
import pytest

from conftest import CONFIGS
from parsolve.cli import main
from parsolve.mesh import cli as mesh_cli
from parsolve.mesh.h5mesh import read_whole
from parsolve.mesh.reader import read_mesh
from parsolve.model import build_model
from parsolve.scene import load_scene



def scene_on(tmp: Path, name: str, mesh_file: Path, comm) -> Path:
    """configs/<name>.toml with its mesh file replaced."""
    text = (CONFIGS / f"{name}.toml").read_text()
    path = tmp / f"{name}_{mesh_file.suffix[1:]}.toml"
    if comm.rank == 0:
        path.write_text(text.replace(f'file = "{name}.msh"', f'file = "{mesh_file}"'))
    comm.Barrier()
    return path


@pytest.mark.parametrize("name", ["contact_ironing_2d", "contact_ironing_3d"])
def test_converted_file_has_the_gmsh_regions(name, comm, shared_tmp):
    out = shared_tmp / f"{name}.h5"
    assert main(["mesh", "convert", str(CONFIGS / f"{name}.msh"), str(out)]) == 0
    direct, back = read_mesh(str(CONFIGS / f"{name}.msh")), read_whole(str(out))
    assert np.array_equal(direct.points, back.points)
    assert np.array_equal(direct.cells, back.cells)
    for kind in ("cell_groups", "facet_groups", "node_groups"):
        a, b = getattr(direct, kind), getattr(back, kind)
        assert sorted(a) == sorted(b), kind
        for group in a:
            assert np.array_equal(a[group], b[group]), (kind, group)
    assert direct.cell_groups and direct.facet_groups
    with h5py.File(out, "r") as f:   # the result file's layout
        assert f["mesh/points"].shape == direct.points.shape
        assert f[f"mesh/cells/{direct.cell_type}"].shape == direct.cells.shape


def test_scene_from_the_parallel_file_runs_as_from_gmsh(comm, shared_tmp, run):
    """The 2D ironing (contact, friction, 20 steps) from the .h5 and the .msh: the same parts
    (the same partition of the same dual graph, ``test_slices``), so the same results to the
    round-off two runs of the .msh already differ by in parallel (1e-11 of the stress: the
    reductions' order), and to the last bit for the mesh, the steps and the displacement
    on one rank."""
    h5 = shared_tmp / "ironing.h5"
    assert mesh_cli.main(["convert", str(CONFIGS / "contact_ironing_2d.msh"), str(h5)]) == 0
    msh = scene_on(shared_tmp, "contact_ironing_2d", CONFIGS / "contact_ironing_2d.msh", comm)
    par = scene_on(shared_tmp, "contact_ironing_2d", h5, comm)
    a, b = run(msh, "from_msh"), run(par, "from_h5")
    assert a["attrs"]["status"] == b["attrs"]["status"] == "complete"
    compared = [k for k in a if k.startswith(("fields/", "cell_fields/", "relations/", "mesh/",
                                              "steps/"))]
    assert "fields/displacement" in compared and any(k.startswith("relations/") for k in compared)
    compared.remove("steps/residual")   # round-off both: each below the tolerance
    assert max(a["steps/residual"].max(), b["steps/residual"].max()) < 1e-9
    for key in compared:
        if key.startswith(("mesh/", "steps/iterations")) or comm.size == 1:
            np.testing.assert_array_equal(b[key], a[key], err_msg=key)
        else:
            scale = max(float(np.abs(a[key]).max(initial=0.0)), 1e-300)
            np.testing.assert_allclose(b[key], a[key], rtol=0, atol=1e-9 * scale + 1e-14,
                                       err_msg=key)
    assert np.abs(a["fields/displacement"]).max() > 1e-3


def test_regions_on_the_parts_are_the_gmsh_regions(comm, shared_tmp):
    """Every region of the 3D ironing mesh resolves to the same input nodes, facets and cells
    from the .h5 (slice path) as from the .msh (rank-0 path)."""
    h5 = shared_tmp / "ironing3d.h5"
    assert mesh_cli.main(["convert", str(CONFIGS / "contact_ironing_3d.msh"), str(h5)]) == 0
    models = [build_model(load_scene(scene_on(shared_tmp, "contact_ironing_3d", f, comm)), comm)
              for f in (CONFIGS / "contact_ironing_3d.msh", h5)]
    names = models[0].regions().names()
    assert names == models[1].regions().names() and len(names) > 4
    for name in sorted(names):
        seen = []
        for m in models:
            r, mesh = m.regions()(name, "test"), m.mesh
            own = r.nodes[r.nodes < mesh.n_owned]
            facets = np.sort(mesh.global_nodes[r.facets], axis=1) if r.facets.size else \
                np.zeros((0, 0), np.int64)
            seen.append((np.sort(mesh.global_nodes[own]), np.sort(mesh.global_cells[r.cells]),
                         facets[np.lexsort(facets.T[::-1])] if facets.size else facets))
        for x, y in zip(*seen):
            assert np.array_equal(x, y), name


def one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    return err[-1] if err else ""


def test_convert_bad_inputs_exit_2(comm, shared_tmp, capsys):
    src = shared_tmp / "in.msh"
    if comm.rank == 0:
        src.write_bytes((CONFIGS / "contact_ironing_2d.msh").read_bytes())
    comm.Barrier()
    before = src.read_bytes()
    assert mesh_cli.main(["convert", str(shared_tmp / "missing.msh"), str(shared_tmp / "m.h5")]) == 2
    if comm.rank == 0:
        assert "missing.msh: mesh.file: mesh file not found" in one_line(capsys)
    comm.Barrier()
    assert not (shared_tmp / "m.h5").exists()
    # the input as output: refused whatever the suffix, --force or not
    assert mesh_cli.main(["convert", str(src), str(src)]) == 2
    h5 = shared_tmp / "in.h5"
    assert mesh_cli.main(["convert", str(src), str(h5)]) == 0
    assert mesh_cli.main(["convert", str(h5), str(h5), "--force"]) == 2
    if comm.rank == 0:
        assert "in.h5: OUT: the output is the input" in one_line(capsys)
    assert src.read_bytes() == before
    # an existing output is kept unless --force
    stamp = os.stat(h5).st_mtime_ns
    assert mesh_cli.main(["convert", str(src), str(h5)]) == 2
    assert os.stat(h5).st_mtime_ns == stamp
    assert mesh_cli.main(["convert", str(src), str(shared_tmp / "out.vtu")]) == 2
    garbage = shared_tmp / "garbage.msh"
    if comm.rank == 0:
        garbage.write_text("not a mesh\n")
    comm.Barrier()
    assert mesh_cli.main(["convert", str(garbage), str(shared_tmp / "g.h5")]) == 2
    assert not (shared_tmp / "g.h5").exists() and not (shared_tmp / "g.h5.part").exists()


def bad_h5(path: Path, comm, edit) -> Path:
    mesh_cli.main(["convert", str(CONFIGS / "contact_ironing_2d.msh"), str(path), "--force"])
    if comm.rank == 0:
        with h5py.File(path, "a") as f:
            edit(f)
    comm.Barrier()
    return path


def _drop_points(f):
    del f["mesh/points"]


def _wrong_dim(f):
    pts = f["mesh/points"][()]
    del f["mesh/points"]
    f["mesh/points"] = np.column_stack([pts, np.zeros(len(pts))])


def _out_of_range(f):
    cells = f["mesh/cells/quad"][()]
    cells[-1, 0] = 10**6
    del f["mesh/cells/quad"]
    f["mesh/cells/quad"] = cells


def _bad_mask(f):
    del f["mesh/cell_groups/base"]
    f["mesh/cell_groups/base"] = np.ones(3, dtype=np.uint8)


@pytest.mark.parametrize("edit, words", [
    (_drop_points, "/mesh: no /mesh/points"),
    (_wrong_dim, "/mesh/points: quad cells need points of shape (npoints, 2)"),
    (_out_of_range, "mesh.file: cells refer to points that do not exist"),
    (_bad_mask, "/mesh/cell_groups/base: a mask of shape (264,) expected"),
])
def test_bad_parallel_file_exits_2_on_every_rank(edit, words, comm, shared_tmp, capsys):
    path = bad_h5(shared_tmp / f"bad_{edit.__name__}.h5", comm, edit)
    scene = scene_on(shared_tmp, "contact_ironing_2d", path, comm)
    assert main(["check", str(scene)]) == 2
    if comm.rank == 0:
        assert f"{path}: {words}" in one_line(capsys)


def test_scene_errors_with_the_parallel_file_exit_2(comm, shared_tmp, capsys):
    """Missing file, a region the file does not have, a 2D mesh under a 3D hypothesis."""
    missing = scene_on(shared_tmp, "contact_ironing_2d", shared_tmp / "none.h5", comm)
    assert main(["check", str(missing)]) == 2
    if comm.rank == 0:
        assert "none.h5: mesh.file: mesh file not found" in one_line(capsys)
    h5 = bad_h5(shared_tmp / "good.h5", comm, lambda f: None)
    scene = scene_on(shared_tmp, "contact_ironing_2d", h5, comm)
    text = scene.read_text()
    for n, (old, new, words) in enumerate([
            ('region = "die_top"', 'region = "no_such_group"', "unknown region 'no_such_group'"),
            ('hypothesis = "plane_strain"', 'hypothesis = "3d"', "a 2D mesh (quad) cannot carry")]):
        bad = shared_tmp / f"bad_scene{n}.toml"
        if comm.rank == 0:
            bad.write_text(text.replace(old, new, 1))
        comm.Barrier()
        assert main(["check", str(bad)]) == 2
        if comm.rank == 0:
            assert words in one_line(capsys)
