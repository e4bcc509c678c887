"""A declared term's values (``TermMatrices``: node tuples, e.g. contact rows' blocks) written
straight into an operator's value array at its own pairs equal the node-pair array of
``reduce`` copied there: the term alone (its pairs assigned, the others zeroed), after and
before a cell part on overlapping components, with a factor, and the dump slot (rows owned
elsewhere) dropped; with no tuples on this rank, its component pairs zeroed."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.fem.element_matrices import (BlockMatrices, ElementMatrices, StiffnessTarget, Term,
                                           TermMatrices)

NC, NEN, NCELLS, NPAIRS, M, K = 3, 4, 20, 37, 2, 6


def _layout(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(data filled with garbage, starts): pair p's block row i at starts[i, p], shuffled."""
    order = rng.permutation(NPAIRS * NC)
    starts = (order * (NC + 2)).reshape(NC, NPAIRS)   # 2 padding entries after each block row
    return rng.normal(size=NPAIRS * NC * (NC + 2)), starts


def _copied(data: np.ndarray, starts: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    out = data.copy()
    blocks = blocks.reshape(NC, NC, -1)
    for i in range(NC):
        for j in range(NC):
            out[starts[i] + j] = blocks[i, j]
    return out


def _term(rng, d: int, k: int = K) -> TermMatrices:
    term = Term("u", "u", nodes=np.zeros((k, M), dtype=np.int64))
    # a few pairs, repeated across tuples, the dump slot NPAIRS among them
    term.slots = rng.choice([3, 4, 9, 20, 21, NPAIRS], size=(M, M, k)).astype(np.int32)
    return TermMatrices(term, rng.normal(size=(d * d, M, M, k)))


@pytest.mark.parametrize("tuples", [K, 0])
def test_term_reduce_into_equals_reduce(tuples: int) -> None:
    rng = np.random.default_rng(7)
    slot = rng.integers(0, NPAIRS + 1, (NEN, NEN, NCELLS)).astype(np.int32)
    cell = ElementMatrices(values=rng.normal(size=(NC * NC, NEN, NEN, NCELLS)))
    cell_part = (np.arange(NC), np.arange(NC), cell, 1.0)
    term_part = (np.array([0, 2]), np.array([1, 2]), _term(rng, 2, tuples), -0.7)
    alone = (np.array([1]), np.array([1]), _term(rng, 1, tuples), 2.5)
    for use in ([term_part], [alone, term_part], [cell_part, term_part, alone],
                [term_part, cell_part]):
        bm = BlockMatrices(NC, use)
        data, starts = _layout(rng)
        expected = _copied(data, starts, bm.reduce(slot, NPAIRS))
        bm.reduce_into(slot, NPAIRS, StiffnessTarget(data, starts))
        scale = np.abs(expected).max()
        assert np.abs(data - expected).max() <= 1e-14 * scale
