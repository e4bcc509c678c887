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
    solver = LinearSolver(comm, scene.solver.prefix, settings, is_q, is_l)
    if scene.solver.preset == "iterative":
        modes = rigid_body_modes(comm, system)
        if has_mult:
            is_q.compose("nearnullspace", modes)
        else:
            system.op.mat_nearnull = modes
    return solver


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
        t0 = time.perf_counter()
        mat = system.assemble()
        solver = make_solver(comm, system, cli_options)
        if getattr(system.op, "mat_nearnull", None) is not None:
            mat.setNearNullSpace(system.op.mat_nearnull)
        solver.set_operator(mat)
        assembly_time = time.perf_counter() - t0
        x, rhs = mat.createVecs()
        for step, t in enumerate(scene.times):
            t1 = time.perf_counter()
            b, _ = system.rhs(t)
            rhs.array[:] = b
            if export_dir is not None and step == 0:
                export_system(comm, export_dir, mat, rhs, system)
            t2 = time.perf_counter()
            iterations = solver.solve(rhs, x)
            solve_time = time.perf_counter() - t2
            residual = solver.residual
            x_full = system.gather(x.array)
            q, multipliers = system.unpack(x_full, t)
            fields, cell_fields, rel_out = _outputs(comm, system, q, multipliers)
            timings = {"assembly": assembly_time if step == 0 else 0.0, "solve": solve_time,
                       "total": time.perf_counter() - t1 + (assembly_time if step == 0 else 0.0)}
            writer.write_step(t, 1, residual, fields, cell_fields, rel_out, timings)
            if comm.rank == 0:
                log(f"step {step + 1}/{len(scene.times)}  t={t:.6g}  iterations=1 "
                    f"(linear its {iterations})  residual={residual:.2e}  {timings['total']:.3f} s")
    except SolverError as exc:
        status = f"failed: {exc}"
        raise
    finally:
        writer.close(status)
    return status


def _outputs(comm: MPI.Comm, system: SaddleSystem, q: np.ndarray, multipliers: dict):
    model = system.model
    mesh = model.mesh
    u = q.reshape(mesh.num_points, model.ncomp)
    owned = system.part.owned_cells(comm.rank)
    sig = model.elasticity.cell_stress(owned, u)
    parts = comm.gather((owned, sig), root=0)
    stress = None
    if comm.rank == 0:
        stress = np.zeros((mesh.num_cells, sig.shape[1]))
        for idx, val in parts:
            stress[idx] = val
    sums, weights = model.elasticity.nodal_stress_sums(owned, u)
    sums = comm.allreduce(sums)
    weights = comm.allreduce(weights)
    nodal = sums / np.maximum(weights, 1e-300)[:, None]
    rel_out = {}
    for r in model.relations:
        rel_out[r.name] = {"multiplier": multipliers[r.name], "primal": r.primal(q)}
    return {"displacement": u, "stress": nodal}, {"stress": stress}, rel_out
