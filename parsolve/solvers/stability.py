"""Whether a converged equilibrium is stable: the inertia of the consistent tangent on the
space the enforced relations leave free.

A secant iteration ((1 - D) C, always positive definite) converges as well to an unstable
equilibrium as to a stable one, and its factorization cannot tell them apart. On a symmetric
softening branch (two damaged columns alike, a bar damaged everywhere) it stays on the unstable
symmetric solution until round-off, which the partition changes, has grown enough to pull it
off: which step that is, and which branch follows, depends on the rank count.

The consistent tangent K_t at the converged state (evaluated from the step's start, so that the
points that load go on softening) tells. With Z a basis of the increments the enforced rows A
allow, the equilibrium is stable in Hill's sense when the symmetric part of Zᵀ K_t Z is positive
definite. Its negative eigenvalues are counted as the negative pivots of an LDLᵀ (MUMPS
INFOG(12)) of

    S = [[K_s + δ k I, Aᵀ], [A, 0]],   K_s = (K_t + K_tᵀ) / 2,

less the enforced rows (each adds one positive and one negative pivot). The control's row is
taken as a held quantity (its dual load does not enter): a controlled equilibrium is stable when
it is stable with the controlled quantity held. The shift δ k (k the mean stiffness diagonal)
keeps a tangent that vanishes at the peak, where its eigenvalues are round-off and their signs
the partition's, from counting: an eigenvalue counts when it is below -δ k, far from round-off
and far below any softening branch's.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from parsolve.solvers.diagnose import NamedFailure

SHIFT = 1e-8   # δ: eigenvalues above -δ k are taken as zero (round-off at a peak)


def checked(problem) -> bool:
    """Whether a Newton run's steps are checked: a nonlinear run with the secant matrix
    (whose own factorization cannot tell), and no maximum control. A maximum group holds only
    its largest row as an equality, where every row at the maximum is held one-sided (none may
    pass it): the comparison solid would let the others pass, and reads the localization
    bar's stable path (one column damaging, its three cells at the maximum) as unstable."""
    ctx = problem.ctx
    return ctx.nonlinear and problem.spec.matrix == "secant" and not problem.active.groups


def check_stable(problem, states: list, step: int, t: float, t_prev: float) -> None:
    """NamedFailure when the converged state of step ``step`` (at ``t``, from ``t_prev``) is
    unstable (``unstable_modes``). Collective."""
    if not problem.comm.allreduce(changed(states, problem.states), op=MPI.LOR):
        return   # (no point left its elastic range: the tangent is the secant, positive)
    modes = unstable_modes(problem, states)
    if modes is None or modes <= 0:   # (None: the factorization cannot tell)
        return
    raise NamedFailure(
        f"the equilibrium at step {step} (t = {t:.6g}) is unstable: the consistent tangent, "
        f"with the relations held, has {modes} negative eigenvalue(s) (a bifurcation or a "
        f"limit point was passed after t = {t_prev:.6g}, e.g. damage softening alike in "
        "several places); the secant iteration follows such a branch until round-off, which "
        "the partition changes, pulls it off, so the branch past here would depend on the rank "
        "count. Break the symmetry (a weaker region where the band is to form), control a "
        "quantity of the band (a maximum strain control), or trace the path with arc-length")


def changed(before, after) -> bool:
    """Whether a material state (nested lists and dicts of arrays) changed over the step on
    this rank."""
    if isinstance(before, dict):
        return any(changed(before[k], after[k]) for k in before)
    if isinstance(before, (list, tuple)):
        return any(changed(a, b) for a, b in zip(before, after))
    if isinstance(before, np.ndarray):
        return not np.array_equal(before, after)
    return before is not after and before != after


def unstable_modes(problem, states: list) -> int | None:
    """Independent directions in which the converged state of ``problem`` is unstable: the
    negative eigenvalues of the symmetric part of the consistent tangent (evaluated at its q
    from the material ``states`` the step started from) on the space the enforced rows leave
    free; None when the factorization cannot tell. Collective; the same on every rank."""
    system = problem.system
    kmat = system.composition.evaluate(problem.q, states, False, system.rate)[2]
    held = _held_symmetric(system, problem.jacobian(kmat), SHIFT * system.kscale)
    negative = negative_pivots(problem.comm, held)
    _, _, l0, l1 = system.dofmap.owned()   # (enforced rows: each counted by its owner)
    enforced = problem.comm.allreduce(int(system.op.active[l0:l1].sum()))
    return None if negative is None else negative - enforced


def _held_symmetric(system, mat: PETSc.Mat, shift: float) -> PETSc.Mat:
    """2 S from the saddle operator [[K, -D], [A, C]] as assembled: N = [[K, 0], [A, C]] (the
    dual columns dropped), N + Nᵀ, and 2 shift on the primal diagonal (C: the inactive rows'
    positive diagonal and the compliant rows' -c, both kept)."""
    op = system.op
    dual = op.data[op.d_final].copy()
    op.data[op.d_final] = 0.0
    held = mat.copy()   # (the operator's own arrays: the solver's matrix gets D back below)
    op.data[op.d_final] = dual
    mat.assemble()
    held.axpy(1.0, held.transpose(PETSc.Mat()),   # (a new matrix: transpose() is in place)
              structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    diagonal = held.createVecs()[0]
    q0, q1, _, _ = system.dofmap.owned()
    diagonal.array[:] = 0.0
    diagonal.array[:q1 - q0] = 2.0 * shift
    held.setDiagonal(diagonal, addv=PETSc.InsertMode.ADD_VALUES)
    return held


def negative_pivots(comm: MPI.Comm, mat: PETSc.Mat) -> int | None:
    """Negative pivots of MUMPS' LDLᵀ of a symmetric matrix (INFOG(12)); None when it has
    null pivots (INFOG(28): dependent rows, a cell with no stiffness left) or fails, where
    the count says nothing (every rank alike: MUMPS' INFOG is global)."""
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    ksp = PETSc.KSP().create(comm)
    try:
        ksp.setOperators(mat)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("cholesky")
        pc.setFactorSolverType("mumps")
        pc.setFactorSetUpSolverType()
        pc.getFactorMatrix().setMumpsIcntl(24, 1)   # (null pivots detected, INFOG(28))
        pc.setUp()
        factor = pc.getFactorMatrix()
        if factor.getMumpsInfog(28) > 0:
            return None
        return int(factor.getMumpsInfog(12))
    except PETSc.Error:
        return None
    finally:
        ksp.destroy()
