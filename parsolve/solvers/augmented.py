"""The augmented Lagrangian form of the saddle system for the iterative preset: the operator
M = [[K, -D], [A, C]] and the right-hand side b multiplied on the left by
T = [[I, γ/k Aₕᵀ Eₕ], [0, I]], Aₕ the rows of A that are enforced and hard (active, not
compliant; Eₕ selects them): each hard row's equation A q + C λ = g, times γ/k Aₕᵀ, added to
the force balance. Hard rows have no C (their compliance is 0), so

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
    """T M (``operator``) and its preconditioning matrix (``pmat``: T M, and -k on the diagonal
    of a row with no sparse Schur diagonal: the same matrix when there is none) from the
    operator's current values, made again on every call (one submatrix, one sparse product,
    one merge: O(nnz)); ``transform`` makes T b. The pattern (the operator's and Aᵀ A of every
    multiplier row, hard or not) is fixed as long as the operator's is, so the preconditioner
    set up on it reuses its structure."""

    def __init__(self, comm, layout):
        self.comm, self.layout = comm, layout
        q0, q1, l0, l1 = layout.owned()
        self.nq, self.nl = q1 - q0, l1 - l0
        off = layout.offset
        self.is_q = PETSc.IS().createStride(self.nq, first=off, step=1, comm=comm)
        self.is_l = PETSc.IS().createStride(self.nl, first=off + self.nq, step=1, comm=comm)
        self._handle = None
        self.operator: PETSc.Mat | None = None
        self.pmat: PETSc.Mat | None = None
        self._weight: PETSc.Vec | None = None
        self._rows = self._scaled = self._rows_a = self._cols = self._coupling = None
        self._products: dict[str, PETSc.Mat] = {}
        self._coupled_extra: PETSc.Mat | None = None

    def update(self, mat: PETSc.Mat, hard: np.ndarray, kscale: float,
               gamma: float = GAMMA) -> "AugmentedMatrix":
        """T M and P for the operator ``mat``; ``hard``: mask of this rank's multiplier rows
        that are enforced and not compliant; k: the stiffness scale; γ: that of the rows of one
        node (T's). A hard row that ties several nodes (more entries than NODAL_SPAN) stays out
        of T and enters P alone, at min(γ, GAMMA_COUPLED)."""
        # a new operator (a new pattern): start again, on every rank alike (the products
        # below are collective: a rank that made them anew while another reused them hung)
        if self.comm.allreduce(int(mat.handle != self._handle), op=MPI.MAX):
            self._handle, self.operator, self.pmat = mat.handle, None, None
            self._rows = self._scaled = self._rows_a = self._cols = self._coupling = None
            self._products = {}
        self._rows = mat.createSubMatrix(self.is_l, self.is_q, submat=self._rows)
        nodal = np.diff(self._rows.getValuesCSR()[0]) <= NODAL_SPAN
        self._weight = self._rows.createVecLeft()
        self._weight.array[:] = np.sqrt(gamma / kscale) * (hard & nodal)
        self._scaled = self._gram("nodal", self._weight)
        extra = self._embedded(self._products["nodal"])
        if self.operator is None:
            self.operator = mat.duplicate(copy=True)
            self.operator.axpy(1.0, extra,
                               structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        else:
            mat.copy(self.operator, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            self.operator.axpy(1.0, extra, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        extra.destroy()
        coupled = self.comm.allreduce(int((~nodal).sum()))   # (fixed by the pattern)
        fill = self._schur_fill(mat, kscale, coupled, hard & ~nodal,
                                np.sqrt(min(gamma, GAMMA_COUPLED) / kscale))
        if fill is None and not coupled:
            self.pmat = self.operator
            return self
        if self.pmat is None or self.pmat is self.operator:
            self.pmat = self.operator.duplicate(copy=True)
            if coupled:
                self.pmat.axpy(1.0, self._coupled_extra,
                               structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        else:
            self.operator.copy(self.pmat, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            if coupled:
                self.pmat.axpy(1.0, self._coupled_extra,
                               structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        if coupled:
            self._coupled_extra.destroy()
        if fill is not None:
            self.pmat.setDiagonal(fill, addv=PETSc.InsertMode.ADD_VALUES)
        return self

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

    def _schur_fill(self, mat: PETSc.Mat, kscale: float, coupled: int, rows: np.ndarray,
                    weight: float) -> PETSc.Vec | None:
        """A relation whose rows and dual share no DOF (a control: the strain of a cell driven by
        a load on the end) has no diagonal in the sparse Schur approximation
        A₁₁ - A diag(K + γ Aₕᵀ Aₕ)⁻¹ (-D), and Jacobi would divide by 0 (PETSc takes 1: a scale
        off by k²). Such a row gets -k on P's diagonal (the vector to add, None when no row
        needs it): the true Schur entry aᵀ K⁻¹ d is a global quantity, but a few rows whose
        scale is merely of the right order are a few isolated eigenvalues, which cost GMRES an
        iteration each. First, when the pattern has coupled rows (``coupled``), their part of
        P (``rows``, weighted by ``weight``) is made, as ``_coupled_extra``."""
        diag = self.operator.getDiagonal()
        if coupled:
            w = self._rows.createVecLeft()
            w.array[:] = weight * rows
            self._gram("coupled", w).destroy()
            self._coupled_extra = self._embedded(self._products["coupled"])
            diag.axpy(1.0, self._coupled_extra.getDiagonal())
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
        if not self.comm.allreduce(int(empty.sum())):
            return None
        lam = diag.getSubVector(self.is_l)
        lam.array[:] = np.where(empty, -kscale, 0.0)
        add = diag.duplicate()
        add.zeroEntries()
        add.isaxpy(self.is_l, 1.0, lam)
        diag.restoreSubVector(self.is_l, lam)
        return add

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
