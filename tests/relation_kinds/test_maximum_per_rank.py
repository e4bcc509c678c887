"""A maximum group's rows are held per rank: a per-cell strain under ``maximum = true`` has
each cell's row on the rank counting the cell (``Relation.ids``), no rank holding another's
rows or their row-sized arrays (values, the active set's masks, the relation set's rows), and
the group is decided by reductions over the ranks (``ActiveSet.choose``): the largest score,
the rows tied with it (the enforced row kept among them, else the lowest row number), the same
row as on one process wherever the rows are. Run at 1, 2, 3 and 4 ranks (4: a rank holding
none of the group's rows)."""

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.model import build_model
from parsolve.relations import Relation, rows_here
from parsolve.scene import parse_scene
from parsolve.solvers.active_set import ActiveSet
from parsolve.solvers.diagnose import GoingBack
from parsolve.solvers.system import SaddleSystem
from tests.helpers.plate import PLATE, dirichlet
from tests.helpers.scene import scene, scene_data

COMM = MPI.COMM_WORLD
#: a 2 × 1 plate of 24 × 12 quads held on the left and pulled by a load pattern on the right,
#: every cell's strain xx under a maximum controlled by that pattern (288 rows)
MAXIMUM = scene(scene_data(
    PLATE, regions={"corner": {"point": [0.0, 0.0]}},
    relations=[dirichlet("left_x", "left", "x"), dirichlet("corner_y", "corner", "y"),
               {"name": "cells", "type": "strain", "region": "all", "component": "xx",
                "per_cell": True, "maximum": True, "sense": "<=", "value": 1.2e-3,
                "dual": "pull"}]))
CELLS = 24 * 12


def held(comm) -> int:
    """The maximum relation's rows and row-sized arrays a rank holds: its rows' values,
    numbers, cells and A entries, the relation set's multiplier row of each row and its
    stacked A entries (the group's multiplier row's: of its carried row alone), the
    operator's relation entries, the active set's masks and keys over them. Collective."""
    text = MAXIMUM
    model = build_model(parse_scene(tomllib.loads(text), "t.toml", text), comm)
    system = SaddleSystem(comm, model)
    (r,) = [r for r in system.multiplied if r.maximum]
    rset = system.relation_set
    aset = ActiveSet(system.multiplied, owned=rset.owned_relrows, comm=comm)
    arrays = [r.values, r.row_ids(), r.a_vals, r.meta["cells"], r.meta["cell_rows"],
              rset.mult_of_row, rset.position, rset.a_vals, rset.a_cols, rset.a_rows,
              system.op.a_final, aset.active, aset.sign, aset.orient, aset.key,
              aset.owned, aset.free, aset.held, aset.maximum]
    assert comm.allreduce(r.nrows) == CELLS and r.total == CELLS and not r.whole
    return sum(a.size for a in arrays)


def test_each_rank_holds_its_share_of_the_group():
    """At 4 ranks the largest rank holds at most 0.35 of one rank's rows and row-sized
    arrays (every cell's row held once over the ranks)."""
    mine, alone = held(COMM), held(MPI.COMM_SELF)
    most = COMM.allreduce(mine, op=MPI.MAX)
    assert most <= 1.4 / COMM.size * alone + 16, (most, alone)
    if COMM.size == 4:
        assert most <= 0.35 * alone, (most, alone)


#: a group of 9 rows: rank r holds rows 3r, 3r + 1, 3r + 2 (the last rank the rest; at 4
#: ranks rank 3 holds none)
ROWS = 9


def group(comm) -> tuple[ActiveSet, np.ndarray]:
    ids = np.arange(ROWS) if comm.size == 1 else \
        np.flatnonzero(np.minimum(np.arange(ROWS) // 3, comm.size - 1) == comm.rank)
    r = Relation("max", ids.size, np.arange(ids.size), ids, np.ones(ids.size), np.zeros(ids.size),
                 sense="<=", maximum=True)
    aset = ActiveSet([rows_here(r, ids, ROWS)], comm=comm)
    aset.start_step()
    return aset, ids


def enforced(aset: ActiveSet, ids: np.ndarray, comm) -> list:
    return sorted(np.concatenate(comm.allgather(ids[aset.active])).tolist())


@pytest.mark.parametrize("scores, first, expected", [
    # the largest row 7 (on rank 2 at 3 and 4 ranks)
    ([0.1, 0.2, 0.3, 0.5, 0.6, 0.65, 0.4, 0.9, 0.8], None, 7),
    # rows 4 and 7 tied (ranks 1 and 2): the lowest number
    ([0.1, 0.2, 0.3, 0.5, 0.9, 0.65, 0.4, 0.9, 0.8], None, 4),
    # tied within the tolerance (1e-7 of the scale): the lowest number
    ([0.1, 0.2, 0.3, 0.5, 0.9, 0.65, 0.4, 0.9 + 1e-9, 0.8], None, 4),
    # tied, the enforced row among them (row 7, moved there first): it stays
    ([0.1, 0.2, 0.3, 0.5, 0.9, 0.65, 0.4, 0.9, 0.8], [0.0] * 7 + [1.0, 0.0], 7),
])
def test_the_group_picks_the_one_process_row(scores, first, expected):
    """The group's row over the ranks is the one-process row: the largest score, ties broken
    by the enforced row, then by the lowest row number, whichever ranks hold them."""
    scores = np.asarray(scores)
    picks = []
    for comm in (MPI.COMM_SELF, COMM):
        aset, ids = group(comm)
        if first is not None:
            assert aset.update(np.asarray(first)[ids], np.zeros(ids.size), 1e-12, 1e-12, 1.0)
            assert enforced(aset, ids, comm) == [7]
            aset.start_step()
        aset.update(scores[ids], np.zeros(ids.size), 1e-12, 1e-12, 1.0)
        picks.append(enforced(aset, ids, comm))
    assert picks == [[expected], [expected]]


def test_going_back_fails_on_every_rank_alike():
    """A group going back to a row it left in the step (row 1 on rank 0, left for row 7 on
    rank 2) fails on every rank with the one-process message."""
    messages = []
    for comm in (MPI.COMM_SELF, COMM):
        aset, ids = group(comm)
        for best in (1, 7, 1):
            scores = np.where(ids == best, 1.0, 0.0)
            try:
                aset.update(scores, np.zeros(ids.size), 1e-12, 1e-12, 1.0)
            except GoingBack as exc:
                messages.append((str(exc), exc.rows))
                break
    assert len(messages) == 2 and messages[0] == messages[1]
    assert messages[0][1] == (7, 1)


def test_the_single_change_moves_the_group_over_the_ranks():
    """Cycling: the one change moves the group's row, wherever the rows are (the best gain's
    row held on one rank, the others' rows off)."""
    for comm in (MPI.COMM_SELF, COMM):
        aset, ids = group(comm)
        gain = np.where(ids == 5, 0.3, np.where(ids == 8, 0.2, -np.inf))
        none = np.full(ids.size, -np.inf)
        new = aset._one_change(none, none, gain)
        assert sorted(np.concatenate(comm.allgather(ids[new])).tolist()) == [5]


def test_the_relation_set_passes_the_enforced_row_between_holder_and_owner():
    """A maximum group of 3 rows built per rank (row i on rank i mod ranks) sharing one load
    pattern: one multiplier row over every rank; the enforced row's number (``select``), its
    gap on the multiplier row's owner (``gap``), the operator's A entries of that row alone
    (``a_on``) and the multiplier back on the holder's row (``every_row``) and in the
    reaction (``Relation.reaction``: the pattern times it)."""
    from parsolve.la.dofmap import DofMap
    from parsolve.la.relation_set import RelationSet
    from parsolve.mesh.distribute import distribute
    from parsolve.mesh.generators import rectangle

    nc = 2
    local = distribute(COMM, rectangle(2.0, 1.0, 8, 4, cell="quad") if COMM.rank == 0 else None,
                       "bisection")
    dm = DofMap(COMM, local, nc)
    ids = np.flatnonzero(np.arange(3) % COMM.size == COMM.rank)
    dofs = np.array([3, 33, 63])[ids]
    pattern = np.array([80, 81])
    own = np.isin(pattern // nc, local.global_nodes[:local.n_owned])
    peak = rows_here(Relation("peak", ids.size, np.arange(ids.size), dofs, np.ones(ids.size),
                              np.full(ids.size, 9.0), sense="<=", maximum=True,
                              shared_dual=(pattern[own], np.ones(int(own.sum())))), ids, 3)
    peak.comm = COMM
    dm.index_inputs([np.array([3, 33, 63]), pattern])   # (every rank: the check below)
    rs = RelationSet([peak], dm)
    assert rs.nrows == 1 and rs.nrelrows == ids.size   # one multiplier, each rank its rows
    _, _, l0, l1 = dm.owned()
    owner = COMM.allreduce(COMM.rank if l1 > l0 else 0)
    q = 0.5 + 3.0 * (local.global_nodes.astype(np.int64)[:, None] * nc + np.arange(nc)).ravel()
    for row in (2, 0):   # the enforced row moves across the ranks
        on = rs.select(ids == row)
        assert rs._enforced.tolist() == [row] and on.all()
        gap = rs.gap(1.0, q)   # (collective) b - A q of the enforced row on the owner
        if COMM.rank == owner:
            np.testing.assert_allclose(gap, [9.0 - (0.5 + 3.0 * [3, 33, 63][row])], rtol=1e-15)
            a_on = rs.a_on
            assert a_on.sum() == 1
            assert rs.a_cols[a_on][0] == dm.input_new_dof(np.array([[3, 33, 63][row]]))[0]
        lam = np.full(l1 - l0, 4.0)
        every = rs.every_row(lam)
        np.testing.assert_array_equal(every, np.where(ids == row, 4.0, 0.0))
        assert COMM.allreduce(float(every.sum())) == 4.0
        _, force = peak.reaction(every)   # (collective) this rank's pattern part × λ
        np.testing.assert_array_equal(force, np.full(int(own.sum()), 4.0))
    rs.select(np.zeros(ids.size, dtype=bool))   # released: the multiplier row is off
    assert rs._enforced.tolist() == [-1] and not rs.a_on.any()


def unit_load(comm, rows: tuple[int, ...]) -> dict[int, float]:
    """The unit load of an associated maximum group's rows (no ``dual``: D = -Aᵀ, the row's
    own reaction pattern; ``Policies.dual_column``) as {input DOF: value}, gathered.
    Collective."""
    from tests.helpers.control import newton_of
    text = MAXIMUM.replace('"dual" = "pull"', "").replace('dual = "pull"', "")
    assert "pull" in text and "dual" not in text.split("[[relations]]")[-1]
    _, model, _, problem, _ = newton_of(text, comm)
    pol, mesh = problem.policies, model.mesh
    k = [r.name for r in problem.ctx.multiplied].index("cells")
    nc, own = problem.ctx.ncomp, mesh.n_owned * problem.ctx.ncomp
    inputs = (mesh.global_nodes.astype(np.int64)[:, None] * nc + np.arange(nc)).ravel()[:own]
    out = {}
    for row in rows:
        v = pol.dual_column(k, row)
        assert np.abs(v[own:]).max(initial=0.0) == 0.0   # (ghost parts moved to their owners)
        nz = np.flatnonzero(v[:own])
        for part in comm.allgather(list(zip(inputs[nz].tolist(), v[nz].tolist()))):
            for dof, val in part:
                out[(row, dof)] = out.get((row, dof), 0.0) + val
    return out


def test_an_associated_groups_unit_load_is_its_rows_reaction_on_every_partition():
    """Without a load pattern a maximum's unit load is its row's own -Aᵀ, the cell's entries
    on the ranks owning its nodes (a row built on its cell's rank, its ghost parts added on
    their owners): the one-process column wherever the cell is (before, each rank took its
    own first row)."""
    rows = (0, 137, CELLS - 1)
    world, alone = unit_load(COMM, rows), unit_load(MPI.COMM_SELF, rows)
    assert world.keys() == alone.keys() and len(alone) == 3 * 4   # (εxx: a quad's 4 x DOFs)
    for key, val in alone.items():
        assert abs(world[key] - val) <= 1e-12 * abs(val), key



def group_row(system: SaddleSystem) -> dict[int, float]:
    """The maximum group's multiplier row of the assembled operator, from its owner:
    {saddle column: unscaled value} of its nonzero entries off the diagonal (a released row's
    placeholder). Collective."""
    rset, dm = system.relation_set, system.dofmap
    mat = system.assemble()
    (mult,) = rset._group_mult
    q0, q1, l0, l1 = dm.owned()
    mine = {}
    if l0 <= mult < l1:
        at = system.op.offset + q1 - q0 + int(mult - l0)
        cols, vals = mat.getRow(at)
        scale = rset.row_scale[mult - l0]
        mine = {int(c): float(v) / scale for c, v in zip(cols, vals) if v != 0.0 and c != at}
    parts = COMM.allgather(mine)
    assert sum(bool(p) for p in parts) <= 1   # (one rank's row)
    return {c: v for p in parts for c, v in p.items()}


def cell_row(system: SaddleSystem, r: Relation, row: int) -> dict[int, float]:
    """Row ``row`` of the group, from the rank holding it: {saddle column: coefficient}.
    Collective."""
    at = r.ids[r.a_rows] == row
    mine = dict(zip(system.dofmap.input_saddle(r.a_dofs[at]).tolist(), r.a_vals[at].tolist()))
    return {c: v for p in COMM.allgather(mine) for c, v in p.items()}


def test_the_operator_row_holds_the_enforced_rows_entries_alone():
    """The group's one multiplier row holds the A entries of one row of the group, on the
    rank owning it: its first at the start (no rank holds the others'), then the enforced
    row's, the operator built anew when the group enforces another row (a cell on another
    rank), kept while the group is released and enforces the same row again."""
    text = MAXIMUM
    model = build_model(parse_scene(tomllib.loads(text), "t.toml", text), COMM)
    system = SaddleSystem(COMM, model)
    rset = system.relation_set
    k = [r.name for r in rset.relations].index("cells")
    r = rset.relations[k]
    grouped = rset.a_gid >= 0
    assert COMM.allreduce(int(grouped.sum())) == 4   # (row 0: its cell's 4 x DOFs)
    assert not np.any(rset.a_gid[grouped] != 0)
    mask = np.ones(rset.nrelrows, dtype=bool)
    ops = [system.op]
    for row in (137, -1, 137, CELLS - 1):   # (-1: the group released)
        mask[rset.rows_of(k)] = r.ids == row
        system.set_active(mask)
        ops.append(system.op)
        carried = 137 if row == -1 else row
        grouped = rset.a_gid >= 0
        assert COMM.allreduce(int(grouped.sum())) == 4
        assert np.all(rset.a_gid[grouped] == carried)
        expected = cell_row(system, r, carried) if row >= 0 else {}
        got = group_row(system)
        assert got.keys() == expected.keys()
        for c, v in expected.items():
            assert abs(got[c] - v) <= 1e-12 * abs(v)
    assert [a is b for a, b in zip(ops, ops[1:])] == [False, True, True, False]


def test_a_moved_group_asks_for_an_assembly_before_a_right_hand_side():
    """The operator built anew when the group moves has no lifting of the eliminated DOFs
    until assembled: a right-hand side asked before raises on every rank alike (before, the
    ranks holding eliminated DOFs raised and the others went on: a hang), and after the
    assembly it is that of a system whose group was on that row from its first assembly."""
    text = MAXIMUM
    rhs = []
    for moved_after_assembly in (True, False):
        model = build_model(parse_scene(tomllib.loads(text), "t.toml", text), COMM)
        system = SaddleSystem(COMM, model)
        rset = system.relation_set
        k = [r.name for r in rset.relations].index("cells")
        ids = rset.relations[k].ids
        q = np.random.default_rng(3).random(system.dofmap.n_local) * 1e-4
        mask = np.ones(rset.nrelrows, dtype=bool)
        if moved_after_assembly:
            mask[rset.rows_of(k)] = ids == 0
            system.set_active(mask)
            system.assemble()
        mask[rset.rows_of(k)] = ids == 137
        system.set_active(mask)
        assert COMM.allreduce(system.n_eliminated) > 0
        if moved_after_assembly:
            with pytest.raises(RuntimeError, match="not yet assembled"):
                system.rhs(0.5, f_int=np.zeros_like(q), q=q)
        system.assemble()
        rhs.append(system.rhs(0.5, f_int=np.zeros_like(q), q=q)[0])
    np.testing.assert_allclose(rhs[0], rhs[1], rtol=0, atol=1e-12 * np.abs(rhs[1]).max())


def test_a_restart_carries_the_groups_operator_row():
    """The row a group's operator row holds is state (``RelationSet.carried``): a released
    group keeps its last row's entries, and a run continued from it (``SaddleSystem.carry``)
    builds the same operator row, on every rank alike; carrying the rows it holds already
    builds nothing."""
    text = MAXIMUM
    systems = []
    for _ in range(2):
        model = build_model(parse_scene(tomllib.loads(text), "t.toml", text), COMM)
        systems.append(SaddleSystem(COMM, model))
    first, later = systems
    rset = first.relation_set
    k = [r.name for r in rset.relations].index("cells")
    ids = rset.relations[k].ids
    mask = np.ones(rset.nrelrows, dtype=bool)
    for row in (137, -1):   # enforced, then released: its entries kept
        mask[rset.rows_of(k)] = ids == row
        first.set_active(mask)
    assert rset.carried.tolist() == [137]
    op = later.op
    later.carry(rset.carried)
    assert later.relation_set.carried.tolist() == [137] and later.op is not op
    mask[later.relation_set.rows_of(k)] = later.relation_set.relations[k].ids == 137
    later.set_active(mask)
    first.set_active(mask)
    assert group_row(later) == group_row(first) != {}
    op = later.op
    later.carry(np.array([137]))
    assert later.op is op


def test_refreshed_values_on_a_group_are_refused():
    """``refresh`` copies the entries each rank keeps, not those sent to a row's owner: a
    maximum group marked refreshed is refused on every rank alike."""
    text = MAXIMUM
    model = build_model(parse_scene(tomllib.loads(text), "t.toml", text), COMM)
    (r,) = [r for r in model.relations if r.maximum]
    r.meta["refresh"] = True
    with pytest.raises(ValueError, match="refreshed between iterations"):
        SaddleSystem(COMM, model)
