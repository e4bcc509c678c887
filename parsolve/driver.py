"""Runs a model: the effects it lists, nothing more. A linear scene (the only kind so far)
assembles once, factorizes once and back-substitutes at every load step."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from parsolve.errors import SolverError
from parsolve.io.hdf5 import ResultWriter
from parsolve.model import Model
from parsolve.solvers import options as opt
from parsolve.solvers.linear import LinearSolver, preset_options
from parsolve.solvers.system import SaddleSystem


def rigid_body_modes(comm: MPI.Comm, system: SaddleSystem) -> PETSc.NullSpace:
    """Near-null space of the primal block (for GAMG), on the owned nodes in new numbering."""
    part, mesh = system.part, system.model.mesh
    lo, hi = part.node_ranges[comm.rank], part.node_ranges[comm.rank + 1]
    old_of_new = np.argsort(part.new_of_old)
    coords = mesh.points[old_of_new[lo:hi]]
    vec = PETSc.Vec().createWithArray(coords.ravel().copy(), size=(coords.size, None),
                                      bsize=mesh.dim, comm=comm)
    return PETSc.NullSpace().createRigidBody(vec)


def make_solver(comm: MPI.Comm, system: SaddleSystem, cli_options: dict[str, str]) -> LinearSolver:
    scene = system.model.scene
    symmetric = all(r.associated for r in system.multiplied)
    has_mult = system.layout.nl > 0
    settings = opt.merge(preset_options(scene.solver.preset, symmetric, has_mult),
                         scene.solver.options, cli_options)
    is_q, is_l = system.op.index_sets()
    modes = rigid_body_modes(comm, system) if scene.solver.preset == "iterative" else None
    if modes is not None and has_mult:  # fieldsplit hands it to the q block's matrix
        is_q.compose("nearnullspace", modes)
    return LinearSolver(comm, scene.solver.prefix, settings, is_q, is_l,
                        near_null=None if has_mult else modes)


def export_system(comm, directory: str, mat: PETSc.Mat, rhs: PETSc.Vec, system: SaddleSystem) -> None:
    """DIR/system.dat (operator then right-hand side) and DIR/fields.dat (IS q, IS lambda)."""
    path = Path(directory)
    if comm.rank == 0:
        path.mkdir(parents=True, exist_ok=True)
    comm.Barrier()
    viewer = PETSc.Viewer().createBinary(str(path / "system.dat"), "w", comm=comm)
    mat.view(viewer)
    rhs.view(viewer)
    viewer.destroy()
    viewer = PETSc.Viewer().createBinary(str(path / "fields.dat"), "w", comm=comm)
    for iset in system.op.index_sets():
        iset.view(viewer)
    viewer.destroy()


def needs_newton(model: Model) -> bool:
    """Only a nonlinear material or a unilateral relation calls for iterations."""
    return model.elasticity.nonlinear or any(r.sense != "=" for r in model.relations)


def run(comm: MPI.Comm, model: Model, out: str, cli_options: dict[str, str],
        export_dir: str | None = None, log=print) -> str:
    """Solve every load step and write the result file; returns the final status."""
    scene = model.scene
    system = SaddleSystem(comm, model)
    relations_meta = {r.name: (r.nrows, r.sense != "=") for r in model.relations}
    writer = ResultWriter(comm, out, model.mesh, scene.text,
                          ".".join(map(str, PETSc.Sys.getVersion())), relations_meta)
    status = "complete"
    try:
        if scene.nonlinear.method == "arc_length":
            from parsolve.solvers.arc_length import run_arc_length

            run_arc_length(comm, system, cli_options, writer, log)
        elif needs_newton(model):
            _run_newton(comm, system, cli_options, writer, log)
        else:
            _run_linear(comm, system, cli_options, writer, export_dir, log)
    except SolverError as exc:
        status = f"failed: {exc}"
        raise
    finally:
        writer.close(status)
    return status


def _progress(log, comm, step: int, total, t: float, iterations: int, residual: float,
              seconds: float, extra: str = "") -> None:
    if comm.rank == 0:
        log(f"step {step}/{total}  t={t:.6g}  iterations={iterations}  residual={residual:.2e}  "
            f"{seconds:.3f} s{extra}")


def _run_linear(comm, system: SaddleSystem, cli_options, writer, export_dir, log) -> None:
    """Assemble and factorize once; one back-substitution per step."""
    scene = system.model.scene
    t0 = time.perf_counter()
    mat = system.assemble()
    solver = make_solver(comm, system, cli_options)
    solver.set_operator(mat)
    assembly_time = time.perf_counter() - t0
    x, rhs = mat.createVecs()
    for step, t in enumerate(scene.times):
        t1 = time.perf_counter()
        rhs.array[:] = system.rhs(t)[0]
        if export_dir is not None and step == 0:
            export_system(comm, export_dir, mat, rhs, system)
        t2 = time.perf_counter()
        linear_its = solver.solve(rhs, x)
        solve_time = time.perf_counter() - t2
        q, multipliers = system.unpack(system.gather(x.array), t)
        fields, cell_fields, rel_out = _outputs(comm, system, q, multipliers)
        first = assembly_time if step == 0 else 0.0
        timings = {"assembly": first, "solve": solve_time,
                   "total": time.perf_counter() - t1 + first}
        writer.write_step(t, 1, solver.residual, fields, cell_fields, rel_out, timings)
        _progress(log, comm, step + 1, len(scene.times), t, 1, solver.residual, timings["total"],
                  f"  (linear its {linear_its})")


def _run_newton(comm, system: SaddleSystem, cli_options, writer, log) -> None:
    """Newton + active set at every step; the steps follow the scene or the automatic rule."""
    from parsolve.solvers.newton import NewtonSolver

    scene = system.model.scene
    system.assemble()
    solver = make_solver(comm, system, cli_options)
    newton = NewtonSolver(comm, system, solver, scene.nonlinear)
    schedule = StepSchedule(scene)
    step = 0
    while (t := schedule.next()) is not None:
        t1 = time.perf_counter()
        snap = newton.snapshot()
        try:
            result = newton.step(t)
        except SolverError as exc:
            newton.restore(snap)
            if not schedule.cut(exc):
                raise
            if comm.rank == 0:
                log(f"step at t={t:.6g} failed ({exc}); retrying with half the step")
            continue
        step += 1
        seconds = time.perf_counter() - t1
        multipliers = newton.multipliers(t, result.f_int)
        fields, cell_fields, rel_out = _outputs(comm, system, newton.q, multipliers, newton)
        writer.write_step(t, result.iterations, result.residual, fields, cell_fields, rel_out,
                          {"assembly": system.timings.get("assembly", 0.0), "solve": seconds,
                           "total": seconds})
        schedule.done(t, _max_strain_increment(comm, system, newton.q - snap[0]))
        _progress(log, comm, step, schedule.total, t, result.iterations, result.residual, seconds)


class StepSchedule:
    """The scene's load parameters, or automatic steps that keep the largest strain increment
    near a target (Cast3M's AUTOMATIQUE): the next step is scaled by target / achieved, within
    [1/2, 2], and a failed step is retried with half its size (up to 6 times in a row)."""

    MAX_CUTS = 6

    def __init__(self, scene):
        self.spec = scene.steps
        self.times = list(scene.times)
        self.t, self.dt, self.count, self.cuts = 0.0, self.times[0], 0, 0

    @property
    def total(self):
        return "?" if self.spec.automatic else len(self.times)

    def next(self) -> float | None:
        if not self.spec.automatic:
            return self.times[self.count] if self.count < len(self.times) else None
        if self.t >= self.spec.end * (1 - 1e-12) or self.count >= self.spec.max_steps:
            return None
        return min(self.t + self.dt, self.spec.end)

    def done(self, t: float, max_strain_increment: float) -> None:
        self.count += 1
        self.cuts = 0
        if self.spec.automatic:
            self.t = t
            if max_strain_increment > 0:
                self.dt *= min(2.0, max(0.5, self.spec.strain_increment / max_strain_increment))

    def cut(self, exc: Exception) -> bool:
        """Halve the step after a failure; False when fixed steps or too many cuts."""
        if not self.spec.automatic or self.cuts >= self.MAX_CUTS:
            return False
        self.cuts += 1
        self.dt *= 0.5
        return True


def _max_strain_increment(comm, system: SaddleSystem, dq: np.ndarray) -> float:
    mesh = system.model.mesh
    owned = system.part.owned_cells(comm.rank, mesh.cells)
    if owned.size == 0:
        return comm.allreduce(0.0, op=MPI.MAX)
    geo = system.model.elasticity.geometry(owned)
    from parsolve.fem.kernels import strains

    eps = strains(geo.strain_operator(), dq.reshape(mesh.num_points, -1)[mesh.cells[owned]]
                  .reshape(len(owned), mesh.cells.shape[1] * mesh.dim))
    return comm.allreduce(float(np.abs(eps).max()), op=MPI.MAX)


def _gather_cells(comm, owned: np.ndarray, values: np.ndarray, ncells: int):
    """Per-cell values of every rank's reported cells, in mesh order, on rank 0."""
    parts = comm.gather((owned, values), root=0)
    if comm.rank != 0:
        return None
    out = np.zeros((ncells,) + values.shape[1:])
    for idx, val in parts:
        out[idx] = val
    return out


def _outputs(comm: MPI.Comm, system: SaddleSystem, q: np.ndarray, multipliers: dict,
             newton=None):
    model = system.model
    mesh = model.mesh
    u = q.reshape(mesh.num_points, model.ncomp)
    owned = system.part.owned_cells(comm.rank, mesh.cells)
    cell_fields = {}
    if newton is None:
        sig = model.elasticity.cell_stress(owned, u)
        sums, weights = model.elasticity.nodal_stress_sums(owned, u)
    else:  # stresses and history from the material state at the quadrature points
        pos = np.searchsorted(system.local_cells, owned)
        wq = model.elasticity.geometry(owned).wdet
        sig = (newton.stress_qp[pos] * wq[:, :, None]).sum(axis=1) / wq.sum(axis=1)[:, None]
        vol = wq.sum(axis=1)
        nodes = mesh.cells[owned].ravel()
        nen = mesh.cells.shape[1]
        sums = np.stack([np.bincount(nodes, weights=np.repeat(sig[:, k] * vol, nen),
                                     minlength=mesh.num_points) for k in range(sig.shape[1])], 1)
        weights = np.bincount(nodes, weights=np.repeat(vol, nen), minlength=mesh.num_points)
        internal = model.elasticity.internal_variables(system.local_cells, newton.states)
        for name, value in internal.items():
            cell_fields[name] = _gather_cells(comm, owned, value[pos], mesh.num_cells)
    cell_fields["stress"] = _gather_cells(comm, owned, sig, mesh.num_cells)
    sums = comm.allreduce(sums)
    weights = comm.allreduce(weights)
    nodal = sums / np.maximum(weights, 1e-300)[:, None]
    rel_out = {}
    active = newton.active.active if newton is not None else None
    for r in model.relations:
        rel_out[r.name] = {"multiplier": multipliers[r.name], "primal": r.primal(q)}
        if r.sense != "=":
            k = system.multiplied.index(r)
            first = system.block.first_row[k]
            rel_out[r.name]["active"] = active[first:first + r.nrows].astype(np.int8)
    return {"displacement": u, "stress": nodal}, cell_fields, rel_out
