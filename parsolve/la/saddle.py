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

from parsolve.la.layout import Layout
from parsolve.relations import Relation


@dataclass
class RelationBlock:
    """All multiplied (not eliminated) relations stacked into global multiplier rows."""

    relations: list[Relation]
    first_row: np.ndarray     # (nrel + 1,) first global multiplier row of each relation
    a_rows: np.ndarray        # global multiplier row of each A entry
    a_cols: np.ndarray        # new primal DOF of each A entry
    a_vals: np.ndarray        # unscaled
    d_rows: np.ndarray        # new primal DOF of each D entry
    d_cols: np.ndarray        # global multiplier row of each D entry
    d_vals: np.ndarray        # unscaled, D itself (the matrix holds -D)
    row_scale: np.ndarray = None
    col_scale: np.ndarray = None

    @property
    def nrows(self) -> int:
        return int(self.first_row[-1])

    def rhs(self, t: float) -> np.ndarray:
        """Scaled b(t) of every multiplier row."""
        b = np.concatenate([r.rhs(t) for r in self.relations]) if self.relations else np.zeros(0)
        return b * self.row_scale

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


def stack_relations(relations: list[Relation], layout: Layout) -> RelationBlock:
    """Concatenate relations into global multiplier rows, in new DOF numbering."""
    sizes = [r.nrows for r in relations]
    first = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    ar, ac, av, dr, dc, dv = [], [], [], [], [], []
    for k, rel in enumerate(relations):
        ar.append(rel.a_rows + first[k])
        ac.append(layout.new_dof(rel.a_dofs))
        av.append(rel.a_vals)
        dofs, rows, vals = rel.dual_coo()
        dr.append(layout.new_dof(dofs))
        dc.append(np.asarray(rows, dtype=np.int64) + first[k])
        dv.append(np.asarray(vals, dtype=float))

    def cat(parts, dtype):
        return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype)

    return RelationBlock(relations, first, cat(ar, np.int64), cat(ac, np.int64), cat(av, float),
                         cat(dr, np.int64), cat(dc, np.int64), cat(dv, float))
