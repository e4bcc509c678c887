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


def _decide_apart(relations, rounds, max_changes=30):
    """The sets an active set decides, every process reading all multipliers, against the
    same on the ranks, each reading the rows it owns (rows dealt out in turn, the others' λ
    garbage): the same sets, every round, on every rank."""
    comm = MPI.COMM_WORLD
    n = sum(r.nrows for r in relations)
    whole = ActiveSet(relations, max_changes)
    mine = np.arange(n) % comm.size == comm.rank
    apart = ActiveSet(relations, max_changes, mine, comm)
    whole.start_step()
    apart.start_step()
    for gap, lam in rounds(whole):
        changed = whole.update(gap, lam, 1e-12, 1e-12)
        seen = np.where(mine, lam, np.nan)   # only its own rows
        assert apart.update(gap, seen, 1e-12, 1e-12) == changed
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
