"""The nonlinear problem of a saddle system: what Newton and arc-length see of it, in the
manner of dolfinx's ``NonlinearProblem`` (``form`` at a state, then the residual F, the
Jacobian J and the preconditioning matrix P) and Firedrake's ``_SNESContext``.

The problem holds the state a step starts from and ends at (q, the total multipliers λ,
material states, a transient step's f_int(q_n)), its relation policies
(``solvers.policies``) and the linear solves of its operator. A driver (``NewtonSolver``,
``ArcLength``) only iterates over these callbacks:

    form()                 f_int, tangent and trial states at the current q
    norms(f_known, f_int)  ‖F + D λ - f_int‖ on the free rows and the forces in play
    jacobian(kmat)         [[K_t, -D], [A, 0]] with the rows the policies enforce
    preconditioner(mat, γ) the iterative preset's augmented form: operator, P, rhs transform
    rhs(t, f_int, f_known) the Newton right-hand side: F - f_int, b(t) - A q
    solve(mat, rhs)        the saddle increment (Δq, λ)
    update(t, x)           q += Δq, λ; the active set and the effects' hooks (changed?)
    accept(t, form, f)     the step converged: states, hooks, the next step's start
    snapshot() / restore() the converged state, to come back to when a trial fails
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsolve.effects.compose import Rate
from parsolve.errors import SolverError
from parsolve.la.dofmap import HeldValues
from parsolve.scene import NonlinearSpec
from parsolve.solvers.linear import LinearSolver
from parsolve.solvers.policies import RelationPolicies
from parsolve.solvers.setup import export_system
from parsolve.solvers.system import SaddleSystem

# |r| below ROUNDOFF · k · |q| is round-off: about 45 ε, where a rigid translation of a
# von Mises box measures 0.7 ε. Not larger: at a snap-back under displacement control, a
# ruptured bar whose forces are 3e-11 of the peak must not pass for converged (1e-12 did).
ROUNDOFF = 1e-14


@dataclass
class Linearization:
    """What ``form`` gives at a state."""
    f_int: np.ndarray    # internal forces, with a transient step's rate terms
    f_pure: np.ndarray   # without them (the next θ-step's f_int(q_n))
    kmat: object         # the tangent's element matrices (or blocks)
    trial: list          # the material states at this q
    extras: list         # per effect, e.g. stresses at the quadrature points


class SaddleProblem:
    """Carries the converged state (q, λ, material history) from step to step."""

    def __init__(self, comm: MPI.Comm, system: SaddleSystem, linear: LinearSolver,
                 spec: NonlinearSpec):
        self.comm, self.system, self.linear, self.spec = comm, system, linear, spec
        self.ctx = ctx = system.context
        self.rset = ctx.relations
        self.states = ctx.composition.init_states()
        self.policies = RelationPolicies(system, spec.max_active_set_changes, self.respond)
        self.q = ctx.initial_q()
        _, _, l0, l1 = ctx.dofs.owned()
        self.lam = np.zeros(l1 - l0)                # this rank's owned multipliers, unscaled
        self.x_full = ctx.dofs.zeros()
        self.extras = [None] * len(ctx.effects)
        self.time = ctx.scene.time                  # transient: θ-scheme from t_prev to t
        self.t_prev = 0.0
        self.q_start = 0.0                          # |q| where the step started (begin)
        self.f_pure = np.zeros(ctx.ndof)            # f_int at the last converged state
        if self.time is not None and self.time.theta != 1.0:  # θ-scheme: f_int(q_0)
            self.f_pure = ctx.composition.evaluate(self.q, self.states, False)[1]
        self.f_ext: np.ndarray | None = None        # the loads the last step balanced
        self.export_dir: str | None = None          # --export-system: the first system solved
        self._mat = None
        self._vecs = None
        if linear.preconditioner is not None:   # P is the problem's (Firedrake's Jp)
            linear.preconditioner = self.preconditioner

    @property
    def active(self):
        """The active set of the unilateral rows (``ActiveSet``)."""
        return self.policies.active

    @property
    def enforced(self) -> np.ndarray:
        """The active rows the last solve enforced (``RelationPolicies.enforced``)."""
        return self.policies.enforced

    # ------------------------------------------------------------ state

    def snapshot(self) -> tuple:
        """The converged state, to come back to when a trial step fails."""
        return (self.q.copy(), self.lam.copy(), self.x_full.copy(), self.states,
                self.active.active.copy(), self.extras, self.t_prev, self.f_pure)

    def restore(self, snap: tuple) -> None:
        (self.q, self.lam, self.x_full, self.states, active, self.extras, self.t_prev,
         self.f_pure) = (snap[0].copy(), snap[1].copy(), snap[2].copy(), *snap[3:])
        self.active.active = active.copy()

    def save_state(self) -> dict:
        """The converged state a restart continues from (``parsolve.io.restart``): the
        snapshot, the active set's senses, the row each maximum group's operator row holds
        (its pattern: a released group keeps its last row's), and the hooks' effects' own
        state."""
        return {"snapshot": self.snapshot(), "f_ext": self.f_ext,
                "carried": self.rset.carried, **self.policies.save_state()}

    def load_state(self, state: dict) -> None:
        """The state ``save_state`` gave, in a new problem of the same model and ranks."""
        self.restore(state["snapshot"])
        if state.get("carried") is not None:   # (a state saved before it was kept: none)
            self.system.carry(state["carried"])
        if state["f_ext"] is not None:
            self.f_ext = state["f_ext"]
        self.policies.load_state(state)
        if self.policies.hooks:
            self._sync()

    def size(self) -> float:
        """max |q| over the ranks (the scale of an increment)."""
        return self.ctx.max_abs(self.q)

    def multipliers(self, t: float, f_int: np.ndarray) -> dict[str, np.ndarray]:
        """λ of every relation by name (eliminated ones recovered from their rows)."""
        x = self.system.with_primal(self.x_full, self.q)
        return self.system.unpack(x, t, f_int=f_int, f_ext=self.f_ext)[1]

    # ------------------------------------------------------------ a step

    def external(self, t: float) -> np.ndarray:
        """The known loads the step balances: F(t), or θ F(t) + (1 - θ) F(t_n) in a transient
        step."""
        theta = None if self.time is None else self.time.theta
        return self.ctx.composition.known_loads(t, self.t_prev, theta)

    def begin(self, t: float) -> np.ndarray:
        """Start a step to t (the hooks' effects, the active set, a transient step's rate
        terms); returns the known loads it balances."""
        # the step's instant, which every effect's evaluation and hook reads
        self.ctx.composition.begin(t, self.t_prev, None if self.time is None else self.time.theta)
        self.q_start = self._norm(self.ctx.owned_rows(self.q))   # (roundoff_force)
        pol = self.policies
        if pol.hooks:   # contact hooks timed apart: /timings/contact
            t0 = time.perf_counter()
            changed = pol.begin_hooks(self.q)
            self.linear.add_time("contact", time.perf_counter() - t0)
            if pol.restructures:   # (every step: one dataset)
                self.linear.add_time("pattern", 0.0)
            # (a restructure always changes values too; said for effects that would not)
            if changed or pol.restructured:
                self._sync()
        pol.start_step()
        if self.time is not None:
            if not t > self.t_prev:
                raise SolverError(f"time step to t = {t:.6g} is not positive")
            self.system.rate = Rate(t - self.t_prev, self.time.theta, self.q.copy(), self.f_pure)
        return self.external(t)

    def form(self) -> Linearization:
        """f_int (with the rate terms), the tangent, trial states and extras at the current q."""
        total, pure, blocks, trial, extras = self.ctx.composition.evaluate(
            self.q, self.states, self.spec.matrix == "secant", self.system.rate)
        return Linearization(total, pure, blocks, trial, extras)

    def first_tangent(self, t: float, lin: Linearization) -> int:
        """The policies of a step's first tangent (orientation, the maximum-control
        predictor): they may replace ``lin.kmat``; returns their solves, counted as
        iterations."""
        lin.kmat, solves = self.policies.first_tangent(
            t, lin.kmat, self.q, self.states, self.t_prev, self.spec.matrix == "secant")
        return solves

    def norms(self, f_known: np.ndarray, f_int: np.ndarray) -> tuple[float, float]:
        """(‖r‖, the forces in play) of the force residual r = F + D λ - f_int on the rows not
        eliminated; the forces in play count the reactions of eliminated DOFs."""
        ctx = self.ctx
        free = self.system.free_rows()
        f_ext = ctx.owned_rows(f_known) + self.rset.reactions(self.lam)
        inner = ctx.owned_rows(f_int)
        ref = max(self._norm(f_ext[free]), self._norm(inner), 1e-300)
        return self._norm((f_ext - inner)[free]), ref

    def roundoff_force(self) -> float:
        """The force residual that is zero to round-off: what evaluating K q can resolve,
        ROUNDOFF · k · max(|q|, |q_start|) (k: the mean stiffness diagonal; q_start: the state
        the step started from, whose round-off the step's first correction carries). It is the
        absolute floor under the relative criterion, which has no scale when every force
        vanishes (a rigid motion, a body at rest on a support, a step unloaded to q = 0): there
        the relative residual is round-off over round-off and never falls (with |q| alone, a
        step whose answer is q = 0 shrinks q by the linear solve's accuracy per iteration and
        stops only when q underflows to 0: 12-13 iterations, on right-hand sides down to
        1e-162). Far below any physical force (a damaged, softened state still carries forces
        orders above it), so it does not accept a state off equilibrium."""
        q = self._norm(self.ctx.owned_rows(self.q))
        return ROUNDOFF * getattr(self.system, "kscale", 0.0) * max(q, self.q_start)

    def _norm(self, v: np.ndarray) -> float:
        return float(np.sqrt(self.comm.allreduce(float(v @ v))))

    def jacobian(self, kmat):
        """The saddle operator with the tangent and the rows the policies enforce now."""
        self.system.set_active(self.policies.enforceable(self.active.active))
        return self.system.assemble(kmat)

    def operator(self, kmat):
        """The saddle operator with the tangent, the enforced rows as they are."""
        return self.system.assemble(kmat)

    def preconditioner(self, mat, gamma: float):
        """The iterative preset's augmented Lagrangian form of the operator as last assembled
        (``SaddleSystem.preconditioner``: its operator T M, preconditioning matrix and
        right-hand side transform; γ/k Aᵀ A of its enforced hard rows added to K)."""
        return self.system.preconditioner(mat, gamma)

    def rhs(self, t: float, f_int: np.ndarray, f_known: np.ndarray) -> np.ndarray:
        """Newton's right-hand side (unknowns Δq and the total λ): F - f_int, b(t) - A q."""
        return self.system.rhs(t, f_int=f_int, q=self.q, f_ext=f_known)[0]

    def rhs_of(self, f: np.ndarray, t: float | None = None) -> np.ndarray:
        """The right-hand side of a force vector with the relations' and eliminated DOFs'
        gaps at t of the current state (arc-length's bordering), or homogeneous (no t)."""
        system, rset = self.system, self.rset
        target, elim = np.zeros(rset.n_owned), np.zeros(system.elim_dofs.size)
        if t is not None:
            if rset.nrows:
                target = rset.gap(t, self.q) * rset.row_scale[:rset.n_owned]
            if system.n_eliminated:
                elim = system.elim_values(t) - system.eliminated_values(self.q)
        return system.rhs_from(f, target, elim)[0]

    def solve(self, mat, rhs: np.ndarray, export: bool = True) -> HeldValues:
        """The saddle vector (this rank's DOFs and multipliers) of one right-hand side;
        ``export``: a system --export-system may write (the first one only)."""
        if mat is not self._mat:   # new after a restructure: the solver sets itself up again
            self.linear.set_operator(mat)
            self._mat = mat
        if self._vecs is None:
            self._vecs = mat.createVecs()
        x, b = self._vecs
        b.array[:] = rhs
        if export and self.export_dir is not None:
            export_system(self.comm, self.export_dir, mat, b, self.system)
            self.export_dir = None
        self.linear.solve(b, x)
        return self.system.gather(x.array)

    def respond(self, kmat, rows: np.ndarray, f: np.ndarray) -> np.ndarray:
        """δq = K⁻¹ f with the tangent and these rows enforced at zero (the policies' solves)."""
        self.system.set_active(rows)
        mat = self.system.assemble(kmat)
        return self.solve(mat, self.rhs_of(f), export=False).q

    def unscaled(self, x: HeldValues) -> np.ndarray:
        """Unscaled λ of this rank's owned multiplier rows of a saddle vector."""
        return self.system.multipliers(x)

    def update(self, t: float, x: HeldValues) -> tuple[float, bool]:
        """Take a Newton solve's (Δq, λ); then the active set and the effects' hooks. Returns
        (max |Δq|, whether a relation row or value changed)."""
        dq_norm = self.ctx.max_abs(x.q)
        self.q = self.q + x.q
        self.lam = self.unscaled(x)
        self.x_full = x
        pol = self.policies
        # each rank reads the multipliers it owns (the active set exchanges what they
        # decide; a hook fetches the relations it reads)
        changed = pol.update_active(t, self.q, self.lam)
        if pol.hooks:
            t0 = time.perf_counter()
            changed = pol.refresh_hooks(self.q, self.lam) or changed
            self.linear.add_time("contact", time.perf_counter() - t0)
            # always: refreshed rows' values (friction's directions, finite sliding's pairing)
            # may change at an iterate that changes no state
            self._sync()
        return dq_norm, changed

    def _sync(self) -> None:
        seconds = self.policies.sync_relations()
        if seconds is not None:
            self.linear.add_time("pattern", seconds)

    def recover(self) -> bool:
        """After a failed first solve: start the contact rows closed (True when it did)."""
        return self.policies.close_contact()

    def commit(self, lin: Linearization, f_ext: np.ndarray) -> None:
        """Keep a converged state's material states and the loads it balances."""
        self.states, self.extras = lin.trial, lin.extras
        self.f_ext = f_ext

    def accept(self, t: float, lin: Linearization, f_known: np.ndarray) -> None:
        """A converged Newton step to t: checked, committed, the next step starts here."""
        self.policies.check_left_out(t, self.q)
        self.commit(lin, f_known)
        self.policies.end_hooks()
        self.t_prev, self.f_pure = t, lin.f_pure
