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
