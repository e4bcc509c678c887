"""Node-pair sums written straight into an operator's value array (``reduce_into``) equal the
node-pair array of ``reduce`` copied there, to 1e-14 of their scale: held and blocked,
factored (one and two materials) and full, several parts with factors on overlapping
components, and the dump slot (rows owned elsewhere) dropped. Synthetic element matrices and
a value layout with padding between blocks, so a stray write shows up. A declared term's
values (``TermMatrices``: node tuples, e.g. contact rows' blocks) written at its own pairs
likewise: the term alone, after and before a cell part on overlapping components, with a
factor, the dump slot dropped; with no tuples on this rank, its component pairs zeroed."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.fem.element_matrices import (BlockMatrices, CellKernel, ElementMatrices,
                                           StiffnessTarget, Term, TermMatrices)

NC, NEN, NCELLS, NPAIRS = 3, 4, 50, 37
M, K = 2, 6   # a declared term's tuple size and count


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


def _matrices(rng, d: int, form: str, blocked: bool) -> ElementMatrices:
    P = rng.normal(size=(d * d, NEN, NEN, NCELLS))
    if form == "full":
        tensors = mat = None
    else:
        nmat = 1 if form == "one" else 2
        tensors = rng.normal(size=(nmat, d * d, d * d))
        mat = rng.integers(0, nmat, NCELLS)
    if not blocked:
        return ElementMatrices(values=P if tensors is None else None,
                               geometric=None if tensors is None else P,
                               tensors=tensors, cell_material=mat)

    def compute(sl, out):
        if out is None:
            return P[..., sl].copy()
        out[...] = P[..., sl]
        return out
    return ElementMatrices(tensors=tensors, cell_material=mat,
                           kernel=CellKernel(compute, NCELLS, d * d, NEN, block=7))


def _slots(rng, kind: str) -> np.ndarray:
    """Random (blocks reach pairs already flushed), or rising with the cells and leaving
    gaps and the last pairs unreached (as a mesh-following numbering on part of the cells)."""
    if kind == "random":
        return rng.integers(0, NPAIRS + 1, (NEN, NEN, NCELLS)).astype(np.int32)  # NPAIRS: dump
    reach = np.sort(rng.choice(np.arange(0, NPAIRS - 6, 2), size=NEN * NEN * NCELLS))
    return reach.reshape(NCELLS, NEN, NEN).transpose(1, 2, 0).astype(np.int32)


@pytest.mark.parametrize("kind", ["random", "rising"])
@pytest.mark.parametrize("blocked", [False, True])
@pytest.mark.parametrize("form", ["one", "two", "full"])
def test_reduce_into_equals_reduce(form: str, blocked: bool, kind: str) -> None:
    rng = np.random.default_rng(3)
    slot = _slots(rng, kind)
    parts = [(np.arange(NC), np.arange(NC), _matrices(rng, NC, form, blocked), 1.0),
             (np.array([0, 2]), np.array([1, 2]), _matrices(rng, 2, form, blocked), -0.7),
             (np.array([1]), np.array([1]), _matrices(rng, 1, "one", blocked), 2.5)]
    for use in (parts[:1], parts[1:], parts):
        bm = BlockMatrices(NC, use)
        data, starts = _layout(rng)
        expected = _copied(data, starts, bm.reduce(slot, NPAIRS))
        bm.reduce_into(slot, NPAIRS, StiffnessTarget(data, starts))
        scale = np.abs(expected).max()
        assert np.abs(data - expected).max() <= 1e-14 * scale


def test_wide_slot_range_is_compressed() -> None:
    """A block whose slots span far more pairs than it has takes the compressed path."""
    rng = np.random.default_rng(5)
    npairs = 100000
    slot = rng.choice(npairs + 1, size=(NEN, NEN, 3)).astype(np.int32)
    m = _matrices(rng, NC, "one", True)
    m.kernel.ncells = 3
    bm = BlockMatrices(NC, [(np.arange(NC), np.arange(NC), m, 1.0)])
    starts = (np.arange(NC * npairs) * NC).reshape(NC, npairs)
    data = np.full(NC * NC * npairs, 9.0)
    expected = _copied(data, starts, bm.reduce(slot, npairs))
    bm.reduce_into(slot, npairs, StiffnessTarget(data, starts))
    assert np.abs(data - expected).max() <= 1e-14 * np.abs(expected).max()


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
