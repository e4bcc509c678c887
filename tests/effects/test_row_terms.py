"""Rows that are a stiffness (parsolve/effects/row_terms.py): friction's cross stiffness and
finite sliding's geometric stiffness as terms on their rows' node tuples, where they were
compliant rows (a row a, dual d, compliance c, its multiplier discarded: −d aᵀ / c on K).

Checked: the tuples and blocks against a dense construction; each contact term, at every
Newton iteration of the shipped scenes, against the dense −D A / c of the rows it replaces;
the scenes' answers on the ranks' parts against one process."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from conftest import CONFIGS, assert_same_results
from parsolve.contact.rows import Rows
from parsolve.effects import contact as contact_effect
from parsolve.effects.row_terms import RowTuples, outer_blocks


def _rows(entries) -> Rows:
    row, node, comp, coef = (np.array(c) for c in zip(*entries))
    return Rows(int(row.max()) + 1, row.astype(np.int64), node.astype(np.int64),
                comp.astype(np.int64), coef.astype(float), 0)


def test_row_tuples_merge_repeated_nodes_and_pad():
    """Two rows per tuple, of different widths, a node repeated within a row: each tuple is
    its rows' distinct nodes (padded with its first), the coefficients summed per node."""
    rows = _rows([(0, 7, 0, 1.0), (0, 3, 1, 2.0), (0, 7, 0, 0.5), (1, 9, 1, -1.0),
                  (2, 4, 0, 3.0), (3, 4, 1, 4.0)])
    t = RowTuples(rows, per=2, dim=2)
    assert t.nodes.tolist() == [[3, 7, 9], [4, 4, 4]]
    dense = t.dense(rows.coef)
    expect = np.zeros((2, 2, 3, 2))
    expect[0, 0, 1, 0], expect[0, 0, 0, 1], expect[0, 1, 2, 1] = 1.5, 2.0, -1.0
    expect[1, 0, 0, 0], expect[1, 1, 0, 1] = 3.0, 4.0
    np.testing.assert_array_equal(dense, expect)


def test_outer_blocks_are_the_tuples_matrices():
    rng = np.random.default_rng(1)
    u, w = rng.normal(size=(2, 5, 3, 4, 2))    # (k, r, m, d)
    blocks = outer_blocks(u, w)                 # (d·d, m, m, k)
    for k in range(5):
        full = sum(np.outer(u[k, r].ravel(), w[k, r].ravel()) for r in range(3))   # (m d)²
        got = blocks[..., k].reshape(2, 2, 4, 4).transpose(2, 0, 3, 1).reshape(8, 8)
        np.testing.assert_allclose(got, full, rtol=0, atol=1e-14)


def _dense_term(term, values: np.ndarray, to_input: np.ndarray, ncomp: int, n: int):
    """A term's values (d·d, m, m, k) on its tuples (global node numbers) as a dense matrix
    over input DOFs."""
    d = int(round(np.sqrt(values.shape[0])))
    nodes = to_input[term.nodes]                                  # (k, m)
    out = np.zeros((n, n))
    v = values.reshape(d, d, *values.shape[1:])
    for i in range(d):
        for j in range(d):
            rows = (nodes[:, :, None] * ncomp + i).transpose(1, 2, 0)
            cols = (nodes[:, None, :] * ncomp + j).transpose(1, 2, 0)
            np.add.at(out, (rows, cols), v[i, j])
    return out


@pytest.mark.parametrize("config", ["contact_ironing_2d", "contact_friction_3d"])
def test_terms_equal_the_compliant_rows(monkeypatch, run, config):
    """At every Newton iteration (one process), the contact's terms equal what its rows did
    as compliant rows: 3D friction's κ aᵀa over the free nodes' rows across s (associated:
    d = −aᵀ, c = 1/κ), finite sliding's −u wᵀ (dual u, row w, c = 1)."""
    seen = {"cross": 0, "geo": 0}
    evaluate = contact_effect.Contact.evaluate

    def checked(self, cells, values, state, secant, at):
        out = evaluate(self, cells, values, state, secant, at)
        ncomp = self.fields_.ncomp
        n = self.mesh.num_points * ncomp
        to_input = np.argsort(self.mesh.node_new)
        got = {id(t): m.values for t, m in out[1]}
        if self.cross is not None and self._kappa is not None:
            t, c = self.trows, self.tangent.a_vals
            A = np.zeros((t.nrows, n))
            np.add.at(A, (t.row, t.node * ncomp + t.comp), c)
            kappa = np.zeros(t.nrows)
            kappa[1::2] = self._kappa
            expect = A.T @ (kappa[:, None] * A)
            term = self.cross.term
            np.testing.assert_allclose(_dense_term(term, got[id(term)], to_input, ncomp, n),
                                       expect, rtol=0, atol=1e-12 * max(np.abs(expect).max(), 1))
            seen["cross"] += bool(np.any(self._kappa > 0))
        if self.geometric and self._geo_rows is not None:
            lay = self._geometry_layout(self.pairing)
            U, W = np.zeros((2, lay.nrows, n))
            dofs = lay.node * ncomp + lay.comp
            np.add.at(U, (lay.row, dofs), self._geo_rows[0])
            np.add.at(W, (lay.row, dofs), self._geo_rows[1])
            expect = -U.T @ W
            term = self.geo.term
            np.testing.assert_allclose(_dense_term(term, got[id(term)], to_input, ncomp, n),
                                       expect, rtol=0, atol=1e-12 * max(np.abs(expect).max(), 1))
            seen["geo"] += bool(np.any(expect))
        return out

    monkeypatch.setattr(contact_effect.Contact, "evaluate", checked)
    run(CONFIGS / f"{config}.toml", name=f"row_terms_{config}", comm=MPI.COMM_SELF)
    # the terms were not all zero: free sliding nodes (3D), closed sliding slaves (ironing)
    assert seen["cross" if config.endswith("3d") else "geo"] > 0


@pytest.mark.parametrize("config", ["contact_ironing_2d", "contact_friction_3d"])
def test_terms_split_over_ranks_give_one_process_answers(run, config):
    """Tuples split over the ranks' parts (declared by each rank owning a node): the same
    results as one process."""
    if MPI.COMM_WORLD.size == 1:
        pytest.skip("the ranks' parts against one process: 2 or more ranks")
    parts = run(CONFIGS / f"{config}.toml", name=f"row_terms_parts_{config}")
    whole = run(CONFIGS / f"{config}.toml", name=f"row_terms_whole_{config}",
                comm=MPI.COMM_SELF)
    assert_same_results(parts, whole, tol=1e-9, ignore=("timings", "attrs"))
