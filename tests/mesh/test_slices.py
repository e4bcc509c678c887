"""The slice path (``mesh.slices``): every rank's part built from slices of a parallel mesh
file equals, field by field, the part the rank-0 path cuts out of the whole mesh for the same
node owners (``distribute._extract``), whatever the partitioner; and no rank allocates a mesh
array near the whole mesh's size."""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.mesh import slices
from parsolve.mesh.checks import check_mesh
from parsolve.mesh.distribute import _extract
from parsolve.mesh.generators import (box, box_slices, plate_slices, plate_with_hole, rectangle,
                                      rectangle_slices, sphere_on_block, sphere_slices)
from parsolve.mesh.h5mesh import open_mesh, read_whole, write_mesh
from parsolve.mesh.partition import Partition
from parsolve.mesh.reader import read_mesh
from parsolve.mesh.regions import allgather_rows

CONFIGS = Path(__file__).resolve().parents[2] / "configs"

MESHES = {
    "ironing_2d": lambda: read_mesh(str(CONFIGS / "contact_ironing_2d.msh")),
    "ironing_3d": lambda: read_mesh(str(CONFIGS / "contact_ironing_3d.msh")),
    "triangle6": lambda: plate_with_hole(4.0, 4.0, 1.0, 4, 8, cell="triangle6"),
    "hexahedron": lambda: box(1.0, 2.0, 1.0, 3, 4, 2, cell="hexahedron"),
    "quad_with_stray_point": lambda: _with_stray(rectangle(2.0, 1.0, 6, 3, cell="quad")),
}


def _with_stray(mesh):
    mesh.points = np.vstack([mesh.points, [[5.0, 5.0]]])
    return mesh


def converted(name: str, tmp: Path, comm) -> tuple[object, Path]:
    whole = MESHES[name]()
    path = tmp / f"{name}.h5"
    if comm.rank == 0:
        write_mesh(whole, str(path))
    comm.Barrier()
    return whole, path


def expected_part(comm, whole, local):
    """The rank-0 path's part of this rank for the node owners the slice path chose."""
    owners = allgather_rows(comm, np.column_stack([
        local.global_nodes[:local.n_owned].astype(np.int64),
        np.full(local.n_owned, comm.rank)]))
    node_part = np.empty(whole.num_points, dtype=np.int64)
    node_part[owners[:, 0]] = owners[:, 1]
    order = np.argsort(node_part, kind="stable")
    new_of_old = np.empty(whole.num_points, dtype=np.int64)
    new_of_old[order] = np.arange(whole.num_points)
    ranges = np.concatenate([[0], np.cumsum(np.bincount(node_part, minlength=comm.size))])
    part = Partition(comm.size, node_part[whole.cells].min(axis=1), node_part, new_of_old, ranges)
    return _extract(whole, part, comm.rank)


@pytest.mark.parametrize("method", ["scotch", "bisection"])
@pytest.mark.parametrize("name", sorted(MESHES))
def test_slice_part_is_the_rank0_part(name, method, comm, shared_tmp):
    whole, path = converted(name, shared_tmp, comm)
    f = open_mesh(str(path))
    try:
        local = slices.distribute_slices(comm, f, method, str(path), "mesh.file")
    finally:
        f.close()
    want = expected_part(comm, whole, local)
    for key in ("points", "cells", "global_nodes", "global_cells", "node_new"):
        got = getattr(local, key)
        assert got.dtype == want[key].dtype, key
        assert np.array_equal(got, want[key]), key
    for kind in ("cell_groups", "facet_groups", "node_groups"):
        got = getattr(local, kind)
        assert sorted(got) == sorted(want[kind]), kind
        for group in got:
            assert np.array_equal(got[group], want[kind][group]), (kind, group)
            assert got[group].dtype == want[kind][group].dtype, (kind, group)
    assert local.num_global_cells == whole.num_cells
    assert local.num_global_points == whole.num_points
    assert np.allclose(local.extent, np.ptp(whole.points, axis=0), rtol=0, atol=0)
    counts = comm.allreduce(np.bincount([comm.rank], minlength=comm.size) * local.n_owned)
    assert np.array_equal(np.diff(local.node_ranges), counts)
    assert local.partitioner == ("none" if comm.size == 1 else
                                 "scotch" if method == "scotch" and whole.num_cells >= 8 * comm.size
                                 else "bisection")
    # the rank-0 path's warnings (unused points, duplicate points: the 2D ironing has 5)
    assert local.warnings == [f"{path}: mesh.file: {w}" for w in check_mesh(whole, None, None)]
    if name in ("quad_with_stray_point", "ironing_2d"):
        assert local.warnings


@pytest.mark.parametrize("name", sorted(MESHES))
def test_file_reads_back_the_same_mesh(name, comm, shared_tmp):
    """The parallel file holds exactly the mesh and regions it was written from."""
    whole, path = converted(name, shared_tmp, comm)
    back = read_whole(str(path))
    assert np.array_equal(back.points, whole.points)
    assert np.array_equal(back.cells, whole.cells) and back.cell_type == whole.cell_type
    for kind in ("cell_groups", "facet_groups", "node_groups"):
        a, b = getattr(back, kind), getattr(whole, kind)
        assert sorted(a) == sorted(b)
        for group in a:
            assert np.array_equal(a[group], b[group]), (kind, group)


def test_morton_parts_are_balanced(comm):
    """The Morton cuts split any cloud into parts of near-equal size (±1 cell per cut)."""
    rng = np.random.default_rng(comm.rank)
    pts = rng.random((1000 + 37 * comm.rank, 3))
    part = slices.morton_parts(comm, pts)
    counts = comm.allreduce(np.bincount(part, minlength=comm.size))
    total = comm.allreduce(pts.shape[0])
    assert counts.sum() == total
    assert counts.max() - counts.min() <= 1


GRIDS = {
    "rectangle_quad": (rectangle_slices, (2.0, 1.0, 7, 4), {"cell": "quad"}),
    "rectangle_triangle": (rectangle_slices, (2.0, 1.0, 5, 3), {"cell": "triangle",
                                                                "origin": (1.0, -2.0)}),
    "box_hexahedron": (box_slices, (1.0, 2.0, 1.0, 3, 4, 2), {"cell": "hexahedron"}),
    "box_tetra": (box_slices, (1.0, 1.0, 2.0, 2, 3, 4), {"cell": "tetra"}),
    "plate_quad": (plate_slices, (5.0, 4.0, 1.0, 5, 7), {"cell": "quad", "grading": 3.0}),
    "plate_triangle": (plate_slices, (4.0, 4.0, 1.5, 6, 4), {"cell": "triangle"}),
    "sphere_hexahedron": (sphere_slices, (10.0, 1.0, 1.5, 1.2, 0.3, 4, 3, 3), {}),
    "sphere_tetra": (sphere_slices, (10.0, 1.0, 1.5, 1.2, 0.3, 3, 2, 2),
                     {"cell": "tetra", "gap": 0.01, "profile": "sphere"}),
}
WHOLE = {rectangle_slices: rectangle, box_slices: box, plate_slices: plate_with_hole,
         sphere_slices: sphere_on_block}


@pytest.mark.parametrize("method", ["scotch", "bisection"])
@pytest.mark.parametrize("name", sorted(GRIDS))
def test_generated_slices_are_the_whole_generators_parts(name, method, comm):
    """Each rank generating its own slice gives the part the rank-0 path cuts out of the
    whole generated mesh (``rectangle``/``box``/``plate_with_hole``, which build the same
    numbering; ``sphere_on_block``'s bodies with their cell groups)."""
    slicer, args, kw = GRIDS[name]
    whole = WHOLE[slicer](*args, **kw)
    local = slices.distribute_slices(comm, slicer(*args, **kw), method, "scene.toml", "mesh")
    want = expected_part(comm, whole, local)
    for key in ("points", "cells", "global_nodes", "global_cells", "node_new"):
        assert np.array_equal(getattr(local, key), want[key]), key
    for kind in ("facet_groups", "node_groups"):
        got = getattr(local, kind)
        assert sorted(got) == sorted(want[kind]) and got
        for group in got:
            assert np.array_equal(got[group], want[kind][group]), (kind, group)
    assert sorted(local.cell_groups) == sorted(whole.cell_groups)
    for group in local.cell_groups:
        assert np.array_equal(local.cell_groups[group], want["cell_groups"][group]), group


SCENE = """
[mesh]
generator = "{generator}"
{params}

[model]
hypothesis = "{hypothesis}"

[[materials]]
E = 1000.0
nu = 0.3

[[loads]]
name = "pull"
region = "{end}"
total_force = {force}

[[relations]]
name = "clamp"
type = "dirichlet"
region = "{start}"
components = {components}
"""

RUNS = {
    "rectangle": dict(generator="rectangle", params='lx = 4.0\nly = 1.0\nnx = 24\nny = 6\n'
                      'cell = "triangle"', hypothesis="plane_stress", end="right", start="left",
                      force="[0.0, -1.0]", components='["x", "y"]'),
    "box": dict(generator="box", params="lx = 4.0\nly = 1.0\nlz = 1.0\nnx = 12\nny = 3\nnz = 3\n"
                'cell = "tetra"', hypothesis="3d", end="xmax", start="xmin",
                force="[0.0, 0.0, -1.0]", components='["x", "y", "z"]'),
    "box_order2": dict(generator="box", params="lx = 4.0\nly = 1.0\nlz = 1.0\nnx = 6\nny = 2\n"
                       'nz = 2\ncell = "tetra"\norder = 2', hypothesis="3d", end="xmax",
                       start="xmin", force="[0.0, 0.0, -1.0]", components='["x", "y", "z"]'),
    "plate_triangle6": dict(generator="plate_with_hole", params="width = 4.0\nheight = 4.0\n"
                            'radius = 1.0\nn_radial = 6\nn_angular = 8\ncell = "triangle6"',
                            hypothesis="plane_stress", end="right", start="left",
                            force="[1.0, 0.0]", components='["x", "y"]'),
}
CELLS = {"rectangle": "triangle", "box": "tetra", "box_order2": "tetra10",
         "plate_triangle6": "triangle6"}


@pytest.mark.parametrize("name", sorted(RUNS))
def test_generated_scene_runs_as_the_whole_generation(name, comm, run, monkeypatch):
    """A cantilever from the generator's slices and from the whole generation on rank 0 (its
    quadratic cells, ``order = 2``, from the whole mesh's ``make_quadratic``): the same mesh
    and the same fields (to the round-off of two parallel runs)."""
    import parsolve.model as model

    text = SCENE.format(**RUNS[name])
    sliced = run(text, f"{name}_slices")
    with monkeypatch.context() as m:
        m.setattr(model, "_slice_source", lambda scene, comm: None)
        whole = run(text, f"{name}_whole")
    for key in ("mesh/points", f"mesh/cells/{CELLS[name]}"):
        assert np.array_equal(sliced[key], whole[key])
    u, w = sliced["fields/displacement"], whole["fields/displacement"]
    assert np.abs(w).max() > 1e-3
    np.testing.assert_allclose(u, w, rtol=0, atol=1e-12 * np.abs(w).max())
    np.testing.assert_allclose(sliced["relations/clamp/resultant"],
                               whole["relations/clamp/resultant"], rtol=0, atol=1e-12)


def test_no_rank_holds_a_whole_mesh_array(comm, shared_tmp):
    """On the slice path the largest mesh array a rank allocates is its slice's or its part's:
    at 4 ranks at most 0.35 of the whole mesh's cells array (a 24 × 24 × 12 box of 41 472
    tetrahedra, from the parallel file and from the generator)."""
    whole = box(2.0, 2.0, 1.0, 24, 24, 12, cell="tetra")
    path = shared_tmp / "box.h5"
    if comm.rank == 0:
        write_mesh(whole, str(path))
    comm.Barrier()
    whole_bytes = max(whole.cells.nbytes, whole.points.nbytes)
    f = open_mesh(str(path))
    for src in (f, box_slices(2.0, 2.0, 1.0, 24, 24, 12, cell="tetra")):
        slices.LARGEST["bytes"] = 0
        local = slices.distribute_slices(comm, src, "scotch", str(path), "mesh.file")
        largest = comm.allreduce(slices.LARGEST["bytes"], op=MPI.MAX)
        assert largest >= local.cells.nbytes > 0   # it records what the path holds
        if comm.size == 4:
            assert largest <= 0.35 * whole_bytes, largest / whole_bytes
        else:
            assert largest <= (1.3 / comm.size + 0.05) * whole_bytes
    f.close()


def test_slice_path_checks_each_ranks_share_of_the_mesh(comm, monkeypatch, shared_tmp):
    """A parallel mesh file's size is known before anything is read: each rank's share of the
    mesh (0.2 KB per DOF over the ranks, not the whole mesh on one rank) is checked first,
    refused below it with a message naming the file, accepted above the solve's estimate."""
    import tomllib

    from parsolve.errors import InputError
    from parsolve.mesh import memory
    from parsolve.model import _distributed_mesh
    from parsolve.scene import parse_scene

    path = shared_tmp / "square.h5"
    if comm.rank == 0:
        write_mesh(rectangle(1.0, 1.0, 30, 30, cell="triangle"), str(path))
    comm.Barrier()
    text = (f'[mesh]\nfile = "{path}"\n[model]\nhypothesis = "plane_stress"\n[[materials]]\n'
            'E = 1.0\nnu = 0.3\n[solver]\npreset = "iterative"\n')
    dofs, n = 2 * 31**2, comm.size
    share = n * (memory.BASE + dofs * memory.WHOLE_MESH_PER_DOF / n)   # n ranks, one machine
    solve = n * memory.estimate_bytes(dofs, 2, "iterative", n)
    assert share < solve
    read = []
    monkeypatch.setattr("parsolve.model.distribute_slices", lambda *a: read.append(a) or 1 / 0)
    monkeypatch.setattr(memory, "available_bytes", lambda local=1: share * 0.99)
    with memory.agreed_over(comm), pytest.raises(InputError) as info:
        _distributed_mesh(parse_scene(tomllib.loads(text), "s.toml"), comm)
    assert info.value.source == str(path) and info.value.key == "mesh.file"
    assert "read by slices" in info.value.message and not read   # refused before reading
    monkeypatch.undo()
    monkeypatch.setattr(memory, "available_bytes", lambda local=1: solve * 1.01)
    with memory.agreed_over(comm):
        part = _distributed_mesh(parse_scene(tomllib.loads(text), "s.toml"), comm)
    assert comm.allreduce(part.n_owned) == 31**2


def test_morton_parts_of_cells_on_a_line(comm):
    """Centroids with a flat direction (all at y = 0) are cut along the other one, without
    invalid values."""
    x = np.arange(comm.rank, 400, comm.size, dtype=float)
    with np.errstate(all="raise"):
        part = slices.morton_parts(comm, np.column_stack([x, np.zeros_like(x)]))
    counts = comm.allreduce(np.bincount(part, minlength=comm.size))
    assert counts.max() - counts.min() <= 1
    # parts are intervals of x: every part's x range lies before the next one's
    ranges = comm.allgather([(x[part == p].min(), x[part == p].max()) if np.any(part == p)
                             else None for p in range(comm.size)])
    lo = [min(r[p][0] for r in ranges if r[p]) for p in range(comm.size)]
    hi = [max(r[p][1] for r in ranges if r[p]) for p in range(comm.size)]
    assert all(hi[p] < lo[p + 1] for p in range(comm.size - 1))


def test_scotch_on_aggregates_gives_balanced_connected_parts(comm, monkeypatch):
    """Above ``COARSE_MIN`` cells per part PT-Scotch partitions aggregates of ``AGGREGATE``
    cells, whose graph the facets build directly: it is the cells' graph with each cell
    replaced by its aggregate (no self loops, no repeats); every cell in one part, each
    aggregate in one part, the parts within one aggregate per rank of equal sizes, and the
    edge cut near the cells' graph's and well under a random split's. A box of 6·12³
    tetrahedra, aggregates of 8 from 64 cells per part: within 2× the cells' graph's cut
    (1.69× at 3 ranks; the 1.05M box at 2 ranks, aggregates of 16: 1.09×)."""
    from parsolve.mesh import blocks
    from parsolve.mesh.partition import block_starts, edge_cut

    src = box_slices(1.0, 1.0, 1.0, 12, 12, 12, cell="tetra")
    n = src.num_cells
    cs = block_starts(n, comm.size)
    cells = src.cells(int(cs[comm.rank]), int(cs[comm.rank + 1]))
    block = blocks.CellBlock(cells, None, int(cs[comm.rank]), n, "tetra", 3)
    graph = blocks.facet_groups(comm, block, None, None)
    idx = np.concatenate(comm.allgather(graph[1]))
    ptr = np.concatenate([[0], np.cumsum(np.concatenate(comm.allgather(np.diff(graph[0]))))])
    monkeypatch.setattr(slices, "AGGREGATE", 8)
    monkeypatch.setattr(slices, "COARSE_MIN", 64)
    coords = slices.CellCoords(src.points(0, src.num_points), cells)
    scotch, vertices = slices._vertices(comm, "scotch", block, coords)
    assert scotch == (comm.size > 1)
    if comm.size == 1:
        return
    agg = vertices.of_cell
    sizes = np.bincount(agg)
    assert (sizes[:-1] == 8).all() and 1 <= sizes[-1] <= 8
    assert vertices.starts[-1] == comm.allreduce(sizes.size)
    coarse = blocks.facet_groups(comm, block, None, None, vertices=vertices)
    # the aggregates' graph from the cells' graph (every rank's whole, mapped)
    of_cell = np.concatenate(comm.allgather(agg + vertices.starts[comm.rank]))
    rows = of_cell[np.repeat(np.arange(n), np.diff(ptr))]
    key = np.unique(rows * n + of_cell[idx])
    key = key[key // n != key % n]
    mine = (key // n >= vertices.starts[comm.rank]) & (key // n < vertices.starts[comm.rank + 1])
    want_rows = key[mine] // n - vertices.starts[comm.rank]
    assert np.array_equal(coarse[1], key[mine] % n)
    assert np.array_equal(coarse[0], np.searchsorted(want_rows, np.arange(sizes.size + 1)))
    parts, used = slices._cell_parts(comm, block, coords, coarse, vertices)
    if used != "scotch":
        pytest.skip("PETSc without PT-Scotch")
    assert np.unique(agg * comm.size + parts).size == sizes.size   # one part per aggregate
    whole = np.concatenate(comm.allgather(parts))
    counts = np.bincount(whole, minlength=comm.size)
    assert counts.sum() == n and counts.min() > 0
    assert counts.max() <= n / comm.size * 1.01 + 8 * comm.size
    fine = slices.scotch_block(comm, n, *graph)
    fine = np.concatenate(comm.allgather(fine))
    assert edge_cut(ptr, idx, whole) <= 2.0 * edge_cut(ptr, idx, fine)
    rng = np.random.default_rng(0)
    assert edge_cut(ptr, idx, whole) < 0.2 * edge_cut(ptr, idx, rng.integers(0, comm.size, n))


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_spread_interleaves_every_bit(dim):
    """The shift-and-mask spread puts bit b of a key at bit b·dim, for every bit a key has
    (63 // dim), as a loop over the bits does."""
    rng = np.random.default_rng(dim)
    bits = 63 // dim
    v = rng.integers(0, 2**bits, 10_000, dtype=np.uint64)
    v[:2] = [0, 2**bits - 1]
    want = np.zeros_like(v)
    for b in range(bits):
        want |= ((v >> np.uint64(b)) & np.uint64(1)) << np.uint64(b * dim)
    assert np.array_equal(slices._spread(v, dim), want)
