"""What a rank holds of the relations on a contact scene whose contact surface splits across
the ranks (the 3D friction box: 147 rows on a rigid obstacle, 441 A and 441 D entries): every
stacked entry kept on exactly one rank, each relation row built and held by one rank (the
owner of its slave node), and each rank's share of the stacked entries, of the multipliers it
holds (owned rows and ghosts), of the relations' own arrays and of the relation set's per-row
vectors at most 0.35 of what one rank holds alone, at 4 ranks. Measured here at 1 / 2 / 3 / 4
ranks: 52,552 / 30,544 / 23,208 / 17,968 B on the largest rank (0.342 of one rank's at 4
ranks); the row and column scales (2,352 B, not counted here) are whole on every rank."""

import tomllib

import numpy as np
from mpi4py import MPI

from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem
from tests.helpers.scene import CONFIGS

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
