"""The relation blocks of the saddle system, in the layout's numbering, scaled.

Relations are rescaled so that their rows and columns are commensurate with the stiffness
(E = 2e11 next to unit coefficients would otherwise wreck pivoting): row k of A is multiplied by
``row_scale[k]`` and column k of D by ``col_scale[k]``, so the solved multiplier is
``λ / col_scale`` and the primal equation's right-hand side ``b · row_scale``. An associated
relation gets equal scales, which keeps the operator symmetric.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.relations import Relation


@dataclass
class RelationBlock:
    """All multiplied (not eliminated) relations stacked into global multiplier rows.

    A relation's rows ("relation rows", what the active set decides) map to multiplier rows
    one to one, except for a collapsed maximum group (``Relation.collapsed``): all its rows
    share one multiplier row and one dual column, which carries the coefficients of the
    enforced row (``selected``); the other rows' A entries are kept in the pattern at zero."""

    relations: list[Relation]
    first_row: np.ndarray     # (nrel + 1,) first global multiplier row of each relation
    a_rows: np.ndarray        # global multiplier row of each A entry
    a_cols: np.ndarray        # new primal DOF of each A entry
    a_vals: np.ndarray        # unscaled
    d_rows: np.ndarray        # new primal DOF of each D entry
    d_cols: np.ndarray        # global multiplier row of each D entry
    d_vals: np.ndarray        # unscaled, D itself (the matrix holds -D)
    row_first: np.ndarray = None   # (nrel + 1,) first relation row of each relation
    mult_of_row: np.ndarray = None  # multiplier row of each relation row
    rep_row: np.ndarray = None     # relation row each multiplier row enforces now
    a_relrow: np.ndarray = None    # relation row of each A entry
    row_scale: np.ndarray = None
    col_scale: np.ndarray = None

    @property
    def nrows(self) -> int:
        """Multiplier rows."""
        return int(self.first_row[-1])

    @property
    def a_on(self) -> np.ndarray:
        """A entries of the rows enforced now (all but a collapsed group's other rows)."""
        return self.rep_row[self.a_rows] == self.a_relrow

    def rhs(self, t: float) -> np.ndarray:
        """Scaled b(t) of every multiplier row."""
        b = np.concatenate([r.rhs(t) for r in self.relations]) if self.relations else np.zeros(0)
        return b[self.rep_row] * self.row_scale

    def select(self, active_rows: np.ndarray) -> np.ndarray:
        """The enforced relation rows → which row each collapsed group carries, and the mask of
        multiplier rows enforced."""
        on = np.zeros(self.nrows, dtype=bool)
        np.logical_or.at(on, self.mult_of_row, active_rows)
        rows = np.flatnonzero(active_rows)
        self.rep_row[self.mult_of_row[rows]] = rows
        return on

    def row_values(self, per_mult: np.ndarray) -> np.ndarray:
        """Per relation row: a multiplier row's value on the row it enforces, 0 on the others."""
        out = per_mult[self.mult_of_row]
        return np.where(self.rep_row[self.mult_of_row] == np.arange(out.size), out, 0.0)

    def set_scales(self, kscale: float) -> None:
        """Scale each row of A and column of D to the size of the stiffness diagonal."""
        n = self.nrows
        amax = np.zeros(n)
        np.maximum.at(amax, self.a_rows, np.abs(self.a_vals))
        dmax = np.zeros(n)
        np.maximum.at(dmax, self.d_cols, np.abs(self.d_vals))
        amax[amax == 0] = 1.0
        dmax[dmax == 0] = 1.0
        self.row_scale = kscale / amax
        self.col_scale = kscale / dmax
        for k, rel in enumerate(self.relations):
            if rel.associated:  # same scale on both sides keeps the operator symmetric
                sl = slice(self.first_row[k], self.first_row[k + 1])
                self.col_scale[sl] = self.row_scale[sl]


def stack_relations(relations: list[Relation], new_dof) -> RelationBlock:
    """Concatenate relations into global multiplier rows, in new DOF numbering. ``new_dof``:
    the relations' input DOFs to new DOFs (``RelationDofs.new_dof``)."""
    sizes = [r.nrows for r in relations]
    mult_sizes = [1 if r.collapsed else r.nrows for r in relations]
    row_first = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    first = np.concatenate([[0], np.cumsum(mult_sizes)]).astype(np.int64)
    ar, ac, av, dr, dc, dv, arel, mult = [], [], [], [], [], [], [], []
    for k, rel in enumerate(relations):
        local = np.zeros(rel.nrows, dtype=np.int64) if rel.collapsed else np.arange(rel.nrows)
        mult.append(local + first[k])
        ar.append(local[rel.a_rows] + first[k])
        arel.append(rel.a_rows + row_first[k])
        ac.append(new_dof(rel.a_dofs))
        av.append(rel.a_vals)
        if rel.collapsed:  # one copy of the shared vector
            dofs, vals = rel.shared_dual
            rows = np.zeros(dofs.size, dtype=np.int64)
        else:
            dofs, rows, vals = rel.dual_coo()
        dr.append(new_dof(dofs))
        dc.append(np.asarray(rows, dtype=np.int64) + first[k])
        dv.append(np.asarray(vals, dtype=float))

    def cat(parts, dtype):
        return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype)

    mult_of_row = cat(mult, np.int64)
    rep_row = np.zeros(int(first[-1]), dtype=np.int64)
    rep_row[mult_of_row[::-1]] = np.arange(mult_of_row.size)[::-1]  # first row of each
    return RelationBlock(relations, first, cat(ar, np.int64), cat(ac, np.int64), cat(av, float),
                         cat(dr, np.int64), cat(dc, np.int64), cat(dv, float), row_first,
                         mult_of_row, rep_row, cat(arel, np.int64))
