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
from parsolve.solvers.finite import check_finite
from parsolve.solvers.linear import DoesNotFit
from parsolve.solvers.newton import NewtonSolver


class ArcLength(NewtonSolver):
    """Reuses the Newton machinery (state, evaluation, operator); only the step differs."""

    def __init__(self, comm, system, linear, spec):
        super().__init__(comm, system, linear, spec)
        # this mesh's DOFs, like the known loads (on a part: its local DOFs)
        self.P = self.ctx.patterns[spec.arc_pattern].vector()
        self.mu = 0.0
        self.prev = None  # previous step's increment (q, μ), to keep going forward

    def _solve(self, f_full: np.ndarray, target: np.ndarray, elim: np.ndarray, mat):
        """(Δq, unscaled λ, the saddle values as ``gather`` returns them) of one right-hand
        side."""
        x, rhs = self._vectors(mat)
        rhs.array[:] = self.system.rhs_from(f_full, target, elim)[0]
        self._export(mat, rhs)
        self.linear.solve(rhs, x)
        x_full = self.system.gather(x.array)
        return x_full.q, self.system.multipliers(x_full), x_full

    def _combined(self, x_r, x_p, dmu: float):
        """x_r + dμ x_p of two gathered saddle vectors (the multipliers the step reports:
        ``multipliers`` reads them from ``x_full``)."""
        out = x_r.copy()
        out.q, out.lam = x_r.q + dmu * x_p.q, x_r.lam + dmu * x_p.lam
        return out

    def step(self, t: float, cuts: int = 8):
        """One arc step; on failure the arc is halved and retried from the last converged
        state (standard step cutting, up to ``cuts`` times). Returns (iterations summed over
        the tries, residual, f_int)."""
        saved = (self.q.copy(), self.mu, self.lam.copy(), self.x_full.copy())
        dl, spent = self.spec.arc_length, 0
        for _ in range(cuts + 1):
            try:
                its, residual, f_int = self._step(t, dl)
                return spent + its, residual, f_int
            except DoesNotFit:
                raise   # (a shorter arc needs the same factor)
            except SolverError as exc:
                spent += getattr(exc, "iterations", self.spec.max_iterations)
                self.q, self.mu, self.lam = saved[0].copy(), saved[1], saved[2].copy()
                self.x_full = saved[3].copy()
                dl *= 0.5
                last = exc
        raise last

    def _step(self, t: float, dl: float):
        system, spec = self.system, self.spec
        q0, mu0 = self.q.copy(), self.mu
        rset = self.rset
        zero_t = np.zeros(rset.nrows)
        zero_e = np.zeros(system.n_eliminated)
        free = system.free_rows()
        self.ctx.composition.begin(t, t, None)
        for it in range(spec.max_iterations + 1):
            f_int, kmat, trial, extras = self._evaluate(self.q)
            f_ext = self.ctx.owned_rows(self.ctx.composition.known_loads(t, t, None) + self.mu * self.P) \
                + self.rset.reactions(self.lam)
            r = (f_ext - self.ctx.owned_rows(f_int))[free]
            # the forces in play, reactions of eliminated DOFs included
            ref = max(self._norm(f_ext[free]), self._norm(self.ctx.owned_rows(f_int)), 1e-300)
            residual = self._norm(r) / ref
            if not np.isfinite(residual):   # (the same on every rank)
                raise SolverError(f"arc-length: non-finite residual at load factor "
                                  f"{self.mu:.6g}, iteration {it} (a diverged solve, or a "
                                  "material that cannot be evaluated there)")
            if it > 0 and residual <= spec.rtol:
                self.states, self.extras = trial, extras
                # the loads the step balances: the reactions of eliminated DOFs are F + μ P
                # minus their rows (``multipliers``)
                self.f_ext = self.ctx.composition.known_loads(t, t, None) + self.mu * self.P
                self.prev = (self.q - q0, self.mu - mu0)
                return it, residual, f_int
            if it == spec.max_iterations:
                break
            mat = system.assemble(kmat)
            self._use(mat)
            # bordering: the response to the residual and to the reference load
            target_r = self.rset.gap(t, self.q)
            elim_r = system.elim_values(t) - system.eliminated_values(self.q) \
                if system.n_eliminated else zero_e
            f_r = self.ctx.composition.known_loads(t, t, None) + self.mu * self.P - f_int
            dq_r, lam_r, x_r = self._solve(f_r, target_r * rset.row_scale if rset.nrows else zero_t,
                                           elim_r, mat)
            dq_p, lam_p, x_p = self._solve(self.P, zero_t, zero_e, mat)
            try:
                dmu = self._root(self.q - q0 + dq_r, dq_p, dl, it == 0)
            except SolverError as exc:
                exc.iterations = it + 1
                raise
            self.q = self.q + dq_r + dmu * dq_p
            self.mu += dmu
            self.lam = lam_r + dmu * lam_p
            self.x_full = self._combined(x_r, x_p, dmu)
        raise SolverError(f"arc-length: no convergence at step (load factor {self.mu:.6g}) after "
                          f"{spec.max_iterations} iterations (relative residual {residual:.1e})")

    def _root(self, a: np.ndarray, b: np.ndarray, dl: float, predictor: bool) -> float:
        """dμ with ||a + dμ b|| = dl, the root that keeps going forward (Crisfield). The dot
        products are the DOF map's (owned rows once, summed over the ranks): the same on
        every rank."""
        dot = self.ctx.dot
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
    solver = ArcLength(comm, system, make_solver(comm, system, cli_options), scene.nonlinear)
    solver.export_dir = export_dir
    nsteps = len(scene.times)
    for step in range(nsteps):
        t1 = time.perf_counter()
        iterations, residual, f_int = solver.step(scene.times[step])
        seconds = time.perf_counter() - t1
        multipliers = solver.multipliers(scene.times[step], f_int)
        fields, cell_fields, rel_out = step_outputs(comm, system.context, solver.q, multipliers, solver)
        check_finite(comm, step + 1, solver.mu, solver.q, multipliers, residual, fields,
                     cell_fields, rel_out, {})
        writer.write_step(solver.mu, iterations, residual, fields, cell_fields, rel_out,
                          {"assembly": 0.0, "solve": seconds, "total": seconds})
        interrupts.check(comm)
        progress(log, comm, step + 1, nsteps, solver.mu, iterations, residual, seconds,
                  "  (t = load factor)")
