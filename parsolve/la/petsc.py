"""The distributed saddle operator [[K, -D], [A, 0]] as one PETSc MPIAIJ matrix.

Each rank owns its primal rows then its multiplier rows (see ``layout``). The rank's CSR is
built once: stiffness entries first in each primal row, then that row's relation columns;
multiplier rows hold A and a diagonal slot (zero unless the row is switched off by an
active-set loop, which then sets it to keep the pattern fixed). Re-assembly places node-pair
blocks (summed from element matrices by ``np.bincount``) into the CSR value array and hands it
to PETSc in one call.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from parsolve.la.layout import Layout
from parsolve.la.pattern import NodePattern
from parsolve.la.saddle import RelationBlock


def _dedupe(rows: np.ndarray, cols: np.ndarray, ncols: int):
    """Unique (row, col) pairs; returns (rows, cols, index of each input entry among them)."""
    key = rows.astype(np.int64) * ncols + cols
    ukey, inv = np.unique(key, return_inverse=True)
    return ukey // max(ncols, 1), ukey % max(ncols, 1), inv


class SaddleOperator:
    """Owned rows of the saddle matrix, their fixed pattern, and the PETSc Mat built from them."""

    def __init__(self, comm: MPI.Comm, layout: Layout, pattern: NodePattern, block: RelationBlock):
        self.comm = comm
        self.layout = layout
        self.block = block
        self.pattern = pattern
        q0, q1, l0, l1 = layout.owned(comm.rank)
        nqo, nlo = q1 - q0, l1 - l0
        self.nrows = nqo + nlo
        self.size = layout.size
        # relation columns in the owned primal rows: entries (q row, λ col) of -D
        own_d = (block.d_rows >= q0) & (block.d_rows < q1)
        d_r, d_c, self._d_inv = _dedupe(block.d_rows[own_d] - q0, block.d_cols[own_d], layout.nl)
        self._d_sel = np.flatnonzero(own_d)
        # multiplier rows: A entries plus a diagonal slot per row
        own_a = (block.a_rows >= l0) & (block.a_rows < l1)
        a_r, a_c, self._a_inv = _dedupe(block.a_rows[own_a] - l0, block.a_cols[own_a], layout.nq)
        self._a_sel = np.flatnonzero(own_a)
        k_nnz = pattern.row_nnz()
        nd_row = np.bincount(d_r, minlength=nqo)
        na_row = np.bincount(a_r, minlength=nlo) + 1
        rowptr = np.concatenate([[0], np.cumsum(np.concatenate([k_nnz + nd_row, na_row]))])
        nnz = int(rowptr[-1])
        cols = np.empty(nnz, dtype=PETSc.IntType)
        # stiffness entries first in each primal row: node-pair blocks; a node's DOFs are
        # consecutive in the saddle numbering
        nc = layout.ncomp
        self.block_pos = pattern.block_positions(rowptr[:nqo], dtype=PETSc.IntType)
        self.diag_pos = pattern.diagonal_positions(rowptr[:nqo])
        self._pair_col = layout.q_index(pattern.ucol * nc)
        cols[self.block_pos] = self._pair_col[None, None, :] + np.arange(nc)[None, :, None]
        # -D entries after the stiffness of each row
        d_start = np.concatenate([[0], np.cumsum(nd_row)])[:-1]
        self.d_final = rowptr[d_r] + k_nnz[d_r] + (np.arange(d_r.size) - d_start[d_r])
        cols[self.d_final] = layout.l_index(d_c)
        # A entries, then the diagonal slot last in each multiplier row
        a_start = np.concatenate([[0], np.cumsum(na_row - 1)])[:-1]
        self.a_final = rowptr[nqo + a_r] + (np.arange(a_r.size) - a_start[a_r])
        cols[self.a_final] = layout.q_index(a_c)
        self.l_diag = rowptr[nqo + np.arange(nlo) + 1] - 1
        cols[self.l_diag] = layout.l_index(np.arange(l0, l1))
        self.offset = int(layout.offsets[comm.rank])
        self.rowptr = rowptr.astype(PETSc.IntType)
        self.cols = cols
        self.data = np.zeros(nnz)
        self.active = np.ones(layout.nl, dtype=bool)  # global multiplier rows enforced
        self._l0, self._l1 = l0, l1
        self.mat: PETSc.Mat | None = None
        # nothing eliminated until the system says so (set_eliminated); no pass over the CSR here
        empty = np.zeros(0, dtype=np.int64)
        self.elim_rows = self._row_entries = self._row_of_row_entries = empty
        self._col_entries = self._row_of_col_entries = self._diag_entries = empty

    # ------------------------------------------------------------------ values

    def relation_values(self, diag: float = 1.0) -> None:
        """Write the scaled -D and A values into the CSR value array. An inactive row keeps its
        pattern: A row and D column zero, ``diag`` on its diagonal, so its λ solves to 0."""
        b, on = self.block, self.active.astype(float)
        d_cols, a_rows = b.d_cols[self._d_sel], b.a_rows[self._a_sel]
        dv = -b.d_vals[self._d_sel] * b.col_scale[d_cols] * on[d_cols]
        av = b.a_vals[self._a_sel] * b.row_scale[a_rows] * on[a_rows] * b.a_on[self._a_sel]
        self.data[self.d_final] = np.bincount(self._d_inv, weights=dv, minlength=self.d_final.size)
        self.data[self.a_final] = np.bincount(self._a_inv, weights=av, minlength=self.a_final.size)
        self.data[self.l_diag] = diag * (1.0 - on[self._l0:self._l1])

    def set_stiffness(self, blocks: np.ndarray) -> None:
        """Place node-pair blocks (ncomp², npairs) into the stiffness slots.

        Relation values are written by ``relation_values`` (they need the stiffness scale).
        """
        nc = self.layout.ncomp
        self.data[self.block_pos] = blocks.reshape(nc, nc, -1)

    def diagonal_scale(self) -> float:
        """Mean absolute stiffness diagonal over all ranks (scale for relations and eliminations)."""
        local = np.abs(self.data[self.diag_pos]).sum()
        total = self.comm.allreduce(local)
        count = self.comm.allreduce(int(self.diag_pos.size))
        return total / max(count, 1) if total > 0 else 1.0

    # ------------------------------------------------------------------ PETSc

    def petsc_matrix(self) -> PETSc.Mat:
        """Create the Mat on first call, then refill it in place (same pattern)."""
        n = self.nrows
        if self.mat is None:
            self.mat = PETSc.Mat().createAIJ(size=((n, self.size), (n, self.size)),
                                             csr=(self.rowptr, self.cols, self.data), comm=self.comm)
            self.mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        else:
            self.mat.setValuesCSR(self.rowptr, self.cols, self.data)
        self.mat.assemble()
        return self.mat

    # ------------------------------------------------------------------ elimination

    def set_eliminated(self, rows: np.ndarray) -> None:
        """Saddle indices (global) of the DOFs to eliminate: their rows and columns are zeroed and
        their diagonal set by ``eliminate``, in the value array itself (no PETSc pass)."""
        is_elim = np.zeros(self.size + 1, dtype=bool)
        is_elim[rows] = True
        local = np.unique(rows[(rows >= self.offset) & (rows < self.offset + self.nrows)]) - self.offset
        self.elim_rows = local + self.offset
        # entries of the eliminated rows: whole CSR rows
        lengths = np.diff(self.rowptr)[local]
        starts = np.repeat(self.rowptr[local].astype(np.int64) - np.cumsum(lengths) + lengths, lengths)
        self._row_entries = starts + np.arange(lengths.sum())
        self._row_of_row_entries = np.repeat(local, lengths)
        # entries in eliminated columns: only in node-pair blocks whose column node has an
        # eliminated DOF, and in relation rows
        nc = self.layout.ncomp
        node_elim = is_elim[self._pair_col[:, None] + np.arange(nc)].any(axis=1)
        cand = np.concatenate([self.block_pos[:, :, node_elim].ravel(), self.a_final])
        self._col_entries = np.sort(cand[is_elim[self.cols[cand]]])
        self._row_of_col_entries = np.searchsorted(self.rowptr, self._col_entries, side="right") - 1
        self._diag_entries = self.diag_pos[local]

    def eliminate(self, diag: float) -> None:
        """Keep the eliminated rows and columns for lifting and reactions, then zero them."""
        self._row_vals = self.data[self._row_entries]
        self._col_vals = self.data[self._col_entries]
        self.data[self._row_entries] = 0.0
        self.data[self._col_entries] = 0.0
        self.data[self._diag_entries] = diag

    def lifting(self, x: np.ndarray) -> np.ndarray:
        """Owned rows of (eliminated columns, before zeroing) × x, x a full saddle vector."""
        e = self._col_entries
        return np.bincount(self._row_of_col_entries, weights=self._col_vals * x[self.cols[e]],
                           minlength=self.nrows)

    def eliminated_rows(self, x: np.ndarray) -> np.ndarray:
        """Owned rows of (matrix before elimination) × x: valid on the eliminated rows."""
        e = self._row_entries
        return np.bincount(self._row_of_row_entries, weights=self._row_vals * x[self.cols[e]],
                           minlength=self.nrows)

    def index_sets(self) -> tuple[PETSc.IS, PETSc.IS]:
        """Stride index sets of the primal and multiplier fields (each rank's blocks are contiguous)."""
        q0, q1, l0, l1 = self.layout.owned(self.comm.rank)
        start = int(self.layout.offsets[self.comm.rank])
        is_q = PETSc.IS().createStride(q1 - q0, first=start, step=1, comm=self.comm)
        is_l = PETSc.IS().createStride(l1 - l0, first=start + q1 - q0, step=1, comm=self.comm)
        is_q.setBlockSize(self.layout.ncomp)
        return is_q, is_l
