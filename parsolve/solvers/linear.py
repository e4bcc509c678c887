"""Linear solver presets for the saddle operator.

``direct``: MUMPS LU (LDLᵀ when every relation is associated, the operator being symmetric)
with the QAMD ordering (PORD, the fallback here, is catastrophic with a dense control column)
and null-pivot detection, so a singular system is an error instead of inf or NaN.
``iterative``: GMRES on the saddle system. When every relation row is nodal (rigid-obstacle
contact and friction, Dirichlet-type rows) or ties one slave node to master nodes
(node-to-face, dual mortar, controls, periodic ties: ``solvers.tied``) it is preconditioned by
the rows condensed on their (slave) nodes and one AMG V-cycle on the condensed primal operator
(``solvers.condensed``); else (a chain of slaves, a compliant row over several nodes) on its
augmented Lagrangian form (``solvers.augmented``: γ/k Aₕᵀ times the hard rows added to the
force balance; the same answer), preconditioned by a Schur fieldsplit (one GAMG V-cycle on
K + γ/k Aₕᵀ Aₕ, Jacobi on the sparse Schur approximation). Both work when K alone is singular
(a body held only by contact). Without multipliers, CG (or GMRES) + GAMG on the stiffness
alone.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from parsolve import progress
from parsolve.errors import SolverError
from parsolve.solvers import factor_log
from parsolve.solvers import options as opt
from parsolve.solvers.augmented import GAMMA, LEVEL, level_smoothers
from parsolve.solvers.condensed import CondensedPreconditioner


#: The V-cycle of the iterative preset's q block. GAMG, its aggregation graph keeping every
#: nonzero connection (threshold 0: -1 keeps zeros too, and on a slender bar of ν = 0, whose
#: x and y do not couple, took 250 Krylov iterations: localization_bar). A threshold of 0.05
#: coarsened the 3D friction box 4x per level instead of 26x, its first coarse operator as
#: large as the fine one: 3.6x the flops per Newton iteration at 16.9k DOFs and a solve of 205
#: iterations (docs/performance.md, the threshold table). PETSc's ML (-fieldsplit_q_pc_type
#: ml, where built in) took ~15 % fewer on the 3D friction box at a threshold of 0.05 but
#: crashed inside ML's aggregation after many solvers in one process: not the default.
AMG = "gamg"


class DoesNotFit(SolverError):
    """The factorization does not fit in memory: a smaller step or more workspace cannot
    help (the step is not cut)."""


def preset_options(preset: str, symmetric: bool, has_multipliers: bool,
                   stiffness_symmetric: bool | None = None) -> dict[str, str]:
    """PETSc options of a preset. ``symmetric``: the whole operator (every multiplied relation
    associated, every effect's tangent symmetric); ``stiffness_symmetric``: the primal block K
    alone (default: ``symmetric``; the iterative preset's V-cycle on the augmented stiffness
    needs no symmetry, so it is not used there)."""
    if preset == "direct":
        return {
            "ksp_type": "preonly",
            "pc_type": "cholesky" if symmetric else "lu",
            "pc_factor_mat_solver_type": "mumps",
            # QAMD: PORD (the only other ordering of Debian's MUMPS: no METIS, no SCOTCH) needs
            # 0.5-0.6x QAMD's flops without long relation rows, but its analysis is ~9x slower
            # with a dense one (scripts/results/bench_setup.md): QAMD is the safe default.
            # -mat_mumps_icntl_7 4 selects PORD for scenes known to have no dense relation.
            "mat_mumps_icntl_7": "6",
            "mat_mumps_icntl_24": "1",    # detect null pivots...
            "mat_mumps_cntl_3": "1e-12",  # ...below 1e-12 ||A|| (relations are scaled to K)
            "mat_mumps_icntl_14": "50",   # workspace margin for delayed pivots
            "ksp_error_if_not_converged": "true",
        }
    # CG needs a symmetric operator: a coupling that makes K unsymmetric (thermal expansion's
    # (u, T) block, non-associated relations eliminated into K) takes GMRES instead
    krylov = "cg" if symmetric else "gmres"
    if not has_multipliers:
        # rtol on the true residual (GMRES: right preconditioning, whose norm is the true one)
        side = {} if symmetric else {"ksp_pc_side": "right"}
        # an unsymmetric K couples fields (thermal expansion's u and T) whose rows differ in
        # scale by E / k: 1e-10 of the whole residual left T off by 1e-7 of its scale
        rtol = "1e-10" if symmetric else "1e-13"
        return {"ksp_type": krylov, "pc_type": "gamg", "ksp_rtol": rtol,
                "ksp_norm_type": "unpreconditioned", **side,
                "ksp_error_if_not_converged": "true", **opt.AMG_PRODUCTS}
    # the augmented Lagrangian form T M x = T b (solvers.augmented; the answers are the direct
    # preset's), preconditioned by its block upper triangle: one AMG V-cycle on
    # K + γ/k Aₕᵀ Aₕ, Jacobi on the sparse Schur approximation A₁₁ - A diag(K + γ Aₕᵀ Aₕ)⁻¹ (-D);
    # GMRES with right preconditioning, so that rtol bounds the true residual of T M x = T b
    # (the solve checks M x = b's after)
    return {
        "ksp_type": "gmres",
        "ksp_pc_side": "right",
        "ksp_norm_type": "unpreconditioned",
        # 1e-13 of M x = b: the answers are the direct preset's to 1e-8 and the Newton and
        # active-set loops take the same iterations (a looser one shifts a switch near its
        # threshold: solubility_well_mixed at t = 3). GMRES measures T (b - M x), and
        # |T⁻¹| <= 1 + γ (solvers.augmented), hence 1e-13 / (1 + 3)
        "ksp_rtol": "2.5e-14",
        "ksp_max_it": "1000",
        "ksp_gmres_restart": "200",
        "pc_type": "fieldsplit",
        "pc_fieldsplit_type": "schur",
        "pc_fieldsplit_schur_fact_type": "upper",
        "pc_fieldsplit_schur_precondition": "selfp",
        "fieldsplit_q_ksp_type": "preonly",
        "fieldsplit_q_pc_type": AMG,
        "fieldsplit_q_pc_gamg_threshold": "0.0",
        # four Chebyshev steps per level (PETSc's default: 2): 25 -> 20 Krylov iterations per
        # solve on the 3D friction box at 1x, fewer V-cycles for twice the smoothing
        "fieldsplit_q_mg_levels_ksp_max_it": "4",
        # Jacobi on each row's largest entry: K holds 3D friction's cross stiffness
        # κ (n × s)(n × s)ᵀ (κ up to 1e4 times the surface's stiffness, on a mix of a node's
        # x and y) and finite sliding's geometric stiffness since they are terms; on the
        # diagonal alone that mix was unsmoothed (the 8× friction box: 208-210 Krylov
        # iterations per solve); levels whose node blocks are invertible take point-block
        # Jacobi (solvers.augmented.level_smoothers)
        "fieldsplit_q_mg_levels_pc_jacobi_type": "rowmax",
        "fieldsplit_lambda_ksp_type": "preonly",
        "fieldsplit_lambda_pc_type": "jacobi",
        # the condensed preconditioner's V-cycle on S (solvers.condensed), when every relation
        # row is nodal: GAMG, every connection kept, SOR on its finest level (set there); ML
        # took as many iterations for 1.2x the peak memory (it copies S and P's transpose)
        "condensed_pc_type": "gamg",
        "condensed_pc_gamg_threshold": "0.0",
        "ksp_error_if_not_converged": "true",
    }


REASONS = {getattr(PETSc.KSP.ConvergedReason, name): name.lower().replace("_", " ")
           for name in dir(PETSc.KSP.ConvergedReason) if name.isupper()}

#: An operator is symmetric when |a_ij - a_ji| <= SYMMETRY_TOL ||A||_inf for every entry:
#: round-off between ranks passes, a non-symmetric tangent or relation does not.
SYMMETRY_TOL = 1e-11


#: MUMPS errors that more workspace cures (INFOG(1) = -8, -9: integer / real work array too
#: small, -11, -12, -14, -15, -17, -19, -20: the same in other arrays or phases). Not -13: an
#: allocation the memory refused, which a larger margin only makes larger.
WORKSPACE_ERRORS = (-8, -9, -11, -12, -14, -15, -17, -19, -20)
OUT_OF_MEMORY = -13


def reason_in_words(reason: int) -> str:
    """PETSc's KSPConvergedReason as words ("diverged its", "diverged indefinite pc", ...)."""
    return REASONS.get(reason, f"reason {reason}")


class LinearSolver:
    """A KSP on the saddle operator, configured once from the layered options.

    Every time the operator's values change (its PETSc state), a Cholesky factorization is
    allowed only if the operator is numerically symmetric: a non-symmetric one switches the
    factorization to LU (and says so in ``notes``), since MUMPS' Cholesky reads one triangle
    and would factor another matrix. Factorization (PCSetUp) and solve are timed apart.

    One KSP for the run, on one operator whose values are rewritten in place (same pattern):
    PCSetUp sees SAME_NONZERO_PATTERN and MUMPS factors numerically only, its analysis
    (ordering, symbolic factorization) done once per run (tests/solvers/test_linear_reuse.py;
    scripts/results/bench_friction.md measures what it saves). A new operator (the system
    built again on a new pattern) or a failed set-up resets the KSP.
    """

    def __init__(self, comm: MPI.Comm, prefix: str, settings: dict[str, str],
                 is_q: PETSc.IS, is_l: PETSc.IS, near_null: PETSc.NullSpace | None = None,
                 splits: list[tuple[str, PETSc.IS]] | None = None,
                 preconditioner: Callable[[PETSc.Mat, float], PETSc.Mat] | None = None):
        """``splits``: the fieldsplit blocks, named (default: "q" and "lambda");
        ``preconditioner``: the augmented Lagrangian form of an operator and γ (made again
        whenever the operator's values change; γ from the option ``augmented_gamma`` under the
        prefix): the KSP solves its ``operator`` with its ``pmat`` and right-hand sides through
        its ``transform``; else the operator itself."""
        self.comm, self.prefix, self.settings = comm, prefix, settings
        self.ksp = PETSc.KSP().create(comm)
        self.ksp.setOptionsPrefix(prefix)
        self.is_q, self.is_l = is_q, is_l
        self.splits = splits or [("q", is_q), ("lambda", is_l)]
        self.near_null = near_null
        self.preconditioner = preconditioner
        self.pmat: PETSc.Mat | None = None
        self.operator: PETSc.Mat | None = None   # M (the KSP's may be T M: solvers.augmented)
        self._transform: Callable[[PETSc.Vec], None] | None = None
        self.configured = False
        self._state = None
        # the iterative preset's choice: the nodal rows condensed (``solvers.condensed``) when
        # every relation row allows it, else the augmented form; said in the solve's line
        self.condensed = (CondensedPreconditioner(comm, is_q.getBlockSize(), is_q, is_l, prefix)
                          if preconditioner is not None else None)
        self.choice: str | None = None
        self.notes: list[str] = []
        self.timings = {"factorization": 0.0, "solve": 0.0}

    def set_operator(self, mat: PETSc.Mat) -> None:
        """Solve with this operator from now on. Another matrix than the last (a system built
        again on a new pattern: ``SaddleSystem.restructure``) resets the KSP, so that its
        preconditioner (MUMPS: the analysis too) is set up on it from scratch."""
        if self.near_null is not None:  # rigid-body modes for GAMG on the stiffness alone
            mat.setNearNullSpace(self.near_null)
        previous = self.operator if self.configured else None
        self.operator = mat
        if previous is not None and previous.handle != mat.handle:
            self._restart(mat)
            self._state = None
            return
        self.ksp.setOperators(mat)
        if not self.configured:
            self._configure()

    def _configure(self) -> None:
        with opt.inserted(self.prefix, self.settings):
            if self.settings.get("pc_type") == "fieldsplit":
                pc = self.ksp.getPC()
                pc.setType("fieldsplit")
                pc.setFieldSplitIS(*self.splits)
            self.ksp.setFromOptions()
        self.configured = True

    def _restart(self, mat: PETSc.Mat) -> None:
        """Forget a failed set-up, so that the next one really factorizes again."""
        pc_type = self.ksp.getPC().getType()
        self.ksp.reset()
        self.ksp.setOperators(mat, self.pmat if self.preconditioner else None)
        self._configure()
        self.choice = None
        if pc_type in ("lu", "cholesky"):  # keep an LU chosen by the symmetry check
            self.ksp.getPC().setType(pc_type)

    def _prepare(self) -> None:
        """Check symmetry and factorize when the operator changed since the last solve. A
        factorization that runs out of MUMPS workspace (delayed pivots of a saddle point
        system) is redone with twice the margin, up to three times."""
        mat = self.operator
        state = mat.stateGet()
        if state == self._state:
            return
        pc = self.ksp.getPC()
        if pc.getType() == "cholesky" and not self.symmetric(mat):
            pc.setType("lu")
            self.notes.append("the operator is not symmetric: LU instead of Cholesky")
        t0, first = time.perf_counter(), self._state is None
        if self.preconditioner is not None:
            self._precondition(mat)
        for attempt in range(4):
            try:
                with opt.inserted(self.prefix, self.settings), factor_log.factorization(first):
                    self.ksp.setUp()
                    # KSPSetUp does not set the PC up again once it has solved: PCSetUp does,
                    # when the operator's values changed (the factorization, timed here)
                    self.ksp.getPC().setUp()
                    # the V-cycle's smoothers, chosen once per operator (a level's blocks
                    # are checked on the first set-up, not at every Newton iteration)
                    smoother = (None if not first and any(k.startswith(LEVEL.format("")[:-8])
                                                          for k in self.settings)
                                else level_smoothers(self.ksp.getPC(), self.settings))
                break
            except PETSc.Error as exc:
                info = self._mumps_info()
                reason = self._reason(exc)
                if info == OUT_OF_MEMORY:
                    reason = self._does_not_fit()
                self._restart(mat)
                if info == OUT_OF_MEMORY:
                    raise DoesNotFit(reason) from None
                if info not in WORKSPACE_ERRORS or attempt == 3:
                    raise SolverError(f"solver set-up failed ({reason}); check the PETSc "
                                      "options of the scene and the command line") from None
                margin = 2 * int(self.settings.get("mat_mumps_icntl_14", "50")) + 50
                self.settings = {**self.settings, "mat_mumps_icntl_14": str(margin)}
                self.notes.append(f"MUMPS workspace too small: margin raised to {margin} %")
        self.timings["factorization"] += time.perf_counter() - t0
        if smoother is not None:   # (set on the V-cycle already; its later set-ups too)
            self.settings = smoother
        self._state = mat.stateGet()

    def _precondition(self, mat: PETSc.Mat) -> None:
        """The iterative preset's preconditioner for this operator: the condensed nodal rows
        (Krylov on M itself) when every relation row is nodal, else the augmented form (Krylov
        on T M, its Schur fieldsplit). The PC's type follows the choice when it changes."""
        with opt.inserted(self.prefix, self.settings):
            options = PETSc.Options(self.prefix)
            gamma = options.getReal("augmented_gamma", GAMMA)
            why = (self.condensed.update(mat) if options.getBool("condensed", True)
                   else "condensation turned off")
        choice = "condensed" if why is None else f"augmented: {why}"
        pc = self.ksp.getPC()
        if (why is None) != (pc.getType() == "python"):
            if why is None:
                pc.setType("python")
                pc.setPythonContext(self.condensed)
            else:   # (back from the condensed PC: the fieldsplit configured again)
                pc.setType("fieldsplit")
                pc.setFieldSplitIS(*self.splits)
                with opt.inserted(self.prefix, self.settings):
                    pc.setFromOptions()
        self.choice = choice
        if why is None:
            self.pmat, self._transform = mat, None
            self.ksp.setOperators(mat, mat)
            return
        form = self.preconditioner(mat, gamma)
        self.pmat, self._transform = form.pmat, form.transform
        self.ksp.setOperators(form.operator, self.pmat)

    def _mumps_info(self) -> int:
        try:
            F = self.ksp.getPC().getFactorMatrix()
            return int(F.getMumpsInfog(1)) if F.getType() == "mumps" else 0
        except PETSc.Error:
            return 0

    def _does_not_fit(self) -> str:
        """INFOG(1) = -13: the sentence with what MUMPS asked for (INFOG(2): the failed
        allocation's entries, in millions when negative) against what the machine has."""
        entries = int(self.ksp.getPC().getFactorMatrix().getMumpsInfog(2))
        need = (entries if entries > 0 else -entries * 1e6) * 8 / 1e9   # (double entries)
        return (f"the factorization does not fit in memory: MUMPS needs {need:.3g} GB "
                f"(one allocation of one process), {available_memory() / 1e9:.3g} GB available "
                "(MUMPS error INFOG(1)=-13); more memory per process, more nodes, or the "
                "iterative preset")

    @staticmethod
    def symmetric(mat: PETSc.Mat) -> bool:
        """Whether the operator is symmetric, the same answer on every rank. PETSc's test of
        a distributed AIJ matrix reduces its diagonal blocks' answer but returns each rank's
        own for the off-diagonal block: a rank whose coupling to another was not mirrored
        there chose LU while the others chose Cholesky, and MUMPS' collectives never met."""
        tol = SYMMETRY_TOL * max(mat.norm(PETSc.NormType.INFINITY), 1e-300)
        return bool(mat.getComm().tompi4py().allreduce(bool(mat.isSymmetric(tol)), op=MPI.LAND))

    def solve(self, rhs: PETSc.Vec, x: PETSc.Vec) -> int:
        """Solve; raise SolverError on failure (non-convergence, null pivots, non-finite)."""
        self._prepare()
        t0 = time.perf_counter()
        norm = rhs.norm()
        if norm == 0.0:   # the answer is 0: no Krylov method is asked to reach 0 relatively
            self._check_factor()
            x.zeroEntries()
            self.residual = 0.0
            self.timings["solve"] += time.perf_counter() - t0
            return 0
        # a Krylov method solves for b / ||b||: its absolute floors (GMRES' happy-breakdown
        # tolerance 1e-30, atol 1e-50) would end it at x = 0 on a right-hand side of 1e-40
        # (a Newton residual at round-off of a tiny load), which is no failure
        scaled = self.ksp.getType() != "preonly"
        if scaled:
            rhs.scale(1.0 / norm)
        given = None
        if self._transform is not None:   # T b (the KSP's operator is T M)
            given = rhs.copy()
            self._transform(rhs)
        try:
            with opt.inserted(self.prefix, self.settings):
                self.ksp.solve(rhs, x)
        except PETSc.Error as exc:
            raise SolverError(f"linear solve failed: {self._reason(exc)}") from None
        finally:
            if given is not None:
                given.copy(rhs)
                given.destroy()
            if scaled:
                rhs.scale(norm)
                x.scale(norm)
            self.timings["solve"] += time.perf_counter() - t0
        self._check_factor()
        if not np.isfinite(x.norm()):
            raise SolverError("linear solve produced non-finite values (singular system?)")
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise SolverError(f"linear solver diverged: {reason_in_words(reason)} after "
                              f"{self.ksp.getIterationNumber()} iterations")
        residual = true_residual(self.operator, x, rhs)
        if residual > self.residual_limit:
            raise SolverError(f"linear solve inaccurate: true relative residual {residual:.1e} "
                              f"(limit {self.residual_limit:.0e}); the system is singular or "
                              "nearly so (a body not held, dependent relations, or a tangent "
                              "that lost its stiffness)")
        self.residual = residual
        how = f" ({self.choice})" if self.choice else ""
        progress.detail(f"linear solve{how}: {self.ksp.getIterationNumber()} Krylov iterations, "
                        f"residual {residual:.2e}")
        return self.ksp.getIterationNumber()

    def add_time(self, phase: str, seconds: float) -> None:
        """Seconds of another phase of the step, recorded beside factorization and solve (the
        Newton's contact hooks: /timings/contact)."""
        self.timings[phase] = self.timings.get(phase, 0.0) + seconds

    def take_timings(self) -> dict[str, float]:
        """Seconds per phase since the last call (factorization, solve and any ``add_time``
        phase: once recorded, a phase stays in every later step's timings, at 0 if it did not
        run, as the result file's per-step datasets need)."""
        out, self.timings = self.timings, dict.fromkeys(self.timings, 0.0)
        return out

    def negative_pivots(self) -> int | None:
        """Negative pivots of the last LDLᵀ factorization (MUMPS INFOG(12)), else None."""
        pc = self.ksp.getPC()
        if pc.getType() != "cholesky":
            return None
        F = pc.getFactorMatrix()
        return int(F.getMumpsInfog(12)) if F.getType() == "mumps" else None

    @property
    def residual_limit(self) -> float:
        """A direct solve must be exact to round-off; a Krylov one to its tolerance."""
        rtol = self.ksp.getTolerances()[0]
        return 1e-8 if self.ksp.getType() == "preonly" else max(1e-8, 100 * rtol)

    def _check_factor(self) -> None:
        pc = self.ksp.getPC()
        if pc.getType() not in ("lu", "cholesky"):
            return
        F = pc.getFactorMatrix()
        if F.getType() == "mumps" and F.getMumpsInfog(28) > 0:
            # (the third cause is what a diverged Newton iterate of a softening material
            # reaches: cells damaged to exactly D = 1 around a node leave it no stiffness)
            raise SolverError(f"singular system: MUMPS found {F.getMumpsInfog(28)} null pivot(s) "
                              "(a body not held, redundant relations, or a tangent that lost "
                              "its stiffness: e.g. every cell around a node fully damaged)")

    def _reason(self, exc: PETSc.Error) -> str:
        pc = self.ksp.getPC()
        try:
            if pc.getType() in ("lu", "cholesky") and pc.getFactorMatrix().getType() == "mumps":
                info = pc.getFactorMatrix().getMumpsInfog(1)
                return f"MUMPS error INFOG(1)={info}"
            reason = self.ksp.getConvergedReason()
            if reason < 0:
                return reason_in_words(reason)
            if pc.getType() == "fieldsplit":
                return ("the fieldsplit preconditioner failed to set up (a body the relations "
                        "do not hold?); preset = \"direct\" says which pivots are null")
        except PETSc.Error:
            pass
        return f"PETSc error {exc.ierr}"


def available_memory() -> float:
    """Bytes this process may still take: the system's available memory (MemAvailable), or
    less when an address-space limit (ulimit -v) is nearer."""
    import resource

    free = float("inf")
    try:
        with open("/proc/meminfo") as f:
            free = next(int(line.split()[1]) * 1024 for line in f
                        if line.startswith("MemAvailable:"))
        with open("/proc/self/statm") as f:
            used = int(f.read().split()[0]) * resource.getpagesize()
    except (OSError, StopIteration, ValueError):
        used = 0
    limit = resource.getrlimit(resource.RLIMIT_AS)[0]
    if limit != resource.RLIM_INFINITY:
        free = min(free, max(limit - used, 0))
    return free


def true_residual(mat: PETSc.Mat, x: PETSc.Vec, rhs: PETSc.Vec) -> float:
    """||b - A x|| / ||b|| (or ||A x|| when b = 0)."""
    r = rhs.duplicate()
    mat.mult(x, r)
    r.axpy(-1.0, rhs)
    nb = rhs.norm()
    return r.norm() / nb if nb > 0 else r.norm()
