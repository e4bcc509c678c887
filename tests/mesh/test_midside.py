"""Quadratic cells by slices (``mesh.midside``): the midside nodes numbered by each edge's home
give the whole upgrade's mesh (``make_quadratic`` on the whole mesh, the generators' side
groups and the plate's hole on the circle) bit for bit, whatever the number of ranks."""

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.errors import InputError
from parsolve.mesh import slices
from parsolve.mesh.generators import (box, box_slices, make_quadratic, plate_slices,
                                      plate_with_hole, rectangle, rectangle_slices,
                                      sphere_on_block, sphere_slices)
from parsolve.mesh.h5mesh import open_mesh, write_mesh
from parsolve.mesh.midside import QuadraticSlices
from parsolve.mesh.partition import block_starts
from tests.mesh.test_slices import expected_part

SOURCES = {   # (slice source, the whole mesh it must give, quadratic cells' side groups)
    "rectangle_triangle6": (lambda: rectangle_slices(2.0, 1.0, 5, 3, cell="triangle6"),
                            lambda: rectangle(2.0, 1.0, 5, 3, cell="triangle6"), True),
    "box_tetra10": (lambda: box_slices(1.0, 2.0, 1.0, 3, 4, 2, cell="tetra10"),
                    lambda: box(1.0, 2.0, 1.0, 3, 4, 2, cell="tetra10"), True),
    "plate_triangle6": (lambda: plate_slices(4.0, 4.0, 1.0, 4, 8, cell="triangle6"),
                        lambda: plate_with_hole(4.0, 4.0, 1.0, 4, 8, cell="triangle6"), True),
    "box_tetra_order2": (lambda: box_slices(1.0, 1.0, 2.0, 2, 3, 4, cell="tetra"),
                         lambda: make_quadratic(box(1.0, 1.0, 2.0, 2, 3, 4, cell="tetra")), False),
    "plate_triangle_order2": (lambda: plate_slices(4.0, 4.0, 1.5, 6, 4, cell="triangle"),
                              lambda: make_quadratic(plate_with_hole(4.0, 4.0, 1.5, 6, 4,
                                                                     cell="triangle")), False),
    "sphere_tetra_order2": (lambda: sphere_slices(10.0, 1.0, 1.5, 1.2, 0.3, 3, 2, 2, cell="tetra"),
                            lambda: make_quadratic(sphere_on_block(10.0, 1.0, 1.5, 1.2, 0.3, 3, 2,
                                                                   2, cell="tetra")), False),
}


def _whole_slices(src, comm):
    """The quadratic source's slices gathered: (points, cells, node flags)."""
    gather = lambda a: np.concatenate(comm.allgather(a))   # noqa: E731
    cs = block_starts(src.num_cells, comm.size)
    return (gather(src.points(0, 0)), gather(src.cells(cs[comm.rank], cs[comm.rank + 1])),
            gather(src.node_flags(0, 0)))


@pytest.mark.parametrize("name", sorted(SOURCES))
def test_slices_are_the_whole_upgrade(name, comm):
    """Points, cells, node groups and facet groups of the quadratic slices, gathered, equal the
    whole quadratic mesh's exactly; so do the parts ``distribute_slices`` makes of them."""
    make_src, make_whole, groups = SOURCES[name]
    whole = make_whole()
    src = QuadraticSlices(comm, make_src(), "scene.toml", "mesh", midside_groups=groups)
    assert src.cell_type == whole.cell_type and src.num_points == whole.num_points
    points, cells, flags = _whole_slices(src, comm)
    assert np.array_equal(points, whole.points) and np.array_equal(cells, whole.cells)
    for k, group in enumerate(src.node_groups):
        assert np.array_equal(np.flatnonzero(flags[:, k]), whole.node_groups[group]), group
    for group in src.facet_groups:
        rows, order = src.facet_slice(group, comm.rank, comm.size)
        rows = np.concatenate(comm.allgather(rows))[np.argsort(np.concatenate(
            comm.allgather(order)), kind="stable")]
        assert np.array_equal(rows, whole.facet_groups[group]), group
    local = slices.distribute_slices(comm, src, "scotch", "scene.toml", "mesh")
    want = expected_part(comm, whole, local)
    for key in ("points", "cells", "global_nodes", "global_cells", "node_new"):
        assert np.array_equal(getattr(local, key), want[key]), key
    for kind in ("facet_groups", "node_groups"):
        got = getattr(local, kind)
        assert sorted(got) == sorted(want[kind]) and got
        for group in got:
            assert np.array_equal(got[group], want[kind][group]), (kind, group)


def test_plate_hole_midsides_on_the_circle(comm):
    """The hole's midside nodes lie on the circle (to round-off), the others are midpoints."""
    src = QuadraticSlices(comm, plate_slices(4.0, 4.0, 1.0, 4, 8, cell="triangle6"),
                          "scene.toml", "mesh", midside_groups=True)
    points, cells, flags = _whole_slices(src, comm)
    hole = flags[:, src.node_groups.index("hole")]
    r = np.linalg.norm(points[hole], axis=1)
    assert hole.sum() == 2 * 8 + 1
    np.testing.assert_allclose(r, 1.0, rtol=0, atol=1e-15)
    inner = ~hole[cells[:, 0]] | ~hole[cells[:, 1]]   # edge 0-1 off the hole: a midpoint
    mid = 0.5 * (points[cells[inner, 0]] + points[cells[inner, 1]])
    assert np.array_equal(points[cells[inner, 3]], mid)


def test_h5_file_of_linear_cells_upgraded(comm, shared_tmp):
    """A parallel mesh file of triangles: the slices give ``make_quadratic``'s mesh, its file
    facet groups become line3 facets."""
    whole = plate_with_hole(4.0, 4.0, 1.0, 3, 6, cell="triangle")
    path = shared_tmp / "plate.h5"
    if comm.rank == 0:
        write_mesh(whole, str(path))
    comm.Barrier()
    f = open_mesh(str(path))
    src = QuadraticSlices(comm, f, str(path), "mesh.file")
    want = make_quadratic(whole)
    points, cells, _ = _whole_slices(src, comm)
    assert np.array_equal(points, want.points) and np.array_equal(cells, want.cells)
    for group in src.facet_groups:
        rows, order = src.facet_slice(group, comm.rank, comm.size)
        rows = np.concatenate(comm.allgather(rows))[np.argsort(np.concatenate(
            comm.allgather(order)), kind="stable")]
        assert np.array_equal(rows, want.facet_groups[group]), group
    src.close()


def test_quads_and_foreign_facets_are_refused(comm, shared_tmp):
    """Quads have no midside nodes; a facet group whose edge is no mesh edge is named (the
    file, on every rank)."""
    with pytest.raises(ValueError, match="quad"):
        QuadraticSlices(comm, rectangle_slices(1.0, 1.0, 2, 2, cell="quad"), "s.toml", "mesh")
    whole = rectangle(1.0, 1.0, 3, 3, cell="triangle")
    whole.facet_groups["left"] = np.array([[0, 6]])   # not an edge
    path = shared_tmp / "bad_facets.h5"
    if comm.rank == 0:
        write_mesh(whole, str(path))
    comm.Barrier()
    f = open_mesh(str(path))
    with pytest.raises(InputError, match="not a mesh edge") as info:
        QuadraticSlices(comm, f, str(path), "mesh.file")
    assert info.value.source == str(path)
    f.close()
    assert comm.allreduce(1, op=MPI.SUM) == comm.size


def test_order_2_on_quads_names_the_key(comm):
    """A scene asking ``order = 2`` of quads: exit-2 error naming the scene and mesh.order, on
    every rank, nothing built."""
    import tomllib

    from parsolve.model import _distributed_mesh
    from parsolve.scene import parse_scene

    text = ('[mesh]\ngenerator = "rectangle"\nlx = 1.0\nly = 1.0\nnx = 4\nny = 4\n'
            'cell = "quad"\norder = 2\n[model]\nhypothesis = "plane_stress"\n[[materials]]\n'
            'E = 1.0\nnu = 0.3\n')
    with pytest.raises(InputError, match="order = 2 needs a simplex mesh, not quad") as info:
        _distributed_mesh(parse_scene(tomllib.loads(text), "s.toml"), comm)
    assert (info.value.source, info.value.key) == ("s.toml", "mesh.order")
