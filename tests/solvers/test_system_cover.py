"""The stiffness pattern of node tuples wider than a cell (``solvers.system._Cover``: a
contact row's span covered by pseudo-cells of chunk pairs): the same pattern and the same
slots as with every cell and tuple padded to the tuples' width."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.la.pattern import node_pattern
from parsolve.solvers.system import _Cover


@pytest.mark.parametrize("nen", [3, 4, 8])
@pytest.mark.parametrize("m", [1, 3, 4, 5, 8, 9, 17])
def test_cover_slots_are_the_padded_pattern(nen, m):
    rng = np.random.default_rng(m * 10 + nen)
    nn = 60
    cells = rng.integers(0, nn, (25, nen))
    tuples = np.array([rng.choice(nn, m, replace=False) for _ in range(7)])
    cover = _Cover(m, nen)
    pseudo = cover.cells(tuples)
    assert pseudo.shape[1] == nen
    lo, hi = 10, 45      # a rank's rows: the others' slots are the dump (nnzb)
    got = node_pattern(np.concatenate([cells, pseudo]), lo, hi, 2, nn)
    slots = cover.slots(got.pair_slot, len(cells), len(tuples))
    width = max(m, nen)
    pad = lambda a: np.concatenate([a, np.repeat(a[:, -1:], width - a.shape[1], axis=1)], axis=1)
    ref = node_pattern(np.concatenate([pad(cells), pad(tuples)]), lo, hi, 2, nn)
    assert got.nnzb == ref.nnzb
    np.testing.assert_array_equal(slots, ref.pair_slot[:m, :m, len(cells):])
    np.testing.assert_array_equal(got.pair_slot[:nen, :nen, :len(cells)],
                                  ref.pair_slot[:nen, :nen, :len(cells)])
