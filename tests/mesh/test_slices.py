"""The slice path (``mesh.slices``): every rank's part built from slices of a parallel mesh
file equals, field by field, the part the rank-0 path cuts out of the whole mesh for the same
node owners (``distribute._extract``), whatever the partitioner; and no rank allocates a mesh
array near the whole mesh's size."""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.errors import InputError
from parsolve.mesh import slices
from parsolve.mesh.distribute import _extract
from parsolve.mesh.generators import box, plate_with_hole, rectangle
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
    if name == "quad_with_stray_point":
        assert len(local.warnings) == 1 and "1 point(s) are used by no cell (points 28)" \
            in local.warnings[0]


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
