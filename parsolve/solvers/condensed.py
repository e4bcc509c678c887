"""The iterative preset's preconditioner for a saddle system whose relation rows are all nodal
(each row's A entries on one node's DOFs, its dual column D on the same node, no multiplier
coupled to another: rigid-obstacle contact and friction, Dirichlet-type rows): the rows are
condensed node by node, and one algebraic multigrid V-cycle works on the condensed primal
operator. Krylov (GMRES) runs on the saddle system M = [[K, B], [A, C]] itself (B = -D), so
its answer is the direct preset's whatever the preconditioner's quality.

With exact solves the preconditioner is M⁻¹, built in three eliminations:

- A row with a diagonal C (a compliant row: friction's cross stiffness; an open row: C the
  placeholder, A and B zero) gives λ = C⁻¹ (r_λ - A q): folded into the primal operator,
  K_eff = K - B C⁻¹ A (per node, a ncomp × ncomp block), r̂ = r_q - B C⁻¹ r_λ.
- The hard rows of a node (C = 0) A_n = Rᵀ Q_cᵀ (a QR of A_nᵀ, Q = [Q_c, Q_f] orthonormal):
  the node's displacement in the frame Q, u = Q_c y_c + Q_f y_f, has y_c = R⁻ᵀ r_h. The
  dual in the frame Qᵀ B_n = [E_c; E_f] (E_f ≠ 0 when the relation is not associated:
  friction's sliding rows): the free rows, less E_f E_c⁻¹ times the constrained ones, hold no
  multiplier: L = [[I, 0], [-E_f E_c⁻¹, I]].
- The free displacement solves S y_f = G (r̂ - K_eff Q_c y_c), S = G K_eff H (G = Z L Qᵀ,
  H = Q Z, Z the free directions, block diagonal; the constrained slots of S hold k on the
  diagonal), then λ_h = E_c⁻¹ Q_cᵀ (r̂ - K_eff q).

S has K's pattern, is symmetric when the relations are associated, and is an elastic
stiffness with some nodal directions held: the AMG sees it with the rigid-body modes in the
nodal frames (Hᵀ times them). Everything per node is batched numpy on (nodes, ncomp, ncomp)
stacks (padded: a node with k hard rows has an identity beyond its k × k block); every row's
node is owned by the rank that owns the row (checked: else the system is not condensable).
"""

from __future__ import annotations

import atexit

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

#: why a system is not condensed (the largest code over the ranks wins), in words
REASONS = {
    1: "a relation row ties several nodes",
    2: "a relation row's DOFs or dual lie on another rank",
    3: "multiplier rows coupled to each other",
    4: "a dual column off its row's node",
    5: "dependent hard rows on a node",
    6: "a node's dual does not hold its hard rows",
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
    Python runs: PetscFinalize does it after Python's end, and the python PC's reset then
    calls into a finished interpreter (a segmentation fault at exit). Collective, as
    PetscFinalize's own clean-up is."""
    import gc

    gc.collect()   # (solvers in reference cycles: freed now, their KSPs deferred)
    for comm in _COMMS:
        try:
            PETSc.garbage_cleanup(comm)
        except Exception:   # (a communicator freed before the end)
            pass


class CondensedPreconditioner:
    """``update(mat)`` condenses the operator's relation rows (None: done; else the reason
    why not, the same on every rank); ``apply`` is the PETSc python PC's application: M⁻¹
    with S⁻¹ replaced by one AMG V-cycle (options under ``<prefix>condensed_``)."""

    def __init__(self, comm: MPI.Comm, ncomp: int, is_q: PETSc.IS, is_l: PETSc.IS,
                 prefix: str):
        self.comm, self.nc, self.prefix = comm, int(ncomp), prefix
        if not _COMMS:
            atexit.register(_clean_up)
        if all(c is not comm for c in _COMMS):
            _COMMS.append(comm)
        self.is_q, self.is_l = is_q, is_l
        self.nq, self.nl = is_q.getLocalSize(), is_l.getLocalSize()
        self._handle = None
        self.S: PETSc.Mat | None = None
        self.amg: PETSc.PC | None = None
        self._reset()

    def _reset(self) -> None:
        self.K = self.A = self.B = self.C = self.S = self.G = self.H = None

    # ------------------------------------------------------------------ set-up

    def update(self, mat: PETSc.Mat) -> str | None:
        """Condense ``mat``'s rows and set the AMG up on S; the reason in words when some rank
        cannot (nothing is set up then)."""
        if self.comm.allreduce(int(mat.handle != self._handle), op=MPI.MAX):
            self._handle = mat.handle
            self._reset()
        self.A = mat.createSubMatrix(self.is_l, self.is_q, submat=self.A)
        self.B = mat.createSubMatrix(self.is_q, self.is_l, submat=self.B)
        self.C = mat.createSubMatrix(self.is_l, self.is_l, submat=self.C)
        code, rows = self._nodal_rows()
        if not code:
            code = self._node_blocks(*rows)
        code = self.comm.allreduce(code, op=MPI.MAX)
        if code:
            return REASONS[code]
        self.K = mat.createSubMatrix(self.is_q, self.is_q, submat=self.K)
        self._condensed_operator()
        self._set_up_amg()
        return None

    def _nodal_rows(self):
        """(code, (node of each multiplier row or -1, C's diagonal)): code 0 when each row's
        A entries lie on one owned node, its B column on the same node, and C is diagonal
        (checked on the patterns, so the answer holds for the operator's life)."""
        nc = self.nc
        ia, ja, _ = self.A.getValuesCSR()
        c0 = self.A.getOwnershipRangeColumn()[0]
        cols = ja - c0
        if cols.size and (cols.min() < 0 or cols.max() >= self.nq):
            return 2, None
        lens = np.diff(ia)
        node = np.full(self.nl, -1, dtype=np.int64)
        some = lens > 0
        if cols.size:
            first = np.minimum.reduceat(cols // nc, ia[:-1][some])
            last = np.maximum.reduceat(cols // nc, ia[:-1][some])
            if np.any(first != last):
                return 1, None
            node[some] = first
        ib, jb, _ = self.B.getValuesCSR()
        l0 = self.B.getOwnershipRangeColumn()[0]
        lcols = jb - l0
        if lcols.size and (lcols.min() < 0 or lcols.max() >= self.nl):
            return 2, None
        qnode = np.repeat(np.arange(self.nq) // nc, np.diff(ib))
        if np.any(node[lcols] != qnode):
            return 4, None
        ic, jc, vc = self.C.getValuesCSR()
        crow = np.repeat(np.arange(self.nl), np.diff(ic))
        if np.any(jc - l0 != crow):
            return 3, None
        diag = np.zeros(self.nl)
        diag[crow] = vc
        if np.any((diag == 0.0) & (node < 0)):
            return 6, None   # (a hard row with no DOF)
        return 0, (node, diag)

    def _node_blocks(self, node: np.ndarray, diag: np.ndarray) -> int:
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
            return 5
        start = np.concatenate([[0], np.cumsum(count)[:-1]])
        pos = np.full(self.nl, -1, dtype=np.int64)
        pos[h] = np.arange(h.size) - start[at[h]]
        self.hard, self.hard_at, self.hard_pos = h, at[h], pos[h]
        # dense ncomp-vectors of each row's A and B on its node
        ia, ja, va = self.A.getValuesCSR()
        arow = np.repeat(np.arange(self.nl), np.diff(ia))
        a = np.zeros((self.nl, nc))
        np.add.at(a, (arow, (ja - self.A.getOwnershipRangeColumn()[0]) % nc), va)
        ib, jb, vb = self.B.getValuesCSR()
        bcol = jb - self.B.getOwnershipRangeColumn()[0]
        b = np.zeros((self.nl, nc))
        np.add.at(b, (bcol, np.repeat(np.arange(self.nq), np.diff(ib)) % nc), vb)
        # compliant and open rows folded: K_eff = K - B C⁻¹ A, per node
        soft = rows[~hard[rows]]
        self.w = np.where(hard, 0.0, 1.0 / np.where(hard, 1.0, diag))
        self.dk = np.zeros((m, nc, nc))
        np.add.at(self.dk, at[soft], -self.w[soft, None, None] * b[soft, :, None] * a[soft, None, :])
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
            return 5
        zc = keep[:, :, None] * np.eye(nc)            # (m, nc, nc) diag(constrained)
        zf = np.eye(nc) - zc
        qt = np.swapaxes(q, 1, 2)
        e = qt @ bn
        ec = zc @ e @ zc + zf
        if m and np.linalg.cond(ec).max() > COND_MAX:
            return 6
        eci = np.linalg.inv(ec)
        ell = np.eye(nc) - (zf @ e @ zc) @ eci
        self.g = zf @ ell @ qt                         # rows of the free directions
        self.h = q @ zf                                # the free directions in the frame
        rinv = np.linalg.inv(zc @ r @ zc + zf)
        self.lift = q @ zc @ np.swapaxes(rinv, 1, 2) @ zc    # hard rows → Q_c R⁻ᵀ r_h
        self.dual = zc @ eci @ zc @ qt                 # → λ_h = E_c⁻¹ Q_cᵀ (r̂ - K_eff q)
        return 0

    def _block_diagonal(self, blocks: np.ndarray, old: PETSc.Mat | None) -> PETSc.Mat:
        """The owned-nodes block diagonal matrix: ``blocks`` on the condensed nodes, identity
        elsewhere (its pattern the same every time: values rewritten in place)."""
        nc, n = self.nc, self.nq // self.nc
        full = np.broadcast_to(np.eye(nc), (n, nc, nc)).copy()
        full[self.nodes] = blocks
        c0 = self.K.getOwnershipRangeColumn()[0]
        indptr = np.arange(0, self.nq * nc + 1, nc, dtype=PETSc.IntType)
        indices = (c0 + np.repeat(np.arange(n) * nc, nc * nc)
                   + np.tile(np.arange(nc), self.nq)).astype(PETSc.IntType)
        values = full.reshape(-1)
        if old is None:
            mat = PETSc.Mat().createAIJ(size=((self.nq, None), (self.nq, None)), bsize=nc,
                                        csr=(indptr, indices, values), comm=self.comm)
            return mat
        old.setValuesCSR(indptr, indices, values)
        old.assemble()
        return old

    def _condensed_operator(self) -> None:
        """S = G K H, plus G (K_eff - K) H and k on the constrained slots' diagonal, per node."""
        self.G = self._block_diagonal(self.g, self.G)
        self.H = self._block_diagonal(self.h, self.H)
        self.S = self.G.matMatMult(self.K, self.H, result=self.S)
        d = self.K.getDiagonal()
        self.kscale = self.comm.allreduce(float(np.abs(d.array).sum())) / max(d.getSize(), 1)
        d.destroy()
        nc = self.nc
        extra = self.g @ self.dk @ self.h + self.kscale * self.keep[:, :, None] * np.eye(nc)
        lens = np.zeros(self.nq // nc, dtype=np.int64)
        lens[self.nodes] = nc
        lens = np.repeat(lens, nc)
        indptr = np.concatenate([[0], np.cumsum(lens)]).astype(PETSc.IntType)
        c0 = self.S.getOwnershipRangeColumn()[0]
        indices = (c0 + np.repeat(self.nodes * nc, nc * nc)
                   + np.tile(np.arange(nc), self.nodes.size * nc)).astype(PETSc.IntType)
        self.S.setValuesCSR(indptr, indices, extra.reshape(-1), addv=PETSc.InsertMode.ADD_VALUES)
        self.S.assemble()
        if self.S.getBlockSize() != nc:
            self.S.setBlockSize(nc)
        self._near_null()

    def _near_null(self) -> None:
        """The rigid-body modes (the primal index set's near-null space) in the nodal frames,
        Hᵀ v, orthonormalized."""
        modes = self.is_q.query("nearnullspace")
        if modes is None:
            return
        vecs = []
        for v in modes.getVecs():
            y = v.copy()
            self._frame_t(y.array)
            for u in vecs:
                y.axpy(-y.dot(u), u)
            y.scale(1.0 / y.norm())
            vecs.append(y)
        if not vecs:   # (a scalar field's constant: the AMG's own default)
            return
        self.S.setNearNullSpace(PETSc.NullSpace().create(vectors=vecs, comm=self.comm))

    def _set_up_amg(self) -> None:
        if self.amg is None:
            self.amg = PETSc.PC().create(self.comm)
            self.amg.setOptionsPrefix(self.prefix + "condensed_")
            self.amg.setOperators(self.S, self.S)
            self.amg.setFromOptions()
        else:
            self.amg.setOperators(self.S, self.S)
        self.amg.setUp()

    # ------------------------------------------------------------------ application

    def _frame_t(self, y: np.ndarray) -> None:
        """y ← Hᵀ y in place (owned nodes)."""
        v = y.reshape(-1, self.nc)
        v[self.nodes] = np.einsum("nji,nj->ni", self.h, v[self.nodes])

    def _nodal(self, blocks: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.einsum("nij,nj->ni", blocks, v.reshape(-1, self.nc)[self.nodes])

    def _stiffness(self, x: PETSc.Vec, out: PETSc.Vec) -> None:
        """out ← K_eff x."""
        self.K.mult(x, out)
        out.array.reshape(-1, self.nc)[self.nodes] += self._nodal(self.dk, x.array)

    def setUp(self, pc: PETSc.PC) -> None:
        if not hasattr(self, "_vq"):
            self._vq = [self.K.createVecLeft() for _ in range(4)]
            self._vl = self.A.createVecLeft()

    def apply(self, pc: PETSc.PC, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """y ← the condensed M⁻¹ x (the module docstring's three eliminations)."""
        nq, nc = self.nq, self.nc
        rhat, qv, t, f = self._vq
        xa = x.getArray(readonly=True)
        r_q, r_l = xa[:nq], xa[nq:]
        self._vl.array[:] = self.w * r_l
        self.B.mult(self._vl, rhat)
        rhat.array[:] = r_q - rhat.array                         # r̂ = r_q - B C⁻¹ r_λ
        padded = np.zeros((self.nodes.size, nc))
        padded[self.hard_at, self.hard_pos] = r_l[self.hard]
        qc = np.zeros(nq)
        qc.reshape(-1, nc)[self.nodes] = np.einsum("nij,nj->ni", self.lift, padded)
        qv.array[:] = qc
        self._stiffness(qv, t)
        t.array[:] = rhat.array - t.array
        f.array[:] = t.array                                    # G (r̂ - K_eff q_c)
        f.array.reshape(-1, nc)[self.nodes] = self._nodal(self.g, t.array)
        self.amg.apply(f, t)                                    # y_f ≈ S⁻¹ f
        yf = t.array.reshape(-1, nc)
        yf[self.nodes] = np.einsum("nij,nj->ni", self.h, yf[self.nodes])   # q_f = H y_f
        qv.array[:] = qc + t.array
        self._stiffness(qv, t)
        t.array[:] = rhat.array - t.array
        lam = np.zeros(self.nl)
        lam[self.hard] = self._nodal(self.dual, t.array)[self.hard_at, self.hard_pos]
        self.A.mult(qv, self._vl)
        lam += self.w * (r_l - self._vl.array)
        ya = y.getArray()
        ya[:nq] = qv.array
        ya[nq:] = lam
