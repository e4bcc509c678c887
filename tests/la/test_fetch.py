"""``Fetch``: a primal vector's values at DOFs any rank owns, from their owners, the same plan
for the relation set (a tie's other end) and contact (master nodes). Run at 1, 2, 3 ranks."""

import numpy as np
from mpi4py import MPI

from parsolve.la.fetch import Fetch

COMM = MPI.COMM_WORLD


def test_values_at_any_ranks_dofs_come_from_their_owners():
    """Rank r owns nodes [5 r + r², ...) (uneven blocks), 3 components; its vector holds
    1000 · node + component at its owned DOFs, then ghosts that must not be read (NaN). Each
    rank asks for DOFs of every rank, some twice, in any order, and of none."""
    ncomp, sizes = 3, [5 + r for r in range(COMM.size)]
    ranges = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    lo, hi = ranges[COMM.rank], ranges[COMM.rank + 1]
    nodes = np.arange(lo, hi)
    q = np.concatenate([(1000.0 * nodes[:, None] + np.arange(ncomp)).ravel(),
                        np.full(7, np.nan)])
    rng = np.random.default_rng(11 + COMM.rank)
    wanted = rng.integers(0, ranges[-1] * ncomp, size=20 + COMM.rank)
    wanted = np.concatenate([wanted, wanted[:3]])
    got = Fetch(COMM, wanted, ranges, ncomp)(q)
    node, comp = np.divmod(wanted, ncomp)
    np.testing.assert_array_equal(got, 1000.0 * node + comp)
    none = Fetch(COMM, np.zeros(0, dtype=np.int64), ranges, ncomp)(q)
    assert none.shape == (0,)


def test_a_tables_columns_come_in_one_call():
    """``width``: each owned DOF's row of a table (n, 2) (1000 · DOF and −DOF, then ghost rows
    that must not be read) at DOFs of every rank, both columns from one call."""
    ncomp, sizes = 2, [4 + 2 * r for r in range(COMM.size)]
    ranges = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    q0, q1 = ranges[COMM.rank] * ncomp, ranges[COMM.rank + 1] * ncomp
    dofs = np.arange(q0, q1, dtype=float)
    table = np.vstack([np.column_stack([1000.0 * dofs, -dofs]), np.full((5, 2), np.nan)])
    wanted = np.random.default_rng(5 + COMM.rank).integers(0, ranges[-1] * ncomp, size=15)
    got = Fetch(COMM, wanted, ranges, ncomp, width=2)(table)
    np.testing.assert_array_equal(got, np.column_stack([1000.0 * wanted, -wanted]))
