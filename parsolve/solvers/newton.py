"""Newton iterations on the full saddle system, with the active set of unilateral relations.

Unknowns per iteration: the increment Δq and the total multipliers λ,

    [ K_t  -D ] [Δq]   [F + 0 - f_int(q)]
    [ A     0 ] [λ ] = [b(t) - A q      ]      (inactive rows: λ = 0)

so that a load intensity driven by a non-associated relation is an unknown like any other.
The step has converged when the force residual F + D λ - f_int is small against the forces in
play, the last increment is small, and the active set did not change.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsolve import interrupts, progress
from parsolve.contact.dependent import dependent_rows
from parsolve.effects.compose import Rate
from parsolve.errors import SolverError
from parsolve.scene import NonlinearSpec
from parsolve.solvers.active_set import GROUP_TOL, ActiveSet
from parsolve.solvers.linear import DoesNotFit, LinearSolver
from parsolve.solvers.setup import export_system
from parsolve.solvers.system import SaddleSystem


# |r| below ROUNDOFF · k · |q| is round-off: about 45 ε, where a rigid translation of a
# von Mises box measures 0.7 ε. Not larger: at a snap-back under displacement control, a
# ruptured bar whose forces are 3e-11 of the peak must not pass for converged (1e-12 did).
ROUNDOFF = 1e-14


@dataclass
class StepResult:
    iterations: int
    residual: float
    f_int: np.ndarray


def _row_dots(r, ndof: int) -> np.ndarray:
    """A_k · D_k of every row of a relation (sparse: entries matched by (row, dof) key)."""
    dofs, drows, vals = r.dual_coo()
    keys, inv = np.unique(np.asarray(drows, dtype=np.int64) * ndof + dofs, return_inverse=True)
    d = np.bincount(inv, weights=vals)
    ka = r.a_rows * ndof + r.a_dofs
    if keys.size == 0:
        return np.zeros(r.nrows)
    pos = np.minimum(np.searchsorted(keys, ka), keys.size - 1)
    hit = keys[pos] == ka
    return np.bincount(r.a_rows[hit], weights=r.a_vals[hit] * d[pos[hit]], minlength=r.nrows)


class _CellReplaced:
    """Tangent blocks with the element matrices of a few cells taken from another evaluation
    (same effects, same parts): reduced like ``BlockMatrices`` plus the few cells' difference."""

    def __init__(self, base, other, cells: np.ndarray):
        self.base, self.other, self.cells = base, other, cells

    def reduce(self, pair_slot: np.ndarray, npairs: int) -> np.ndarray:
        out = self.base.reduce(pair_slot, npairs)
        if self.cells.size == 0:
            return out
        nc = self.base.ncomp
        slots = pair_slot[:, :, self.cells].ravel()
        for (ci, cj, m0, fac), (_, _, m1, _) in zip(self.base.parts, self.other.parts):
            diff = (_cell_values(m1, self.cells) - _cell_values(m0, self.cells))
            diff = diff.reshape(len(diff), -1)
            idx = (np.asarray(ci)[:, None] * nc + np.asarray(cj)[None, :]).ravel()
            out[idx] += fac * np.stack([np.bincount(slots, weights=v, minlength=npairs + 1)[:npairs]
                                        for v in diff])
        return out


def _cell_values(m, cells: np.ndarray) -> np.ndarray:
    """Element matrices (d², nen, nen, len(cells)) of some cells, whatever the form."""
    if m.kernel is not None and not m.factored:   # blocked full values: just these cells
        return m.kernel.compute(cells, None)
    if m.values is not None:
        return m.values[..., cells]
    return np.einsum("ckm,kabc->mabc", m.tensors[m.cell_material[cells]], m.geometric[..., cells])


def _branch_reach(rate: np.ndarray, room: np.ndarray, current: int) -> np.ndarray:
    """Control load at which each row of a maximum group reaches its value, along the branch
    the enforced row ``current`` follows (rate: d(s A q)/dλ with the enforced row loading;
    room: s (b - A q)). Rising branch (the enforced row's rate > 0, before its peak): rows
    with r > 0 reach it at room / r. Past the enforced row's peak (rate < 0), its value grows
    only as the load falls, while the other rows unload: the rows with r < 0 reach it at
    room / -r. Rows that never reach it on that branch: +inf."""
    tol = 1e-9 * max(float(np.abs(rate).max()), 1e-300)
    side = -1.0 if rate[current] < -tol else 1.0
    r = side * rate
    return np.where(r > tol, room / np.where(r > tol, r, 1.0), np.inf)


class NewtonSolver:
    """Carries the converged state (q, λ, material history) from step to step."""

    def __init__(self, comm: MPI.Comm, system: SaddleSystem, linear: LinearSolver,
                 spec: NonlinearSpec):
        self.comm, self.system, self.linear, self.spec = comm, system, linear, spec
        # what the steps see of the system (values, reductions, relations, effects): the
        # system itself only assembles, builds right-hand sides and unpacks solutions
        self.ctx = ctx = system.context
        self.rset = ctx.relations   # the stacked relations: views, values, refresh
        self.cells = ctx.cells
        self.states = ctx.composition.init_states()
        self.active = ActiveSet(ctx.multiplied, spec.max_active_set_changes)
        self.ndof = ctx.ndof
        # bound of the relations' DOF numbers (input numbering: the whole mesh's)
        self.ndof_keys = ctx.mesh.num_global_points * ctx.ncomp
        self.q = ctx.initial_q()
        self.lam = np.zeros(ctx.dofs.nl)
        self.x_full = ctx.dofs.zeros()
        self.extras = [None] * len(ctx.effects)     # e.g. stresses at the quadrature points
        self.time = ctx.scene.time                  # transient: θ-scheme from t_prev to t
        self.t_prev = 0.0
        self.f_pure = np.zeros(self.ndof)           # f_int at the last converged state
        if self.time is not None and self.time.theta != 1.0:  # θ-scheme: f_int(q_0)
            self.f_pure = self.ctx.composition.evaluate(self.q, self.states, False)[1]
        self.residual_history: list[float] = []
        self._mat = None
        self._oriented = False
        # effects whose relations change between iterations (contact with friction): their
        # begin_step / refresh / end_step hooks, and where each relation's D and A entries
        # sit in the relation set (values are copied there in place; a new sparsity, finite
        # sliding's spans made again, has the system build its operator again)
        self.hooks = [e for e in ctx.effects if e.refreshes]
        self._rows = self._dependence_rows()
        self.left_out = np.zeros(self.active.sign.size, dtype=bool)
        self.export_dir: str | None = None   # --export-system: the first system assembled

    def _dependence_rows(self) -> tuple | None:
        """The multiplied rows as COO (row numbers of the active set) with the contact rows
        marked, and the eliminated DOFs: what ``_enforceable`` needs (None without contact)."""
        system = self.system
        mult = self.ctx.multiplied
        if not any(r.meta.get("type") == "contact" for r in mult):
            return None
        rset = self.rset
        keep = [k for k, r in enumerate(mult) if not r.collapsed]
        rows = np.concatenate([mult[k].a_rows + rset.rows_of(k).start for k in keep])
        dofs = np.concatenate([mult[k].a_dofs for k in keep])
        candidate = np.zeros(rset.nrelrows, dtype=bool)
        for k, r in enumerate(mult):
            candidate[rset.rows_of(k)] = r.meta.get("type") == "contact"
        fixed = np.concatenate([r.a_dofs for r in self.ctx.eliminated] + [np.zeros(0, np.int64)])
        return rows, dofs, [mult[k] for k in keep], candidate, np.unique(fixed)

    def _enforceable(self, active: np.ndarray) -> np.ndarray:
        """The active rows less the contact rows that depend on the others (a held, tied or
        shared contact node: ``parsolve.contact.dependent``), which the solve leaves out (their
        multipliers zero): the same displacements, and no null pivot."""
        if self._rows is None:
            return active
        rows, dofs, rels, candidate, fixed = self._rows
        vals = np.concatenate([r.a_vals for r in rels])   # current (friction turns them)
        # compliant rows constrain nothing (``Relation.compliance``): out of the analysis
        hard = active & ~(self.rset.compliance[self.rset.mult_of_row] > 0.0)
        self.left_out = dependent_rows(rows, dofs, vals, active.size, hard, candidate, fixed,
                                       self.ctx.ncomp)
        return active & ~self.left_out

    @property
    def enforced(self) -> np.ndarray:
        """The active rows the last solve enforced: less the contact rows it left out (a held
        or tied node's: multiplier zero, the rows it depends on carry its reaction), which a
        step's outputs report as carrying nothing (state open), not as stuck."""
        return self.active.active & ~self.left_out

    def _empty_rows(self) -> np.ndarray:
        """Per relation row of the active set: no A entry (a finite-sliding slave that no facet
        faces yet): never enforced, whatever its value."""
        rset = self.rset
        empty = np.ones(rset.nrelrows, dtype=bool)
        for k, r in enumerate(self.ctx.multiplied):
            empty[rset.rows_of(k)] = False if r.collapsed else r.empty_rows()
        return empty

    def _close_contact(self) -> bool:
        """Enforce every contact row that is not (True when there was one): the first solve of
        a step failed with rows open, which is a body held only by contact (nothing else, or
        soft supports, in the contact direction: a singular or ill-conditioned operator).
        Started in contact, the body is held; the active set then opens the rows that pull
        (a frictional node closing this way sticks or slides as any closing node). No
        tolerance to guess (``closed``) and the same answer: the set is decided as always.
        Every rank decides from the same active set."""
        if self._rows is None:
            return False
        closing = self._rows[3] & ~self.active.active & ~self._empty_rows()
        if not closing.any():
            return False
        self.active.active[closing] = True
        self.active.held |= closing
        self.active.seen.add(self.active.active.tobytes())
        return True

    def _check_left_out(self, t: float) -> None:
        """A left-out row is decided by the rows it depends on: fail when they violate it (a
        node held inside the obstacle), rather than return a penetrating answer."""
        if not self.left_out.any():
            return
        system = self.system
        gap = self.rset.primal_values(self.q) - self.rset.targets(t)
        # against the rows' values and the displacements (a row at rest on the plane has A q = 0)
        scale = max(float(np.abs(self.rset.primal_values(self.q)).max()), self.ctx.max_abs(self.q),
                    1e-300)
        bad = self.left_out & (self.active.sign * gap > 1e-9 * scale)
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            k, local = self.rset.locate(row)
            rel = self.ctx.multiplied[k]
            node = int(rel.a_dofs[rel.a_rows == local][0]) // self.ctx.ncomp
            raise SolverError(f"contact row {local} of {rel.name!r} (node {node}) depends on "
                              "other relations (a held or tied node) that violate it by "
                              f"{abs(float(gap[row])):.3g}: they push it into the obstacle")

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
        snapshot, the active set's senses, and the hooks' effects' own state."""
        return {"snapshot": self.snapshot(), "f_ext": getattr(self, "f_ext", None),
                "orient": self.active.orient.copy(), "oriented": self._oriented,
                "hooks": [e.restart_state() for e in self.hooks]}

    def load_state(self, state: dict) -> None:
        """The state ``save_state`` gave, in a new solver of the same model and ranks."""
        self.restore(state["snapshot"])
        if state["f_ext"] is not None:
            self.f_ext = state["f_ext"]
        self.active.orient[:] = state["orient"]
        self._oriented = state["oriented"]
        for e, saved in zip(self.hooks, state["hooks"]):
            e.load_restart_state(saved)
        if self.hooks:
            self._sync_relations()

    def _evaluate(self, q: np.ndarray):
        """(f_int with the rate terms, tangent, trial states, extras); keeps f_int alone."""
        total, pure, blocks, trial, extras = self.ctx.composition.evaluate(
            q, self.states, self.spec.matrix == "secant", self.system.rate)
        self._f_trial = pure
        return total, blocks, trial, extras

    def external(self, t: float) -> np.ndarray:
        """The known loads the step balances: F(t), or θ F(t) + (1 - θ) F(t_n) in a transient
        step."""
        theta = None if self.time is None else self.time.theta
        return self.ctx.composition.known_loads(t, self.t_prev, theta)

    def _start_rate(self, t: float) -> None:
        if self.time is not None:
            if not t > self.t_prev:
                raise SolverError(f"time step to t = {t:.6g} is not positive")
            self.system.rate = Rate(t - self.t_prev, self.time.theta, self.q.copy(), self.f_pure)

    def _roundoff_force(self, q_start: float) -> float:
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
        return ROUNDOFF * getattr(self.system, "kscale", 0.0) * max(q, q_start)

    def _norm(self, v: np.ndarray) -> float:
        return float(np.sqrt(self.comm.allreduce(float(v @ v))))

    def step(self, t: float) -> StepResult:
        system, spec = self.system, self.spec
        free = system.free_rows()
        if self.hooks:   # contact hooks timed apart: /timings/contact
            t0 = time.perf_counter()
            changed = self._begin_hooks()
            self.linear.add_time("contact", time.perf_counter() - t0)
            if any(e.restructures for e in self.hooks):   # (every step: one dataset)
                self.linear.add_time("pattern", 0.0)
            # (a restructure always changes values too; said for effects that would not)
            if changed or any(e.restructured for e in self.hooks):
                self._sync_relations()
        self.active.start_step()
        self._start_rate(t)
        f_known = self.external(t)
        changed, dq_norm, predictions = True, np.inf, 0
        q_start = self._norm(self.ctx.owned_rows(self.q))
        self.residual_history = []
        for it in range(spec.max_iterations + 1):
            interrupts.check(self.comm)   # every rank at the same iteration (see interrupts)
            f_int, kmat, trial, extras = self._evaluate(self.q)
            if it == 0 and not self._oriented:
                self._orient(kmat)
                self._oriented = True
            if it == 0 and self.active.groups:
                if spec.matrix != "secant":
                    kmat = self._loading_tangent(kmat)
                self._predict_maximum_rows(t, kmat)
                predictions = 1
            f_ext = self.ctx.owned_rows(f_known) + self.rset.reactions(self.lam)
            r = (f_ext - self.ctx.owned_rows(f_int))[free]
            # the forces in play, reactions of eliminated DOFs included; when there are none
            # (or only round-off), the residual is measured against the round-off floor
            ref = max(self._norm(f_ext[free]), self._norm(self.ctx.owned_rows(f_int)), 1e-300)
            r_norm = self._norm(r)
            residual = r_norm / max(ref, self._roundoff_force(q_start) / spec.rtol)
            self.residual_history.append(residual)
            if not np.isfinite(residual):   # (the same on every rank): a failed iteration
                raise SolverError(f"non-finite residual at t = {t:.6g}, iteration {it} (a "
                                  "diverged solve, or a material that cannot be evaluated "
                                  "there)")
            progress.detail(f"newton {it + 1}: residual {residual:.3e}")
            small_step = dq_norm <= spec.stol * max(self.ctx.max_abs(self.q), 1e-300)
            balanced = residual <= spec.rtol or small_step and r_norm < 1e-6 * ref
            if it > 0 and not changed and balanced:
                self._check_left_out(t)
                self.states, self.extras = trial, extras
                for e in self.hooks:
                    e.end_step()
                self.t_prev, self.f_pure = t, self._f_trial
                self.f_ext = f_known
                return StepResult(it + predictions, residual, f_int)
            if it == spec.max_iterations:
                break
            for attempt in (0, 1):
                system.set_active(self._enforceable(self.active.active))
                mat = system.assemble(kmat)
                self._use(mat)
                x, rhs = self._vectors(mat)
                rhs.array[:] = system.rhs(t, f_int=f_int, q=self.q, f_ext=f_known)[0]
                self._export(mat, rhs)
                try:
                    self.linear.solve(rhs, x)
                    break
                except SolverError as exc:
                    if it == 0 and attempt == 0 and self._close_contact():
                        continue   # a body floating until contact: start it in contact
                    if it == 0 or isinstance(exc, DoesNotFit):
                        raise
                    # singular at a later iterate only: the iterates diverged first (a
                    # softening material driven past full damage), which the cut step must know
                    history = ", ".join(f"{r:.1e}" for r in self.residual_history[-4:])
                    raise SolverError(f"Newton diverged at t = {t:.6g}, iteration {it} (relative "
                                      f"residuals ..., {history}): {exc}") from None
            x_full = system.gather(x.array)
            dq = x_full.q
            dq_norm = self.ctx.max_abs(dq)
            self.q = self.q + dq
            self.lam = system.multipliers(x_full)
            self.x_full = x_full
            changed = self._update_active(t) if self.active.unilateral else False
            if self.hooks:
                t0 = time.perf_counter()
                changed = self._refresh_hooks() or changed
                self.linear.add_time("contact", time.perf_counter() - t0)
                # always: rows of the Newton matrix alone (compliant) change at every iterate
                self._sync_relations()
        history = ", ".join(f"{r:.1e}" for r in self.residual_history[-6:])
        trend = "diverged" if len(self.residual_history) > 2 and \
            self.residual_history[-1] > self.residual_history[1] else "did not converge"
        raise SolverError(f"Newton {trend} at t = {t:.6g} after {spec.max_iterations} iterations "
                          f"(relative residuals ..., {history})")

    # ------------------------------------------------------------ switched relations

    def _views(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Per multiplied relation, its rows of x (relation rows; writable views)."""
        return self.rset.views(x)

    def _begin_hooks(self) -> bool:
        changed = False
        for e in self.hooks:
            changed = e.begin_step(self.q, self._views(self.active.active)) or changed
        return changed

    def _refresh_hooks(self) -> bool:
        """The effects' updates between iterations (e.g. friction states and slip senses);
        their relation values are then copied into the system (``_sync_relations``)."""
        lam = self._views(self.rset.row_values(self.lam) if self.lam.size else self.lam)
        active = self._views(self.active.active)
        changed = False
        for e in self.hooks:
            changed = e.refresh(self.q, lam, active) or changed
        return changed

    def _sync_relations(self) -> None:
        """Copy the current A and D values of the relations marked ``meta["refresh"]`` into
        the relation set (unscaled; the scales of the first assembly stay); when a hook
        changed their sparsity (``Effect.restructured``), the system's operator is built
        again on the new pattern (timed: /timings/pattern) and the rows of the dependence
        analysis made again. Every rank decides alike (the same relations everywhere)."""
        if not any(e.restructured for e in self.hooks):
            self.rset.refresh()
            return
        t0 = time.perf_counter()
        self.system.restructure()
        self._rows = self._dependence_rows()
        for e in self.hooks:
            e.restructured = False
        self.linear.add_time("pattern", time.perf_counter() - t0)

    def _use(self, mat) -> None:
        """The linear solver on this operator: the system's matrix, new after a restructure
        (the solver then sets itself up on its pattern again)."""
        if mat is not self._mat:
            self.linear.set_operator(mat)
            self._mat = mat

    def _unit_response(self, kmat, released: np.ndarray, f: np.ndarray) -> np.ndarray:
        """δq = K⁻¹ f with the tangent, the rows ``released`` switched off and the other
        active rows enforced at zero (homogeneous): how the structure answers a unit load."""
        system = self.system
        active = self.active.active.copy()
        active[released] = False
        system.set_active(self._enforceable(active))
        mat = system.assemble(kmat)
        self._use(mat)
        x, rhs = self._vectors(mat)
        rhs.array[:] = system.rhs_from(f, np.zeros(self.rset.nrows),
                                       np.zeros(system.n_eliminated))[0]
        self.linear.solve(rhs, x)
        return system.gather(x.array).q

    def _dual_column(self, k: int, row: int | None = None) -> np.ndarray:
        """Column of D of relation k (its first row when every row shares one vector)."""
        rel = self.ctx.multiplied[k]
        if rel.shared_dual is not None:
            return self.ctx.local_vector(*rel.shared_dual)
        dofs, rows, vals = rel.dual_coo()
        sel = rows == (0 if row is None else row)
        return self.ctx.local_vector(dofs[sel], vals[sel])

    def _orient(self, kmat) -> None:
        """o = -sign(A K⁻¹ D) of every free unilateral non-associated row, from the first
        tangent: the reaction must push the row back whichever way its dual points. A relation
        whose rows share one dual vector (a load pattern) costs one solve; rows with their own
        local duals take the sign of -A_k·D_k."""
        system = self.system
        for k, r in enumerate(self.ctx.multiplied):
            if r.sense == "=" or r.associated or r.maximum or r.groups is not None:
                continue  # a group's enforced row is chosen by value, whatever its sign
            span = self.rset.rows_of(k)
            rows = np.arange(span.start, span.stop)
            if r.meta.get("dual"):
                rate = self.ctx.relation_primal(r, self._unit_response(kmat, rows,
                                                                     self._dual_column(k)))
            else:
                rate = _row_dots(r, self.ndof_keys)
            # a row with no entry yet (a contact slave that no facet faces) is never enforced
            # until it has some: it takes the sense of the relation's other rows, for good (the
            # sense is decided once; a contact's normal rows all have the sense +1)
            empty = r.empty_rows()
            if np.any(~empty & (np.abs(rate) <= 1e-12 * max(float(np.abs(rate).max()), 1e-300))):
                raise SolverError(f"relation {r.name!r}: its dual does not move its primal value "
                                  "(A K⁻¹ D = 0), so the sense of its reaction is undefined")
            sense = -np.sign(rate)
            known = sense[~empty]
            sense[empty] = known[0] if known.size and np.all(known == known[0]) else 1.0
            self.active.orient[rows] = sense

    def _enforced_rows(self) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
        """Per maximum group, its enforced row: (row, its relation row b index, A's DOFs and
        coefficients on that row)."""
        system = self.system
        out = []
        for g in self.active.groups:
            row = int(g[self.active.active[g]][0])
            k, local = self.rset.locate(row)
            rel = self.ctx.multiplied[k]
            sel = rel.a_rows == local
            out.append((row, k, np.asarray(rel.a_dofs)[sel], np.asarray(rel.a_vals)[sel]))
        return out

    def _enforced_cells(self) -> np.ndarray:
        """Positions (in this rank's cells) of the cells measured by the enforced rows of the
        maximum groups: the cells all of whose nodes carry an entry of such a row."""
        ctx = self.ctx
        marked = np.zeros(ctx.mesh.num_points, dtype=bool)
        for _, _, dofs, _ in self._enforced_rows():   # (input DOFs: this rank's nodes of them)
            marked |= ctx.local_vector(dofs, np.ones(dofs.size)).reshape(-1, ctx.ncomp).any(axis=1)
        return np.flatnonzero(marked[ctx.mesh.cells[self.cells]].all(axis=1))

    def _loading_tangent(self, kmat):
        """The first tangent of a step for a maximum control: the enforced rows' cells on
        their loading branch, every other cell as it is at the converged state (unloading).

        At a converged state no material point is loading (its history equals its current
        value), so the first tangent is the unloading one everywhere and the control load can
        only grow: past the peak, where the enforced cell softens and its neighbours must
        unload, the first iterate loaded every cell of the band, and the next tangent, softening
        in all of them, was nearly singular (the plate refined 8× ran into null pivots). The
        enforced cell's loading tangent is taken at q + δ, δ along its row with A δ = 1e-10 of
        the row's value; all other cells keep theirs. Not for a secant matrix: it does not tell
        loading from unloading (and a perturbed cell would break a symmetric tie)."""
        system = self.system
        delta = np.zeros(self.ndof)
        for row, k, dofs, a in self._enforced_rows():
            rel, local = self.ctx.multiplied[k], self.rset.locate(row)[1]
            b = rel.rhs(self.t_prev)[local]
            value = self.ctx.relation_primal(rel, self.q)[local]   # A q of the row (collective)
            size = 1e-10 * max(abs(float(value)), abs(float(b)), 1e-300)
            delta += self.ctx.local_vector(dofs, self.active.sign[row] * a * size / max(float(a @ a), 1e-300))
        loading = self.ctx.composition.evaluate(self.q + delta, self.states, False, system.rate)[2]
        return _CellReplaced(kmat, loading, self._enforced_cells())

    def _predict_maximum_rows(self, t: float, kmat) -> None:
        """For each maximum relation, enforce the row that reaches its value first under the
        relation's own control load: one solve with the tangent (``_loading_tangent``) and a
        unit control load, rates r = A δq, then the smallest (b - A q) / |r| along the branch
        the enforced row follows (``_branch_reach``)."""
        system = self.system
        groups = np.concatenate(self.active.groups)
        f = np.zeros(self.ndof)
        for g in self.active.groups:  # the control load of each group at unit intensity
            f += self._dual_column(self.rset.locate(int(g[0]))[0])
        dq = self._unit_response(kmat, groups, f)
        rates = self.rset.primal_values(dq)
        gap = self.rset.targets(t) - self.rset.primal_values(self.q)
        for g in self.active.groups:
            s = self.active.sign[g]
            current = g[self.active.active[g]][0]
            reach = _branch_reach(s * rates[g], s * gap[g], int(current - g[0]))
            if np.isfinite(reach).any():
                tol = GROUP_TOL * float(np.abs(reach[np.isfinite(reach)]).min())
                best = self.active.pick(g, reach, current, False, tol)
                self.active.active[g] = False
                self.active.active[best] = True
        self.active.start_step()

    def _export(self, mat, rhs) -> None:
        """--export-system DIR: the first system solved, once (collective)."""
        if self.export_dir is not None:
            export_system(self.comm, self.export_dir, mat, rhs, self.system)
            self.export_dir = None

    def _vectors(self, mat):
        if not hasattr(self, "_xr"):
            self._xr = mat.createVecs()
        return self._xr

    def _update_active(self, t: float) -> bool:
        system = self.system
        gap = self.rset.primal_values(self.q) - self.rset.targets(t)
        scale_gap = max(float(np.abs(gap).max()), float(np.abs(self.rset.primal_values(self.q)).max()),
                        1e-300)
        scale_lam = max(float(np.abs(self.lam).max()), 1e-300)
        lam = self.rset.row_values(self.lam) if self.lam.size else self.lam
        return self.active.update(gap, lam, 1e-9 * scale_gap, 1e-9 * scale_lam, scale_gap)

    def multipliers(self, t: float, f_int: np.ndarray) -> dict[str, np.ndarray]:
        """λ of every relation by name (eliminated ones recovered from their rows)."""
        x = self.system.with_primal(self.x_full, self.q)
        return self.system.unpack(x, t, f_int=f_int, f_ext=getattr(self, "f_ext", None))[1]
