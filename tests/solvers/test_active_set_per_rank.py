"""The active set of a relation built per rank (each rank its own rows, ``Relation.ids``):
decisions on each rank's rows, agreed over the ranks where the set as a whole decides (a
change anywhere, the one most needed change, a set already seen) — the same as one rank's
decisions on the whole relation (1, 2, 3 ranks)."""

import numpy as np
from mpi4py import MPI

from parsolve.relations import Relation, rows_here
from parsolve.solvers.active_set import ActiveSet, _Seen

COMM = MPI.COMM_WORLD
N = 7   # rows of the relation over every rank


def per_rank_relation() -> Relation:
    """u[i] >= 0 for rows i = 0..N-1, rank r holding the rows i ≡ r (mod ranks)."""
    ids = np.arange(COMM.rank, N, COMM.size)
    n = ids.size
    r = Relation("c", n, np.arange(n), ids, np.ones(n), np.zeros(n), sense=">=")
    return rows_here(r, ids, N)


def held_ids(aset: ActiveSet, mask: np.ndarray) -> list[int]:
    """The relation rows (global ids) of a mask over the rows held here, from every rank."""
    return sorted(int(k) for part in COMM.allgather(aset.key[mask]) for k in part)


def test_violated_rows_close_on_their_ranks():
    rel = per_rank_relation()
    aset = ActiveSet([rel], comm=COMM)
    aset.start_step()
    # s (A q - b) > 0 is a violation (s = -1 for ">="): rows 1 and 4 penetrate
    excess = np.where(np.isin(rel.ids, [1, 4]), 1.0, -1.0)
    assert aset.update(-excess, np.zeros(rel.nrows), 1e-9, 1e-9, 1.0)
    assert held_ids(aset, aset.active) == [1, 4]
    # nothing changes on any rank: no change anywhere
    assert not aset.update(-excess, np.zeros(rel.nrows), 1e-9, 1e-9, 1.0)


def test_the_one_change_is_the_first_best_row_over_the_ranks():
    rel = per_rank_relation()
    aset = ActiveSet([rel], comm=COMM)
    # rows 1 and 3 tie for the best score: the first (row 1) is taken, on its rank alone
    value = np.array([0.0, 3.0, 1.0, 3.0, 2.0, -np.inf, 0.5])[rel.ids]
    none = np.full(rel.nrows, -np.inf)
    kind, row, key = aset._best([value, none, none])
    assert kind == 0
    taken = COMM.allgather(int(aset.key[row]) if row >= 0 else -1)
    assert sorted(taken) == [-1] * (COMM.size - 1) + [1] and key == 1
    # no finite score anywhere: no row
    assert aset._best([none, none, none])[1] == -1


def test_a_set_was_seen_when_every_rank_saw_its_part_at_once():
    seen = _Seen(COMM, b"start")
    seen.add(b"mine" if COMM.rank == 0 else b"theirs")
    assert b"start" in seen
    assert (b"mine" if COMM.rank == 0 else b"theirs") in seen
    # rank 0's part seen at the second set, the others' at the first: never at once
    mixed = (b"mine" if COMM.rank == 0 else b"start") in seen
    assert mixed == (COMM.size == 1)
