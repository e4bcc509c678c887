"""The augmented Lagrangian form of the saddle system for the iterative preset: the operator
M = [[K, -D], [A, C]] and the right-hand side b multiplied on the left by
T = [[I, γ/k Aₕᵀ Eₕ], [0, I]], Aₕ the rows of A that are enforced (Eₕ selects them): each
enforced row's equation A q + C λ = g, times γ/k Aₕᵀ, added to the force balance. Enforced
rows have no C (it is the inactive rows' placeholder diagonal), so

    T M = [[K + γ/k Aₕᵀ Aₕ, -D], [A, C]],     T b = [b_q + γ/k Aₕᵀ b_h, b_λ]

and T M x = T b holds the same x as M x = b (T is invertible, its inverse -γ/k in place of
γ/k): the answer is the direct preset's. Krylov solves the transformed system, preconditioned by
its own block upper triangle (``solvers.linear``: a V-cycle on K + γ/k Aₕᵀ Aₕ, Jacobi on the
sparse Schur approximation).

K alone is singular whenever a body is held only by relations (a box pressed on an obstacle,
free in the normal direction): no multigrid can invert it, and a Schur complement built on it
does not exist. K + γ/k Aₕᵀ Aₕ is the stiffness of the body held by penalty springs along its
hard rows: positive definite once the relations hold the body, symmetric whatever D is
(friction's non-associated dual stays in the operator), and an algebraic multigrid sees it as
an elastic stiffness. With the term in the operator too (not in the preconditioner alone), the
Schur complement A (K + γ/k Aₕᵀ Aₕ)⁻¹ D of the hard rows tends to k/γ as γ grows: its
eigenvalues cluster, and Krylov's iterations fall (the 3D friction box: 43 → 25 per solve at
γ = 3, scripts/results/bench_relations.md), while the V-cycle's task grows with γ (a penalty
of γ k on the constrained DOFs). Compliant rows (friction's cross stiffness, finite sliding's
geometric stiffness on the multiplier diagonal) and inactive rows are never augmented: their
diagonal already makes their Schur block invertible, and their C would enter T M's (q, λ) block.

γ is dimensionless against the relation scale: the rows of A are scaled so that their largest
entry is the mean stiffness diagonal k (``RelationSet.set_scales``), so γ/k · Aₕᵀ Aₕ adds about
γ k on the diagonal of a constrained DOF.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

#: γ of the augmentation, relative to the stiffness scale: the fewest Krylov iterations on the
#: 3D friction box (1: 27, 3: 25, 10: 24 with a tail of 48 per solve at 1×: the V-cycle's task
#: grows with γ; bench_relations.md); the option -<prefix>augmented_gamma sets another
GAMMA = 3.0
#: γ of a row that ties several nodes (mortar, node-to-face: more entries than one node's
#: DOFs): its Aᵀ A couples those nodes, and at γ = 3 the V-cycle on the coarsened mortar
#: sphere stalled (GMRES out of 1000 iterations); 0.1 converges (64-213 per solve)
GAMMA_COUPLED = 0.1
#: the most entries a row of one node has (one per displacement component in 3D)
NODAL_SPAN = 3


class AugmentedMatrix:
    """T M (``operator``) and its preconditioning matrix (``pmat``: T M, with γ_c/k Aᵀ A of the
    coupled hard rows and -k on the diagonal of a row with no sparse Schur diagonal) from the
    operator's current values, made again on every call (submatrices and sparse products of the
    relation rows: O(nnz)); ``transform`` makes T b.

    Neither is a copy of M beside it: both are block (nest) matrices [[K + γ/k Aₕᵀ Aₕ, -D],
    [A, C]] on the saddle layout, sharing their blocks (P's own: the coupled rows' stiffness
    block, and C with its fill), and the stiffness block is the one copy of K, the block the
    Schur fieldsplit's V-cycle works on (handed over, not copied again). Its pattern is K's
    when every entry of Aᵀ A falls in it (the rows of one node), else K's and Aᵀ A's (then K's
    values pass through a submatrix kept beside it); it is fixed as long as the operator's is,
    so the preconditioner set up on it
    reuses its structure."""

    def __init__(self, comm, layout):
        self.comm, self.layout = comm, layout
        q0, q1, l0, l1 = layout.owned()
        self.nq, self.nl = q1 - q0, l1 - l0
        off = layout.offset
        self.is_q = PETSc.IS().createStride(self.nq, first=off, step=1, comm=comm)
        self.is_q.setBlockSize(layout.ncomp)
        self.is_l = PETSc.IS().createStride(self.nl, first=off + self.nq, step=1, comm=comm)
        self._handle = None
        self.operator: PETSc.Mat | None = None
        self.pmat: PETSc.Mat | None = None
        self._weight: PETSc.Vec | None = None
        self._reset()

    def _reset(self) -> None:
        self.operator = self.pmat = None
        self._rows = self._scaled = self._cols = self._coupling = None
        self._stiffness = self._k = self._dual = self._lam = self._plam = self._coupled = None
        self._products: dict[str, PETSc.Mat] = {}

    def update(self, mat: PETSc.Mat, hard: np.ndarray, kscale: float,
               gamma: float = GAMMA) -> "AugmentedMatrix":
        """T M and P for the operator ``mat``; ``hard``: mask of this rank's multiplier rows
        that are enforced; k: the stiffness scale; γ: that of the rows of one
        node (T's). A hard row that ties several nodes (more entries than NODAL_SPAN) stays out
        of T and enters P alone, at min(γ, GAMMA_COUPLED)."""
        # a new operator (a new pattern): start again, on every rank alike (the products
        # below are collective: a rank that made them anew while another reused them hung)
        if self.comm.allreduce(int(mat.handle != self._handle), op=MPI.MAX):
            self._handle = mat.handle
            self._reset()
        self._rows = mat.createSubMatrix(self.is_l, self.is_q, submat=self._rows)
        nodal = np.diff(self._rows.getValuesCSR()[0]) <= NODAL_SPAN
        self._weight = self._rows.createVecLeft()
        self._weight.array[:] = np.sqrt(gamma / kscale) * (hard & nodal)
        self._scaled = self._gram("nodal", self._weight)
        self._augment_stiffness(mat, self._products["nodal"])
        self._dual = mat.createSubMatrix(self.is_q, self.is_l, submat=self._dual)
        self._lam = mat.createSubMatrix(self.is_l, self.is_l, submat=self._lam)
        same = PETSc.Mat.Structure.SAME_NONZERO_PATTERN
        stiffness = self._stiffness
        if self.comm.allreduce(int((~nodal).sum())):   # coupled rows (fixed by the pattern)
            w = self._rows.createVecLeft()
            w.array[:] = np.sqrt(min(gamma, GAMMA_COUPLED) / kscale) * (hard & ~nodal)
            self._gram("coupled", w).destroy()
            self._coupled = stiffness = self._stiffness.copy(
                self._coupled, structure=same if self._coupled is not None else None)
            stiffness.axpy(1.0, self._products["coupled"],
                           structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        self._plam = self._lam.copy(self._plam, structure=same if self._plam is not None else None)
        fill = self._schur_fill(stiffness, kscale)
        if fill is not None:
            self._plam.setDiagonal(fill, addv=PETSc.InsertMode.ADD_VALUES)
        if self.pmat is None:
            self.operator = self._nest(self._stiffness, self._lam)
            self.pmat = self._nest(stiffness, self._plam)
        for m in (self.operator, self.pmat):   # (their state: the preconditioner sees the
            m.assemble()                       # blocks' new values)
        return self

    def _nest(self, stiffness: PETSc.Mat, lam: PETSc.Mat) -> PETSc.Mat:
        """[[stiffness, -D], [A, lam]] on the saddle layout, its blocks not copied."""
        blocks = [[stiffness, self._dual], [self._rows, lam]]
        index = [self.is_q, self.is_l]
        return PETSc.Mat().createNest(blocks, isrows=index, iscols=index, comm=self.comm)

    def _augment_stiffness(self, mat: PETSc.Mat, extra: PETSc.Mat) -> None:
        """K + ``extra`` into the stiffness block. Its first build tries K's own pattern (the
        submatrix of M, then the block itself); when ``extra`` has entries outside it on any
        rank, the block takes both patterns and K's submatrix is kept beside it."""
        subset = PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN
        if self._stiffness is None:
            k = mat.createSubMatrix(self.is_q, self.is_q)
            if self.comm.allreduce(int(not _within(k, extra)), op=MPI.MAX):
                self._k, self._stiffness = k, extra.duplicate()
                self._stiffness.axpy(1.0, k,
                                     structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
            else:
                self._stiffness = k
        if self._k is None:
            mat.createSubMatrix(self.is_q, self.is_q, submat=self._stiffness)
        else:
            mat.createSubMatrix(self.is_q, self.is_q, submat=self._k)
            self._k.copy(self._stiffness, structure=subset)
        self._stiffness.axpy(1.0, extra, structure=subset)

    def _gram(self, name: str, weight: PETSc.Vec) -> PETSc.Mat:
        """(W A)ᵀ (W A) into the product kept under ``name`` (its pattern reused); W A."""
        rows = self._rows.copy()
        rows.diagonalScale(L=weight)
        self._products[name] = rows.transposeMatMult(rows, result=self._products.get(name))
        return rows

    def transform(self, rhs: PETSc.Vec) -> None:
        """b → T b in place: γ/k Aₕᵀ b_h added to the primal rows."""
        lam = rhs.getSubVector(self.is_l)
        weighted = lam.copy()
        rhs.restoreSubVector(self.is_l, lam)
        weighted.pointwiseMult(weighted, self._weight)
        add = self._rows.createVecRight()
        self._scaled.multTranspose(weighted, add)   # (Eₕ √(γ/k) A)ᵀ √(γ/k) b_h
        q = rhs.getSubVector(self.is_q)
        q.axpy(1.0, add)
        rhs.restoreSubVector(self.is_q, q)
        weighted.destroy()
        add.destroy()

    def _schur_fill(self, stiffness: PETSc.Mat, kscale: float) -> PETSc.Vec | None:
        """A relation whose rows and dual share no DOF (a control: the strain of a cell driven by
        a load on the end) has no diagonal in the sparse Schur approximation
        A₁₁ - A diag(K + γ Aₕᵀ Aₕ)⁻¹ (-D), and Jacobi would divide by 0 (PETSc takes 1: a scale
        off by k²). Such a row gets -k on P's diagonal (the vector of the multiplier rows to
        add, None when no row needs it): the true Schur entry aᵀ K⁻¹ d is a global quantity,
        but a few rows whose scale is merely of the right order are a few isolated eigenvalues,
        which cost GMRES an iteration each."""
        inv = stiffness.getDiagonal()
        inv.reciprocal()
        self._cols = self._dual.copy(self._cols, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN
                                     if self._cols is not None else None)
        self._cols.diagonalScale(L=inv)
        self._coupling = self._rows.matMult(self._cols, result=self._coupling)
        schur = self._lam.getDiagonal().array - self._coupling.getDiagonal().array
        empty = np.abs(schur) <= 1e-8 * kscale
        if not self.comm.allreduce(int(empty.sum())):
            return None
        add = self._lam.createVecLeft()
        add.array[:] = np.where(empty, -kscale, 0.0)
        return add


#: a level's smoother option of the V-cycle on the stiffness block (PCMG's numbers: 0 the
#: coarsest), and any level's (set: the scene's or the command line's choice, kept)
LEVEL = "fieldsplit_q_mg_levels_{}_pc_type"
ANY_LEVEL = "fieldsplit_q_mg_levels_pc_type"
#: a node (or aggregate) block this ill-conditioned is left to scalar Jacobi
BLOCK_COND = 1e10


def level_smoothers(pc: PETSc.PC, settings: dict[str, str]) -> dict[str, str] | None:
    """Point-block Jacobi (each node's, or coarse aggregate's, diagonal block inverted) put in
    the Chebyshev smoother of every level of the fieldsplit's GAMG V-cycle whose blocks are
    all invertible and which the settings leave alone, on the V-cycle as set up (once): the
    settings with those levels' choice (for its later set-ups); None when no level changes,
    or there is no such V-cycle, or every level's smoother is chosen in ``settings``
    (``-fieldsplit_q_mg_levels_pc_type``). A level with any option
    of its own in the settings (``-fieldsplit_q_mg_levels_1_ksp_type``, ``..._1_pc_type``:
    the scene's or the command line's) keeps it and is not touched; no setting is dropped.
    Call with the options inserted (it sets the V-cycle up; collective).

    K holds 3D friction's cross stiffness κ (n × s)(n × s)ᵀ (κ up to 1e4 times the surface's
    stiffness: ``contact.friction.KAPPA_MAX``) on a mix of a node's x and y, and finite sliding's
    geometric stiffness, since both are terms (``effects.row_terms``): Jacobi on the diagonal
    leaves that mix unsmoothed (the friction box at 8×: 208-210 Krylov iterations per solve,
    at 64× 206-210 with point blocks on the finest level alone). A coarse level's blocks are
    its aggregates' (six rigid modes), singular for an aggregate of one or two nodes (the
    coarsened mortar sphere at 3 ranks): such a level keeps the preset's (rowmax) Jacobi."""
    if pc.getType() != "fieldsplit" or ANY_LEVEL in settings:
        return None
    q = pc.getFieldSplitSubKSP()[0]
    if q.getPC().getType() != "gamg":
        return None
    q.setUp()   # (the fieldsplit sets its blocks' solvers up at their first use)
    amg = q.getPC()
    own = [lv for lv in range(1, amg.getMGLevels())
           if not any(k.startswith(LEVEL.format(lv)[:-7]) for k in settings)]
    blocks = [lv for lv in own if _blocks_invertible(amg.getMGSmoother(lv).getOperators()[1])]
    chosen = {**settings, **{LEVEL.format(lv): "pbjacobi" for lv in blocks}}
    if chosen == settings:
        return None
    # the hierarchy kept (it does not depend on the smoothers), the chosen levels' smoothers
    # changed in place: no second set-up. GAMG gave a Chebyshev on point Jacobi its smoothed
    # aggregation's bounds of D⁻¹A and turned its own estimate off; those are not point
    # blocks' bounds: the Chebyshev made anew (its type set again, its options read again)
    # estimates them at its first smoothing, as when the setting is there at the set-up (the
    # same iterations and answers, bit for bit at 1 and 2 ranks)
    for lv in blocks:
        smoother = amg.getMGSmoother(lv)
        if smoother.getType() == "chebyshev":
            smoother.setType("richardson")
            smoother.setType("chebyshev")
        smoother.getPC().setType("pbjacobi")
        smoother.setFromOptions()
        smoother.setUp()
    return chosen


def _blocks_invertible(mat: PETSc.Mat) -> bool:
    """Whether every diagonal block (the matrix's block size) is well-conditioned, on every
    rank (a block size of 1: no blocks to invert)."""
    bs = mat.getBlockSize()
    ok = bs > 1
    if ok:
        indptr, cols, vals = mat.getValuesCSR()
        n = indptr.size - 1
        r0 = mat.getOwnershipRange()[0]
        rows = np.repeat(np.arange(n), np.diff(indptr))
        inside = cols // bs == (rows + r0) // bs
        blocks = np.zeros((n // bs, bs, bs))
        blocks[rows[inside] // bs, rows[inside] % bs, cols[inside] % bs] = vals[inside]
        ok = bool(n % bs == 0 and (np.linalg.cond(blocks) < BLOCK_COND).all())
    return bool(mat.getComm().tompi4py().allreduce(ok, op=MPI.LAND))


def _within(mat: PETSc.Mat, extra: PETSc.Mat) -> bool:
    """Whether every entry of ``extra`` (same layout) is in the pattern of ``mat``, on this
    rank: the rows of ``extra`` that have entries (a few, the constrained DOFs) taken out of
    ``mat`` and compared."""
    indptr, cols, _ = extra.getValuesCSR()
    lengths = np.diff(indptr)
    rows = np.flatnonzero(lengths)
    r0, c0 = mat.getOwnershipRange(), mat.getOwnershipRangeColumn()
    is_rows = PETSc.IS().createGeneral((rows + r0[0]).astype(PETSc.IntType), comm=mat.comm)
    is_cols = PETSc.IS().createStride(c0[1] - c0[0], first=c0[0], step=1, comm=mat.comm)
    part = mat.createSubMatrix(is_rows, is_cols)
    p_ptr, p_cols, _ = part.getValuesCSR()
    part.destroy()
    width = np.int64(mat.getSize()[1])
    have = np.repeat(np.arange(rows.size, dtype=np.int64), np.diff(p_ptr)) * width + p_cols
    want = np.repeat(np.arange(rows.size, dtype=np.int64), lengths[rows]) * width + cols
    return bool(np.isin(want, have).all())
