"""The relation set on the ranks' parts of a small mesh, against the relations' own dense
products on the whole mesh (``Relation.primal``, ``Relation.reaction``): stacking and the
collapsed group's one multiplier row, A q in one reduction, gaps, D λ on the owned rows,
scales, per-relation views and the in-place refresh of refreshed relations (1, 2, 3 ranks)."""

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.la.dofmap import DofMap
from parsolve.la.relation_set import RelationSet
from parsolve.mesh.distribute import distribute
from parsolve.mesh.generators import rectangle
from parsolve.mesh.regions import allgather_rows
from parsolve.relations import Relation

from helpers.scales import whole_scales

COMM = MPI.COMM_WORLD
NC, NPTS = 2, 45


def value(input_dofs) -> np.ndarray:
    return 0.5 + 3.0 * np.asarray(input_dofs, dtype=float)


def relations() -> list[Relation]:
    tie = Relation("tie", 3, [0, 1, 1, 2, 2], [0, 89, 10, 40, 42], [1.0, 2.0, -1.0, 1.0, 1.0],
                   [1.0, 2.0, 3.0])                                   # associated
    push = Relation("push", 2, [0, 1], [7, 60], [1.0, 1.0], [0.5, -0.5], sense=">=",
                    dual=(np.array([7, 61, 60]), np.array([0, 0, 1]), np.array([1.0, 4.0, -2.0])),
                    meta={"refresh": True})                           # non-associated
    peak = Relation("peak", 3, [0, 1, 2], [3, 33, 63], [1.0, 1.0, 1.0], [9.0, 9.0, 9.0],
                    sense="<=", maximum=True,
                    shared_dual=(np.array([80, 81]), np.array([1.0, 1.0])))   # collapsed
    return [tie, push, peak]


@pytest.fixture()
def rset():
    whole = rectangle(2.0, 1.0, 8, 4, cell="quad")
    local = distribute(COMM, whole if COMM.rank == 0 else None, "bisection")
    rels = relations()
    dm = DofMap(COMM, local, NC)
    dm.index_inputs([r.a_dofs for r in rels] + [r.dual_coo()[0] for r in rels])
    q = value((local.global_nodes.astype(np.int64)[:, None] * NC + np.arange(NC)).ravel())
    return RelationSet(rels, dm), q


def test_stacking(rset):
    rs, _ = rset
    assert rs.nrows == 6 and rs.nrelrows == 8 and len(rs) == 3
    pos = rs.position    # multiplier rows in stacking order (numbered by owner)
    np.testing.assert_array_equal(np.sort(pos), np.arange(6))
    np.testing.assert_array_equal(rs.mult_of_row, pos[[0, 1, 2, 3, 4, 5, 5, 5]])
    np.testing.assert_array_equal(rs.rep_row[pos], [0, 1, 2, 3, 4, 5])   # a group: its first row
    assert rs.locate(6) == (2, 1) and rs.rows_of(1) == slice(3, 5)
    views = rs.views(np.arange(8.0))
    assert list(views) == ["tie", "push", "peak"]
    np.testing.assert_array_equal(views["peak"], [5.0, 6.0, 7.0])


def test_primal_values_and_gaps(rset):
    rs, q = rset
    every = value(np.arange(NPTS * NC))
    expected = np.concatenate([r.primal(every) for r in rs.relations])
    np.testing.assert_allclose(rs.primal_values(q), expected, rtol=1e-15)
    np.testing.assert_allclose(rs.relation_primal(rs.relations[1], q), expected[3:5], rtol=1e-15)
    b = np.concatenate([r.rhs(0.5) for r in rs.relations])
    _, _, l0, l1 = rs.dofmap.owned()   # (gaps: of the owned rows)
    np.testing.assert_allclose(rs.gap(0.5, q), (b - expected)[rs.rep_row][l0:l1],
                               rtol=1e-15)
    # the enforced row of the group moves to its third row: its gap follows
    active = np.array([True] * 5 + [False, False, True])
    on = rs.select(active)
    pos = rs.position
    assert on.all() and rs.rep_row[pos[5]] == 7
    gap = rs.gap(0.5, q)   # (collective)
    if l0 <= pos[5] < l1:
        np.testing.assert_allclose(gap[pos[5] - l0], b[7] - expected[7], rtol=1e-15)
    lam = np.empty(6)
    lam[pos] = np.arange(6.0)   # the stacked rows' values, in multiplier numbering
    _, _, l0, l1 = rs.dofmap.owned()   # (from this rank's owned rows, gathered)
    np.testing.assert_array_equal(rs.per_relation(lam[l0:l1])["peak"], [0.0, 0.0, 5.0])


def test_reactions_on_the_owned_rows(rset):
    rs, _ = rset
    dm = rs.dofmap
    lam = np.array([1.0, -2.0, 0.5, 3.0, 7.0, 2.0])   # stacking order
    numbered = np.empty(6)
    numbered[rs.position] = lam
    _, _, l0, l1 = dm.owned()   # each rank its owned rows: the ghosts' from their owners
    owned = rs.reactions(numbered[l0:l1])
    assert owned.size == dm.nrows and not owned[dm.n_owned:].any()
    # back to input DOFs: each owned row once, from every rank
    local = dm.mesh
    ids = (local.global_nodes[:local.n_owned].astype(np.int64)[:, None] * NC + np.arange(NC)).ravel()
    rows = dm.saddle_of_local[:dm.n_owned] - dm.offset
    pairs = allgather_rows(COMM, np.column_stack([ids.astype(float), owned[rows]]))
    got = np.zeros(NPTS * NC)
    got[pairs[:, 0].astype(np.int64)] = pairs[:, 1]
    expected = np.zeros(NPTS * NC)
    per_row = [lam[0:3], lam[3:5], np.array([lam[5], 0.0, 0.0])]
    for r, lr in zip(rs.relations, per_row):
        dofs, force = r.reaction(lr)
        np.add.at(expected, dofs, force)
    np.testing.assert_allclose(got, expected, rtol=1e-15, atol=0)


def test_scales_and_right_hand_side(rset):
    rs, q = rset
    rs.set_scales(10.0)
    pos = rs.position
    row_scale, col_scale = whole_scales(rs)
    np.testing.assert_allclose(row_scale[pos], [10.0, 5.0, 10.0, 10.0, 10.0, 10.0])
    # associated: the column scale is the row's; the others from |D|
    np.testing.assert_allclose(col_scale[pos], [10.0, 5.0, 10.0, 2.5, 5.0, 10.0])
    # per held multiplier row (owned, then ghosts): the owners' scales
    np.testing.assert_array_equal(rs.row_scale, row_scale[rs.dofmap.l_held])
    np.testing.assert_array_equal(rs.col_scale, col_scale[rs.dofmap.l_held])
    _, _, l0, l1 = rs.dofmap.owned()   # the owned rows (the right-hand side, the residual)
    b = np.concatenate([r.rhs(1.0) for r in rs.relations])[rs.rep_row]
    np.testing.assert_allclose(rs.rhs(1.0), (b * row_scale)[l0:l1], rtol=1e-15)
    every = value(np.arange(NPTS * NC))
    aq = np.concatenate([r.primal(every) for r in rs.relations])[rs.rep_row]
    np.testing.assert_allclose(rs.scaled_residual(1.0, q),
                               ((b - aq) * row_scale)[l0:l1], rtol=1e-14)
    held = np.ones(rs.dofmap.n_held)
    np.testing.assert_allclose(rs.multipliers(held), col_scale[l0:l1])


def test_refresh_in_place(rset):
    """A q reads the relations' current values; the stacked copy the operator reads follows
    them only on refresh (the relations marked ``refresh``)."""
    rs, q = rset
    push, tie = rs.relations[1], rs.relations[0]
    push.a_vals[:] = [2.0, -1.0]                       # a turned row: same sparsity
    push.dual[2][:] = [1.0, 1.0, 1.0]
    tie.a_vals[0] = 5.0                                # not marked: never copied
    every = value(np.arange(NPTS * NC))
    np.testing.assert_allclose(rs.primal_values(q)[3:5], push.primal(every), rtol=1e-15)
    a, d = stacked(rs)
    np.testing.assert_array_equal(a[(a[:, 0] >= 3) & (a[:, 0] < 5), 2], [1.0, 1.0])
    rs.refresh()
    a, d = stacked(rs)
    np.testing.assert_array_equal(a[(a[:, 0] >= 3) & (a[:, 0] < 5), 2], [2.0, -1.0])
    pushed = np.isin(d[:, 0], rs.position[3:5])
    np.testing.assert_array_equal(d[pushed, 2], [1.0, 1.0, 1.0])
    assert a[0, 0] == 0 and a[0, 2] == 1.0


def stacked(rs) -> tuple[np.ndarray, np.ndarray]:
    """Every rank's kept entries, gathered and sorted: A as (relation row, new DOF, value), D
    as (multiplier row, new DOF, value)."""
    a = allgather_rows(COMM, np.column_stack([rs.a_relrow, rs.a_cols, rs.a_vals]).astype(float))
    d = allgather_rows(COMM, np.column_stack([rs.d_cols, rs.d_rows, rs.d_vals]).astype(float))
    return a[np.lexsort(a.T[::-1])], d[np.lexsort(d.T[::-1])]


def test_each_rank_keeps_its_operator_rows_only(rset):
    """A entries of the multiplier rows a rank owns, D entries on the primal DOFs it owns:
    each entry of the relations on one rank, none twice (tie 5 + push 2 + peak 3 A entries;
    tie's Aᵀ 5 + push's 3 + the peak's one shared column 2 D entries)."""
    rs, _ = rset
    q0, q1, l0, l1 = rs.dofmap.owned()
    assert np.all((rs.a_rows >= l0) & (rs.a_rows < l1))
    assert np.all((rs.d_rows >= q0) & (rs.d_rows < q1))
    a, d = stacked(rs)
    assert a.shape[0] == 10 and d.shape[0] == 10
    new = rs.dofmap.input_new_dof
    rels = rs.relations
    want_a = np.concatenate([np.column_stack([r.a_rows + rs.rows_of(k).start, new(r.a_dofs),
                                              r.a_vals]) for k, r in enumerate(rels)])
    np.testing.assert_array_equal(a, want_a[np.lexsort(want_a.T[::-1])])


def test_rows_live_with_most_of_their_dofs(rset):
    """A multiplier row is owned by the rank owning most of the DOFs its A row and D column
    name (ties: the lowest rank), each rank's rows after the lower ranks' in stacking order;
    the DOF map's ranges are those counts."""
    rs, _ = rset
    dm = rs.dofmap
    # the DOFs of each stacked row: tie (3 rows), push (2), peak (one collapsed row)
    named = [[0, 0], [89, 10, 89, 10], [40, 42, 40, 42], [7, 7, 61], [60, 60],
             [3, 33, 63, 80, 81]]
    nodes = np.unique(np.concatenate(named)) // NC
    own, _ = dm.owned_nodes(nodes)
    node_owner = dm.sum_ranks(np.where(own, COMM.rank, 0).astype(np.int64))
    owner = []
    for dofs in named:
        count = np.bincount(node_owner[np.searchsorted(nodes, np.array(dofs) // NC)],
                            minlength=COMM.size)
        owner.append(int(np.argmax(count)))          # the first of the largest: lowest rank
    owner = np.array(owner)
    expected = np.argsort(np.argsort(owner, kind="stable"), kind="stable")
    np.testing.assert_array_equal(rs.position, expected)
    np.testing.assert_array_equal(np.diff(dm.l_ranges), np.bincount(owner, minlength=COMM.size))
    l0, l1 = dm.l_ranges[COMM.rank], dm.l_ranges[COMM.rank + 1]
    mine = np.flatnonzero((rs.position >= l0) & (rs.position < l1))
    np.testing.assert_array_equal(mine, np.flatnonzero(owner == COMM.rank))


def test_owned_reads_and_fetched_relations(rset):
    """Each rank reads its owned rows' multipliers; a relation's rows fetched from their
    owners (``relation_values``, ``by_relation``) are the row values of the whole vector."""
    rs, _ = rset
    lam = np.array([1.0, -2.0, 0.5, 3.0, 7.0, 2.0])   # stacking order
    numbered = np.empty(6)
    numbered[rs.position] = lam
    _, _, l0, l1 = rs.dofmap.owned()
    every = np.array([1.0, -2.0, 0.5, 3.0, 7.0, 2.0, 0.0, 0.0])   # per relation row
    mine = rs.owned_relrows
    np.testing.assert_array_equal(mine, (rs.mult_of_row >= l0) & (rs.mult_of_row < l1))
    assert mine[5:].all() or not mine[5:].any()   # a collapsed group: one owner
    # every row on exactly one rank
    np.testing.assert_array_equal(COMM.allreduce(mine.astype(np.int64)), np.ones(8))
    np.testing.assert_array_equal(rs.owned_row_values(numbered[l0:l1]), np.where(mine, every, 0.0))
    np.testing.assert_array_equal(rs.every_row(numbered[l0:l1]), every)
    np.testing.assert_array_equal(rs.relation_values(1, numbered[l0:l1]), [3.0, 7.0])
    fetched = rs.by_relation(numbered[l0:l1])
    assert list(fetched) == ["tie", "push", "peak"] and len(fetched) == 3
    np.testing.assert_array_equal(fetched["peak"], [2.0, 0.0, 0.0])
    np.testing.assert_array_equal(fetched["tie"], [1.0, -2.0, 0.5])
    assert fetched["peak"] is fetched["peak"]   # fetched once


def test_owned_primal_sums_each_row_on_its_owner(rset):
    """A q of the rows a rank owns, its entries summed from the ranks owning their DOFs (the
    tie's rows cross ranks on a partition): the whole vector's values there, 0 elsewhere."""
    rs, q = rset
    every = value(np.arange(NPTS * NC))
    expected = np.concatenate([r.primal(every) for r in rs.relations])
    mine = rs.owned_relrows
    got = rs.owned_primal(q)
    np.testing.assert_allclose(got[mine], expected[mine], rtol=1e-15)
    assert not got[~mine].any()
    np.testing.assert_allclose(rs.owned_primal(2.0 * q)[mine], 2.0 * expected[mine], rtol=1e-15)


def test_groups_are_owned_together():
    """Each local group the active set decides together (a relation's groups) has one owner,
    whatever its rows' DOFs; a maximum group's rows need not (the group is decided by
    reductions): each row goes with its own DOFs."""
    whole = rectangle(2.0, 1.0, 8, 4, cell="quad")
    local = distribute(COMM, whole if COMM.rank == 0 else None, "bisection")
    far = [0, 89, 44, 60, 2, 88]   # DOFs at both ends of the strip
    rels = [Relation("max", 3, [0, 1, 2], far[:3], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0],
                     sense="<=", maximum=True),
            Relation("pairs", 4, [0, 1, 2, 3], far[2:], [1.0] * 4, [0.0] * 4, sense="<=",
                     groups=np.array([0, 1, 0, 1]))]
    dm = DofMap(COMM, local, NC)
    dm.index_inputs([r.a_dofs for r in rels])
    rs = RelationSet(rels, dm)
    owner = np.searchsorted(dm.l_ranges, rs.mult_of_row, side="right") - 1
    node_owner = dm.sum_ranks(np.where(dm.owned_nodes(np.array(far[:3]) // NC)[0], COMM.rank,
                                       0).astype(np.int64))
    np.testing.assert_array_equal(owner[:3], node_owner)
    assert owner[3] == owner[5] and owner[4] == owner[6]
