"""A stiffness pattern that changes between steps: a declared term whose node tuples move to
nodes no cell joins (``Term.nodes`` given anew), the system restructured, derives its pattern
again from the declared terms and preallocates it (new node pairs, the old ones gone), and
the assembled operator is the brute-force dense sum of the cells and the tuples where they
are now; on 1, 2 and 3 ranks. Tuples in the partition's global node numbers (a contact
pair whose slave and master facet lie on different ranks), declared by each rank owning one
of their nodes, are assembled whole though a rank holds no part of their far end."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from conftest import stiffness_block
from helpers.saddle import SCENE

from parsolve.effects.base import Effect
from parsolve.fem.element_matrices import Term, TermMatrices
from parsolve.mesh.regions import allgather_rows
from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem

COMM = MPI.COMM_WORLD
K = 40.0
TEXT = SCENE.format(cell="quad", preset="direct", eliminate="false")


def ties(mesh, choice: int) -> np.ndarray:
    """(1, 2) local nodes: this rank's owned node of smallest input id, tied to the owned node
    of the ``choice``-th largest id among those no cell shares with it (rows of both owned
    here: the owner declares the whole tie)."""
    owned = np.arange(mesh.n_owned)
    if owned.size < 4:
        return np.zeros((0, 2), dtype=np.int64)
    ids = mesh.global_nodes[owned]
    a = owned[np.argmin(ids)]
    near = np.unique(mesh.cells[np.any(mesh.cells == a, axis=1)])
    far = owned[~np.isin(owned, near)]
    far = far[np.argsort(-mesh.global_nodes[far])]
    return np.array([[a, far[choice]]])


class Ties(Effect):
    """Springs K (u_a − u_b) between node tuples that move (a pairing's, say)."""

    name = "ties"

    def __init__(self, mesh):
        self.mesh = mesh
        self.term = Term("u", "u", ties(mesh, 0))

    def terms(self) -> list[Term]:
        return [self.term]

    def term_values(self, term: Term, cells: np.ndarray) -> TermMatrices:
        k = len(term.nodes)
        block = K * np.array([[1.0, -1.0], [-1.0, 1.0]])
        values = np.zeros((2, 2, 2, 2, k))
        values[0, 0] = values[1, 1] = block[:, :, None]   # per component, none across
        return TermMatrices(term, values.reshape(4, 2, 2, k))


def brute_ties(mesh, nodes: np.ndarray, npoints: int) -> np.ndarray:
    """Dense springs of every rank's tuples (input numbering)."""
    pairs = allgather_rows(COMM, mesh.global_nodes[nodes].astype(np.int64).reshape(-1, 2))
    out = np.zeros((npoints * 2, npoints * 2))
    for a, b in pairs:
        for c in range(2):
            i, j = a * 2 + c, b * 2 + c
            out[i, i] += K
            out[j, j] += K
            out[i, j] -= K
            out[j, i] -= K
    return out


def model():
    return build_model(parse_scene(tomllib.loads(TEXT), "t.toml", TEXT), COMM)


def test_a_term_that_moves_gets_a_new_preallocated_pattern():
    bare = stiffness_block(COMM, SaddleSystem(COMM, model()))
    m = model()
    effect = Ties(m.mesh)
    m.effects.append(effect)
    system = SaddleSystem(COMM, m)
    npoints = m.mesh.num_global_points
    first = brute_ties(m.mesh, effect.term.nodes, npoints)
    assert np.abs(first).max() == K   # every rank with nodes ties two
    np.testing.assert_allclose(stiffness_block(COMM, system) - bare, first,
                               atol=1e-12 * np.abs(bare).max())

    pattern, mat = system.pattern, system.op.petsc_matrix()
    effect.term.nodes = ties(m.mesh, 1)             # the tie moves to another far node
    system.restructure()
    assert system.pattern is not pattern and system.op.petsc_matrix() is not mat
    moved = brute_ties(m.mesh, effect.term.nodes, npoints)
    got = stiffness_block(COMM, system)
    np.testing.assert_allclose(got - bare, moved, atol=1e-12 * np.abs(bare).max())
    gone = (first != 0) & (moved == 0) & (bare == 0)   # where the tie was: nothing left
    assert gone.any() and np.all(got[gone] == 0.0)
    # the pattern is the one a system built with the tie there from the start derives: the
    # old node pairs out of it, the new ones in
    fresh_model = model()
    fresh = Ties(fresh_model.mesh)
    fresh.term = Term("u", "u", ties(fresh_model.mesh, 1))
    fresh_model.effects.append(fresh)
    start = SaddleSystem(COMM, fresh_model)
    assert system.pattern.nnzb == start.pattern.nnzb
    np.testing.assert_array_equal(system.pattern.ucol, start.pattern.ucol)
    np.testing.assert_array_equal(system.pattern.nb, start.pattern.nb)
    np.testing.assert_allclose(got, stiffness_block(COMM, start), rtol=0, atol=0)

    # nothing moved: the pattern stays
    pattern = system.pattern
    system.restructure()
    assert system.pattern is pattern


def split_tie(system) -> np.ndarray:
    """On rank 0 only: its owned node of smallest input id tied to its first ghost node
    (another rank owns it, and declares nothing); no tuple elsewhere, nor on one rank."""
    mesh = system.model.mesh
    if COMM.rank != 0 or mesh.num_points == mesh.n_owned:
        return np.zeros((0, 2), dtype=np.int64)
    a = int(np.argmin(mesh.global_nodes[:mesh.n_owned]))
    return np.array([[a, mesh.n_owned]])


def test_a_tuple_its_nodes_owner_does_not_declare_is_refused():
    m = model()
    effect = Ties(m.mesh)
    effect.term.nodes = np.zeros((0, 2), dtype=np.int64)
    m.effects.append(effect)
    system = SaddleSystem(COMM, m)
    effect.term.nodes = split_tie(system)
    if COMM.size == 1:   # (no rank to split it with: nothing to refuse)
        system.restructure()
        return
    # refused on every rank alike, rank 0's row of the tie would be whole and the owner's
    # row of the ghost node would lack it
    with pytest.raises(RuntimeError, match="1 node tuples of declared terms join nodes whose "
                       "owners do not all declare them"):
        system.restructure()


def far_ties(mesh, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Ties, in the partition's global node numbers, between the first node of every rank's
    block and the last node of the next rank's block (of its own on one rank): nodes no cell
    joins, each on no part of the other's owner. A tie is declared by the rank owning its
    first node alone (the rows of its other node travel to their owner). (all ties (k, 2),
    this rank's)."""
    ranges = np.asarray(mesh.node_ranges, dtype=np.int64)
    first, last = ranges[:-1], ranges[1:] - 1
    ties = np.column_stack([first, np.roll(last, -1)]) if size > 1 else \
        np.array([[first[0], last[0]]])
    lo, hi = ranges[COMM.rank], ranges[COMM.rank + 1]
    mine = (ties[:, 0] >= lo) & (ties[:, 0] < hi)
    return ties, ties[mine]


def test_tuples_split_over_ranks_in_global_numbers_are_assembled_whole():
    """A node term in global node numbers (``Term.global_ids``: a contact pair's slave and
    master facet on different ranks) declared by one rank, the owner of its first node: the
    assembled operator is the cells' plus the dense springs of every tie, rows of both ends
    (each from its owner), on 1, 2 and 3 ranks; moved, the pattern follows."""
    bare = stiffness_block(COMM, SaddleSystem(COMM, model()))
    m = model()
    ties, mine = far_ties(m.mesh, COMM.size)
    effect = Ties(m.mesh)
    effect.term = Term("u", "u", mine, global_ids=True)
    m.effects.append(effect)
    system = SaddleSystem(COMM, m)
    npoints = m.mesh.num_global_points
    # input ids of the ties' nodes: each owner's, gathered
    own = m.mesh.node_new[:m.mesh.n_owned].astype(np.int64)
    pairs = allgather_rows(COMM, np.column_stack([own, m.mesh.global_nodes[:m.mesh.n_owned]
                                                  .astype(np.int64)]))
    input_of = np.empty(npoints, dtype=np.int64)
    input_of[pairs[:, 0]] = pairs[:, 1]
    def dense(t):
        out = np.zeros((npoints * 2, npoints * 2))
        for a, b in input_of[t]:
            for c in range(2):
                i, j = a * 2 + c, b * 2 + c
                out[i, i] += K
                out[j, j] += K
                out[i, j] -= K
                out[j, i] -= K
        return out

    got = stiffness_block(COMM, system)
    np.testing.assert_allclose(got - bare, dense(ties), atol=1e-12 * np.abs(bare).max())
    if COMM.size > 1:   # some tie's far end is on no part of its rank's (not even a ghost)
        assert COMM.allreduce(bool(np.any(~np.isin(mine, m.mesh.node_new))), op=MPI.LOR)
    # moved: each tie's second end one node back
    moved = ties.copy()
    moved[:, 1] -= 1
    lo, hi = m.mesh.node_ranges[COMM.rank], m.mesh.node_ranges[COMM.rank + 1]
    effect.term.nodes = moved[(moved[:, 0] >= lo) & (moved[:, 0] < hi)]
    system.restructure()
    np.testing.assert_allclose(stiffness_block(COMM, system) - bare, dense(moved),
                               atol=1e-12 * np.abs(bare).max())
