"""The distributed mesh: each rank's part against the whole mesh's partition it must
reproduce, the 1-rank part sharing the whole mesh's arrays, groups restricted to the parts,
regions decided for the whole mesh, collective input errors, and the deprecated scene key."""

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.errors import InputError
from parsolve.mesh.distribute import COMPONENT_MARGIN, _extract, distribute, index_dtype
from parsolve.mesh.generators import box, plate_with_hole, rectangle
from parsolve.mesh.regions import allgather_rows
from parsolve.mesh.distribute import _cell_parts
from parsolve.mesh.partition import from_cell_parts
from parsolve.mesh.regions import RegionResolver
from parsolve.scene import parse_scene

MESHES = {
    "quad": lambda: rectangle(2.0, 1.0, 12, 5, cell="quad"),
    "triangle6": lambda: plate_with_hole(4.0, 4.0, 1.0, 4, 8, cell="triangle6"),
    "tetra": lambda: box(1.0, 1.0, 2.0, 3, 3, 5, cell="tetra"),
    "hexahedron": lambda: box(1.0, 2.0, 1.0, 3, 4, 2, cell="hexahedron"),
}


def parts(name, comm, method="scotch"):
    whole = MESHES[name]()
    local = distribute(comm, whole if comm.rank == 0 else None, method)
    return whole, local


@pytest.mark.parametrize("method", ["scotch", "bisection"])
@pytest.mark.parametrize("name", sorted(MESHES))
def test_parts_are_the_whole_meshs_partition(name, method, comm):
    """Same owners and numbering as the whole mesh's partition; local cells = every cell
    touching an owned node (input order), owned nodes first, ghosts by global number."""
    whole, local = parts(name, comm, method)
    cell_part, used = _cell_parts(comm, whole, method)   # the run's partition, on rank 0
    part = from_cell_parts(whole, comm.bcast(cell_part, root=0), comm.size, used)
    rank = comm.rank
    assert local.partitioner == part.method
    assert np.array_equal(local.global_cells, part.local_cells(rank, whole.cells))
    owned = np.flatnonzero(part.node_part == rank)
    assert local.n_owned == owned.size
    assert np.array_equal(local.global_nodes[:local.n_owned], owned)
    ghosts = local.global_nodes[local.n_owned:]
    assert np.all(part.node_part[ghosts] != rank)
    assert np.all(np.diff(part.new_of_old[ghosts]) > 0)
    assert np.array_equal(local.node_new, part.new_of_old[local.global_nodes])
    assert np.array_equal(local.node_owner, part.node_part[local.global_nodes])
    assert np.array_equal(local.owner_of(local.cells), part.node_part[whole.cells[local.global_cells]])
    assert np.all(local.node_owner[:local.n_owned] == rank)
    assert np.array_equal(local.points, whole.points[local.global_nodes])
    assert np.array_equal(local.global_nodes[local.cells], whole.cells[local.global_cells])
    assert local.num_global_points == whole.num_points
    assert local.num_global_cells == whole.num_cells
    # every cell reported by exactly one rank, every node owned by exactly one
    reported = local.partition().owned_cells(rank, local.cells)
    cells = np.sort(allgather_rows(comm, local.global_cells[reported]))
    assert np.array_equal(cells, np.arange(whole.num_cells))
    nodes = np.sort(allgather_rows(comm, local.global_nodes[:local.n_owned]))
    assert np.array_equal(nodes, np.arange(whole.num_points))


@pytest.mark.parametrize("name", sorted(MESHES))
def test_index_arrays_are_int32_when_they_fit(name, comm):
    """A part keeps no owner array (it follows from the global numbers), and its index arrays
    are int32 at these sizes: 4 bytes per entry against the whole mesh's 8."""
    whole, local = parts(name, comm)
    assert "node_owner" not in vars(local)
    for key in ("cells", "global_nodes", "global_cells", "node_new"):
        assert getattr(local, key).dtype == np.int32, key
    for groups in (local.cell_groups, local.facet_groups, local.node_groups):
        assert all(ids.dtype == np.int32 for ids in groups.values())
    assert local.node_owner.dtype == np.int32


def test_index_dtype_keeps_int64_where_a_number_can_pass_int32():
    limit = 2**31 - 1
    assert index_dtype(limit) == np.int32 and index_dtype(limit + 1) == np.int64
    # node numbers are multiplied by up to COMPONENT_MARGIN components into DOF numbers
    nodes = limit // COMPONENT_MARGIN
    assert index_dtype(nodes, COMPONENT_MARGIN) == np.int32
    assert index_dtype(nodes + 1, COMPONENT_MARGIN) == np.int64


def test_a_part_is_smaller_than_the_whole(comm):
    whole, local = parts("hexahedron", comm)
    if comm.size == 1:
        assert local.num_points == whole.num_points
    else:
        assert local.num_cells < whole.num_cells and local.num_points < whole.num_points


@pytest.mark.parametrize("name", sorted(MESHES))
def test_groups_are_restricted_to_the_parts(name, comm):
    """Each rank keeps the group facets that have an owned node (their cell is then local)
    and the cells and nodes it holds; together the ranks hold each group whole."""
    whole, local = parts(name, comm)
    for group, facets in whole.facet_groups.items():
        mine = local.facet_groups[group]
        assert np.all((mine < local.n_owned).any(axis=1))
        key = np.sort(local.global_nodes[mine], axis=1)
        everyone = np.unique(allgather_rows(comm, key), axis=0)
        assert np.array_equal(everyone, np.unique(np.sort(facets, axis=1), axis=0)), group
    for group, cells in whole.cell_groups.items():
        mine = local.global_cells[local.cell_groups[group]]
        assert np.array_equal(np.unique(allgather_rows(comm, mine)), np.unique(cells)), group
    for group, nodes in whole.node_groups.items():
        mine = local.global_nodes[local.node_groups[group]]
        assert np.array_equal(np.unique(allgather_rows(comm, mine)), np.unique(nodes)), group


SPECS = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 1.0
nx = 12
ny = 5
cell = "quad"
[model]
hypothesis = "plane_stress"
[regions]
near = { point = [1.04, 0.51] }
strip = "x >= 0.5 and x <= 0.8"
corner_box = { box = [[1.7, 0.0], [2.0, 0.3]] }
[[materials]]
E = 1.0
nu = 0.3
"""


@pytest.mark.parametrize("name", sorted(MESHES))
def test_one_rank_part_is_the_whole_mesh_not_a_copy(name):
    """On 1 rank the part is what the general extraction gives (every node owned, input
    numbering), but its coordinates are the whole mesh's array itself (and its cells too
    where their type is kept): the set-up never holds the mesh twice."""
    whole = MESHES[name]()
    whole.node_groups["corner"] = np.array([0, 3])
    local = distribute(MPI.COMM_SELF, whole, "scotch")
    general = _extract(whole, from_cell_parts(whole, np.zeros(whole.num_cells, np.int64), 1,
                                              "none"), 0)
    assert local.points is whole.points
    assert local.n_owned == local.num_points == whole.num_points and local.partitioner == "none"
    for key, value in general.items():
        got = getattr(local, key)
        if isinstance(value, dict):
            assert sorted(got) == sorted(value), key
            for group in value:
                assert got[group].dtype == value[group].dtype, (key, group)
                assert np.array_equal(got[group], value[group]), (key, group)
        else:
            assert got.dtype == value.dtype and np.array_equal(got, value), key
    if whole.cells.dtype == local.cells.dtype:
        assert local.cells is whole.cells


@pytest.mark.parametrize("region", ["near", "strip", "corner_box", "all", "left", "top"])
def test_regions_are_the_whole_meshs(region, comm):
    """A region on the parts is the whole mesh's region: the same nodes (by input id), cells
    and boundary facets, each counted once over the ranks."""
    scene = parse_scene(tomllib.loads(SPECS), "s.toml")
    whole, local = parts("quad", comm)
    expected = RegionResolver(whole, scene.regions, "s.toml")(region, "k")
    got = RegionResolver(local, scene.regions, "s.toml", comm)
    r = got(region, "k")
    assert np.array_equal(got.relation_nodes(region, "k"), expected.nodes)
    owned_cells = r.cells[local.node_owner[local.cells[r.cells]].min(axis=1) == comm.rank]
    assert np.array_equal(np.sort(allgather_rows(comm, local.global_cells[owned_cells])),
                          expected.cells)
    facets = r.facets[local.node_owner[r.facets].min(axis=1) == comm.rank] if r.facets.size \
        else r.facets.reshape(0, 2)
    mine = np.sort(local.global_nodes[facets], axis=1)
    assert np.array_equal(np.unique(allgather_rows(comm, mine), axis=0),
                          np.unique(np.sort(expected.facets, axis=1), axis=0))


def test_a_region_empty_on_some_parts_is_not_empty(comm):
    """'selects no node and no cell' is decided over every rank; a region that some parts do
    not reach is fine, one that no part reaches fails on every rank."""
    text = SPECS.replace('strip = "x >= 0.5 and x <= 0.8"',
                         'strip = "x >= 1.95"\nnowhere = "x > 5"')
    scene = parse_scene(tomllib.loads(text), "s.toml")
    _, local = parts("quad", comm)
    regions = RegionResolver(local, scene.regions, "s.toml", comm)
    assert regions.relation_nodes("strip", "k").size == 6
    with pytest.raises(InputError, match="region 'nowhere' selects no node and no cell"):
        regions("nowhere", "regions.nowhere")


def test_an_expression_error_on_one_part_is_raised_on_every_rank(comm):
    """An expression that is not finite on one rank's points only: every rank raises it
    (no rank is left waiting in the next collective call)."""
    text = SPECS.replace('strip = "x >= 0.5 and x <= 0.8"', 'strip = "1 / (x - 2) > 0"')
    scene = parse_scene(tomllib.loads(text), "s.toml")
    _, local = parts("quad", comm)
    regions = RegionResolver(local, scene.regions, "s.toml", comm)
    with pytest.raises(InputError, match="regions.strip"):
        regions("strip", "k")
    comm.Barrier()


@pytest.mark.serial
def test_scene_key_mesh_is_deprecated(capsys, monkeypatch):
    """[solver] mesh, whatever its value, is accepted and ignored, said once per process on
    rank 0 (naming the file and the key); a scene without it says nothing."""
    import parsolve.scene as scene_module

    monkeypatch.setattr(scene_module, "_MESH_WARNED", False)
    base = parse_scene(tomllib.loads(SPECS), "s.toml")
    assert capsys.readouterr().err == ""
    for value in ('"replicated"', '"scattered"', "3"):
        text = SPECS + f"[solver]\nmesh = {value}\n"
        assert parse_scene(tomllib.loads(text), "s.toml").solver == base.solver
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("parsolve: warning: s.toml: solver.mesh: deprecated and ignored")
    assert "refused in the next release" in err


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_scene_key_mesh_not_a_number_is_refused(value):
    """The deprecated key takes any value, but a number the scene reads must be one."""
    text = SPECS + f"[solver]\nmesh = {value}\n"
    with pytest.raises(InputError) as err:
        parse_scene(tomllib.loads(text), "s.toml")
    assert err.value.source == "s.toml" and err.value.key == "solver.mesh", err.value.oneline()
