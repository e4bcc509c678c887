"""What a rank holds of the relations on a contact scene whose contact surface splits across
the ranks (the 3D friction box: 147 rows on a rigid obstacle, 441 A and 441 D entries): every
stacked entry kept on exactly one rank, each relation row built and held by one rank (the
owner of its slave node), and each rank's share of the stacked entries, of the multipliers it
holds (owned rows and ghosts), of the relations' own arrays and of the relation set's per-row
vectors at most 0.35 of what one rank holds alone, at 4 ranks. Measured here at 1 / 2 / 3 / 4
ranks: 50,592 / 28,920 / 21,696 / 16,536 B on the largest rank (0.327 of one rank's at 4
ranks). The row and column scales are per held multiplier row (owned rows and ghosts), like the
multipliers (counted in the periodic test below)."""

import tomllib

import numpy as np
from mpi4py import MPI

from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem
from tests.helpers.plate import PLATE, dirichlet, mean
from tests.helpers.scene import CONFIGS, scene

COMM = MPI.COMM_WORLD
#: int64 or float64 arrays per stacked A entry (rows, columns, values, relation row) and per
#: D entry (rows, columns, values, held place of the column)
A_ARRAYS, D_ARRAYS = ("a_rows", "a_cols", "a_vals", "a_relrow"), ("d_rows", "d_cols", "d_vals",
                                                                     "_d_held")


def held_bytes(rs, dm) -> int:
    """Bytes of the stacked entries a rank keeps and of the multipliers it holds."""
    arrays = [getattr(rs, n) for n in A_ARRAYS + D_ARRAYS]
    assert all(a.itemsize == 8 for a in arrays)
    return sum(a.nbytes for a in arrays) + 8 * dm.n_held


#: per-row vectors of the relation set (per relation row or multiplier row held here)
ROW_VECTORS = ("position", "mult_of_row", "rep_row", "row_first", "mults_here", "whole_rows",
               "own_rows")
#: the relations' arrays and the per-row vectors on one rank alone
ONE_RANK = 21_192


def whole_bytes(rs) -> int:
    """Bytes of the relations' arrays a rank holds (A's entries, values, duals, groups) and
    of the relation set's per-row vectors."""
    arrays = [getattr(rs, n) for n in ROW_VECTORS]
    for r in rs.relations:
        arrays += [r.a_rows, r.a_dofs, r.a_vals, r.values]
        arrays += list(r.dual or ()) + list(r.shared_dual or ())
        arrays += [r.groups] if r.groups is not None else []
    return sum(np.asarray(a).nbytes for a in arrays)


def test_each_rank_holds_its_share_of_the_relations():
    name = "contact_friction_3d.toml"
    text = (CONFIGS / name).read_text(encoding="utf-8")
    model = build_model(parse_scene(tomllib.loads(text), str(CONFIGS / name), text), COMM)
    system = SaddleSystem(COMM, model)
    rs, dm = system.relation_set, system.dofmap
    # one rank alone keeps every entry of every relation and holds every multiplier (each
    # rank holds its own rows' entries: summed)
    n_a = COMM.allreduce(sum(r.a_vals.size for r in rs.relations))
    n_d = COMM.allreduce(sum(r.shared_dual[0].size if r.collapsed else r.dual_coo()[0].size
                             for r in rs.relations))
    alone = 8 * (len(A_ARRAYS) * n_a + len(D_ARRAYS) * n_d) + 8 * dm.nl
    kept = np.array([rs.a_vals.size, rs.d_vals.size], dtype=np.int64)
    COMM.Allreduce(MPI.IN_PLACE, kept)
    assert kept.tolist() == [n_a, n_d] == [441, 441]
    mine = held_bytes(rs, dm)
    most = COMM.allreduce(mine, op=MPI.MAX)
    owners = COMM.allreduce(int(dm.l_ranges[COMM.rank + 1] > dm.l_ranges[COMM.rank]))
    assert owners == COMM.size   # the surface splits: every rank owns contact rows
    if COMM.size == 1:
        assert mine == alone
    if COMM.size == 4:
        assert most <= 0.35 * alone, (most, alone)
    # the relations: each row on one rank (147 relation rows: 49 normal, 98 tangential)
    assert COMM.allreduce(rs.nrelrows) == 147
    assert [r.total for r in rs.relations] == [49, 98]
    ids = np.concatenate([r.row_ids() + 49 * k for k, r in enumerate(rs.relations)])
    assert np.array_equal(np.sort(np.concatenate(COMM.allgather(ids))), np.arange(147))
    whole = whole_bytes(rs)
    if COMM.size == 1:
        assert whole == ONE_RANK
    with_whole = COMM.allreduce(mine + whole, op=MPI.MAX)
    if COMM.size == 4:
        assert with_whole <= 0.35 * (alone + ONE_RANK), (with_whole, alone + ONE_RANK)


#: the periodic laminate refined to 24 × 24 cells with its Dirichlet rows multiplied: 146 rows,
#: each built and held by one rank (bottom 50, top 25 + 25: Dirichlet; the periodic tie 46,
#: its A row and D column on the partner node's rank too)
PERIODIC = (CONFIGS / "periodic_shear_laminate.toml").read_text(encoding="utf-8") \
    .replace("nx = 6", "nx = 24").replace("ny = 8", "ny = 24") + "\n[solver]\neliminate = false\n"
#: the relations' arrays, the per-row vectors and the row and column scales on one rank alone
ONE_RANK_PERIODIC = 13_992


def test_dirichlet_and_periodic_rows_split_across_the_ranks():
    """Multiplied Dirichlet rows and periodic ties, each built by the rank owning the DOF or
    node it constrains: every row on one rank, numbered as on one rank; every stacked entry
    kept on one rank (a tie's D entry on its partner's rank); A q of a tie reading its partner
    on another rank; and the largest rank's share of the bytes at most 0.35 of one rank's at
    4 ranks. Measured at 1 / 2 / 3 / 4 ranks: 27,448 / 13,992 / 15,096 / 9,064 B on the
    largest rank (0.330 of one rank's at 4 ranks; at 3 ranks the partition gives one rank 78
    of the 146 rows, most of two sides)."""
    model = build_model(parse_scene(tomllib.loads(PERIODIC), "periodic.toml", PERIODIC), COMM)
    system = SaddleSystem(COMM, model)
    system.assemble()   # (the scales)
    rs, dm = system.relation_set, system.dofmap
    assert [r.name for r in rs.relations] == ["bottom_held", "top_shear", "top_y", "cell"]
    assert [r.total for r in rs.relations] == [50, 25, 25, 46]
    assert not any(r.whole for r in rs.relations)
    for r in rs.relations:   # each row on one rank, numbered by its place in the whole relation
        ids = np.concatenate(COMM.allgather(r.row_ids()))
        assert np.array_equal(np.sort(ids), np.arange(r.total))
    n_a = COMM.allreduce(sum(r.a_vals.size for r in rs.relations))
    kept = np.array([rs.a_vals.size, rs.d_vals.size], dtype=np.int64)
    COMM.Allreduce(MPI.IN_PLACE, kept)
    assert kept.tolist() == [n_a, n_a] == [50 + 25 + 25 + 2 * 46] * 2   # associated: D = -Aᵀ
    # A q of every row, q the input DOF numbers: a tie u_a - u_b reads u_b where it is owned
    local = dm.mesh
    q = ((local.global_nodes.astype(np.int64)[:, None] * dm.ncomp + np.arange(dm.ncomp))
         .ravel().astype(float))
    every = np.arange(local.num_global_points * dm.ncomp, dtype=float)
    expected = np.concatenate([r.primal(every) for r in rs.relations])
    np.testing.assert_array_equal(rs.primal_values(q), expected)
    tie = rs.relations[3]
    assert np.all(np.abs(expected[rs.rows_of(3)]) > 0) or tie.nrows == 0
    # the bytes
    alone = 8 * (len(A_ARRAYS) + len(D_ARRAYS)) * n_a + 8 * dm.nl
    mine = held_bytes(rs, dm) + whole_bytes(rs) + rs.row_scale.nbytes + rs.col_scale.nbytes
    most = COMM.allreduce(mine, op=MPI.MAX)
    if COMM.size == 1:
        assert mine == alone + ONE_RANK_PERIODIC, (mine, alone)
    if COMM.size == 4:
        assert most <= 0.35 * (alone + ONE_RANK_PERIODIC), (most, alone + ONE_RANK_PERIODIC)


#: a 48 × 24 plate whose relations cover the mesh split across the ranks: every node's y held
#: and the left side's x (eliminated Dirichlet rows: 1,225 + 25), the top's x, multiplied (48
#: rows: its left corner is left_x's); spread rows: the mean x of the right side controlled by
#: a load there, the mean x of each quarter (at 4 ranks each quarter mostly one rank's) and the
#: mean strain of every cell (its entries on the boundary's nodes, the inner ones cancelling)
COVERED = scene(
    PLATE, mesh={"nx": 48, "ny": 24},
    regions={q: {"box": [[x, y], [x + 1.0, y + 0.5]]}
             for q, (x, y) in zip("abcd", [(0.0, 0.0), (1.0, 0.0), (0.0, 0.5), (1.0, 0.5)])},
    relations=[dirichlet("held_y", "all", "y"), dirichlet("left_x", "left", "x"),
               dirichlet("top_x", "top", "x", eliminate=False),
               mean("mean_x", "right", 1e-4, dual="pull")]
    + [mean(f"mean_{q}", q, 0.0, eliminate=False) for q in "abcd"]
    + [{"name": "mean_strain", "type": "strain", "region": "all", "component": "xx"}])
#: what one rank alone holds of them (relations, stacking, per-row vectors, scales, held
#: multipliers, the eliminated DOFs' arrays)
ONE_RANK_COVERED = 240_042
#: the system's arrays per eliminated DOF it reads (its own, then the others' its rows name)
ELIM_ARRAYS = ("elim_dofs", "elim_coefs", "_elim_refs", "_elim_which", "elim_local",
               "elim_saddle", "elim_own")


def relation_bytes(system) -> int:
    """Bytes of what a rank holds of the relations, the eliminated ones included: their own
    arrays (A, values, duals, a strain's cells), the relation set's stacked entries, per-row
    vectors, scales and held multipliers, and the system's arrays of the eliminated DOFs."""
    rs, dm = system.relation_set, system.dofmap
    arrays = [getattr(rs, n) for n in A_ARRAYS + D_ARRAYS + ROW_VECTORS]
    arrays += [rs.row_scale, rs.col_scale] + [getattr(system, n) for n in ELIM_ARRAYS]
    for r in system.model.relations:
        arrays += [r.a_rows, r.a_dofs, r.a_vals, r.values]
        arrays += list(r.dual or ()) + list(r.shared_dual or ())
        arrays += [a for a in (r.groups, r.meta.get("cells"), r.meta.get("cell_rows"))
                   if a is not None]
    return sum(np.asarray(a).nbytes for a in arrays) + 8 * dm.n_held


def test_dirichlet_and_spread_rows_over_the_mesh_split_across_the_ranks():
    """Eliminated Dirichlet rows are held by the rank owning their DOF (none gathered), each
    rank reading the others' only where its rows name them (its ghosts, its relation rows'
    columns); spread rows' entries on their DOFs' owners, a row's A entries on its owner: the
    largest rank holds at most 0.35 of what one rank holds alone at 4 ranks. Measured at
    1 / 2 / 3 / 4 ranks: 240,042 / 126,627 / 92,475 / 71,405 B on the largest rank (0.297 of
    one rank's at 4 ranks; main held the eliminated rows and DOFs whole on every rank)."""
    model = build_model(parse_scene(tomllib.loads(COVERED), "covered.toml", COVERED), COMM)
    system = SaddleSystem(COMM, model)
    system.assemble()   # (the scales)
    assert [r.name for r in system.eliminated] == ["held_y", "left_x"]
    assert [r.total for r in system.eliminated] == [49 * 25, 25]
    assert [(r.name, r.total) for r in system.multiplied] == [
        ("top_x", 48), ("mean_x", 1), ("mean_a", 1), ("mean_b", 1), ("mean_c", 1), ("mean_d", 1),
        ("mean_strain", 1)]
    # each eliminated row on the rank owning its DOF, every row once over the ranks
    own = system.elim_dofs[system.elim_own]
    assert np.all(system.elim_local[system.elim_own] < system.dofmap.n_owned)
    every = np.concatenate(COMM.allgather(own))
    assert every.size == np.unique(every).size == 49 * 25 + 25
    assert system.n_eliminated == every.size
    # the others' a rank reads: its ghosts' and its rows' columns, never every one
    read = system.elim_dofs[~system.elim_own]
    assert np.isin(read, every).all() and not np.isin(read, own).any()
    mine = relation_bytes(system)
    most = COMM.allreduce(mine, op=MPI.MAX)
    if COMM.size == 1:
        assert mine == ONE_RANK_COVERED, mine
    if COMM.size == 4:
        assert most <= 0.35 * ONE_RANK_COVERED, (most, ONE_RANK_COVERED)

