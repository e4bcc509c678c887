"""Newton iterations on the full saddle system, with the active set of unilateral relations.

Unknowns per iteration: the increment Δq and the total multipliers λ,

    [ K_t  -D ] [Δq]   [F + 0 - f_int(q)]
    [ A     0 ] [λ ] = [b(t) - A q      ]      (inactive rows: λ = 0)

so that a load intensity driven by a non-associated relation is an unknown like any other.
Its first guess needs no separate predictor: the step's first solve, with the tangent at the
converged state and the control row enforced, gives λ = (b - A q - A K⁻¹ r) / (A K⁻¹ G), the
linear response (at the first step, from rest: the target over the load pattern's
compliance; exact in one iteration for a linear model).
The step has converged when the force residual F + D λ - f_int is small against the forces in
play, the last increment is small, and the active set did not change.

The iteration only: the state, the operator and the relation policies are the problem's
(``solvers.problem``), seen through its callbacks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve import interrupts, progress
from parsolve.errors import SolverError
from parsolve.la.dofmap import HeldValues
from parsolve.scene import NonlinearSpec
from parsolve.solvers.linear import DoesNotFit
from parsolve.solvers.problem import Linearization, SaddleProblem


@dataclass
class StepResult:
    iterations: int
    residual: float
    f_int: np.ndarray


class NewtonSolver:
    """Newton's iteration over a problem's callbacks, one load step at a time."""

    def __init__(self, problem: SaddleProblem, spec: NonlinearSpec):
        self.problem, self.spec = problem, spec
        self.comm = problem.comm
        self.residual_history: list[float] = []

    def step(self, t: float) -> StepResult:
        problem, spec = self.problem, self.spec
        f_known = problem.begin(t)
        changed, dq_norm, predictions = True, np.inf, 0
        self.residual_history = []
        for it in range(spec.max_iterations + 1):
            interrupts.check(self.comm)   # every rank at the same iteration (see interrupts)
            lin = problem.form()
            if it == 0:
                predictions = problem.first_tangent(t, lin)
            # the forces in play, reactions of eliminated DOFs included; when there are none
            # (or only round-off), the residual is measured against the round-off floor
            r_norm, ref = problem.norms(f_known, lin.f_int)
            residual = r_norm / max(ref, problem.roundoff_force() / spec.rtol)
            self.residual_history.append(residual)
            if not np.isfinite(residual):   # (the same on every rank): a failed iteration
                raise SolverError(f"non-finite residual at t = {t:.6g}, iteration {it} (a "
                                  "diverged solve, or a material that cannot be evaluated "
                                  "there)")
            progress.detail(f"newton {it + 1}: residual {residual:.3e}")
            small_step = dq_norm <= spec.stol * max(problem.size(), 1e-300)
            balanced = residual <= spec.rtol or small_step and r_norm < 1e-6 * ref
            if it > 0 and not changed and balanced:
                problem.accept(t, lin, f_known)
                return StepResult(it + predictions, residual, lin.f_int)
            if it == spec.max_iterations:
                break
            dq_norm, changed = problem.update(t, self._solve(t, it, lin, f_known))
            # this iterate's tangent and states go before the next are formed: held through
            # ``form`` they were a second tangent at its peak (about 1 KB per DOF)
            lin = None
        history = ", ".join(f"{r:.1e}" for r in self.residual_history[-6:])
        trend = "diverged" if len(self.residual_history) > 2 and \
            self.residual_history[-1] > self.residual_history[1] else "did not converge"
        raise SolverError(f"Newton {trend} at t = {t:.6g} after {spec.max_iterations} iterations "
                          f"(relative residuals ..., {history})")

    def _solve(self, t: float, it: int, lin: Linearization, f_known: np.ndarray) -> HeldValues:
        """The iteration's saddle solve. A first solve that fails with contact rows open is
        tried once more with them closed (``SaddleProblem.recover``)."""
        try:
            return self._attempt(t, lin, f_known)
        except SolverError as exc:
            if it == 0 and self.problem.recover():
                return self._attempt(t, lin, f_known)  # a body floating until contact
            if it == 0 or isinstance(exc, DoesNotFit):
                raise
            # singular at a later iterate only: the iterates diverged first (a softening
            # material driven past full damage), which the cut step must know
            history = ", ".join(f"{r:.1e}" for r in self.residual_history[-4:])
            raise SolverError(f"Newton diverged at t = {t:.6g}, iteration {it} (relative "
                              f"residuals ..., {history}): {exc}") from None

    def _attempt(self, t: float, lin: Linearization, f_known: np.ndarray) -> HeldValues:
        problem = self.problem
        mat = problem.jacobian(lin.kmat)
        return problem.solve(mat, problem.rhs(t, lin.f_int, f_known))
