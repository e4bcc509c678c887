"""Declared terms on tuples of nodes (``Term``, ``TermMatrices``): values reduced into the
term's own slots (a row owned elsewhere dropped), products with node values equal to the
dense matrix's, and a rank holding none of the term's tuples contributing nothing."""

import numpy as np

from parsolve.fem.element_matrices import NodeForces, Term, TermMatrices


def _dense(term: Term, values: np.ndarray, npoints: int, d: int) -> np.ndarray:
    """The term as a dense (npoints·d)² matrix, entry by entry (an independent sum)."""
    K = np.zeros((npoints * d, npoints * d))
    k, m = term.nodes.shape
    for t in range(k):
        for a in range(m):
            for b in range(m):
                for i in range(d):
                    for j in range(d):
                        K[term.nodes[t, a] * d + i, term.nodes[t, b] * d + j] += \
                            values[i * d + j, a, b, t]
    return K


def test_reduce_into_its_slots_and_drop_rows_owned_elsewhere():
    rng = np.random.default_rng(7)
    term = Term("u", "u", [[0, 3], [3, 1], [0, 3]])
    values = rng.normal(size=(4, 2, 2, 3))
    npairs = 5
    # slots of (i, j) of each tuple; tuple 1's row of node 3 is another rank's (slot npairs)
    term.slots = np.array([[[0, 2, 0], [1, 3, 1]],
                           [[1, npairs, 1], [4, npairs, 4]]]).transpose(0, 1, 2)
    out = TermMatrices(term, values).reduce(np.zeros((4, 4, 0), dtype=np.intp), npairs)
    expected = np.zeros((4, npairs))
    for (a, b, t), s in np.ndenumerate(term.slots):
        if s < npairs:
            expected[:, s] += values[:, a, b, t]
    np.testing.assert_allclose(out, expected, rtol=1e-15)
    assert out.shape == (4, npairs)


def test_forces_are_the_dense_product():
    rng = np.random.default_rng(11)
    d, npoints = 3, 6
    term = Term("u", "u", [[0, 4], [2, 5], [4, 1], [5, 5]])
    values = rng.normal(size=(d * d, 2, 2, 4))
    x = rng.normal(size=(npoints, d))
    f = TermMatrices(term, values).forces(x)
    assert isinstance(f, NodeForces) and f.values.shape == (4, 2, d)
    got = np.zeros((npoints, d))
    np.add.at(got, f.nodes.ravel(), f.values.reshape(-1, d))
    np.testing.assert_allclose(got.ravel(), _dense(term, values, npoints, d) @ x.ravel(),
                               rtol=1e-13, atol=1e-13)


def test_single_nodes_and_an_empty_term():
    term = Term("u", "u", np.array([2, 0]))          # (k,): one node per tuple
    assert term.nodes.shape == (2, 1)
    values = np.arange(8.0).reshape(4, 1, 1, 2)    # tuple t: [[t, 2 + t], [4 + t, 6 + t]]
    x = np.arange(6.0).reshape(3, 2)
    f = TermMatrices(term, values).forces(x)
    np.testing.assert_allclose(f.values[:, 0], [[0 * 4 + 2 * 5, 4 * 4 + 6 * 5],     # node 2
                                                [1 * 0 + 3 * 1, 5 * 0 + 7 * 1]])    # node 0
    empty = Term("u", "u", np.zeros((0, 2), dtype=np.int64))
    m = TermMatrices(empty, np.zeros((4, 2, 2, 0)))
    assert m.forces(x).values.shape == (0, 2, 2)
    empty.slots = np.zeros((2, 2, 0), dtype=np.intp)
    np.testing.assert_array_equal(m.reduce(None, 7), np.zeros((4, 7)))


def test_a_region_cell_term_reduced_with_a_few_cells_replaced():
    """A cell term on a region (its cells' positions and slots): ``reduce`` sums its cells
    into their slots, and ``reduce_replaced`` (a loading tangent on a few of the composition's
    cells) equals the reduction of the values with those cells swapped, whichever of the
    replaced cells the region holds; a term on every cell beside it is replaced too."""
    from parsolve.fem.element_matrices import BlockMatrices, ElementMatrices

    rng = np.random.default_rng(11)
    ncells, nen, npairs = 9, 3, 14
    pair_slot = rng.integers(0, npairs + 1, size=(nen, nen, ncells))   # npairs: dropped
    region = np.array([1, 2, 5, 8])
    replaced = np.array([2, 4, 8])                  # 2, 8 in the region; 4 only in "every"
    v_all, w_all = rng.normal(size=(2, 1, nen, nen, ncells))
    v_reg, w_reg = rng.normal(size=(2, 1, nen, nen, region.size))

    def blocks(every, reg):
        m = ElementMatrices(values=reg)
        m.positions, m.slots = region, pair_slot[:, :, region]
        return BlockMatrices(1, [([0], [0], ElementMatrices(values=every), 1.0),
                                 ([0], [0], m, 2.0)])

    def brute(every, reg):
        out = np.zeros(npairs + 1)
        np.add.at(out, pair_slot.ravel(), every[0].ravel())
        np.add.at(out, pair_slot[:, :, region].ravel(), 2.0 * reg[0].ravel())
        return out[None, :npairs]

    base, other = blocks(v_all, v_reg), blocks(w_all, w_reg)
    np.testing.assert_allclose(base.reduce(pair_slot, npairs), brute(v_all, v_reg), atol=1e-13)
    swap_all, swap_reg = v_all.copy(), v_reg.copy()
    swap_all[..., replaced] = w_all[..., replaced]
    at = np.flatnonzero(np.isin(region, replaced))
    swap_reg[..., at] = w_reg[..., at]
    np.testing.assert_allclose(base.reduce_replaced(other, replaced, pair_slot, npairs),
                               brute(swap_all, swap_reg), atol=1e-13)
