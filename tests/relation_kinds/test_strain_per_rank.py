"""Per-cell strain rows without a maximum are built per rank: each cell's row by the rank
counting the cell (``Relation.ids``: row j the region's j-th cell by input id), no rank
holding another's rows; over the ranks the rows are the one-process build's, entry by entry,
and A q of the stacked rows is the one-process value. Under a maximum (a group spanning the
ranks) the rows are per rank too (``tests/relation_kinds/test_maximum_per_rank.py``). Run at
1, 2 and 3 ranks."""

import tomllib

import numpy as np
from mpi4py import MPI

from parsolve.model import build_model
from parsolve.relation_kinds.strain import row_cell
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem

COMM = MPI.COMM_WORLD
#: a 2 × 1 plate of 24 × 12 quads, held on the left, pulled on the right; a box's cells' strain
#: in the direction (1, 1) capped one by one (72 rows, inactive under this pull)
PLATE = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 1.0
nx = 24
ny = 12
cell = "quad"

[model]
hypothesis = "plane_stress"

[regions]
corner = { point = [0.0, 0.0] }
mid = { box = [[0.5, 0.25], [1.5, 0.75]] }

[[materials]]
E = 1e9
nu = 0.25

[[loads]]
name = "pull"
region = "right"
total_force = [1.0, 0.5]

[[relations]]
name = "left_x"
type = "dirichlet"
region = "left"
components = ["x"]

[[relations]]
name = "corner_y"
type = "dirichlet"
region = "corner"
components = ["y"]

[[relations]]
name = "cap"
type = "strain"
region = "mid"
direction = [1.0, 1.0]
per_cell = true
sense = "<="
value = 1.0
"""
CELLS = 12 * 6


def model_of(comm):
    return build_model(parse_scene(tomllib.loads(PLATE), "t.toml", PLATE), comm)


def cap(model):
    return next(r for r in model.relations if r.name == "cap")


def test_each_rank_holds_its_cells_rows():
    here, one = cap(model_of(COMM)), cap(model_of(MPI.COMM_SELF))
    assert one.nrows == CELLS and not here.whole and here.total == CELLS
    assert np.all(np.diff(here.ids) > 0)
    every = np.sort(np.concatenate(COMM.allgather(here.ids)))
    np.testing.assert_array_equal(every, np.arange(CELLS))       # each row on one rank
    if COMM.size > 1:
        assert here.nrows < CELLS                                 # none holds them all
    # its cells: the ones it counts, with their rows; the one-process cells of those rows
    np.testing.assert_array_equal(here.meta["cell_rows"], here.ids)
    np.testing.assert_array_equal(one.meta["cells"][here.ids], here.meta["cells"])
    assert [row_cell(COMM, here, j) for j in (0, CELLS - 1)] == \
        [int(one.meta["cells"][0]), int(one.meta["cells"][-1])]
    # entries (global row, DOF, coefficient) as the one-process build's, each once
    mine = np.column_stack([here.ids[here.a_rows], here.a_dofs, here.a_vals])
    got = np.concatenate(COMM.allgather(mine))
    got = got[np.lexsort((got[:, 1], got[:, 0]))]
    ref = np.column_stack([one.a_rows, one.a_dofs, one.a_vals])
    ref = ref[np.lexsort((ref[:, 1], ref[:, 0]))]
    assert got.shape == ref.shape
    np.testing.assert_array_equal(got[:, :2], ref[:, :2])
    np.testing.assert_allclose(got[:, 2], ref[:, 2], rtol=1e-13)


def test_the_stacked_rows_give_the_one_process_values():
    """A q of the rows held here (their entries on ghost nodes read from the owners), q the
    input DOF numbers, against the one-process relation's rows."""
    model = model_of(COMM)
    system = SaddleSystem(COMM, model)
    rs, dm = system.relation_set, system.dofmap
    k = [r.name for r in rs.relations].index("cap")
    r = rs.relations[k]
    local = dm.mesh
    q = ((local.global_nodes.astype(np.int64)[:, None] * dm.ncomp + np.arange(dm.ncomp))
         .ravel().astype(float))
    every = np.arange(local.num_global_points * dm.ncomp, dtype=float)
    expected = cap(model_of(MPI.COMM_SELF)).primal(every)[r.ids]
    np.testing.assert_allclose(rs.primal_values(q)[rs.rows_of(k)], expected, rtol=1e-12)
    assert np.all(np.abs(expected) > 0)   # (the rows read their nodes)
