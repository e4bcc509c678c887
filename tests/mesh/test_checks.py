"""Mesh checks: cells by hand for every cell type (valid, inverted, bow-tie/folded, collapsed),
non-finite coordinates, unused and duplicate points, and the memory estimate."""

import time

import numpy as np
import pytest

from mpi4py import MPI

from parsolve.errors import InputError
from parsolve.fem.elements import element
from parsolve.mesh import blocks, memory
from parsolve.mesh.checks import check_mesh, duplicate_points
from parsolve.mesh.mesh import Mesh
from parsolve.mesh.topology import FLIP
from helpers.cells import reference_cell

TYPES = ["triangle", "triangle6", "quad", "tetra", "tetra10", "hexahedron"]


def checked(mesh: Mesh) -> list[str]:
    """Every check of a run in one process: coordinates and warnings, then the cells (by
    blocks: one block here; tests/mesh/test_blocks.py has them at any rank count)."""
    warnings = check_mesh(mesh, "m.msh", "mesh.file")
    blocks.check_cells(MPI.COMM_SELF, mesh, "m.msh", "mesh.file", graph=False)
    return warnings


def raises(mesh: Mesh, words: str) -> str:
    with pytest.raises(InputError, match=words) as info:
        checked(mesh)
    assert info.value.source == "m.msh" and info.value.key == "mesh.file"
    return info.value.message


@pytest.mark.parametrize("cell_type", TYPES)
def test_valid_cell(cell_type):
    assert checked(reference_cell(cell_type)) == []


@pytest.mark.parametrize("cell_type", TYPES)
def test_inverted_cell(cell_type):
    m = reference_cell(cell_type)
    m.cells = m.cells[:, FLIP[cell_type]]
    msg = raises(m, "1 invalid")
    assert f"cells 0; cell 0 is inverted" in msg


@pytest.mark.parametrize("cell_type", TYPES)
def test_collapsed_cell(cell_type):
    m = reference_cell(cell_type)
    m.points[:, -1] = 0.0  # flattened onto a line / a plane
    raises(m, "cell 0 is collapsed")


@pytest.mark.parametrize("cell_type", ["quad", "hexahedron", "triangle6", "tetra10"])
def test_bow_tie_or_folded_cell(cell_type):
    m = reference_cell(cell_type)
    if cell_type == "quad":        # swap two corners: a bow-tie
        m.cells = m.cells[:, [0, 1, 3, 2]]
    elif cell_type == "hexahedron":  # the top face twisted into a bow-tie
        m.cells = m.cells[:, [0, 1, 2, 3, 4, 5, 7, 6]]
    else:                          # a midside node pushed beyond the opposite side
        m.points[3] = m.points[2] + 0.3 * (m.points[2] - m.points[3]) * 4
    raises(m, "folded or bow-tie|degenerate")


@pytest.mark.parametrize("cell_type", ["triangle", "quad", "tetra", "hexahedron"])
def test_cell_folded_over_its_neighbour(cell_type):
    """Two positively oriented cells on the same side of their shared facet overlap."""
    a = reference_cell(cell_type)
    n = a.num_points
    # the second cell: the first one mirrored through its facet 0's plane would be valid;
    # a copy shifted a little along that facet overlaps instead
    pts = np.vstack([a.points, a.points + 0.0])
    second = np.arange(n, 2 * n)
    facet = {"triangle": [0, 1], "quad": [0, 1], "tetra": [0, 1, 2], "hexahedron": [0, 1, 2, 3]}
    second[facet[cell_type]] = facet[cell_type]  # share the facet's nodes
    pts[n:] += 0.1 * np.eye(pts.shape[1])[-1]    # lift the free nodes: same side, overlapping
    m = Mesh(pts, cell_type, np.vstack([a.cells[0], second]))
    used = np.unique(m.cells)
    m.points = m.points  # unused copies of the shared nodes stay: a warning, not the error
    raises(m, "2 cells overlap a neighbour")
    assert used.size < m.num_points


def test_many_bad_cells_named_first_few():
    from parsolve.mesh.generators import rectangle

    m = rectangle(1.0, 1.0, 4, 4, "quad")
    bad = [3, 5, 8, 9, 11, 14]
    m.cells[bad] = m.cells[bad][:, [0, 1, 3, 2]]
    msg = raises(m, "6 invalid quad cell")
    assert "cells 3, 5, 8, 9, 11, ... (6 in all)" in msg


def test_non_finite_coordinates():
    m = reference_cell("quad")
    m.points[2, 1] = np.nan
    raises(m, r"non-finite coordinates \(NaN or inf\): points 2")
    m.points[2, 1] = 1e300
    raises(m, "absurd coordinates")


def test_unused_points_are_a_warning():
    m = reference_cell("triangle")
    m.points = np.vstack([m.points, [[3.0, 3.0], [4.0, 4.0]]])
    assert m.unused_points().tolist() == [3, 4]
    assert checked(m) == [
        "2 point(s) are used by no cell (points 3, 4): they are left out of the system"]


def test_duplicate_points_crack_is_a_warning():
    """Two triangles that touch along an edge through distinct nodes: a crack."""
    pts = np.array([[0, 0], [1, 0], [0, 1], [1, 0], [1, 1], [0, 1]], float)
    m = Mesh(pts, "triangle", np.array([[0, 1, 2], [3, 4, 5]]))
    assert duplicate_points(m).tolist() == [[1, 3], [2, 5]]
    (warning,) = checked(m)
    assert warning.startswith("2 point(s) duplicate another (first: points 1 and 3 at (1, 0))")


def test_generator_counts_match_the_generated_meshes():
    from parsolve.mesh.generators import GENERATORS

    cases = [("rectangle", dict(lx=1, ly=1, nx=7, ny=5, cell="quad")),
             ("rectangle", dict(lx=1, ly=1, nx=7, ny=5, cell="triangle6")),
             ("box", dict(lx=1, ly=1, lz=1, nx=3, ny=4, nz=2, cell="tetra10")),
             ("box", dict(lx=1, ly=1, lz=1, nx=3, ny=4, nz=2)),
             ("plate_with_hole", dict(width=5, height=5, radius=1, n_radial=4, n_angular=6, cell="triangle"))]
    for name, params in cases:
        m = GENERATORS[name](**params)
        assert memory.cell_counts(name, params) == (m.num_points, m.num_cells, m.dim), (name, params)


def test_memory_estimate_refuses_a_huge_rectangle_without_building_it():
    """20000 × 20000 quads: refused from the counts in well under a second, nothing allocated."""
    import tomllib

    from parsolve.model import build_mesh
    from parsolve.scene import parse_scene

    text = """[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 20000
ny = 20000
[model]
hypothesis = "plane_stress"
[[materials]]
E = 1.0
nu = 0.3
"""
    t0 = time.perf_counter()
    with pytest.raises(InputError) as info:
        build_mesh(parse_scene(tomllib.loads(text), "s.toml"))
    assert time.perf_counter() - t0 < 5.0
    assert info.value.key == "mesh.generator"
    need = memory.whole_mesh_bytes(2 * 20001**2)   # the whole mesh, before it is built
    assert need == pytest.approx(92e6 + 2 * 20001**2 * 200)
    assert f"needs about {need / 2**30:.0f} GiB" in info.value.message
    assert "GiB available" in info.value.message


def test_memory_estimate_per_rank():
    one, two = (memory.estimate_bytes(10**6, 2, "direct", n) for n in (1, 2))
    assert one - 92e6 == pytest.approx(1e6 * 3100) and two - 92e6 == pytest.approx(1e6 * 1550)
    # 3D direct: measured 18.6 KB per DOF at 27 783 DOFs, growing like DOFs^(1/3)
    assert memory.estimate_bytes(8 * 27783, 3, "direct") == pytest.approx(
        92e6 + 8 * 27783 * 2 * 18.6e3)


def _scene_with_file(path) -> str:
    return f"""[mesh]
file = "{path}"
[model]
hypothesis = "plane_stress"
[[materials]]
E = 1.0
nu = 0.3
"""


def test_file_with_an_inverted_cell_is_refused(shared_tmp):
    """The reader turns clockwise cells round; one flipped cell among good ones then overlaps
    its neighbour, which the facet check sees."""
    import tomllib

    import meshio
    from mpi4py import MPI

    from parsolve.model import build_mesh, build_model
    from parsolve.scene import parse_scene

    pts = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]], float)
    good = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    bad_pts = pts.copy()
    bad_pts[4] = [0.5, -0.5]  # centre pulled below the bottom edge: cell 0 inverted
    path = shared_tmp / "inverted.vtu"
    nan_path = shared_tmp / "nan.vtu"
    if MPI.COMM_WORLD.rank == 0:
        meshio.write(path, meshio.Mesh(bad_pts, [("triangle", good)]))
        nan_pts = pts.copy()
        nan_pts[2, 0] = np.nan
        meshio.write(nan_path, meshio.Mesh(nan_pts, [("triangle", good)]))
    MPI.COMM_WORLD.Barrier()
    text = _scene_with_file(path)
    # a run checks the cells by blocks on every rank: the same error everywhere, at any count
    with pytest.raises(InputError, match="overlap a neighbour") as info:
        build_model(parse_scene(tomllib.loads(text), "s.toml", text), MPI.COMM_SELF)
    assert info.value.source == str(path) and info.value.key == "mesh.file"
    with pytest.raises(InputError) as parts:
        build_model(parse_scene(tomllib.loads(text), "s.toml", text), MPI.COMM_WORLD)
    assert str(parts.value) == str(info.value)
    text = _scene_with_file(nan_path)
    for build in (build_mesh, lambda scene: build_model(scene, MPI.COMM_WORLD)):
        with pytest.raises(InputError, match=r"non-finite coordinates \(NaN or inf\): points 2"):
            build(parse_scene(tomllib.loads(text), "s.toml", text))


def test_memory_check_of_a_run(monkeypatch):
    """A run checks each rank's share of the solve (every machine's verdict; for a generator
    before the mesh is built) and rank 0's whole mesh (that rank alone): memory just above
    the ranks' shares builds the model, just below refuses it; a file's mesh is checked once
    read."""
    import tomllib

    from mpi4py import MPI

    from parsolve.model import build_mesh, build_model
    from parsolve.scene import parse_scene

    comm = MPI.COMM_WORLD
    text = """[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 40
ny = 40
[model]
hypothesis = "plane_stress"
[[materials]]
E = 1.0
nu = 0.3
"""
    dofs, n = 2 * 41**2, comm.size
    shared = n * memory.estimate_bytes(dofs, 2, "direct", n)   # n ranks on this machine
    assert shared == pytest.approx(n * (92e6 + dofs * 3.1e3 / n))
    assert memory.whole_mesh_bytes(dofs) == pytest.approx(92e6 + dofs * 200.0)
    assert memory.whole_mesh_bytes(dofs) < shared

    def build(have: float):
        monkeypatch.setattr(memory, "available_bytes", lambda local=1: have)
        scene = parse_scene(tomllib.loads(text), "s.toml")
        with memory.agreed_over(comm):
            return build_model(scene, comm)

    assert build(shared * 1.01).mesh.num_global_points == 41**2
    with pytest.raises(InputError) as info:
        build(shared * 0.99)
    assert info.value.key == "mesh.generator" and "too large for this machine" in info.value.message
    assert "built on one rank" not in info.value.message
    # the whole mesh alone on one rank (which a run's shares on one machine always exceed)
    monkeypatch.setattr(memory, "available_bytes",
                        lambda local=1: memory.whole_mesh_bytes(dofs) * 0.99)
    with pytest.raises(InputError) as info:
        build_mesh(parse_scene(tomllib.loads(text), "s.toml"))
    assert info.value.key == "mesh.generator" and "built on one rank" in info.value.message
