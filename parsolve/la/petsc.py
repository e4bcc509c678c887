"""The distributed saddle operator [[K, -D], [A, 0]] as one PETSc MPIAIJ matrix.

Each rank owns its primal rows then its multiplier rows (see ``dofmap``). The rank's CSR is
built once, directly in PETSc's own split format, and PETSc works on these arrays without
copying them (``createAIJWithArrays``: ``MatCreateSeqAIJWithArrays`` on one rank,
``MatCreateMPIAIJWithSplitArrays`` on several): the value array ``data`` holds first the
*diagonal block* (the columns this rank owns, local column numbers), then the *off-diagonal
block* (the other columns, global numbers), each row by row with its columns in increasing
order, as PETSc keeps them. Re-assembly places node-pair blocks (summed from element
matrices by ``np.bincount``) into ``data`` through fixed positions and tells PETSc that the
values changed: no copy, no ``MatSetValues`` pass, and no second value array beside PETSc's.

A primal row of the diagonal block: its stiffness entries (owned column nodes, increasing),
then its relation columns (-D, owned multipliers); of the off-diagonal block: stiffness
entries of other ranks' nodes merged with their relation columns by column. A multiplier row
holds A (owned then other primal columns) and a diagonal slot (zero unless the row is switched
off by an active-set loop, which then sets it to keep the pattern fixed). A primal row with no
stiffness entry (a point no cell uses) gets a diagonal slot of its own.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from parsolve.la.dofmap import DofMap
from parsolve.la.pattern import NodePattern
from parsolve.la.relation_set import RelationSet


def _dedupe(rows: np.ndarray, cols: np.ndarray, ncols: int):
    """Unique (row, col) pairs, sorted; returns (rows, cols, index of each input entry among
    them). Entries already strictly increasing (the usual case: one entry per pair, built in
    order) skip the sort."""
    key = rows.astype(np.int64) * max(ncols, 1) + cols
    if key.size == 0 or np.all(key[1:] > key[:-1]):
        ukey, inv = key, np.arange(key.size)
    else:
        ukey, inv = np.unique(key, return_inverse=True)
    return ukey // max(ncols, 1), ukey % max(ncols, 1), inv


def _rank_in_row(rows: np.ndarray, nrows: int) -> np.ndarray:
    """Rank of each entry among the entries of its row (entries sorted by row)."""
    counts = np.bincount(rows, minlength=nrows)
    return np.arange(rows.size) - (np.cumsum(counts) - counts)[rows]


def _count_below(keys: np.ndarray, row: np.ndarray, value: np.ndarray, width: int) -> np.ndarray:
    """Entries of sorted ``keys`` (row * width + column) in ``row`` with a column < ``value``."""
    if keys.size == 0:
        return np.zeros(row.size, dtype=np.int64)
    base = row.astype(np.int64) * width
    return np.searchsorted(keys, base + value) - np.searchsorted(keys, base)


def _row_pointer(lengths: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(lengths, dtype=np.int64)])


def _ranges(rowptr: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(entries, row of each entry) of the given rows of a CSR."""
    starts = rowptr[rows].astype(np.int64)
    lengths = rowptr[rows + 1].astype(np.int64) - starts
    first = np.repeat(starts - (np.cumsum(lengths) - lengths), lengths)
    return first + np.arange(int(lengths.sum())), np.repeat(rows, lengths)


class SaddleOperator:
    """Owned rows of the saddle matrix, their fixed pattern, and the PETSc Mat built on them."""

    def __init__(self, comm: MPI.Comm, layout: DofMap, pattern: NodePattern, block: RelationSet):
        self.comm = comm
        self.layout = layout   # the DofMap
        self.block = block
        self.pattern = pattern
        q0, q1, l0, l1 = layout.owned(comm.rank)
        nqo, nlo = q1 - q0, l1 - l0
        self.nrows = nqo + nlo
        self.size = layout.size
        self.offset = off = int(layout.offsets[comm.rank])
        nc = layout.ncomp
        # relation columns in the owned primal rows: entries (q row, λ col) of -D
        own_d = (block.d_rows >= q0) & (block.d_rows < q1)
        d_r, d_c, self._d_inv = _dedupe(block.d_rows[own_d] - q0, block.d_cols[own_d], layout.nl)
        self._d_sel = np.flatnonzero(own_d)
        # multiplier rows: A entries plus a diagonal slot per row
        own_a = (block.a_rows >= l0) & (block.a_rows < l1)
        a_r, a_c, self._a_inv = _dedupe(block.a_rows[own_a] - l0, block.a_cols[own_a], layout.nq)
        self._a_sel = np.flatnonzero(own_a)
        d_in, a_in = (d_c >= l0) & (d_c < l1), (a_c >= q0) & (a_c < q1)
        # node pairs by the owner of their column node: ucol is increasing in a row and the
        # owned nodes are one range, so a row is [lower ranks' nodes, own nodes, upper ranks']
        lo, hi = pattern.lo, pattern.lo + pattern.nown
        bptr = _row_pointer(pattern.nb)
        pair_in = (pattern.ucol >= lo) & (pattern.ucol < hi)
        all_in = bool(pair_in.all())
        if all_in:
            n_low, n_in = np.zeros(pattern.nown, dtype=np.int64), pattern.nb.astype(np.int64)
        else:
            c_low = _row_pointer(pattern.ucol < lo)
            c_in = _row_pointer(pair_in)
            n_low = c_low[bptr[1:]] - c_low[bptr[:-1]]
            n_in = c_in[bptr[1:]] - c_in[bptr[:-1]]
        empty = np.repeat(pattern.nb == 0, nc)            # DOF rows with no stiffness entry
        k_in = np.repeat(n_in * nc, nc)
        # row lengths of the diagonal block (d) and the off-diagonal block (o)
        len_d = np.concatenate([k_in + empty + np.bincount(d_r[d_in], minlength=nqo),
                                np.bincount(a_r[a_in], minlength=nlo) + 1])
        len_o = np.concatenate([np.repeat((pattern.nb - n_in) * nc, nc)
                                + np.bincount(d_r[~d_in], minlength=nqo),
                                np.bincount(a_r[~a_in], minlength=nlo)])
        rowptr_d, rowptr_o = _row_pointer(len_d), _row_pointer(len_o)
        self.nnz_d = nnz_d = int(rowptr_d[-1])
        nnz = nnz_d + int(rowptr_o[-1])
        itype = PETSc.IntType
        cols_d = np.empty(nnz_d, dtype=itype)             # local column numbers
        cols_o = np.empty(nnz - nnz_d, dtype=np.int64)    # global column numbers
        # off-diagonal relation entries, as sorted keys (row, global column): they interleave
        # with the off-diagonal stiffness entries of their row
        d_out = np.flatnonzero(~d_in)
        d_out_col = layout.l_index(d_c[d_out])
        d_out_key = d_r[d_out] * self.size + d_out_col
        # stiffness entries: positions of the owned-column pairs by a ramp (NodePattern), then
        # the few other pairs
        shift = rowptr_d[:nqo] + empty - nc * np.repeat(n_low, nc)
        # entry (i, j) of pair p is at block_start[i, p] + j: a block row's entries are
        # consecutive (a relation column never falls inside a node's DOFs)
        self.block_start = starts = pattern.block_starts(
            shift, dtype=itype if nnz < 2**31 else np.int64)
        if all_in:
            local = (pattern.ucol - lo) * nc
            for i in range(nc):
                for j in range(nc):
                    cols_d[j:][starts[i]] = local + j
        else:
            local = (pattern.ucol[pair_in] - lo) * nc
            for i in range(nc):
                inner = starts[i, pair_in]
                for j in range(nc):
                    cols_d[j:][inner] = local + j
            p_out = np.flatnonzero(~pair_in)
            node = np.searchsorted(bptr, p_out, side="right") - 1
            k = p_out - bptr[node]
            k_out = np.where(pattern.ucol[p_out] < lo, k, k - n_in[node])
            qcol = layout.q_index(pattern.ucol[p_out] * nc)
            for i in range(nc):
                row = node * nc + i
                start = rowptr_o[row] + nc * k_out + _count_below(d_out_key, row, qcol, self.size)
                starts[i, p_out] = nnz_d + start
                for j in range(nc):
                    cols_o[start + j] = qcol + j
            # pairs outside, as sorted keys (node, global column of their first component)
            pair_out_key = node * self.size + qcol
        # -D entries: owned multipliers after the stiffness of the row, others merged by column
        self.d_final = np.empty(d_r.size, dtype=np.int64)
        r = d_r[d_in]
        self.d_final[d_in] = rowptr_d[r] + empty[r] + k_in[r] + _rank_in_row(r, nqo)
        cols_d[self.d_final[d_in]] = nqo + d_c[d_in] - l0
        if d_out.size:
            r = d_r[d_out]
            before = 0 if all_in else nc * _count_below(pair_out_key, r // nc, d_out_col, self.size)
            pos = rowptr_o[r] + _rank_in_row(r, nqo) + before
            self.d_final[d_out] = nnz_d + pos
            cols_o[pos] = d_out_col
        # A entries (owned primal columns, then the others), the diagonal slot last
        self.a_final = np.empty(a_r.size, dtype=np.int64)
        r = a_r[a_in]
        self.a_final[a_in] = rowptr_d[nqo + r] + _rank_in_row(r, nlo)
        cols_d[self.a_final[a_in]] = a_c[a_in] - q0
        r = a_r[~a_in]
        pos = rowptr_o[nqo + r] + _rank_in_row(r, nlo)
        self.a_final[~a_in] = nnz_d + pos
        cols_o[pos] = layout.q_index(a_c[~a_in])
        self.l_diag = rowptr_d[nqo + np.arange(nlo) + 1] - 1
        cols_d[self.l_diag] = nqo + np.arange(nlo)
        # diagonal entries of the primal rows
        rows = np.arange(nqo)
        self.diag_pos = np.where(empty, rowptr_d[:nqo], pattern.diagonal_positions(shift)).astype(
            starts.dtype)
        cols_d[rowptr_d[rows[empty]]] = rows[empty]
        self.rowptr_d, self.cols_d = rowptr_d.astype(itype), cols_d
        self.rowptr_o, self._cols_o = rowptr_o.astype(itype), cols_o
        self.data = np.zeros(nnz)
        self.active = np.ones(layout.n_held, dtype=bool)  # held multiplier rows enforced
        self._l0, self._l1 = l0, l1
        self.mat: PETSc.Mat | None = None
        # nothing eliminated until the system says so (set_eliminated); no pass over the CSR here
        empty64 = np.zeros(0, dtype=np.int64)
        self.elim_rows = self._row_entries = self._row_of_row_entries = empty64
        self._col_entries = self._row_of_col_entries = self._diag_entries = empty64
        self._row_cols = self._col_cols = empty64

    # ------------------------------------------------------------------ the CSR

    def global_columns(self, entries: np.ndarray) -> np.ndarray:
        """Global (saddle) column of entries of ``data``."""
        entries = np.asarray(entries, dtype=np.int64)
        inner = entries < self.nnz_d
        out = np.empty(entries.size, dtype=np.int64)
        out[inner] = self.cols_d[entries[inner]] + self.offset
        out[~inner] = self._cols_o[entries[~inner] - self.nnz_d]
        return out

    def row_of(self, entries: np.ndarray) -> np.ndarray:
        """Owned row (0-based) of entries of ``data``."""
        entries = np.asarray(entries, dtype=np.int64)
        inner = entries < self.nnz_d
        out = np.empty(entries.size, dtype=np.int64)
        out[inner] = np.searchsorted(self.rowptr_d, entries[inner], side="right") - 1
        out[~inner] = np.searchsorted(self.rowptr_o, entries[~inner] - self.nnz_d, side="right") - 1
        return out

    @property
    def block_pos(self) -> np.ndarray:
        """(ncomp, ncomp, nnzb) place in ``data`` of entry (i, j) of each node-pair block
        (built on demand from ``block_start``: not kept)."""
        nc = self.layout.ncomp
        return self.block_start[:, None, :] + np.arange(nc, dtype=self.block_start.dtype)[None, :, None]

    @property
    def cols(self) -> np.ndarray:
        """Global column of every entry of ``data`` (built on demand: not kept)."""
        return np.concatenate([self.cols_d + np.int64(self.offset), self._cols_o])

    def dense(self) -> np.ndarray:
        """The owned rows as a dense (nrows, size) array (small systems: tests)."""
        out = np.zeros((self.nrows, self.size))
        entries = np.arange(self.data.size)
        np.add.at(out, (self.row_of(entries), self.global_columns(entries)), self.data)
        return out

    # ------------------------------------------------------------------ values

    def relation_values(self, diag: float = 1.0) -> None:
        """Write the scaled -D and A values into the CSR value array. An inactive row keeps its
        pattern: A row and D column zero, ``diag`` on its diagonal, so its λ solves to 0."""
        b, on = self.block, self.active.astype(float)   # (per held multiplier row)
        d_cols, a_rows = b.d_places[self._d_sel], b.a_rows[self._a_sel] - self._l0
        dv = -b.d_vals[self._d_sel] * b.col_scale[d_cols] * on[d_cols]
        av = b.a_vals[self._a_sel] * b.row_scale[a_rows] * on[a_rows] * b.a_on[self._a_sel]
        self.data[self.d_final] = np.bincount(self._d_inv, weights=dv, minlength=self.d_final.size)
        self.data[self.a_final] = np.bincount(self._a_inv, weights=av, minlength=self.a_final.size)
        own = slice(0, self._l1 - self._l0)   # (owned rows first among the held)
        self.data[self.l_diag] = diag * (1.0 - on[own])

    def set_stiffness(self, blocks: np.ndarray) -> None:
        """Place node-pair blocks (ncomp², npairs) into the stiffness slots.

        Relation values are written by ``relation_values`` (they need the stiffness scale).
        """
        nc = self.layout.ncomp
        blocks = blocks.reshape(nc, nc, -1)
        for i in range(nc):
            for j in range(nc):
                self.data[j:][self.block_start[i]] = blocks[i, j]

    def diagonal_scale(self) -> float:
        """Mean absolute stiffness diagonal over all ranks (scale for relations and eliminations)."""
        local = np.abs(self.data[self.diag_pos]).sum()
        total = self.comm.allreduce(local)
        count = self.comm.allreduce(int(self.diag_pos.size))
        return total / max(count, 1) if total > 0 else 1.0

    # ------------------------------------------------------------------ PETSc

    def petsc_matrix(self) -> PETSc.Mat:
        """Create the Mat on first call, on the operator's own arrays; afterwards the values
        are already in place: assembling tells PETSc they changed (its state increases, so a
        preconditioner or factorization set up on the old values is set up again)."""
        if self.mat is not None and self.mat.getType() != self._mat_type:
            self.mat = None   # converted in place (e.g. Mat.convert("dense") with no target):
            # it no longer works on ``data``, so a new one is made
        if self.mat is None:
            n, d = self.nrows, self.data
            diag = (self.rowptr_d, self.cols_d, d[:self.nnz_d])
            if self.comm.size == 1:
                csr = diag
            else:  # PETSc compacts the off-diagonal columns in place: give it a copy
                csr = (diag, (self.rowptr_o, self._cols_o.astype(PETSc.IntType), d[self.nnz_d:]))
            # without multiplier rows every rank's rows are whole nodes (ncomp DOFs each, node-
            # major): the block size tells GAMG so; as a scalar problem its set-up took ~25x
            # the memory on a 3D box (+1195 MiB against +46 MiB at 499k DOFs, same iterations)
            self.mat = PETSc.Mat().createAIJWithArrays(size=((n, self.size), (n, self.size)),
                                                       csr=csr, comm=self.comm)
            if self.layout.nl == 0 and self.layout.ncomp > 1:   # (the constructor ignores bsize)
                self.mat.setBlockSize(self.layout.ncomp)
            self.mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
            self._mat_type = self.mat.getType()
            # petsc4py falls back to a copying constructor (global columns everywhere) when an
            # off-diagonal array has no storage: that would be another matrix
            if int(self.mat.getInfo(PETSc.Mat.InfoType.LOCAL)["nz_used"]) != d.size:
                raise RuntimeError("PETSc did not take the operator's arrays as given")
        self.mat.assemble()
        return self.mat

    # ------------------------------------------------------------------ elimination

    def set_eliminated(self, rows: np.ndarray) -> None:
        """Saddle indices (global) of the DOFs to eliminate: their rows and columns are zeroed and
        their diagonal set by ``eliminate``, in the value array itself (no PETSc pass)."""
        rows = np.unique(rows)   # (those this rank reads: no array of the global size)
        local = rows[(rows >= self.offset) & (rows < self.offset + self.nrows)] - self.offset
        self.elim_rows = local + self.offset
        # entries of the eliminated rows, in the order of their row then column (stiffness
        # before relation columns), as the products below sum them
        ent_d, row_d = _ranges(self.rowptr_d, local)
        ent_o, row_o = _ranges(self.rowptr_o, local)
        entries = np.concatenate([ent_d, ent_o + self.nnz_d])
        erow = np.concatenate([row_d, row_o])
        ecol = self.global_columns(entries)
        is_rel = np.isin(entries, self.d_final)
        order = np.lexsort((ecol, is_rel, erow))
        self._row_entries, self._row_of_row_entries = entries[order], erow[order]
        self._row_cols = ecol[order]
        # entries in eliminated columns: only in node-pair blocks whose column node has an
        # eliminated DOF, and in relation rows
        nc, lay = self.layout.ncomp, self.layout
        # nodes with an eliminated DOF (new numbering), then the node pairs in their columns
        new_dof, prim_rows = lay.saddle_to_new(rows)
        node_elim = np.isin(self.pattern.ucol, new_dof[prim_rows] // nc)
        first = self.block_start[:, None, node_elim].astype(np.int64)
        cand = np.concatenate([(first + np.arange(nc)[None, :, None]).ravel(), self.a_final])
        cand = cand[np.isin(self.global_columns(cand), rows)]
        crow, ccol = self.row_of(cand), self.global_columns(cand)
        order = np.lexsort((ccol, crow))
        self._col_entries, self._row_of_col_entries = cand[order], crow[order]
        self._col_cols = ccol[order]
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
        return np.bincount(self._row_of_col_entries, weights=self._col_vals * x[self._col_cols],
                           minlength=self.nrows)

    def eliminated_rows(self, x: np.ndarray) -> np.ndarray:
        """Owned rows of (matrix before elimination) × x: valid on the eliminated rows."""
        return np.bincount(self._row_of_row_entries, weights=self._row_vals * x[self._row_cols],
                           minlength=self.nrows)

    def index_sets(self) -> tuple[PETSc.IS, PETSc.IS]:
        """Stride index sets of the primal and multiplier fields (each rank's blocks are contiguous)."""
        q0, q1, l0, l1 = self.layout.owned()
        start = self.layout.offset
        is_q = PETSc.IS().createStride(q1 - q0, first=start, step=1, comm=self.comm)
        is_l = PETSc.IS().createStride(l1 - l0, first=start + q1 - q0, step=1, comm=self.comm)
        is_q.setBlockSize(self.layout.ncomp)
        return is_q, is_l
