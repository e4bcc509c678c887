"""Baseline: Crisfield's cylindrical arc-length method with bordering (two back-substitutions
per iteration), on the same saddle system (associated relations kept) and the same matrix
choice as Newton, so the comparison with non-associated control is like for like.

Unknowns: q and the load factor μ of a reference load pattern P:  f_int(q) = F + μ P, with
the constraint ||q - q_n||² = Δl² on each step. The saved "time" of a step is μ.

q, P and the responses are vectors of the rank's local DOFs (owned and ghost): the arc's norm
and every dot product count the owned rows once and add them over the ranks (``StepContext.dot``),
so each rank takes the same root whatever the number of ranks.
"""

from __future__ import annotations

import time

import numpy as np

from parsolve import interrupts
from parsolve.errors import SolverError
from parsolve.la.dofmap import HeldValues
from parsolve.scene import NonlinearSpec
from parsolve.solvers.finite import check_finite
from parsolve.solvers.linear import DoesNotFit
from parsolve.solvers.problem import SaddleProblem
from parsolve.solvers.stability import ArcWatch


class ArcLength:
    """Another driver over the problem Newton iterates on (its state, evaluation, operator
    and solves); only the step differs. The relations' rows stay as the system has them."""

    def __init__(self, problem: SaddleProblem, spec: NonlinearSpec):
        self.problem, self.spec = problem, spec
        ctx = problem.ctx
        # this mesh's DOFs, like the known loads (on a part: its local DOFs)
        self.P = ctx.patterns[spec.arc_pattern].vector()
        self.mu = 0.0
        self.prev = None  # previous step's increment (q, μ), to keep going forward

    def _solve(self, mat, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray, HeldValues]:
        """(Δq, unscaled λ, the saddle values as ``gather`` returns them) of one right-hand
        side."""
        x_full = self.problem.solve(mat, rhs)
        return x_full.q, self.problem.unscaled(x_full), x_full

    @staticmethod
    def _combined(x_r: HeldValues, x_p: HeldValues, dmu: float) -> HeldValues:
        """x_r + dμ x_p of two gathered saddle vectors (the multipliers the step reports:
        ``multipliers`` reads them from ``x_full``)."""
        out = x_r.copy()
        out.q, out.lam = x_r.q + dmu * x_p.q, x_r.lam + dmu * x_p.lam
        return out

    def loads(self, t: float) -> np.ndarray:
        """The known loads of the step plus μ times the reference pattern."""
        return self.problem.ctx.composition.known_loads(t, t, None) + self.mu * self.P

    def step(self, t: float, cuts: int = 8):
        """One arc step; on failure the arc is halved and retried from the last converged
        state (standard step cutting, up to ``cuts`` times). Returns (iterations summed over
        the tries, residual, f_int)."""
        saved, mu = self.problem.snapshot(), self.mu
        dl, spent = self.spec.arc_length, 0
        for _ in range(cuts + 1):
            try:
                its, residual, f_int = self._step(t, dl)
                return spent + its, residual, f_int
            except DoesNotFit:
                raise   # (a shorter arc needs the same factor)
            except SolverError as exc:
                spent += getattr(exc, "iterations", self.spec.max_iterations)
                self.problem.restore(saved)
                self.mu = mu
                dl *= 0.5
                last = exc
        raise last

    def _step(self, t: float, dl: float):
        problem, spec = self.problem, self.spec
        q0, mu0 = problem.q.copy(), self.mu
        problem.ctx.composition.begin(t, t, None)   # the step's instant for every effect
        for it in range(spec.max_iterations + 1):
            lin = problem.form()
            # the forces in play, reactions of eliminated DOFs included
            r_norm, ref = problem.norms(self.loads(t), lin.f_int)
            residual = r_norm / ref
            if not np.isfinite(residual):   # (the same on every rank)
                raise SolverError(f"arc-length: non-finite residual at load factor "
                                  f"{self.mu:.6g}, iteration {it} (a diverged solve, or a "
                                  "material that cannot be evaluated there)")
            if it > 0 and residual <= spec.rtol:
                # the loads the step balances: the reactions of eliminated DOFs are F + μ P
                # minus their rows (``multipliers``)
                problem.commit(lin, self.loads(t))
                self.prev = (problem.q - q0, self.mu - mu0)
                return it, residual, lin.f_int
            if it == spec.max_iterations:
                break
            mat = problem.operator(lin.kmat)
            # bordering: the response to the residual and to the reference load
            rhs_r = problem.rhs_of(self.loads(t) - lin.f_int, t)
            dq_r, lam_r, x_r = self._solve(mat, rhs_r)
            dq_p, lam_p, x_p = self._solve(mat, problem.rhs_of(self.P))
            try:
                dmu = self._root(problem.q - q0 + dq_r, dq_p, dl, it == 0)
            except SolverError as exc:
                exc.iterations = it + 1
                raise
            problem.q = problem.q + dq_r + dmu * dq_p
            self.mu += dmu
            problem.lam = lam_r + dmu * lam_p
            problem.x_full = self._combined(x_r, x_p, dmu)
            # this iterate's tangent goes before the next is formed (as in Newton)
            mat = lin = None
        raise SolverError(f"arc-length: no convergence at step (load factor {self.mu:.6g}) after "
                          f"{spec.max_iterations} iterations (relative residual {residual:.1e})")

    def _root(self, a: np.ndarray, b: np.ndarray, dl: float, predictor: bool) -> float:
        """dμ with ||a + dμ b|| = dl, the root that keeps going forward (Crisfield). The dot
        products are the DOF map's (owned rows once, summed over the ranks): the same on
        every rank."""
        dot = self.problem.ctx.dot
        if predictor:
            dmu = dl / max(np.sqrt(dot(b, b)), 1e-300)
            if self.prev is not None and dot(self.prev[0], b) < 0:
                dmu = -dmu  # past a limit point the load decreases
            return dmu
        A, B, C = dot(b, b), 2 * dot(a, b), dot(a, a) - dl * dl
        disc = B * B - 4 * A * C
        if disc < 0:
            raise SolverError("arc-length: no intersection with the arc (complex roots)")
        roots = [(-B + s * np.sqrt(disc)) / (2 * A) for s in (1.0, -1.0)]
        ref = self.prev[0] if self.prev is not None else b
        a_ref, b_ref = dot(a, ref), dot(b, ref)   # (a + m b) · ref of each root m
        return max(roots, key=lambda m: a_ref + m * b_ref)


def run_arc_length(comm, system, cli_options, writer, log, export_dir: str | None = None) -> None:
    from parsolve.outputs import progress, step_outputs
    from parsolve.solvers.setup import make_solver

    scene = system.context.scene
    system.assemble()
    problem = SaddleProblem(comm, system, make_solver(comm, system, cli_options), scene.nonlinear)
    problem.export_dir = export_dir
    solver = ArcLength(problem, scene.nonlinear)
    # a softening run's bifurcations (a linear one has none: its tangent never changes)
    watch = ArcWatch(problem) if system.context.nonlinear else None
    nsteps = len(scene.times)
    for step in range(nsteps):
        t1 = time.perf_counter()
        states, mu_prev = problem.states, solver.mu
        iterations, residual, f_int = solver.step(scene.times[step])
        seconds = time.perf_counter() - t1
        multipliers = problem.multipliers(scene.times[step], f_int)
        fields, cell_fields, rel_out = step_outputs(comm, system.context, problem.q, multipliers,
                                                    problem)
        check_finite(comm, step + 1, solver.mu, problem.q, multipliers, residual, fields,
                     cell_fields, rel_out, {})
        if watch is not None:
            watch.check(states, step + 1, mu_prev, solver.mu)
        writer.write_step(solver.mu, iterations, residual, fields, cell_fields, rel_out,
                          {"assembly": 0.0, "solve": seconds, "total": seconds})
        interrupts.check(comm)
        progress(log, comm, step + 1, nsteps, solver.mu, iterations, residual, seconds,
                  "  (t = load factor)")
