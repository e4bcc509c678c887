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

A maximum control holds its other rows at the value one-sided; they are held here as
equalities too (``_hold_maximum_rows``), which can only hide instabilities, never invent one.
Beyond the converged states: the path just ahead of one (``check_path``: a snap-back, where
no nearby equilibrium carries the path on, named alike whether the step from there fails or
jumps), a maximum control's own path when a step fails for good (``control_path_failure``: the
rows at the maximum held, a limit point of the controlled maximum), and an arc-length run's
bifurcations (``ArcWatch``).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from parsolve.la.fetch import Fetch
from parsolve.solvers.active_set import GROUP_TOL
from parsolve.solvers.diagnose import NamedFailure, short_control

SHIFT = 1e-8   # δ: eigenvalues above -δ k are taken as zero (round-off at a peak)
# the points of a step's tangent predictor whose stability is checked, nearest first: a
# limit point just past the converged state (a snap-back's unstable stretch may be a few
# percent of a step long) is seen at the smallest, one further on at the others. A step that
# converged is checked inside only (its end, which may be a peak reached exactly, is
# ``check_stable``'s)
FRACTIONS = (1 / 64, 1 / 8, 1.0)
INSIDE = (1 / 64, 1 / 8, 1 / 2)
AHEAD = 1e-6   # where the predictor's tangent is taken, as a fraction of the step's predictor
PENALTY = 1e6  # a row at the maximum held: γ |a|² = PENALTY k (k the mean stiffness diagonal)


def checked(problem) -> bool:
    """Whether a Newton run's steps are checked: a nonlinear run with the secant matrix, whose
    own factorization cannot tell."""
    ctx = problem.ctx
    return ctx.nonlinear and problem.spec.matrix == "secant"


def check_stable(problem, states: list, step: int, t: float, t_prev: float) -> None:
    """NamedFailure when the converged state of step ``step`` (at ``t``, from ``t_prev``) is
    unstable (``unstable_modes``). Collective."""
    if not problem.comm.allreduce(changed(states, problem.states), op=MPI.LOR):
        return   # (no point left its elastic range: the tangent is the secant, positive)
    modes = unstable_modes(problem, states)
    if modes is None or modes <= 0:   # (None: the factorization cannot tell)
        return
    held = "the relations held" + (" (every row of a maximum control at its value among "
                                   "them)" if problem.active.groups else "")
    raise NamedFailure(
        f"the equilibrium at step {step} (t = {t:.6g}) is unstable: the consistent tangent, "
        f"with {held}, has {modes} negative eigenvalue(s) (a bifurcation or a "
        f"limit point was passed after t = {t_prev:.6g}, e.g. damage softening alike in "
        "several places); the secant iteration follows such a branch until round-off, which "
        "the partition changes, pulls it off, so the branch past here would depend on the rank "
        "count. Break the symmetry (a weaker region where the band is to form), control a "
        "quantity of the band (a maximum strain control), or trace the path with arc-length")


def check_path(problem, q0: np.ndarray, states: list, t_prev: float, t: float) -> None:
    """NamedFailure when the path from the converged state (``q0``, material ``states``, at
    ``t_prev``) toward ``t`` is unstable just ahead (``modes_ahead``), though the step may have
    converged: a secant iteration then lands on a distant stable branch (a bar ruptured past a
    snap-back), or on none, as round-off, which the partition changes, decides. (Not in a
    transient step, whose rate terms hold the path.) Collective."""
    if problem.ctx.transient or problem.active.groups:
        return   # (a maximum control holds its path: it is what it is for)
    if not problem.comm.allreduce(changed(states, problem.states), op=MPI.LOR):
        return   # (an elastic step: the path to it is the secant's, linear and stable)
    if modes_ahead(problem, q0, states, t, INSIDE):
        raise path_failure(t_prev)


def path_failure(t_prev: float) -> NamedFailure:
    """The failure of a path that turns back just past ``t_prev``: the same words whether the
    step from there failed or jumped (``check_path``)."""
    return NamedFailure(
        f"the equilibrium path turns back just past t = {t_prev:.6g}: from the state reached "
        "there, the consistent tangent with the relations held has negative eigenvalues along "
        "the step's tangent predictor (a limit point: under a prescribed displacement a "
        "snap-back, under a prescribed load the peak), so no equilibrium near that state "
        "carries the path on, and a step from it fails or jumps to a distant branch, which one "
        "depending on round-off and so on the rank count. Control a quantity that keeps "
        "growing past the point (a maximum strain control, a crack opening), or trace the path "
        "with arc-length")


def control_path_failure(exc: Exception, problem, t: float) -> NamedFailure | None:
    """A step of a maximum control failed for good toward ``t`` (``problem`` back at the last
    converged state, the control short of its value): NamedFailure when the path from that
    state turns back just ahead with the group's rows at the maximum held (``modes_ahead``):
    the controlled maximum itself has a limit point (damage spreading to cells beside the
    controlled one, which a maximum of the cells' strains does not hold), and the secant
    iteration only stalls on it. None otherwise. Collective."""
    if problem.ctx.transient or not problem.active.groups:
        return None
    short = short_control(problem, t)
    if short is None:
        return None
    modes = modes_ahead(problem, problem.q, problem.states, t)
    if not modes:
        return None
    c, kind, reached, target, load, row, cell = short
    where = f"its enforced row {row}" + (f", cell {cell}" if cell is not None else "")
    return NamedFailure(
        f"{kind} {c.name!r} can no longer follow its value: {target:.6g} at t = {t:.6g}, where "
        f"it reached {reached:.6g} (t = {problem.t_prev:.6g}, control load {load:.6g}, "
        f"{where}); the equilibrium path turns back just past t = {problem.t_prev:.6g}: with "
        f"every row at the maximum held, the consistent tangent has {modes} negative "
        "eigenvalue(s) along the step's tangent predictor (a limit point of the controlled "
        "maximum, e.g. damage spreading to cells beside the controlled one), so no equilibrium "
        "near that state carries the path on and the iteration stalls however small the step. "
        "Control a quantity that keeps growing past the point (the mean strain or the opening "
        f"of the damaged band), or trace the path with arc-length (the last attempt: {exc})")


def modes_ahead(problem, q0: np.ndarray, states: list, t: float,
                fractions: tuple = FRACTIONS) -> int | None:
    """Negative eigenvalues (``unstable_modes``) at the first of the points q0 + s Δq (s in
    ``fractions``) that has any, Δq the tangent predictor toward ``t`` (the consistent tangent at
    q0, the enforced rows as they are); 0 when none has; None when the predictor or a count
    cannot be had. Points where no material leaves its elastic range are stable (their
    tangent is the secant) and cost no factorization. Collective."""
    system, comm = problem.system, problem.comm
    f_int, _, kmat = system.composition.evaluate(q0, states, False, system.rate)[:3]
    dq = _predictor(problem, kmat, f_int, q0, t)
    if dq is None:
        return None
    # the tangent just past q0 along it: a state reached exactly at a threshold (a peak at a
    # step) is elastic at q0 itself, while its points that load go on softening
    kmat = system.composition.evaluate(q0 + AHEAD * dq, states, False, system.rate)[2]
    dq = _predictor(problem, kmat, f_int, q0, t)
    if dq is None:
        return None
    for s in fractions:
        q = q0 + s * dq
        trial = system.composition.evaluate(q, states, False, system.rate)[3]
        if not comm.allreduce(changed(states, trial), op=MPI.LOR):
            continue
        modes = unstable_modes(problem, states, q)
        if modes is None:
            return None
        if modes > 0:
            return modes
    return 0


def _predictor(problem, kmat, f_int: np.ndarray, q0: np.ndarray, t: float
               ) -> np.ndarray | None:
    """Δq of one Newton solve from q0 (internal forces ``f_int``) toward t with the tangent
    ``kmat`` and the enforced rows as they are, by MUMPS' LU on its own (the run's solver keeps
    its factor and its choices: the consistent tangent is not symmetric); None when it is
    singular or fails. Collective."""
    system = problem.system
    mat = problem.jacobian(kmat)   # (first: the right-hand side's lifting is this operator's)
    rhs = system.rhs(t, f_int=f_int, q=q0, f_ext=problem.external(t))[0]
    ksp = PETSc.KSP().create(problem.comm)
    try:
        if _mumps_factor(ksp, mat, "lu").getMumpsInfog(28) > 0:
            return None
        x, b = mat.createVecs()
        b.array[:] = rhs
        ksp.solve(b, x)
        return system.gather(x.array).q
    except PETSc.Error:
        return None
    finally:
        ksp.destroy()


class ArcWatch:
    """An arc-length run's bifurcations. Past a limit point the path it traces is unstable
    under its dead load, which is no failure: the tangent gains one negative eigenvalue as the
    load factor turns (within a step, possibly: the step's net load increment does not tell).
    Several at once are a bifurcation, branches crossing the path (damage softening alike in
    several places, a symmetric mode beside the limit point's): which branch the iteration
    follows past it is round-off's, and so the partition's."""

    def __init__(self, problem):
        self.problem = problem
        self.count: int | None = 0      # the unloaded state's: the elastic tangent, positive

    def check(self, states: list, step: int, mu_prev: float, mu: float) -> None:
        """NamedFailure when step ``step`` (load factor ``mu_prev`` to ``mu``, from the material
        ``states``) crossed a bifurcation. Collective."""
        problem = self.problem
        if problem.comm.allreduce(changed(states, problem.states), op=MPI.LOR):
            # the arc keeps the rows the system has: put back on its operator as it is after
            # (built anew if a maximum group moved)
            rows = problem.system.op.active
            count = unstable_modes(problem, states)
            problem.system.op.active = rows
        else:
            count = 0   # (no point left its elastic range: the secant, positive)
        if count is not None and self.count is not None and abs(count - self.count) > 1:
            raise NamedFailure(
                f"arc-length passed a bifurcation at step {step} (load factor {mu_prev:.6g} to "
                f"{mu:.6g}): the consistent tangent, with the relations held, went from "
                f"{self.count} to {count} negative eigenvalues at once (a limit point changes "
                "the count by one): branches cross the path there (e.g. damage softening alike "
                "in several places), and which one the iteration follows depends on round-off, "
                "so on the rank count. Break the symmetry (a weaker region where the band is to "
                "form), or control a quantity of the band (a maximum strain control)")
        self.count = count if count is not None else self.count


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


def unstable_modes(problem, states: list, q: np.ndarray | None = None) -> int | None:
    """Independent directions in which the converged state of ``problem`` is unstable: the
    negative eigenvalues of the symmetric part of the consistent tangent (evaluated at its q
    from the material ``states`` the step started from) on the space the enforced rows leave
    free; None when the factorization cannot tell. At ``q`` instead of the problem's when
    given. Collective; the same on every rank."""
    system = problem.system
    q = problem.q if q is None else q
    kmat = system.composition.evaluate(q, states, False, system.rate)[2]
    held = _held_symmetric(system, problem.jacobian(kmat), SHIFT * system.kscale)
    if problem.active.groups:
        _hold_maximum_rows(problem, held, q)
    negative = negative_pivots(problem.comm, held)
    _, _, l0, l1 = system.dofmap.owned()   # (enforced rows: each counted by its owner)
    enforced = problem.comm.allreduce(int(system.op.active[:l1 - l0].sum()))
    return None if negative is None else negative - enforced


def at_maximum(problem, q: np.ndarray) -> np.ndarray:
    """The rows of the maximum groups held here that are at their value at ``q`` (tied with
    the largest, the active set's GROUP_TOL) but not enforced. Collective (a group's largest
    target: one reduction of the groups' number)."""
    rset, active = problem.rset, problem.active
    values, targets = rset.primal_values(q), rset.targets(problem.t_prev)
    out = np.zeros(values.size, dtype=bool)
    scale = np.array([np.abs(targets[g]).max(initial=0.0) for g in active.groups])
    if problem.comm.size > 1:
        problem.comm.Allreduce(MPI.IN_PLACE, scale, op=MPI.MAX)
    for g, top in zip(active.groups, scale):
        sign = active.sign[g]
        out[g] = sign * (targets[g] - values[g]) <= GROUP_TOL * max(float(top), 1e-300)
    return out & ~active.active


def _hold_maximum_rows(problem, held: PETSc.Mat, q: np.ndarray) -> None:
    """Hold the rows of the maximum groups at their value besides the enforced one, as
    equalities: γ a aᵀ on the primal block of 2 S per row a (γ |a|² = PENALTY k; the DOFs that
    are held already left out). A maximum group enforces only its largest row, and the others
    at the value may not pass it (held one-sided): the comparison solid that lets them pass
    reads a stable localization (one column damaging, its three cells at the maximum) as
    unstable; held both ways the count is at most the one-sided problem's (a quadratic form
    negative on a subspace of the admissible directions is negative on them), so an unstable
    count is one for sure. Each row is held by the rank building it (a per-cell strain's: the
    rank counting the cell), which adds its γ a aᵀ: no rank gathers the others' rows.
    Collective."""
    rows = np.flatnonzero(at_maximum(problem, q))
    # (on every rank: logically collective, a reduction in a debugging PETSc)
    held.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    got = owned_row_entries(problem, rows)
    got = got[np.lexsort((got["dof"], got["row"]))]    # (rows in order, each by input DOF)
    starts = np.flatnonzero(np.diff(got["row"], prepend=-1))
    gamma_k = 2.0 * PENALTY * problem.system.kscale
    for row in np.split(got, starts[1:]):
        if row.size:
            vals, index = row["val"], row["saddle"].astype(PETSc.IntType)
            held.setValues(index, index, gamma_k / float(vals @ vals) * np.outer(vals, vals),
                           addv=PETSc.InsertMode.ADD_VALUES)
    held.assemble()


# an entry of a relation row: the row (its place in the rows asked for), its input DOF, its
# saddle index, its coefficient
ROW_ENTRY = np.dtype([("row", np.int64), ("dof", np.int64), ("saddle", np.int64),
                      ("val", np.float64)])


def owned_row_entries(problem, rows: np.ndarray) -> np.ndarray:
    """The entries (``ROW_ENTRY``) of the relation rows ``rows`` held here (a maximum
    group's, built per rank: every entry of a row on the rank holding it) on the primal DOFs
    that are not eliminated (each asked of its owner). Collective."""
    rset, system, dm = problem.rset, problem.system, problem.rset.dofmap
    parts = [np.zeros(0, ROW_ENTRY)]
    for place, row in enumerate(rows):
        k, local = rset.locate(int(row))
        r = problem.ctx.multiplied[k]
        sel = np.flatnonzero(r.a_rows == local)
        part = np.empty(sel.size, ROW_ENTRY)
        part["row"], part["dof"], part["val"] = place, r.a_dofs[sel], r.a_vals[sel]
        part["saddle"] = dm.input_saddle(r.a_dofs[sel])
        parts.append(part)
    out = np.concatenate(parts)
    held = np.zeros(dm.n_owned)   # (the eliminated DOFs, each told by its owner)
    held[system.elim_local[system.elim_own]] = 1.0
    return out[Fetch.of(dm, dm.input_new_dof(out["dof"]))(held) < 0.5]


def _held_symmetric(system, mat: PETSc.Mat, shift: float) -> PETSc.Mat:
    """2 S from the saddle operator [[K, -D], [A, C]] as assembled: N = [[K, 0], [A, C]] (the
    dual columns dropped), N + Nᵀ, and 2 shift on the primal diagonal (C: the inactive rows'
    positive diagonal, kept)."""
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


def _mumps_factor(ksp: PETSc.KSP, mat: PETSc.Mat, kind: str) -> PETSc.Mat:
    """MUMPS' ``kind`` ("lu", "cholesky") factor of ``mat`` by ``ksp``, set up with null
    pivots detected (ICNTL(24): INFOG(28) counts them); returns the factor."""
    ksp.setOperators(mat)
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType(kind)
    pc.setFactorSolverType("mumps")
    pc.setFactorSetUpSolverType()
    pc.getFactorMatrix().setMumpsIcntl(24, 1)
    pc.setUp()
    return pc.getFactorMatrix()


def negative_pivots(comm: MPI.Comm, mat: PETSc.Mat) -> int | None:
    """Negative pivots of MUMPS' LDLᵀ of a symmetric matrix (INFOG(12)); None when it has
    null pivots (INFOG(28): dependent rows, a cell with no stiffness left) or fails, where
    the count says nothing (every rank alike: MUMPS' INFOG is global)."""
    mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    ksp = PETSc.KSP().create(comm)
    try:
        factor = _mumps_factor(ksp, mat, "cholesky")
        if factor.getMumpsInfog(28) > 0:
            return None
        return int(factor.getMumpsInfog(12))
    except PETSc.Error:
        return None
    finally:
        ksp.destroy()
