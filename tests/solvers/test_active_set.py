"""The active-set loop on small dense systems against brute-force enumeration of all sets."""

import itertools

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.errors import SolverError
from parsolve.relations import Relation
from parsolve.solvers.active_set import ActiveSet


def problem(seed: int, n: int = 6, m: int = 4):
    rng = np.random.default_rng(seed)
    L = rng.normal(size=(n, n))
    K = L @ L.T + n * np.eye(n)
    A = rng.normal(size=(m, n))
    b = rng.normal(size=m) * 0.3
    F = rng.normal(size=n)
    senses = rng.choice(["<=", ">="], size=m)
    return K, A, b, F, senses


def solve(K, A, b, F, active):
    """K q + Aᵀ λ = F, A_active q = b_active, λ_inactive = 0 (associated: D = -Aᵀ)."""
    n, m = K.shape[0], A.shape[0]
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = K, A.T * active
    M[n:, :n] = A * active[:, None]
    M[n:, n:] = np.diag(1.0 - active)
    x = np.linalg.solve(M, np.concatenate([F, b * active]))
    return x[:n], x[n:]


def relations_of(A, b, senses):
    return [Relation(f"r{k}", 1, [0], [0], [1.0], [b[k]], sense=senses[k]) for k in range(len(b))]


def brute_force(K, A, b, F, senses):
    s = np.where(senses == "<=", 1.0, -1.0)
    found = []
    for bits in itertools.product([0.0, 1.0], repeat=len(b)):
        active = np.array(bits)
        q, lam = solve(K, A, b, F, active)
        feasible = np.all(s * (A @ q - b) <= 1e-9) and np.all(s * lam >= -1e-9)
        if feasible:
            found.append((active, q, lam))
    return found


@pytest.mark.parametrize("seed", range(25))
def test_matches_enumeration(seed):
    K, A, b, F, senses = problem(seed)
    solutions = brute_force(K, A, b, F, senses)
    assert len(solutions) == 1  # K SPD: the complementarity problem has one solution
    aset = ActiveSet(relations_of(A, b, senses))
    aset.start_step()
    for _ in range(50):
        q, lam = solve(K, A, b, F, aset.active.astype(float))
        if not aset.update(A @ q - b, lam, 1e-12, 1e-12):
            break
    expected_active, expected_q, expected_lam = solutions[0]
    np.testing.assert_array_equal(aset.active, expected_active.astype(bool))
    np.testing.assert_allclose(q, expected_q, atol=1e-12)
    np.testing.assert_allclose(lam, expected_lam, atol=1e-12)


def test_maximum_group_enforces_the_largest_row():
    """Rows of a maximum relation: exactly one enforced, the one with the largest value."""
    rel = Relation("max", 5, np.arange(5), np.arange(5), np.ones(5), np.zeros(5), sense="<=",
                   maximum=True)
    aset = ActiveSet([rel])
    aset.start_step()
    gap = np.array([0.0, 0.3, 0.7, 0.7, -1.0])
    assert aset.update(gap, np.zeros(5), 1e-12, 1e-12)
    np.testing.assert_array_equal(np.flatnonzero(aset.active), [2])  # ties: lowest row
    # enforced row at its value, all others below: settled
    assert not aset.update(np.array([-0.7, -0.4, 0.0, -1e-3, -1.7]), np.zeros(5), 1e-12, 1e-12)
    # another row exceeds it: the enforced row moves there
    assert aset.update(np.array([-0.7, 0.1, 0.0, -1e-3, -1.7]), np.zeros(5), 1e-12, 1e-12)
    np.testing.assert_array_equal(np.flatnonzero(aset.active), [1])


def test_cycling_is_bounded():
    rel = Relation("u", 2, [0, 1], [0, 1], [1.0, 1.0], [0.0, 0.0], sense="<=")
    aset = ActiveSet([rel], max_changes=5)
    aset.start_step()
    with pytest.raises(SolverError, match="did not settle"):
        for k in range(100):  # an adversary that always violates the inactive row
            gap = np.where(aset.active, 0.0, 1.0)
            lam = np.where(aset.active, -1.0, 0.0)
            aset.update(gap, lam, 1e-12, 1e-12)


def _decide_apart(relations, rounds, max_changes=30, owner=None):
    """The sets an active set decides, every process reading every row's gap and
    multiplier, against the same on the ranks, each reading the rows it owns (``owner``;
    default: rows dealt out in turn; the others' values NaN): the same sets, every round,
    on every rank."""
    comm = MPI.COMM_WORLD
    n = sum(r.nrows for r in relations)
    whole = ActiveSet(relations, max_changes)
    mine = (np.arange(n) if owner is None else owner) % comm.size == comm.rank
    apart = ActiveSet(relations, max_changes, mine, comm)
    whole.start_step()
    apart.start_step()
    for gap, lam in rounds(whole):
        changed = whole.update(gap, lam, 1e-12, 1e-12)
        # only its own rows
        seen_gap, seen_lam = np.where(mine, gap, np.nan), np.where(mine, lam, np.nan)
        assert apart.update(seen_gap, seen_lam, 1e-12, 1e-12) == changed
        np.testing.assert_array_equal(apart.active, whole.active)
        np.testing.assert_array_equal(comm.allgather(apart.active.tobytes()),
                                      [apart.active.tobytes()] * comm.size)


@pytest.mark.parametrize("seed", range(6))
def test_owned_rows_decide_as_the_whole(seed):
    K, A, b, F, senses = problem(seed, n=8, m=7)
    rels = relations_of(A, b, senses)

    def rounds(aset):
        for _ in range(20):
            q, lam = solve(K, A, b, F, aset.active.astype(float))
            yield A @ q - b, lam

    _decide_apart(rels, rounds)


def test_owned_rows_decide_the_single_change_as_the_whole():
    """Cycling: the one change (the worst pulling row, found on its owner) is the same."""
    rel = Relation("u", 5, np.arange(5), np.arange(5), np.ones(5), np.zeros(5), sense="<=")

    def rounds(aset):
        for k in range(4):   # every row closes, then all pull; then it cycles
            yield np.where(aset.active, 0.0, 1.0), np.where(aset.active, -1.0 - np.arange(5), 0.0)

    with pytest.raises(SolverError, match="did not settle"):
        _decide_apart([rel], rounds, max_changes=3)


def test_owned_rows_decide_a_forming_zone_and_groups_as_the_whole():
    """A forming contact zone (its violated rows' count and deepest excess reduced over the
    ranks) and maximum groups (each on one rank: their rows' owner) beside free rows."""
    from parsolve.evolution import CONSTANT
    contact = Relation("c", 6, np.arange(6), np.arange(6), np.ones(6), np.zeros(6), CONSTANT,
                       ">=", None, eliminate=False, forming=True)
    peak = Relation("peak", 3, np.arange(3), np.arange(3), np.ones(3), np.zeros(3),
                    sense="<=", maximum=True)
    pairs = Relation("pairs", 4, np.arange(4), np.arange(4), np.ones(4), np.zeros(4),
                     sense="<=", groups=np.array([0, 0, 1, 1]))
    # contact rows in turn; the peak's rows on one rank, each pair on one rank
    owner = np.concatenate([np.arange(6), [1, 1, 1], [2, 2, 0, 0]])
    gaps = [-np.array([1.0, 0.3, 0.8, 0.0, 0.55, 0.2]),     # forming: >= 0.5 of the deepest
            -np.array([0.0, 0.3, 0.0, 0.1, 0.0, 0.2])]      # then every violated row
    group_gaps = [np.array([0.1, 0.5, 0.2, 0.3, 0.1, -0.1, 0.2]),
                  np.array([0.1, 0.2, 0.6, 0.1, 0.3, 0.2, -0.1])]

    def rounds(aset):
        for g, h in zip(gaps, group_gaps):
            yield np.concatenate([g, h]), np.zeros(13)

    _decide_apart([contact, peak, pairs], rounds, owner=owner)
    whole = ActiveSet([contact, peak, pairs])
    whole.start_step()
    whole.update(np.concatenate([gaps[0], group_gaps[0]]), np.zeros(13), 1e-12, 1e-12)
    np.testing.assert_array_equal(np.flatnonzero(whole.active), [0, 2, 4, 7, 9, 12])
    whole.update(np.concatenate([gaps[1], group_gaps[1]]), np.zeros(13), 1e-12, 1e-12)
    np.testing.assert_array_equal(np.flatnonzero(whole.active), [0, 1, 2, 3, 4, 5, 8, 10, 11])
