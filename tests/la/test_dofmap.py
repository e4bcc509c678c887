"""The DOF map on the ranks' parts of a small mesh, against numbers known from the whole mesh:
the saddle numbering is one bijection whatever the ranks, the forward exchange gives every
ghost its owner's value, the reverse one counts the ranks holding a node, and every owned
reduction equals the whole mesh's sum (1, 2, 3 ranks)."""

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.la.dofmap import DofMap
from parsolve.mesh.distribute import distribute
from parsolve.mesh.generators import rectangle
from parsolve.mesh.regions import allgather_rows

COMM = MPI.COMM_WORLD
NC, NMULT = 2, 7
#: multiplier rows per rank (uneven on purpose: the relation set gives each rank its rows)
COUNTS = {1: [7], 2: [5, 2], 3: [0, 4, 3], 4: [2, 0, 4, 1]}


def value(input_dofs: np.ndarray) -> np.ndarray:
    """A known value per input DOF (exact in floating point)."""
    return 0.5 + 3.0 * np.asarray(input_dofs, dtype=float)


@pytest.fixture(scope="module")
def parts():
    whole = rectangle(2.0, 1.0, 8, 4, cell="quad")           # 45 nodes
    local = distribute(COMM, whole if COMM.rank == 0 else None, "bisection")
    dm = DofMap(COMM, local, NC)
    dm.set_multipliers(COUNTS[COMM.size])
    return whole, local, dm


def input_dofs(local) -> np.ndarray:
    return (local.global_nodes.astype(np.int64)[:, None] * NC + np.arange(NC)).ravel()


def test_ranges_and_one_numbering(parts):
    whole, local, dm = parts
    n = COMM.size
    assert dm.nq == 45 * NC and dm.nl == NMULT and dm.size == 45 * NC + NMULT
    np.testing.assert_array_equal(dm.l_ranges, np.concatenate([[0], np.cumsum(COUNTS[n])]))
    np.testing.assert_array_equal(np.diff(dm.offsets), np.diff(dm.q_ranges) + np.diff(dm.l_ranges))
    assert dm.nrows == dm.n_owned + np.diff(dm.l_ranges)[COMM.rank]
    # owned primal rows then the multiplier share: together, every saddle index once
    mine = np.concatenate([dm.saddle_of_local[dm.owned_dofs],
                           dm.l_index(np.arange(dm.l_ranges[COMM.rank], dm.l_ranges[COMM.rank + 1]))])
    np.testing.assert_array_equal(np.sort(mine), dm.offset + np.arange(dm.nrows))
    every = allgather_rows(COMM, mine[:, None])[:, 0]
    np.testing.assert_array_equal(np.sort(every), np.arange(dm.size))
    if n == 1:   # no ghosts: the input numbering itself
        assert dm.n_local == dm.n_owned == 90
        np.testing.assert_array_equal(dm.saddle_of_local, np.arange(90))


def ghost_rows(rank: int) -> np.ndarray:
    """Multiplier rows a rank holds besides its own (some of them its own: dropped)."""
    return np.array([(3 * rank + k) % NMULT for k in range(3)] + [NMULT - 1])


def test_forward_exchange_and_held_values(parts):
    _, local, dm = parts
    counts = COUNTS[COMM.size]
    dm.set_multipliers(counts, ghost_rows(COMM.rank))
    x_owned = np.zeros(dm.nrows)
    x_owned[:dm.n_owned] = value(input_dofs(local)[:dm.n_owned])
    l0, l1 = dm.l_ranges[COMM.rank], dm.l_ranges[COMM.rank + 1]
    x_owned[dm.n_owned:] = 1000.0 + np.arange(l0, l1)
    held = dm.gather(x_owned)
    np.testing.assert_array_equal(held.q, value(input_dofs(local)))   # ghosts: their owners'
    # held: the owned rows, then the others' rows asked for, each its owner's value
    ghosts = np.setdiff1d(ghost_rows(COMM.rank), np.arange(l0, l1))
    np.testing.assert_array_equal(dm.l_held, np.concatenate([np.arange(l0, l1), ghosts]))
    np.testing.assert_array_equal(held.lam, 1000.0 + dm.l_held)
    np.testing.assert_array_equal(dm.held_index(dm.l_held[::-1]), np.arange(dm.n_held)[::-1])
    np.testing.assert_array_equal(held[dm.saddle_of_local], held.q)
    np.testing.assert_array_equal(held[dm.l_index(dm.l_held)], held.lam)
    missing = np.setdiff1d(np.arange(NMULT), dm.l_held)
    for bad in (np.array([dm.size + 5]), dm.l_index(missing[:1])):
        if bad.size:
            with pytest.raises(IndexError):
                held[bad]
    if missing.size:
        with pytest.raises(IndexError):
            dm.held_index(missing)
    assert dm.zeros().lam.size == dm.n_held and not dm.zeros()[dm.l_index(dm.l_held)].any()
    dm.set_multipliers(counts)
    assert dm.n_held == l1 - l0


def test_owned_reductions_equal_the_whole_meshs(parts):
    _, local, dm = parts
    q = value(input_dofs(local))
    every = value(np.arange(45 * NC))
    assert dm.norm(q) == pytest.approx(np.sqrt(every @ every), rel=1e-15)
    assert dm.dot(q, 2.0 * q) == pytest.approx(2.0 * (every @ every), rel=1e-15)
    assert dm.max_abs(q) == every.max()
    # A q of COO rows over input DOFs, the same on every rank
    rng = np.random.default_rng(3)
    dofs = rng.integers(0, 45 * NC, 40)
    rows = rng.integers(0, 5, 40)
    coefs = rng.normal(size=40)
    expected = np.bincount(rows, weights=coefs * every[dofs], minlength=5)
    np.testing.assert_allclose(dm.rows(dofs, rows, coefs, 5, q), expected, rtol=1e-14)


def test_input_ids(parts):
    whole, local, dm = parts
    dofs = np.array([1, 17, 88, 40])
    dm.index_inputs([dofs])
    np.testing.assert_array_equal(dm.input_points(dofs // NC), whole.points[dofs // NC])
    here = dm.local_dofs(dofs)
    on = here >= 0
    np.testing.assert_array_equal(dm.input_saddle(dofs)[on], dm.saddle_of_local[here[on]])
    np.testing.assert_array_equal(dm.local_nodes(local.global_nodes), np.arange(local.num_points))
    assert (dm.local_nodes(np.array([10**6])) == -1).all()
    # a local vector from input entries, and a nodal output on the owned rows
    vec = dm.local_vector(dofs, np.ones(4))
    assert vec.sum() == on.sum()
    out = dm.nodal(dofs // NC, np.arange(4.0), fill=-1.0).values
    owned = local.global_nodes[:local.n_owned]
    expected = np.full(local.n_owned, -1.0)
    for k, node in enumerate(dofs // NC):   # (4 entries: a loop in the reference is fine)
        expected[owned == node] = k
    np.testing.assert_array_equal(out[:, 0], expected)


def test_field_sets(parts):
    _, local, dm = parts
    ys = dm.field_dofs(np.array([1]))
    assert (ys % NC == 1).all() and ys.size == local.n_owned
    rows = dm.field_rows(np.array([0]))
    np.testing.assert_array_equal(rows, dm.saddle_of_local[np.arange(0, dm.n_owned, NC)])
    total = COMM.allreduce(rows.size)
    assert total == 45


def test_local_dofs_of_dofs_not_owned_here(parts):
    """This rank's owned DOFs are its first local DOFs; a DOF of no rank's node gives -1, and
    with ``owned`` (what they are) any DOF not owned here, a ghost's included, is refused
    naming it: a -1 would index the last entry silently."""
    whole, local, dm = parts
    mine = input_dofs(local)
    owned = mine[:dm.n_owned]
    np.testing.assert_array_equal(dm.local_dofs(owned, owned="mine"), np.arange(dm.n_owned))
    nowhere = 45 * NC + 1
    np.testing.assert_array_equal(dm.local_dofs([owned[3], nowhere]), [3, -1])
    with pytest.raises(RuntimeError, match=rf"the far ones: 1 input DOFs not owned by rank "
                                           rf"{COMM.rank} \(the first: {nowhere}\)"):
        dm.local_dofs([owned[3], nowhere], owned="the far ones")
    ghosts = mine[dm.n_owned:]
    assert (ghosts.size > 0) == (COMM.size > 1)
    if ghosts.size:
        np.testing.assert_array_equal(dm.local_dofs(ghosts), np.arange(dm.n_owned, dm.n_local))
        with pytest.raises(RuntimeError, match=f"ghosts: {ghosts.size} input DOFs not owned"):
            dm.local_dofs(ghosts, owned="ghosts")
