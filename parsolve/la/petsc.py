"""The distributed saddle operator [[K, -D], [A, 0]] as one PETSc MPIAIJ matrix.

Each rank owns its primal rows then its multiplier rows (see ``layout``). The rank's CSR is
built once: stiffness entries first in each primal row, then that row's relation columns;
multiplier rows hold A and a diagonal slot (zero unless the row is switched off by an
active-set loop, which then sets it to keep the pattern fixed). Re-assembly scatters element
matrices into the CSR value array with one ``np.bincount`` and hands it to PETSc in one call.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from parsolve.la.layout import Layout
from parsolve.la.pattern import RowPattern
from parsolve.la.saddle import RelationBlock


def _dedupe(rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, ncols: int):
    """Sum duplicate (row, col) entries; returns (rows, cols, index of each input entry)."""
    key = rows.astype(np.int64) * ncols + cols
    ukey, inv = np.unique(key, return_inverse=True)
    return ukey // ncols, ukey % ncols, inv


class SaddleOperator:
    """Owned rows of the saddle matrix, their fixed pattern, and the PETSc Mat built from them."""

    def __init__(self, comm: MPI.Comm, layout: Layout, pattern: RowPattern, block: RelationBlock):
        self.comm = comm
        self.layout = layout
        self.block = block
        rank = comm.rank
        q0, q1, l0, l1 = layout.owned(rank)
        nqo, nlo = q1 - q0, l1 - l0
        self.nrows = nqo + nlo
        size = layout.size
        # relation columns in the owned primal rows: entries (q row, λ col) of -D
        own_d = (block.d_rows >= q0) & (block.d_rows < q1)
        d_r, d_c, d_inv = _dedupe(block.d_rows[own_d] - q0, block.d_cols[own_d], None, layout.nl)
        self._d_sel, self._d_inv = np.flatnonzero(own_d), d_inv
        # multiplier rows: A entries plus a diagonal slot per row
        own_a = (block.a_rows >= l0) & (block.a_rows < l1)
        a_r, a_c, a_inv = _dedupe(block.a_rows[own_a] - l0, block.a_cols[own_a], None, layout.nq)
        self._a_sel, self._a_inv = np.flatnonzero(own_a), a_inv
        nd_row = np.bincount(d_r, minlength=nqo)
        na_row = np.bincount(a_r, minlength=nlo) + 1
        row_nnz = np.concatenate([pattern.row_nnz_k + nd_row, na_row])
        rowptr = np.concatenate([[0], np.cumsum(row_nnz)]).astype(np.int64)
        nnz = int(rowptr[-1])
        cols = np.empty(nnz, dtype=np.int64)
        # stiffness entries keep their order at the head of each primal row
        k_row = np.repeat(np.arange(nqo), pattern.row_nnz_k)
        k_final = rowptr[k_row] + (np.arange(k_row.size) - pattern.row_start_k[k_row])
        cols[k_final] = layout.q_index(pattern.cols_k)
        kmap = np.append(k_final, nnz)  # element entries of rows owned elsewhere go to a dump slot
        pos = pattern.positions
        self.k_positions = np.where(pos >= 0, kmap[np.where(pos >= 0, pos, -1)], nnz).ravel()
        # -D entries after the stiffness of each row
        d_start = np.concatenate([[0], np.cumsum(nd_row)])[:-1]
        self.d_final = rowptr[d_r] + pattern.row_nnz_k[d_r] + (np.arange(d_r.size) - d_start[d_r])
        cols[self.d_final] = layout.l_index(d_c)
        # A entries, then the diagonal slot last in each multiplier row
        a_start = np.concatenate([[0], np.cumsum(na_row - 1)])[:-1]
        self.a_final = rowptr[nqo + a_r] + (np.arange(a_r.size) - a_start[a_r])
        cols[self.a_final] = layout.q_index(a_c)
        self.l_diag = rowptr[nqo + np.arange(nlo) + 1] - 1
        cols[self.l_diag] = layout.l_index(np.arange(l0, l1))
        self.rowptr = rowptr.astype(PETSc.IntType)
        self.cols = cols.astype(PETSc.IntType)
        self.data = np.zeros(nnz)
        self.l_diag_vals = np.zeros(nlo)
        self.mat: PETSc.Mat | None = None
        self.elim_rows = np.zeros(0, dtype=PETSc.IntType)  # saddle indices of eliminated DOFs
        self.elim_diag = 1.0
        self.size = size

    # ------------------------------------------------------------------ values

    def relation_values(self) -> None:
        """Write the scaled -D and A values into the CSR value array."""
        b = self.block
        dv = -b.d_vals[self._d_sel] * b.col_scale[b.d_cols[self._d_sel]]
        av = b.a_vals[self._a_sel] * b.row_scale[b.a_rows[self._a_sel]]
        self.data[self.d_final] = np.bincount(self._d_inv, weights=dv, minlength=self.d_final.size)
        self.data[self.a_final] = np.bincount(self._a_inv, weights=av, minlength=self.a_final.size)
        self.data[self.l_diag] = self.l_diag_vals

    def set_stiffness(self, ke: np.ndarray) -> None:
        """Scatter element matrices (local cells × ndof × ndof) into the stiffness slots.

        Relation values are written by ``relation_values`` (they need the stiffness scale).
        """
        nnz = self.data.size
        self.data[:] = np.bincount(self.k_positions, weights=ke.ravel(), minlength=nnz + 1)[:nnz]

    def diagonal_scale(self) -> float:
        """Mean absolute stiffness diagonal over all ranks (scale for relations and eliminations)."""
        q0, q1, _, _ = self.layout.owned(self.comm.rank)
        nqo = q1 - q0
        diag_cols = self.layout.q_index(np.arange(q0, q1))
        row = np.repeat(np.arange(self.nrows), np.diff(self.rowptr))
        on_diag = (row < nqo) & (self.cols == diag_cols[np.minimum(row, nqo - 1)]) if nqo else row < 0
        local = np.abs(self.data[on_diag]).sum()
        total = self.comm.allreduce(local)
        count = self.comm.allreduce(int(on_diag.sum()))
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
        if self.comm.allreduce(self.elim_rows.size):  # collective: every rank must call it
            self.mat.zeroRowsColumns(self.elim_rows, diag=self.elim_diag)
        return self.mat

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """Owned rows of (matrix as assembled, before elimination) × x, x a full saddle vector."""
        row = np.repeat(np.arange(self.nrows), np.diff(self.rowptr))
        return np.bincount(row, weights=self.data * x[self.cols], minlength=self.nrows)

    def index_sets(self) -> tuple[PETSc.IS, PETSc.IS]:
        """Stride index sets of the primal and multiplier fields (each rank's blocks are contiguous)."""
        q0, q1, l0, l1 = self.layout.owned(self.comm.rank)
        start = int(self.layout.offsets[self.comm.rank])
        is_q = PETSc.IS().createStride(q1 - q0, first=start, step=1, comm=self.comm)
        is_l = PETSc.IS().createStride(l1 - l0, first=start + q1 - q0, step=1, comm=self.comm)
        is_q.setBlockSize(self.layout.ncomp)
        return is_q, is_l
