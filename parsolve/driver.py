"""Runs a model: the effects it lists, nothing more. A linear scene assembles once,
factorizes once and back-substitutes at every step (a transient linear scene refactorizes only
when the time step changes); unilateral relations, switched relations or a nonlinear effect
call for Newton with the active set; arc-length is a baseline for control."""

from __future__ import annotations

import time

import numpy as np
from mpi4py import MPI

from parsolve.diagnostics import no_equilibrium, unsupported
from parsolve.effects.base import Effect
from parsolve.effects.compose import Rate
from parsolve import interrupts
from parsolve.progress import timed
from parsolve.errors import InputError, Interrupted, SolverError
from parsolve.io.hdf5 import output_mode, result_writer
from parsolve.io.mesh_rows import output_mesh
from parsolve.io.restart import Checkpoint, Restart
from parsolve.model import Model
from parsolve.outputs import Balance, contact_line, contact_totals, progress, resultant_labels, \
    resultant_line, step_outputs
from parsolve.solvers.arc_length import run_arc_length
from parsolve.solvers.diagnose import GoingBack, NamedFailure, name_failure, \
    name_linear_failure
from parsolve.solvers.finite import check_finite
from parsolve.solvers.linear import DoesNotFit
from parsolve.solvers.newton import NewtonSolver
from parsolve.solvers.problem import SaddleProblem
from parsolve.solvers.setup import export_system, make_solver
from parsolve.solvers.stability import check_path, check_stable, checked, \
    control_path_failure, modes_ahead, path_failure
from parsolve.solvers.system import SaddleSystem
from parsolve.version import petsc_version


def needs_newton(model: Model) -> bool:
    """Only a nonlinear effect or a unilateral relation calls for iterations."""
    return model.nonlinear or any(r.sense != "=" for r in model.relations)


def run(comm: MPI.Comm, model: Model, out: str, cli_options: dict[str, str],
        export_dir: str | None = None, log=print, output: str | None = None,
        watch=None, restart: Restart | None = None) -> str:
    """Solve every step and write the result file; returns the final status. ``output``: the
    output mode ("swmr", "parallel", "auto"; default: the scene's, else "swmr"); ``watch``:
    wraps the writer (``parsolve.api``'s per-step callbacks); ``restart``: the finished run to
    continue (``parsolve.io.restart``: its steps are copied, then the run goes on from its
    state). Every finished step's state is saved for a later restart."""
    scene = model.scene
    system = SaddleSystem(comm, model)
    relations_meta = {r.name: (r.total, r.sense != "=") for r in model.relations}
    unknowns = {"unknowns": " ".join(f.output for f in model.fields),
                "dofs": model.mesh.num_global_points * model.ncomp,
                "resultant_components": " ".join(resultant_labels(model.fields, model.mesh.dim))}
    if restart is not None:
        unknowns.update(restart_of=str(restart.path), restart_steps=restart.steps)
    mode = output_mode(output or scene.output_mode, comm, unknowns["dofs"])
    # the file's mesh and rows from every rank's owned part
    written, owners = timed("result file", output_mesh, comm, model.mesh, system.part)
    writer = result_writer(mode, comm, out, written, scene.text, petsc_version(), relations_meta,
                           attrs=unknowns, owners=owners)
    status = "complete"
    if scene.solver.chosen and comm.rank == 0:
        log(f"solver: {scene.solver.preset} preset ({scene.solver.chosen})")
    try:
        checkpoint = _start(comm, model, system, out, writer, restart)
        writer = watch(writer) if watch is not None else writer
        if scene.nonlinear.method == "arc_length":
            run_arc_length(comm, system, cli_options, writer, log, export_dir)
        elif needs_newton(model):
            _run_newton(comm, system, cli_options, writer, log, checkpoint, restart, export_dir)
        else:
            _run_linear(comm, system, cli_options, writer, export_dir, log, checkpoint, restart)
    except SolverError as exc:
        hints = _failure_hints(model)
        if "singular" in str(exc) or "inaccurate" in str(exc):
            hints += unsupported(model)
        if hints and isinstance(exc, StepFailure):   # the effects' cause before the generic way out
            exc = SolverError(f"{exc.head}; likely cause: {'; '.join(hints)}; otherwise, the way "
                              f"out: {exc.way_out}")
        elif hints and not isinstance(exc, NamedFailure):   # (its cause named already)
            exc = SolverError(f"{exc}; likely cause: {'; '.join(hints)}")
        status = f"failed: {exc}"
        raise exc from None
    except Interrupted as exc:
        status = str(exc)  # "interrupted: SIGINT"
        raise
    except BaseException as exc:  # disk full, a bug: never "complete"
        status = f"failed: {type(exc).__name__}: {exc}"
        raise
    finally:
        writer.close(status)
    return status


def check_restart(model: Model, restart: Restart) -> None:
    """A restart this model can take (before any output is touched): InputError otherwise."""
    if model.scene.nonlinear.method == "arc_length":
        raise InputError("an arc-length run cannot be restarted", restart.path, "--restart")
    unsaved = [type(e).__name__ for e in model.effects if e.refreshes
               and type(e).restart_state is Effect.restart_state]
    if unsaved:
        raise InputError(f"restart does not keep the state of {', '.join(unsaved)}",
                         restart.path, "--restart")


def _start(comm, model, system, out, writer, restart: Restart | None) -> Checkpoint:
    """The earlier steps of a restart copied into the new result; the checkpoint that keeps
    every finished step's state from now on."""
    if restart is not None:
        mesh = model.mesh
        cells = mesh.global_cells[system.part.owned_cells(comm.rank, mesh.cells)]
        restart.copy_steps(writer, mesh.global_nodes[:mesh.n_owned], cells)
    return Checkpoint(comm, out, restart.steps if restart else 0)


def _failure_hints(model) -> list[str]:
    """The effects' sentences on a failed step (the same on every rank); one that cannot
    say must not hide the failure itself."""
    hints = []
    for e in model.effects:
        try:
            hints += e.failure_hints()
        except Exception:   # (a diagnostic's own error: the solver's failure is the news)
            continue
    return hints


def _run_linear(comm, system: SaddleSystem, cli_options, writer, export_dir, log,
                checkpoint: Checkpoint, restart: Restart | None = None) -> None:
    """Assemble and factorize once (again when a transient step size changes); one
    back-substitution per step."""
    ctx = system.context
    scene = ctx.scene
    solver = make_solver(comm, system, cli_options)
    mat, vecs = None, None
    q_prev, t_prev = ctx.initial_q(), 0.0
    balance = Balance(comm, ctx, q_prev) if ctx.transient else None
    first = 0
    if restart is not None:
        q_prev, t_prev, first = restart.state["q"], restart.state["t"], _first_step(scene, restart)
        if balance is not None:
            balance.__dict__.update(restart.state["balance"])
    for step, t in enumerate(scene.times):
        if step < first:
            continue
        t1 = time.perf_counter()
        assembly = 0.0
        theta = scene.time.theta if ctx.transient else None
        f_known = ctx.composition.known_loads(t, t_prev, theta)  # (θ-weighted)
        f_rhs = f_known
        if ctx.transient:
            dt = t - t_prev
            if system.rate is None or not np.isclose(dt, system.rate.dt, rtol=1e-12, atol=0):
                system.rate, mat = Rate(dt, theta, q_prev, np.zeros(0)), None
            f_rhs = ctx.composition.linear_step_loads(f_known, q_prev, dt, theta)
        try:
            if mat is None:
                t0 = time.perf_counter()
                mat = timed("assembly", system.assemble)
                solver.set_operator(mat)
                vecs = vecs or mat.createVecs()
                assembly = time.perf_counter() - t0
            x, rhs = vecs
            rhs.array[:] = system.rhs_from(f_rhs, ctx.relations.rhs(t), system.elim_values(t))[0]
            if export_dir is not None and step == 0:
                export_system(comm, export_dir, mat, rhs, system)
            linear_its = solver.solve(rhs, x)
        except SolverError as exc:
            raise name_linear_failure(exc, system, solver, t) from None
        t2 = time.perf_counter()
        q, multipliers = system.unpack(system.gather(x.array), t, f_ext=f_rhs)
        fields, cell_fields, rel_out = step_outputs(comm, ctx, q, multipliers)
        extra = balance.step(q, t - t_prev, f_known, multipliers) if balance else {}
        check_finite(comm, step + 1, t, q, multipliers, solver.residual, fields, cell_fields,
                     rel_out, extra)
        timings = {"assembly": assembly, **solver.take_timings()}
        timings["output"] = time.perf_counter() - t2
        timings["total"] = time.perf_counter() - t1
        writer.write_step(t, 1, solver.residual, fields, cell_fields, rel_out, timings, extra=extra)
        interrupts.check(comm)
        progress(log, comm, step + 1, len(scene.times), t, 1, solver.residual, timings["total"],
                 f"  (linear its {linear_its})" + reported(ctx, rel_out, fields))
        _pass_notes(comm, solver, writer, log)
        q_prev, t_prev = q, t
        checkpoint.save({"q": q, "t": t, "balance": _balance_state(balance)})


def _first_step(scene, restart: Restart) -> int:
    """The first of the scene's steps after the restart's last time."""
    times = np.asarray(scene.times, dtype=float)
    return int(np.searchsorted(times, restart.time * (1 + 1e-12) + 1e-300, side="right"))


def _plain(obj) -> dict:
    """An object's attributes but the scene's (what a restart restores)."""
    return {k: v for k, v in vars(obj).items() if k not in ("spec", "times")}


def _load_newton(restart: Restart, problem, schedule, watch, balance) -> int:
    """The Newton run's state at the restart's last step; returns the steps saved so far.
    Fixed steps go on with the scene's first time after it (the scene may end later)."""
    state = restart.state
    problem.load_state(state["newton"])
    schedule.__dict__.update(state["schedule"])
    if not schedule.spec.automatic:
        schedule.count = _first_step(schedule, restart)
    watch.__dict__.update(state["watch"])
    if balance is not None:
        balance.__dict__.update(state["balance"])
    return state["step"]


def _balance_state(balance) -> dict | None:
    """The conservation sums so far (transient runs), without what the model builds."""
    if balance is None:
        return None
    return {k: v for k, v in vars(balance).items() if k not in ("comm", "ctx")}


def _run_newton(comm, system: SaddleSystem, cli_options, writer, log,
                checkpoint: Checkpoint, restart: Restart | None = None,
                export_dir: str | None = None) -> None:
    """Newton + active set at every step; the steps follow the scene or the automatic rule.
    A step that fails is cut in two and retried (bounded), fixed steps as automatic ones; the
    log and /steps/cuts say so."""
    ctx = system.context
    scene = ctx.scene
    t0 = time.perf_counter()
    timed("assembly", system.assemble)
    system.timings.pop("assembly")   # (counted in the set-up, which step 1 carries)
    solver = make_solver(comm, system, cli_options)
    problem = SaddleProblem(comm, system, solver, scene.nonlinear)
    problem.export_dir = export_dir
    newton = NewtonSolver(problem, scene.nonlinear)
    schedule = StepSchedule(scene)
    balance = Balance(comm, ctx, problem.q) if ctx.transient else None
    watch = BranchWatch(ctx.nonlinear)
    stability = checked(problem)   # (a secant run: solvers.stability)
    step, setup = 0, time.perf_counter() - t0
    if restart is not None:
        step = _load_newton(restart, problem, schedule, watch, balance)
    while (t := schedule.next()) is not None:
        t1 = time.perf_counter()
        snap = problem.snapshot()
        t_prev = problem.t_prev
        try:
            result = newton.step(t)
        except SolverError as exc:
            problem.restore(snap)
            if isinstance(exc, DoesNotFit) or \
                    not schedule.cut(t, no_equilibrium(system.model, problem.t_prev, t)):
                raise _final_failure(exc, problem, t, stability, schedule, step) from None
            if comm.rank == 0:
                log(f"step to t={t:.6g} failed ({exc}); retrying with half the step")
            continue
        step += 1
        seconds = time.perf_counter() - t1
        t2 = time.perf_counter()
        multipliers = problem.multipliers(t, result.f_int)
        fields, cell_fields, rel_out = step_outputs(comm, ctx, problem.q, multipliers, problem)
        extra = balance.step(problem.q, t - t_prev, problem.f_ext, multipliers) if balance else {}
        check_finite(comm, step, t, problem.q, multipliers, result.residual, fields, cell_fields,
                     rel_out, extra)
        if stability:
            check_stable(problem, snap[3], step, t, t_prev)
            check_path(problem, snap[0], snap[3], t_prev, t)
        pivots = solver.negative_pivots()  # the saddle's: one per enforced multiplier row
        if pivots is not None:
            pivots -= comm.allreduce(int(problem.active.active[problem.active.owned].sum()))
        warning = watch.check(ctx.norm(problem.q - snap[0]), pivots, t - t_prev)
        extra.update({"steps/cuts": schedule.cuts, "steps/branch_warning": int(warning is not None)})
        timings = solver.take_timings()
        timings["assembly"] = system.timings.pop("assembly", 0.0) + (setup if step == 1 else 0.0)
        timings["output"] = time.perf_counter() - t2
        timings["total"] = time.perf_counter() - t1 + (setup if step == 1 else 0.0)
        writer.write_step(t, result.iterations, result.residual, fields, cell_fields, rel_out,
                          timings, extra=extra)
        interrupts.check(comm)
        cut_note = f"  (after {schedule.cuts} cut{'s' * (schedule.cuts > 1)})" if schedule.cuts else ""
        # (the largest strain increment sizes automatic steps only; every rank takes this branch)
        schedule.done(t, _max_strain_increment(comm, ctx, problem.q - snap[0])
                      if schedule.spec.automatic else 0.0)
        checkpoint.save({"newton": problem.save_state(), "schedule": _plain(schedule),
                         "watch": _plain(watch), "balance": _balance_state(balance), "step": step})
        progress(log, comm, step, schedule.total, t, result.iterations, result.residual, seconds,
                 cut_note + reported(ctx, rel_out, fields))
        if warning and comm.rank == 0:
            log(f"warning: step {step}: {warning}")
            writer.note(f"step {step}: {warning}")
        _pass_notes(comm, solver, writer, log)


def _final_failure(exc: SolverError, problem, t: float, stability: bool, schedule,
                   step: int) -> SolverError:
    """A step's failure for good (``problem`` back at the last converged state), named: a path
    that turns back just ahead (a checked run: ``solvers.stability``), a control out of reach
    (``name_failure``), a maximum control's own path turning back (a checked run); else what
    the last attempt failed on, with the cuts tried and the way out. Collective."""
    if isinstance(exc, DoesNotFit):
        return exc
    if stability and not problem.ctx.transient and not problem.active.groups and schedule.cuts \
            and modes_ahead(problem, problem.q, problem.states, t):
        return path_failure(problem.t_prev)
    named = name_failure(exc, problem, t)
    if named is not exc or isinstance(exc, GoingBack):   # (the active set's words: named)
        return named
    named = control_path_failure(exc, problem, t) if stability and schedule.cuts else None
    if named is not None:   # (a maximum control's own limit point)
        return named
    cuts = f"after {schedule.cuts} cut{'s' * (schedule.cuts != 1)}"
    if schedule.hopeless:
        return _hopeless(exc, problem, t, schedule, step, cuts)
    if step == 0:
        return StepFailure(
            f"no step converged: the first step failed down to t = {t:.6g} ({cuts}); the last "
            f"attempt: {exc}", "check that the supports hold the body and the loads' sizes, "
            "then take smaller first steps ([steps] count, or automatic steps) or allow more "
            "iterations ([nonlinear] max_iterations)")
    return StepFailure(
        f"step {step + 1} from t = {problem.t_prev:.6g} failed down to t = {t:.6g} ({cuts}); "
        f"the last attempt: {exc}", "smaller steps ([steps] count, or automatic steps), more "
        "iterations ([nonlinear] max_iterations), or the tangent matrix")


def _hopeless(exc: SolverError, problem, t: float, schedule, step: int,
              cuts: str) -> SolverError:
    """A step whose cuts stopped on a cause no smaller step removes (``StepSchedule.cut``):
    where, the cause, and a way out without smaller steps."""
    where = ("no step converged: the first step failed" if step == 0 else
             f"step {step + 1} from t = {problem.t_prev:.6g} failed")
    return StepFailure(
        f"{where} down to t = {t:.6g} ({cuts}, then no more: every smaller step takes the same "
        f"loads, and at the last two sizes {'; '.join(schedule.hopeless)}); the last attempt: "
        f"{exc}", "check that the supports hold the body and the loads' sizes (smaller steps "
        "cannot help: no state carries these loads)")


class StepFailure(SolverError):
    """A step failed for good on no cause the solver could name: where and on what (``head``),
    and the generic way out (the effects' likely cause, when they give one, goes before it)."""

    def __init__(self, head: str, way_out: str):
        self.head, self.way_out = head, way_out
        super().__init__(f"{head}; the way out: {way_out}")


def _pass_notes(comm, solver, writer, log) -> None:
    """What the linear solver changed on its own (LU for a non-symmetric operator, more MUMPS
    workspace): in the log and in the file's warnings."""
    for note in solver.notes:
        if comm.rank == 0:
            log(f"note: {note}")
        writer.note(note)
    solver.notes.clear()


def reported(ctx, rel_out: dict, fields: dict) -> str:
    """For the log: the resultants of the relations the scene marks ``report = true``, and
    the totals of the contacts it marks so (collective: every rank calls it)."""
    labels = resultant_labels(ctx.fields, ctx.mesh.dim)
    lines = [resultant_line(r.name, labels, rel_out[r.name]["resultant"])
             for r in ctx.scene.relations if r.report]
    lines += [contact_line(e.spec.name, contact_totals(ctx.comm, e.spec.name, fields, rel_out))
              for e in ctx.effects if getattr(getattr(e, "spec", None), "report", False)
              and f"{e.spec.name}_state" in fields]
    return "".join(f"\n    {line}" for line in lines)


class BranchWatch:
    """Warns when a softening run may have jumped to another equilibrium branch: the number of
    negative pivots of an LDLᵀ factorization changed, or the step's increment per unit of the
    load parameter is over ten times the previous step's (which branch a secant iteration lands
    on depends on round-off). Per unit of the parameter, so that the warning is the solution
    path's, not the steps': a step cut four times leaves an intermediate step of 1/16 and a
    rest of 15/16, whose plain increments differ 15× on one branch — and whether a step is cut
    can depend on the partition."""

    def __init__(self, nonlinear: bool):
        self.nonlinear = nonlinear  # a linear scene's increments may legitimately jump
        self.pivots, self.previous = None, None

    def check(self, dq, pivots: int | None, dt: float = 1.0) -> str | None:
        """``dq``: the step's increment, or its norm (the same on every rank); ``dt``: the
        step's size in the load parameter."""
        warning = None
        if pivots is not None and self.pivots is not None and pivots != self.pivots:
            warning = (f"the tangent's negative pivots went from {self.pivots} to {pivots}: "
                       "a limit point or a bifurcation was crossed")
        size = float(np.linalg.norm(dq)) if np.ndim(dq) else float(dq)
        rate = size / dt if dt > 0 else size
        if self.nonlinear and self.previous is not None and self.previous > 0 \
                and rate > 10 * self.previous:
            warning = (f"the increment is {rate / self.previous:.0f}× the previous one (per unit "
                       "of the load parameter): the run may have jumped to another equilibrium "
                       "branch (smaller steps, or the tangent matrix, tell)")
        self.pivots, self.previous = pivots, rate
        return warning


class StepSchedule:
    """The scene's steps, or automatic steps that keep the largest strain increment near a
    target (Cast3M's AUTOMATIQUE): the next step is scaled by target / achieved, within
    [1/2, 2]. A failed step is retried with half its size, up to MAX_CUTS times in a row, or
    until the same cause that no smaller step can remove held at two sizes (``cut``); with
    fixed steps the intermediate points are computed (and saved) on the way to the scene's."""

    MAX_CUTS = 6         # in a row
    MAX_STEP_CUTS = 24   # on the way to one of the scene's fixed steps

    def __init__(self, scene):
        self.spec = scene.steps
        self.times = list(scene.times)
        self.t, self.dt, self.count, self.cuts = 0.0, self.times[0], 0, 0
        self.pending: float | None = None  # a cut fixed step: the intermediate time
        self.step_cuts = 0
        self.extra = 0  # intermediate steps saved so far
        # the no-equilibrium cause of this step's last failed attempt, and the one that
        # stopped the cuts (``cut``)
        self.cause: tuple[str, ...] = ()
        self.hopeless: tuple[str, ...] = ()

    @property
    def total(self):
        """Steps to save, as known now (the scene's, plus the intermediate ones of cuts)."""
        return "?" if self.spec.automatic else len(self.times) + self.extra

    def next(self) -> float | None:
        if self.pending is not None:
            return self.pending
        if not self.spec.automatic:
            return self.times[self.count] if self.count < len(self.times) else None
        if self.t >= self.spec.end * (1 - 1e-12) or self.count >= self.spec.max_steps:
            return None
        return min(self.t + self.dt, self.spec.end)

    def done(self, t: float, max_strain_increment: float) -> None:
        self.cuts, self.cause = 0, ()
        if not self.spec.automatic:
            if self.pending is not None and t < self.times[self.count]:
                self.t, self.pending = t, None  # the scene's step is still ahead
                self.extra += 1
                return
            self.pending = None
            self.count += 1
            self.t, self.step_cuts = t, 0
            return
        self.count += 1
        self.t = t
        if max_strain_increment > 0:
            self.dt *= min(2.0, max(0.5, self.spec.strain_increment / max_strain_increment))

    def cut(self, t: float, cause: tuple[str, ...] = ()) -> bool:
        """Halve the step that failed at t; False after too many cuts, or when the attempt
        failed on a cause no smaller step can remove (``diagnostics.no_equilibrium``: the
        same equations at every smaller step, no state that carries them) that the attempt
        twice its size failed on too (then ``hopeless`` names it). One sighting is not
        enough: the cause is read at a failed iterate, which a converging attempt may pass
        through; at two sizes of the same equations it is the equations'."""
        if cause and cause == self.cause:
            self.hopeless = cause
            return False
        self.cause = cause
        if self.cuts >= self.MAX_CUTS or self.step_cuts >= self.MAX_STEP_CUTS:
            return False
        self.cuts += 1
        self.step_cuts += 1
        if self.spec.automatic:
            self.dt *= 0.5
        else:
            self.pending = self.t + 0.5 * (t - self.t)
        return True


def _max_strain_increment(comm, ctx, dq: np.ndarray) -> float:
    """The largest increment of the step over the effects (``Effect.increment_size``: the
    elasticity's largest strain increment), on every rank."""
    cells = ctx.owned_cells
    values = ctx.values(dq) if cells.size else {}
    local = max((e.increment_size(cells, values) for e in ctx.effects if cells.size),
                default=0.0)
    return comm.allreduce(float(local), op=MPI.MAX)