"""The preconditioning matrix of the iterative preset: the saddle operator with an augmented
Lagrangian term γ Aₕᵀ Aₕ added to its stiffness block, Aₕ the rows of A that are enforced and
hard (active, not compliant).

K alone is singular whenever a body is held only by relations (a box pressed on an obstacle,
free in the normal direction): no multigrid can invert it, and a Schur complement built on it
does not exist. K + γ Aₕᵀ Aₕ is the stiffness of the body held by penalty springs along its hard
rows: positive definite once the relations hold the body, symmetric whatever D is (friction's
non-associated dual stays in the operator), and an algebraic multigrid sees it as an elastic
stiffness. Only the preconditioner changes: the operator, hence the answer, is the direct
preset's. Compliant rows (friction's cross stiffness, finite sliding's geometric stiffness on
the multiplier diagonal) and inactive rows are never augmented: their diagonal already makes
their Schur block invertible, and a penalty on them would enforce what the operator softens.

γ is dimensionless against the relation scale: the rows of A are scaled so that their largest
entry is the mean stiffness diagonal k (``RelationSet.set_scales``), so γ/k · Aₕᵀ Aₕ adds about
γ k on the diagonal of a constrained DOF (scripts/results/bench_relations.md measures γ).
"""

from __future__ import annotations

import numpy as np
from petsc4py import PETSc

#: γ of the augmentation, relative to the stiffness scale: 0.01-0.1 take the fewest Krylov
#: iterations on the 3D friction box, 10 and more make the V-cycle's task harder
#: (bench_relations.md); the option -<prefix>augmented_gamma sets another
GAMMA = 0.1


class AugmentedMatrix:
    """P = [[K + γ/k Aₕᵀ Aₕ, -D], [A, C]] from the operator's current values, made again on
    every call (one submatrix, one sparse product, one merge: O(nnz)). The pattern of P (the
    operator's and Aᵀ A of every multiplier row, hard or not) is fixed as long as the operator's
    is, so the preconditioner set up on it reuses its structure."""

    def __init__(self, comm, layout):
        self.comm, self.layout = comm, layout
        q0, q1, l0, l1 = layout.owned()
        self.nq, self.nl = q1 - q0, l1 - l0
        off = layout.offset
        self.is_q = PETSc.IS().createStride(self.nq, first=off, step=1, comm=comm)
        self.is_l = PETSc.IS().createStride(self.nl, first=off + self.nq, step=1, comm=comm)
        self._handle = None
        self.pmat: PETSc.Mat | None = None
        self._rows = self._product = self._rows_a = self._cols = self._coupling = None

    def update(self, mat: PETSc.Mat, hard: np.ndarray, kscale: float,
               gamma: float = GAMMA) -> PETSc.Mat:
        """P for the operator ``mat``; ``hard``: mask of this rank's multiplier rows that are
        enforced and not compliant; k: the stiffness scale."""
        if mat.handle != self._handle:   # a new operator (a new pattern): start again
            self._handle, self.pmat = mat.handle, None
            self._rows = self._product = self._rows_a = self._cols = self._coupling = None
        self._rows = mat.createSubMatrix(self.is_l, self.is_q, submat=self._rows)
        weight = self._rows.createVecLeft()
        weight.array[:] = np.sqrt(gamma / kscale) * hard
        self._rows.diagonalScale(L=weight)
        self._product = self._rows.transposeMatMult(self._rows, result=self._product)
        extra = self._embedded(self._product)
        if self.pmat is None:
            self.pmat = mat.duplicate(copy=True)
            self.pmat.axpy(1.0, extra, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        else:
            mat.copy(self.pmat, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            self.pmat.axpy(1.0, extra, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        extra.destroy()
        self._fill_schur_diagonal(mat, kscale)
        return self.pmat

    def _fill_schur_diagonal(self, mat: PETSc.Mat, kscale: float) -> None:
        """A relation whose rows and dual share no DOF (a control: the strain of a cell driven by
        a load on the end) has no diagonal in the sparse Schur approximation
        A₁₁ - A diag(K + γ Aₕᵀ Aₕ)⁻¹ (-D), and Jacobi would divide by 0 (PETSc takes 1: a scale
        off by k²). Such a row gets -k on P's diagonal: the true Schur entry aᵀ K⁻¹ d is a
        global quantity, but a few rows whose scale is merely of the right order are a few
        isolated eigenvalues, which cost GMRES an iteration each."""
        diag = self.pmat.getDiagonal()
        inv = diag.getSubVector(self.is_q)
        inv.reciprocal()
        self._cols = mat.createSubMatrix(self.is_q, self.is_l, submat=self._cols)
        self._cols.diagonalScale(L=inv)
        diag.restoreSubVector(self.is_q, inv)
        self._rows_a = mat.createSubMatrix(self.is_l, self.is_q, submat=self._rows_a)
        self._coupling = self._rows_a.matMult(self._cols, result=self._coupling)
        coupling = self._coupling.getDiagonal().array
        schur = diag.array[self.nq:] - coupling
        empty = np.abs(schur) <= 1e-8 * kscale
        if self.comm.allreduce(int(empty.sum())):
            lam = diag.getSubVector(self.is_l)
            lam.array[:] = np.where(empty, -kscale, 0.0)
            add = diag.duplicate()
            add.zeroEntries()
            add.isaxpy(self.is_l, 1.0, lam)
            diag.restoreSubVector(self.is_l, lam)
            self.pmat.setDiagonal(add, addv=PETSc.InsertMode.ADD_VALUES)

    def _embedded(self, product: PETSc.Mat) -> PETSc.Mat:
        """The q-space matrix ``product`` as a matrix of the saddle layout (its rows the primal
        rows of each rank, empty multiplier rows)."""
        indptr, cols, vals = product.getValuesCSR()
        cols = self.layout.q_index(np.asarray(cols, dtype=np.int64))
        indptr = np.concatenate([indptr, np.full(self.nl, indptr[-1], dtype=indptr.dtype)])
        n, size = self.nq + self.nl, self.layout.size
        out = PETSc.Mat().createAIJ(size=((n, size), (n, size)), comm=self.comm,
                                    csr=(indptr.astype(PETSc.IntType),
                                         cols.astype(PETSc.IntType), vals))
        out.assemble()
        return out
