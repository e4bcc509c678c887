"""The iterative preset's preconditioner for a saddle system whose relation rows are all nodal
(each row's A entries on one node's DOFs, its dual column D on the same node, no multiplier
coupled to another: rigid-obstacle contact and friction, Dirichlet-type rows): the rows are
condensed node by node, and one algebraic multigrid V-cycle works on the condensed primal
operator. Krylov (GMRES) runs on the saddle system M = [[K, B], [A, C]] itself (B = -D), so
its answer is the direct preset's whatever the preconditioner's quality.

With exact solves the preconditioner is M⁻¹, built in three eliminations:

- A row with a diagonal C (an open row: C the placeholder, A and B zero; any diagonal C
  alike) gives λ = C⁻¹ (r_λ - A q): folded into the primal operator,
  K_eff = K - B C⁻¹ A (per node, a ncomp × ncomp block), r̂ = r_q - B C⁻¹ r_λ.
- The hard rows of a node (C = 0) A_n = Rᵀ Q_cᵀ (a QR of A_nᵀ, Q = [Q_c, Q_f] orthonormal):
  the node's displacement in the frame Q, u = Q_c y_c + Q_f y_f, has y_c = R⁻ᵀ r_h. The
  dual in the frame Qᵀ B_n = [E_c; E_f] (E_f ≠ 0 when the relation is not associated:
  friction's sliding rows): the free rows, less E_f E_c⁻¹ times the constrained ones, hold no
  multiplier: L = [[I, 0], [-E_f E_c⁻¹, I]].
- The free displacement solves S y_f = G (r̂ - K_eff Q_c y_c), S = G K_eff H (G = Z L Qᵀ,
  H = Q Z, Z the free directions, block diagonal; the constrained slots of S hold k on the
  diagonal), then λ_h = E_c⁻¹ Q_cᵀ (r̂ - K_eff q).

S is a copy of K whose condensed nodes' rows (G) and columns (H) are transformed in place,
with no product of matrices: K's pattern, one copy of K's values and no temporary as large.
It is symmetric when the relations are associated, and is an elastic stiffness with some
nodal directions held: the AMG sees it with the rigid-body modes in the nodal frames (Hᵀ
times them). Everything per node is batched numpy on (nodes, ncomp, ncomp)
stacks (padded: a node with k hard rows has an identity beyond its k × k block); every row's
node is owned by the rank that owns the row (checked: else the system is not condensable).
"""

from __future__ import annotations

import atexit

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from parsolve.solvers import tied
from parsolve.solvers.options import product_clear
from parsolve.solvers.vcycle import FINE_SWEEPS, TIED_SWEEPS, VCycle

#: why a system is not condensed, in words; the largest code over the ranks wins (a row that
#: ties several nodes is the plainest reason, a row across ranks the least)
REASONS = {
    1: "a relation row's DOFs or dual lie on another rank",
    2: "multiplier rows coupled to each other",
    3: "a dual column off its row's node",
    4: "dependent hard rows on a node",
    5: "a node's dual does not hold its hard rows",
    6: "a relation row ties several nodes",
    7: "the stiffness is not made of whole nodal blocks at a condensed node",
    8: "a compliant relation row ties several nodes",
    9: "a relation row's master node holds hard rows of its own (a chain, or a row over "
       "several slave nodes)",
}
#: a hard row's QR diagonal, relative to the node's largest entry, below which the rows are
#: taken as dependent; E_c's condition number above which the dual does not hold them
RANK_TOL = 1e-8
COND_MAX = 1e12


#: the communicators of the preconditioners made: their PETSc garbage is destroyed before
#: Python exits (``_clean_up``)
_COMMS: list = []


def _clean_up() -> None:
    """Destroy the deferred PETSc objects (the KSPs whose Python objects are gone) while
    Python runs, and take the condensed python PCs still alive (a solver held by a module's
    global, or by an uncaught exception's traceback: Python keeps it as sys.last_* past the
    exit handlers) off their context: PetscFinalize and the interpreter's teardown destroy
    them after Python's end, and the python PC's destroy then calls into a finished
    interpreter (a segmentation fault at exit, hiding the run's own error). Collective, as
    PetscFinalize's own clean-up is."""
    import gc
    import sys

    for name in ("last_type", "last_value", "last_traceback", "last_exc"):
        if hasattr(sys, name):
            setattr(sys, name, None)
    gc.collect()   # (solvers in reference cycles: freed now, their KSPs deferred)
    for comm in _COMMS:
        try:
            PETSc.garbage_cleanup(comm)
        except Exception:   # (a communicator freed before the end)
            pass
    for obj in gc.get_objects():
        if isinstance(obj, (PETSc.KSP, PETSc.PC)) and obj.handle:
            _detach(obj.getPC() if isinstance(obj, PETSc.KSP) else obj)


def _detach(pc: PETSc.PC) -> None:
    """A python PC whose context is a CondensedPreconditioner made a plain one (its context
    released while Python runs)."""
    if pc.getType() == "python" and isinstance(pc.getPythonContext(), CondensedPreconditioner):
        pc.setType("none")


class CondensedPreconditioner:
    """``update(mat)`` condenses the operator's relation rows (None: done; else the reason
    why not, the same on every rank); ``apply`` is the PETSc python PC's application: M⁻¹
    with S⁻¹ replaced by one AMG V-cycle (options under ``<prefix>condensed_``).

    S is K's copy (a submatrix of M, its storage reused by the next updates) with the rows
    and columns of the condensed nodes transformed in place; the application's products with
    K and A are products with M of vectors zero in the multipliers (B's only on the rows with
    a diagonal C, per node)."""

    def __init__(self, comm: MPI.Comm, ncomp: int, is_q: PETSc.IS, is_l: PETSc.IS,
                 prefix: str):
        self.comm, self.nc, self.prefix = comm, int(ncomp), prefix
        if not _COMMS:
            atexit.register(_clean_up)
        if all(c is not comm for c in _COMMS):
            _COMMS.append(comm)
        self.is_q, self.is_l = is_q, is_l
        self.nq, self.nl = is_q.getLocalSize(), is_l.getLocalSize()
        # each rank's first saddle row, primal rows' and multiplier rows' counts (comm-size)
        sizes = np.array(comm.allgather((self.nq, self.nl)), dtype=np.int64)
        self.starts = np.concatenate([[0], np.cumsum(sizes.sum(axis=1))])
        self.nqs = sizes[:, 0]
        self.start = int(self.starts[comm.rank])
        self.q_start = int(self.nqs[:comm.rank].sum())   # in the primal numbering (S's)
        self.l_start = int(sizes[:comm.rank, 1].sum())    # in the multipliers' numbering
        self.is_all = PETSc.IS().createStride(self.nq + self.nl, first=self.start, step=1,
                                              comm=comm)
        self._handle = None
        self.amg: VCycle | None = None
        self._reset()

    def _reset(self) -> None:
        self.mat = self.S = self._work = None
        # the tied rows' frames (solvers.tied; None: every row nodal), their pattern's digest
        # and K's copy
        self.G = self.H = self.X = self._k = self.frame_pattern = None

    # ------------------------------------------------------------------ set-up

    def update(self, mat: PETSc.Mat) -> str | None:
        """Condense ``mat``'s rows and set the AMG up on S; the reason in words when some rank
        cannot (nothing is set up then)."""
        if self.comm.allreduce(int(mat.handle != self._handle), op=MPI.MAX):
            self._handle = mat.handle
            self._reset()
        code, rows = self._nodal_rows(mat)
        # rows tying several nodes, or reaching another rank's DOFs (on the pattern: the same
        # for the operator's life): condensed on their slave nodes, S by a triple product
        # (solvers.tied)
        multi = bool(self.comm.allreduce(int(code in (1, 6)), op=MPI.MAX))
        if multi:
            code, rows = tied.tied_rows(self, mat)
        if not code:
            code = self._node_blocks(*rows)
        code = self.comm.allreduce(code, op=MPI.MAX)
        if not code and multi:
            code = 9 if tied.chain(self) else 0
        if not code:
            operator = self._tied_operator if multi else self._condensed_operator
            code = self.comm.allreduce(operator(mat), op=MPI.MAX)
        if code:
            return REASONS[code]
        self.mat = mat
        self._near_null()
        self._set_up_amg()
        return None

    def _blocks(self, mat: PETSc.Mat):
        """M's entries of A (row: the local multiplier row, column: the local primal DOF),
        B (row: the local primal DOF, column: the local multiplier row) and C (local rows) as
        (row, column, value), those in this rank's columns; code 1 when an entry of A, B or C
        lies in another's. Read from two submatrices of M (its multiplier rows; its multiplier
        columns), each as large as the relation rows, never from a copy of the whole of M."""
        rows_l = mat.createSubMatrix(self.is_l, self.is_all)   # [A, C]: saddle columns
        indptr, cols, vals = rows_l.getValuesCSR()
        rows_l.destroy()
        rows = np.repeat(np.arange(self.nl), np.diff(indptr))
        owner = np.searchsorted(self.starts, cols, side="right") - 1
        local = cols - self.start
        on_l = cols - self.starts[owner] >= self.nqs[owner]     # a multiplier column
        mine = owner == self.comm.rank
        a, c = ~on_l & mine, on_l & mine
        across = not np.all(mine)
        cols_l = mat.createSubMatrix(self.is_all, self.is_l)   # [B; C]: multipliers' columns
        indptr, cols, vals_b = cols_l.getValuesCSR()
        cols_l.destroy()
        rows_b = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
        local_b = cols - self.l_start
        b = (rows_b < self.nq) & (local_b >= 0) & (local_b < self.nl)
        across |= bool(np.any((local_b < 0) | (local_b >= self.nl)))
        return int(across), ((rows[a], local[a], vals[a]), (rows_b[b], local_b[b], vals_b[b]),
                             (rows[c], local[c] - self.nq, vals[c]))

    def _nodal_rows(self, mat: PETSc.Mat):
        """(code, (node of each multiplier row or -1, C's diagonal, A, B)): code 0 when each
        row's A entries lie on one owned node, its B column on the same node, and C is
        diagonal (checked on the patterns, so the answer holds for the operator's life)."""
        nc = self.nc
        across, parts = self._blocks(mat)
        (ar, ac, _), (br, bc, _), (cr, cc, cv) = parts
        node = np.full(self.nl, -1, dtype=np.int64)
        lo = np.full(self.nl, np.iinfo(np.int64).max)
        np.minimum.at(lo, ar, ac // nc)
        hi = np.full(self.nl, -1)
        np.maximum.at(hi, ar, ac // nc)
        some = hi >= 0
        if np.any(lo[some] != hi[some]):
            return 6, None
        node[some] = hi[some]
        if np.any(node[bc] != br // nc):
            return 3, None
        if np.any(cc != cr):
            return 2, None
        if across:
            return 1, None
        diag = np.zeros(self.nl)
        diag[cr] = cv
        if np.any((diag == 0.0) & (node < 0)):
            return 5, None   # (a hard row with no DOF)
        return 0, (node, diag, parts[0], parts[1])

    def _node_blocks(self, node: np.ndarray, diag: np.ndarray, arows, bcols) -> int:
        """The per-node stacks of the rows' nodes (``nodes``): the frames and maps of the module
        docstring; 0, or the code of why not."""
        nc = self.nc
        hard = diag == 0.0
        rows = np.flatnonzero(node >= 0)
        self.nodes = np.unique(node[rows])
        m = self.nodes.size
        at = np.searchsorted(self.nodes, node)          # (valid where node >= 0)
        # the hard rows' place in their node's stack: sorted by node, counted in each
        h = np.flatnonzero(hard)
        h = h[np.argsort(node[h], kind="stable")]
        count = np.bincount(at[h], minlength=m)
        if count.size and count.max() > nc:
            return 4
        start = np.concatenate([[0], np.cumsum(count)[:-1]])
        pos = np.full(self.nl, -1, dtype=np.int64)
        pos[h] = np.arange(h.size) - start[at[h]]
        self.hard, self.hard_at, self.hard_pos = h, at[h], pos[h]
        # dense ncomp-vectors of each row's A and B on its node
        a = np.zeros((self.nl, nc))
        np.add.at(a, (arows[0], arows[1] % nc), arows[2])
        b = np.zeros((self.nl, nc))
        np.add.at(b, (bcols[1], bcols[0] % nc), bcols[2])
        # rows with a diagonal (open rows) folded: K_eff = K - B C⁻¹ A, per node
        soft = rows[~hard[rows]]
        self.w = np.where(hard, 0.0, 1.0 / np.where(hard, 1.0, diag))
        self.dk = np.zeros((m, nc, nc))
        np.add.at(self.dk, at[soft], -self.w[soft, None, None] * b[soft, :, None] * a[soft, None, :])
        self.soft, self.soft_at, self.soft_b = soft, at[soft], b[soft]   # (B on their nodes)
        # the hard rows: A_nᵀ (columns padded with zeros) = Q R
        an = np.zeros((m, nc, nc))
        bn = np.zeros((m, nc, nc))
        an[self.hard_at, :, self.hard_pos] = a[h]
        bn[self.hard_at, :, self.hard_pos] = b[h]
        q, r = np.linalg.qr(an, mode="complete")
        keep = np.arange(nc)[None, :] < count[:, None]          # (m, nc): constrained slots
        self.keep = keep
        rdiag = np.abs(np.diagonal(r, axis1=1, axis2=2))
        big = np.abs(an).max(axis=(1, 2), initial=0.0)[:, None]
        if np.any(keep & (rdiag <= RANK_TOL * big)):
            return 4
        zc = keep[:, :, None] * np.eye(nc)            # (m, nc, nc) diag(constrained)
        zf = np.eye(nc) - zc
        qt = np.swapaxes(q, 1, 2)
        e = qt @ bn
        ec = zc @ e @ zc + zf
        if m and np.linalg.cond(ec).max() > COND_MAX:
            return 5
        eci = np.linalg.inv(ec)
        ell = np.eye(nc) - (zf @ e @ zc) @ eci
        self.g = zf @ ell @ qt                         # rows of the free directions
        self.h = q @ zf                                # the free directions in the frame
        rinv = np.linalg.inv(zc @ r @ zc + zf)
        self.lift = q @ zc @ np.swapaxes(rinv, 1, 2) @ zc    # hard rows → Q_c R⁻ᵀ r_h
        self.dual = zc @ eci @ zc @ qt                 # → λ_h = E_c⁻¹ Q_cᵀ (r̂ - K_eff q)
        return 0

    def _condensed_operator(self, mat: PETSc.Mat) -> int:
        """S = G K_eff H, k on the constrained slots' diagonal: K copied from M (a submatrix,
        its storage reused from one update to the next), then its rows that couple to a
        condensed node taken out, transformed in place (G on the condensed nodes' rows, H on
        their columns, other ranks' nodes included, G (K_eff - K) H + k on their diagonal
        blocks) and put back: no matrix but S (and the near rows' small one) is made.
        0, or 7 (on every rank) when K's pattern is not made of whole nodal blocks there."""
        self.S = mat.createSubMatrix(self.is_q, self.is_q, submat=self.S)
        self.kscale = self._stiffness_scale(mat)
        near = self._near_rows(mat)
        rows = PETSc.IS().createGeneral((self.start + near).astype(PETSc.IntType),
                                        comm=self.comm)
        part = mat.createSubMatrix(rows, self.is_q)   # K's near rows, primal columns
        indptr, cols, vals = part.getValuesCSR()
        part.destroy()
        rows.destroy()
        ghosts, h_ghost = self._ghost_frames(cols)
        code = self._transform(near, indptr, cols, vals, ghosts, h_ghost)
        code = self.comm.allreduce(code, op=MPI.MAX)
        if code:
            return code
        self.S.setValuesIJV(indptr, cols, vals,
                            rowmap=(self.q_start + near).astype(PETSc.IntType))
        self.S.assemble()
        if self.S.getBlockSize() != self.nc:
            self.S.setBlockSize(self.nc)
        return 0

    def _tied_operator(self, mat: PETSc.Mat) -> int:
        """S = G K_eff H + k on the constrained slots (solvers.tied): K copied from M (its
        storage reused), the folded rows' blocks added on the nodes' diagonal blocks, then
        PETSc's triple product: reused (its values recomputed in place, S the same matrix, its
        V-cycle's hierarchy kept while it serves) while G's and H's patterns stay, else made
        anew (the active set changed)."""
        self._k = mat.createSubMatrix(self.is_q, self.is_q, submat=self._k)
        self.kscale = self._stiffness_scale(mat)
        nc = self.nc
        dofs = self.q_start + self.nodes[:, None] * nc + np.arange(nc)
        folded = np.flatnonzero(np.abs(self.dk).max(axis=(1, 2), initial=0.0) > 0)
        if folded.size:   # (nodes with a compliant row: none in the tied scenes)
            rows = dofs[folded].reshape(-1)
            self._k.setValuesIJV(np.arange(rows.size + 1, dtype=PETSc.IntType) * nc,
                                 np.repeat(dofs[folded], nc, axis=0).reshape(-1)
                                 .astype(PETSc.IntType), self.dk[folded].reshape(-1),
                                 rowmap=rows.astype(PETSc.IntType),
                                 addv=PETSc.InsertMode.ADD_VALUES)
        self._k.assemble()
        frames = tied.frames(self)
        same = frames[0] is self.G   # (the same pattern: G, H, X filled in place)
        # the product's symbolic part reused, unless the user's -mat_product_clear freed it
        # (PETSc aborts on a reuse of a cleared product)
        if same and not product_clear():
            self.S = self.G.matMatMult(self._k, self.H, result=self.S)
        else:
            for m in ((self.S,) if same else (self.G, self.H, self.X, self.S)):
                if m is not None:
                    m.destroy()
            self.G, self.H, self.X = frames
            self.S = self.G.matMatMult(self._k, self.H)
            self._work = None
        slots = dofs[self.keep]
        self.S.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        self.S.setValuesIJV(np.arange(slots.size + 1, dtype=PETSc.IntType),
                            slots.astype(PETSc.IntType), np.full(slots.size, self.kscale),
                            rowmap=slots.astype(PETSc.IntType),
                            addv=PETSc.InsertMode.ADD_VALUES)
        self.S.assemble()
        if self.S.getBlockSize() != nc:
            self.S.setBlockSize(nc)
        return 0

    def _stiffness_scale(self, mat: PETSc.Mat) -> float:
        """k: the mean |diagonal| of K."""
        d = mat.getDiagonal()
        total = self.comm.allreduce(float(np.abs(d.array[:self.nq]).sum()))
        d.destroy()
        return total / max(int(self.nqs.sum()), 1)

    def _near_rows(self, mat: PETSc.Mat) -> np.ndarray:
        """The local primal rows that S changes: the condensed nodes' own and those with an
        entry of K's pattern in a condensed node's columns (any rank's), read from K's
        submatrix on those columns (as large as the condensed nodes' couplings): exact
        whatever the values (an entry that sums to zero is still in the pattern)."""
        nc = self.nc
        own = (self.nodes[:, None] * nc + np.arange(nc)).reshape(-1)
        cols = PETSc.IS().createGeneral((self.start + own).astype(PETSc.IntType),
                                        comm=self.comm)
        part = mat.createSubMatrix(self.is_q, cols)   # K's columns of the condensed nodes
        indptr = part.getValuesCSR()[0]
        part.destroy()
        cols.destroy()
        return np.union1d(np.flatnonzero(np.diff(indptr)), own)

    def _ghost_frames(self, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The nodes of other ranks among the primal columns ``cols`` (sorted) and their
        frames H (the identity where not condensed), scattered from their owners."""
        nc, nn = self.nc, self.nc * self.nc
        frames = PETSc.Vec().createMPI((self.nq * nc, None), comm=self.comm)
        blocks = frames.array.reshape(-1, nc, nc)
        blocks[:] = np.eye(nc)
        blocks[self.nodes] = self.h
        node = cols // nc
        lo, hi = self.q_start // nc, (self.q_start + self.nq) // nc
        ghosts = np.unique(node[(node < lo) | (node >= hi)])
        index = PETSc.IS().createGeneral(
            (ghosts[:, None] * nn + np.arange(nn)).reshape(-1).astype(PETSc.IntType),
            comm=self.comm)
        out = PETSc.Vec().createSeq(ghosts.size * nn, comm=PETSc.COMM_SELF)
        scatter = PETSc.Scatter().create(frames, index, out, None)
        scatter.scatter(frames, out, addv=PETSc.InsertMode.INSERT_VALUES,
                        mode=PETSc.ScatterMode.FORWARD)
        h_ghost = out.array.reshape(-1, nc, nc).copy()
        for obj in (scatter, out, index, frames):
            obj.destroy()
        return ghosts, h_ghost

    def _transform(self, near: np.ndarray, indptr: np.ndarray, cols: np.ndarray,
                   vals: np.ndarray, ghosts: np.ndarray, h_ghost: np.ndarray) -> int:
        """K's ``near`` rows (CSR, primal columns) → S's, in place in ``vals``: a condensed
        node's nc rows (one column list) ← G times them; then each column triple of a node
        whose frame moves it ← it times H; then the diagonal blocks += G dk H + k on the
        constrained slots. 7 when the pattern is not made of whole nodal blocks there."""
        nc, m = self.nc, self.nodes.size
        lengths = np.diff(indptr)
        at = np.searchsorted(near, self.nodes * nc)[:, None] + np.arange(nc)   # (m, nc)
        span = lengths[at]
        if np.any(span != span[:, :1]):
            return 7
        span = span[:, 0]
        offset = np.arange(span.sum()) - np.repeat(np.cumsum(span) - span, span)
        pos = np.repeat(indptr[at], span, axis=0) + offset[:, None]   # (entries, its rows)
        owner = np.repeat(np.arange(m), span)
        col = cols[pos[:, 0]]
        if np.any(cols[pos] != col[:, None]):
            return 7
        vals[pos] = np.einsum("kab,kb->ka", self.g[owner], vals[pos])
        # the column triples of the nodes whose frame moves them, this rank's and others'
        table = np.concatenate([self.h, h_ghost])
        moves = ~np.all(table == np.eye(nc), axis=(1, 2))
        node = cols // nc
        here = node - self.q_start // nc
        mine = (here >= 0) & (here < self.nq // nc)
        which = np.full(cols.size, -1)
        if m:
            s = np.minimum(np.searchsorted(self.nodes, here[mine]), m - 1)
            which[mine] = np.where(self.nodes[s] == here[mine], s, -1)
        which[~mine] = m + np.searchsorted(ghosts, node[~mine])
        hit = which >= 0
        hit[hit] = moves[which[hit]]
        first = np.flatnonzero(hit & (cols % nc == 0))
        triple = np.minimum(first[:, None] + np.arange(nc), cols.size - 1)
        row = np.repeat(np.arange(near.size), lengths)
        if (np.count_nonzero(hit) != first.size * nc
                or np.any(cols[triple] != cols[first, None] + np.arange(nc))
                or np.any(row[triple] != row[first, None])):
            return 7
        vals[triple] = np.einsum("kb,kbc->kc", vals[triple], table[which[first]])
        # the diagonal blocks: the entries of each node's own columns in its rows
        j = np.flatnonzero(col == self.q_start + self.nodes[owner] * nc)
        jj = np.minimum(j[:, None] + np.arange(nc), max(owner.size - 1, 0))
        if (j.size != m or np.any(owner[j] != np.arange(m))
                or np.any(col[jj] != col[j, None] + np.arange(nc))
                or np.any(owner[jj] != owner[j, None])):
            return 7
        extra = self.g @ self.dk @ self.h + self.kscale * self.keep[:, :, None] * np.eye(nc)
        vals[np.swapaxes(pos[jj], 1, 2)] += extra
        return 0

    def _near_null(self) -> None:
        """The rigid-body modes (the primal index set's near-null space) in the nodal frames,
        Hᵀ v, orthonormalized."""
        modes = self.is_q.query("nearnullspace")
        if modes is None:
            return
        vecs = []
        for v in modes.getVecs():
            y = v.copy()
            if self.H is None:
                self._frame_t(y.array)
            else:
                self.H.multTranspose(v, y)
            for u in vecs:
                y.axpy(-y.dot(u), u)
            y.scale(1.0 / y.norm())
            vecs.append(y)
        if not vecs:   # (a scalar field's constant: the AMG's own default)
            return
        self.S.setNearNullSpace(PETSc.NullSpace().create(vectors=vecs, comm=self.comm))

    def _set_up_amg(self) -> None:
        if self.amg is None:
            self.amg = VCycle(self.comm, self.prefix + "condensed_")
        self.amg.set_up(self.S, TIED_SWEEPS if self.G is not None else FINE_SWEEPS)
        if self._work is None:   # (work vectors of the application, per pattern)
            self._work = [*self.mat.createVecs(), *self.S.createVecs(), self.S.createVecLeft()]

    # ------------------------------------------------------------------ application

    def _frame_t(self, y: np.ndarray) -> None:
        """y ← Hᵀ y in place (owned nodes)."""
        v = y.reshape(-1, self.nc)
        v[self.nodes] = np.einsum("nji,nj->ni", self.h, v[self.nodes])

    def _nodal(self, blocks: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.einsum("nij,nj->ni", blocks, v.reshape(-1, self.nc)[self.nodes])

    def _folded_dual(self, r_l: np.ndarray) -> np.ndarray:
        """B C⁻¹ r_λ on the condensed nodes (m, ncomp): the rows with a diagonal C only, whose
        dual lies on their own node (checked: ``_nodal_rows``, ``tied.tied_rows``), summed per
        node from their B columns (no product with M)."""
        out = np.zeros((self.nodes.size, self.nc))
        np.add.at(out, self.soft_at, self.soft_b * (self.w[self.soft] * r_l[self.soft])[:, None])
        return out

    def _product(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """M [q; 0] as (primal rows, multiplier rows), with K_eff in place of K (the folded
        rows' - B C⁻¹ A, per node)."""
        u, v = self._work[0], self._work[1]
        ua = u.array
        ua[:self.nq] = q
        ua[self.nq:] = 0.0
        self.mat.mult(u, v)
        out_q, out_l = v.array[:self.nq].copy(), v.array[self.nq:].copy()
        out_q.reshape(-1, self.nc)[self.nodes] += self._nodal(self.dk, q)
        return out_q, out_l

    def setUp(self, pc: PETSc.PC) -> None:
        pass

    def apply(self, pc: PETSc.PC, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """y ← the condensed M⁻¹ x (the module docstring's three eliminations)."""
        nq, nc = self.nq, self.nc
        xa = x.getArray(readonly=True)
        r_q, r_l = xa[:nq], xa[nq:]
        rhat = r_q.copy()                                       # r̂ = r_q - B C⁻¹ r_λ
        rhat.reshape(-1, nc)[self.nodes] -= self._folded_dual(r_l)
        padded = np.zeros((self.nodes.size, nc))
        padded[self.hard_at, self.hard_pos] = r_l[self.hard]
        qc = np.zeros(nq)
        qc.reshape(-1, nc)[self.nodes] = np.einsum("nij,nj->ni", self.lift, padded)
        f, yf, work = self._work[2], self._work[3], self._work[4]
        if self.X is not None:                                  # tied rows: (I + X) c
            work.array[:] = qc
            self.X.mult(work, f)
            qc = qc + f.array
        t = rhat - self._product(qc)[0]
        fa = f.array
        if self.G is None:
            fa[:] = t                                           # G (r̂ - K_eff q_c)
            fa.reshape(-1, nc)[self.nodes] = self._nodal(self.g, t)
        else:
            work.array[:] = t
            self.G.mult(work, f)
        self.amg.apply(f, yf)                                   # y_f ≈ S⁻¹ f
        if self.H is None:
            q = yf.array.copy()
            q.reshape(-1, nc)[self.nodes] = self._nodal(self.h, q)  # q_f = H y_f
        else:
            self.H.mult(yf, work)
            q = work.array.copy()
        q += qc
        kq, aq = self._product(q)
        lam = np.zeros(self.nl)
        lam[self.hard] = self._nodal(self.dual, rhat - kq)[self.hard_at, self.hard_pos]
        lam += self.w * (r_l - aq)
        ya = y.getArray()
        ya[:nq] = q
        ya[nq:] = lam
