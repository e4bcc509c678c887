"""Cell partition: the dual graph, PT-Scotch against coordinate bisection, the fallbacks, the
scene key, and shipped scenes solved on either partition."""

import hashlib
import os
import subprocess
import sys
import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from conftest import CONFIGS, ROOT, assert_same_results, run_scene
from parsolve.errors import InputError
from parsolve.mesh.generators import box, plate_with_hole, rectangle
from parsolve.mesh.mesh import Mesh
from parsolve.mesh import blocks
from parsolve.mesh.distribute import _cell_parts, distribute
from parsolve.mesh.topology import NUM_VERTICES
from parsolve.mesh.partition import MIN_CELLS_PER_PART, bisect, edge_cut, from_cell_parts


def dual_graph(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """The whole dual graph: the run's block-wise graph with one block (one process)."""
    return blocks.check_cells(MPI.COMM_SELF, mesh, None, None)


def cell_parts(mesh: Mesh, comm, method: str) -> tuple[np.ndarray, str]:
    """The run's partition (``distribute``'s: graph by blocks, PT-Scotch or bisection), every
    cell's part on every rank."""
    part, used = _cell_parts(comm, mesh, method)
    return comm.bcast(part, root=0), used


def partition(mesh: Mesh, comm, method: str):
    part, used = cell_parts(mesh, comm, method)
    return from_cell_parts(mesh, part, comm.size, used)


def l_shape(n: int) -> Mesh:
    """[0, 2]² minus its upper right quarter, 2 n × 2 n quads split into triangles (the
    points of the removed quarter stay, unused)."""
    mesh = rectangle(2.0, 2.0, 2 * n, 2 * n, cell="triangle")
    c = mesh.points[mesh.cells].mean(axis=1)
    keep = ~((c[:, 0] > 1.0) & (c[:, 1] > 1.0))
    return Mesh(mesh.points, mesh.cell_type, mesh.cells[keep])


def fingerprint(a: np.ndarray) -> str:
    return hashlib.sha1(np.ascontiguousarray(a, dtype=np.int64).tobytes()).hexdigest()


# ------------------------------------------------------------------ dual graph


@pytest.mark.parametrize("cell, nx, ny, expected", [
    ("quad", 7, 5, 6 * 5 + 7 * 4),                  # vertical + horizontal grid lines
    ("triangle", 7, 5, 7 * 5 + 6 * 5 + 7 * 4),      # plus one diagonal per quad
    ("triangle6", 4, 3, 4 * 3 + 3 * 3 + 4 * 2),     # midside nodes change nothing
])
def test_dual_graph_of_a_rectangle(cell, nx, ny, expected):
    mesh = rectangle(1.0, 1.0, nx, ny, cell=cell)
    indptr, indices = dual_graph(mesh)
    assert indptr[-1] == 2 * expected
    rows = np.repeat(np.arange(mesh.num_cells), np.diff(indptr))
    assert np.all(rows != indices)                                   # no self loops
    key = np.sort(rows * mesh.num_cells + indices)
    assert np.array_equal(key, np.sort(indices * mesh.num_cells + rows))  # symmetric
    assert np.unique(key).size == key.size                           # no repeats
    # neighbours share a facet: two nodes in 2D
    nv = NUM_VERTICES[mesh.cell_type]
    shared = [np.intersect1d(mesh.cells[r, :nv], mesh.cells[c, :nv]).size
              for r, c in zip(rows[:50], indices[:50])]
    assert set(shared) == {2}


@pytest.mark.parametrize("cell", ["hexahedron", "tetra"])
def test_dual_graph_of_a_box(cell):
    nx, ny, nz = 4, 3, 2
    mesh = box(1.0, 1.0, 1.0, nx, ny, nz, cell=cell)
    indptr, _ = dual_graph(mesh)
    if cell == "hexahedron":
        expected = (nx - 1) * ny * nz + nx * (ny - 1) * nz + nx * ny * (nz - 1)
    else:  # every facet is interior but the two triangles of each boundary square
        boundary = 2 * 2 * (nx * ny + ny * nz + nx * nz)
        expected = (4 * mesh.num_cells - boundary) // 2
    assert indptr[-1] == 2 * expected


def test_dual_graph_ignores_a_crack():
    """Duplicate points along x = 1 (a crack): no edge across it."""
    mesh = rectangle(2.0, 1.0, 4, 2, cell="quad")
    right = mesh.points[mesh.cells].mean(axis=1)[:, 0] > 1.0
    on_crack = np.flatnonzero(np.isclose(mesh.points[:, 0], 1.0))
    copies = np.arange(mesh.num_points, mesh.num_points + on_crack.size)
    renumber = np.arange(mesh.num_points)
    renumber[on_crack] = copies
    cells = mesh.cells.copy()
    cells[right] = renumber[cells[right]]
    cracked = Mesh(np.vstack([mesh.points, mesh.points[on_crack]]), "quad", cells)
    assert dual_graph(mesh)[0][-1] == 2 * (3 * 2 + 4 * 1)
    assert dual_graph(cracked)[0][-1] == 2 * (3 * 2 + 4 * 1 - 2)
    indptr, indices = dual_graph(cracked)
    assert edge_cut(indptr, indices, right.astype(np.int64)) == 0


def test_edge_cut_counts_each_shared_facet_once():
    mesh = rectangle(1.0, 1.0, 6, 4, cell="quad")
    indptr, indices = dual_graph(mesh)
    halves = (mesh.points[mesh.cells].mean(axis=1)[:, 0] > 0.5).astype(np.int64)
    assert edge_cut(indptr, indices, halves) == 4          # one vertical line of 4 facets
    stripes = np.arange(mesh.num_cells) % 2                # every vertical facet cut
    assert edge_cut(indptr, indices, stripes) == 5 * 4


# ------------------------------------------------------------------ partitions


MESHES = {
    "l_shape": lambda: l_shape(30),                                    # 5400 triangles
    "plate_hole": lambda: plate_with_hole(10.0, 10.0, 1.0, 30, 60, cell="triangle"),
    "box_tetra": lambda: box(1.0, 1.0, 1.0, 8, 8, 8, cell="tetra"),     # 3072 tets
}


@pytest.mark.parametrize("method", ["scotch", "bisection"])
@pytest.mark.parametrize("name", sorted(MESHES))
def test_every_cell_in_one_balanced_part(name, method, comm):
    mesh = MESHES[name]()
    nparts = comm.size
    part = partition(mesh, comm, method)
    assert part.cell_part.shape == (mesh.num_cells,)
    assert part.cell_part.min() >= 0 and part.cell_part.max() < nparts
    counts = np.bincount(part.cell_part, minlength=nparts)
    assert counts.sum() == mesh.num_cells
    assert counts.max() <= 1.03 * mesh.num_cells / nparts             # within 3 %
    assert part.method == ("none" if nparts == 1 else method)
    # the same partition on every rank
    assert len(set(comm.allgather(fingerprint(part.cell_part)))) == 1
    # node rule: the lowest rank among a node's cells; contiguous blocks in input order
    low = np.full(mesh.num_points, nparts - 1)
    np.minimum.at(low, mesh.cells, part.cell_part[:, None])
    assert np.array_equal(part.node_part, low)
    assert np.array_equal(np.sort(part.new_of_old), np.arange(mesh.num_points))
    for r in range(nparts):
        mine = np.flatnonzero(part.node_part == r)
        assert np.array_equal(part.new_of_old[mine],
                              np.arange(part.node_ranges[r], part.node_ranges[r + 1]))


@pytest.mark.parametrize("name", sorted(MESHES))
def test_scotch_is_deterministic(name, comm):
    """Twice in the same process: the same parts (Scotch's random generator is restarted)."""
    mesh = MESHES[name]()
    first = cell_parts(mesh, comm, "scotch")[0]
    second = cell_parts(mesh, comm, "scotch")[0]
    assert np.array_equal(first, second)


@pytest.mark.parametrize("name", ["l_shape", "plate_hole"])
def test_scotch_cuts_no_more_than_bisection(name, comm):
    mesh = MESHES[name]()
    graph = dual_graph(mesh)
    scotch, used = cell_parts(mesh, comm, "scotch")
    rcb, _ = cell_parts(mesh, comm, "bisection")
    assert edge_cut(*graph, scotch) <= edge_cut(*graph, rcb)
    if comm.size == 1:
        assert used == "none" and edge_cut(*graph, scotch) == 0


def test_the_fallbacks(comm):
    tiny = rectangle(1.0, 1.0, 2, 2, cell="quad")                  # 4 cells
    part, used = cell_parts(tiny, comm, "scotch")
    assert used == ("none" if comm.size == 1 else "bisection")
    centroids = tiny.points[tiny.cells].mean(axis=1)
    assert np.array_equal(part, bisect(centroids, comm.size))
    big = rectangle(1.0, 1.0, 20, 20, cell="quad")
    assert big.num_cells >= MIN_CELLS_PER_PART * 4
    with pytest.raises(ValueError, match="unknown partitioner"):
        distribute(comm, big if comm.rank == 0 else None, "metis")
    # bisection needs no communicator and any number of parts
    assert np.bincount(bisect(big.points[big.cells].mean(axis=1), 4)).tolist() == [100] * 4


@pytest.mark.serial
def test_scotch_gives_the_same_parts_in_every_run():
    """Separate runs on 2 and 3 ranks: PT-Scotch's threads would make the partition change
    from run to run; one thread per process and a fixed seed make it repeat."""
    code = ("from mpi4py import MPI; import hashlib, numpy as np;"
            "from parsolve.mesh.generators import plate_with_hole;"
            "from parsolve.mesh.distribute import _cell_parts;"
            "m = plate_with_hole(10.0, 10.0, 1.0, 40, 80, cell='triangle');"
            "p, used = _cell_parts(MPI.COMM_WORLD, m, 'scotch');"
            "MPI.COMM_WORLD.rank or print(used, hashlib.sha1(p.tobytes()).hexdigest())")
    env = {k: v for k, v in os.environ.items() if k != "SCOTCH_PTHREAD_NUMBER"}
    for n in (2, 3):
        outs = [subprocess.run(["bash", str(ROOT / "scripts" / "mpirun.sh"), "-n", str(n),
                                sys.executable, "-c", code], cwd=ROOT, env=env, text=True,
                               capture_output=True, timeout=300).stdout.split()
                for _ in range(3)]
        assert outs[0][0] == "scotch" and len(outs[0]) == 2, outs
        assert outs[1] == outs[0] and outs[2] == outs[0]


# ------------------------------------------------------------------ scene key


SCENE = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 2
ny = 2
[model]
hypothesis = "plane_stress"
[[materials]]
E = 1.0
nu = 0.3
"""


def test_scene_partitioner_key():
    from parsolve.scene import parse_scene

    assert parse_scene(tomllib.loads(SCENE), "s.toml").solver.partitioner == "scotch"
    text = SCENE + '[solver]\npartitioner = "bisection"\n'
    assert parse_scene(tomllib.loads(text), "s.toml").solver.partitioner == "bisection"
    for bad in ('"metis"', '1', '"Scotch"'):
        with pytest.raises(InputError) as err:
            parse_scene(tomllib.loads(SCENE + f"[solver]\npartitioner = {bad}\n"), "s.toml")
        assert str(err.value).startswith("s.toml: solver.partitioner: ")


# ------------------------------------------------------------------ shipped scenes


SHIPPED = sorted(p.name for p in CONFIGS.glob("*.toml"))
# The softening bar's steps (localization_bar.toml) are solved by secant iterations, which converge linearly: a step
# ends about its tolerance (relative residual 1e-9 to 2e-9 past the peak, against rtol = 1e-8)
# from equilibrium, and its damage carries that error into the next step, where the peak
# amplifies it (measured at 3 ranks, scotch against bisection: 1e-17 of the strain at step 1,
# x5 a step to 5e-10 at step 12, 1.15e-9 on another CPU). Two partitions of such a run are only
# as close as its convergence tolerance: the comparison is made to the scene's own rtol, a bound
# round-off does not move. Every other shipped scene converges quadratically or is linear.
def tolerance(name: str) -> float:
    from parsolve.scene import load_scene

    nonlinear = load_scene(CONFIGS / name).nonlinear
    return nonlinear.rtol if nonlinear.matrix == "secant" else 1e-10


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scene_same_on_any_partition(name, shared_tmp, comm):
    """Results are in input order: the two partitions give the same arrays to 1e-10 of
    each quantity's size (active rows exactly), and so does one rank alone."""
    if comm.size == 1:
        pytest.skip("one rank: both partitioners give the one trivial part")
    scotch = run_scene(CONFIGS / name, shared_tmp / "scotch.h5", solver={"partitioner": "scotch"})
    rcb = run_scene(CONFIGS / name, shared_tmp / "rcb.h5", solver={"partitioner": "bisection"})
    assert_same_results(scotch, rcb, tolerance(name))
    alone = run_scene(CONFIGS / name, shared_tmp / f"alone{comm.rank}.h5", MPI.COMM_SELF)
    assert_same_results(alone, scotch, tolerance(name))
