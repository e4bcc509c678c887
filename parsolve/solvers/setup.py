"""The linear solver of a system: preset options layered with the scene's and the command
line's, the near-null space for algebraic multigrid, and the export of the assembled system."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from parsolve.solvers import options as opt
from parsolve.solvers.linear import LinearSolver, preset_options
from parsolve.solvers.system import SaddleSystem


def rigid_body_modes(comm: MPI.Comm, system: SaddleSystem) -> PETSc.NullSpace | None:
    """Near-null space of the primal block (for GAMG), on the owned nodes in new numbering:
    rigid-body modes of a displacement-only model, constants of a scalar field."""
    ctx = system.context
    mesh = ctx.mesh
    fields = list(ctx.fields)
    if len(fields) != 1 or fields[0].scalar:   # rigid-body modes of one vector field only
        return None if ctx.ncomp > 1 else PETSc.NullSpace().create(constant=True, comm=comm)
    coords = mesh.points[:mesh.n_owned]   # owned nodes first, in the global numbering's order
    vec = PETSc.Vec().createWithArray(coords.ravel().copy(), size=(coords.size, None),
                                      bsize=mesh.dim, comm=comm)
    return PETSc.NullSpace().createRigidBody(vec)


def make_solver(comm: MPI.Comm, system: SaddleSystem, cli_options: dict[str, str]) -> LinearSolver:
    """Cholesky is chosen when every multiplied relation is associated and every effect's
    tangent symmetric; the solver still checks each operator (LinearSolver)."""
    ctx = system.context
    scene = ctx.scene
    secant = scene.nonlinear.matrix == "secant"
    stiffness_symmetric = ctx.symmetric(secant)
    symmetric = all(r.associated for r in ctx.multiplied) and stiffness_symmetric
    has_mult = ctx.dofs.nl > 0
    settings = opt.merge(preset_options(scene.solver.preset, symmetric, has_mult,
                                        stiffness_symmetric),
                         scene.solver.options, cli_options)
    is_q, is_l = system.index_sets()
    modes = rigid_body_modes(comm, system) if scene.solver.preset == "iterative" else None
    if modes is not None and has_mult:  # fieldsplit hands it to the q block's matrix
        is_q.compose("nearnullspace", modes)
    splits = None
    if scene.solver.split == "fields":  # one block per field (options -fieldsplit_<field>_...)
        splits = list(field_index_sets(comm, system).items())
        splits += [("lambda", is_l)] if has_mult else []
        if settings.get("pc_type") != "fieldsplit":
            settings = opt.merge(settings, {"pc_type": "fieldsplit"}, cli_options)
        if settings.get("pc_fieldsplit_type") == "schur" and len(splits) != 2:
            settings = {k: v for k, v in settings.items()
                        if not k.startswith("pc_fieldsplit_schur")}
            settings["pc_fieldsplit_type"] = "multiplicative"
    # the augmented preconditioning matrix of the iterative preset's Schur fieldsplit
    augmented = (scene.solver.preset == "iterative" and has_mult and splits is None
                 and settings.get("pc_type") == "fieldsplit")
    return LinearSolver(comm, scene.solver.prefix, settings, is_q, is_l,
                        near_null=None if has_mult else modes, splits=splits,
                        preconditioner=system.preconditioner if augmented else None)


def export_system(comm, directory: str, mat: PETSc.Mat, rhs: PETSc.Vec, system: SaddleSystem) -> None:
    """DIR/system.dat: operator, right-hand side, then the scaling s of the unknowns (1 on q,
    the relation scale on λ: the result file's λ is s · x on the λ rows); DIR/fields.dat: the
    index sets of q and λ, then one per field, in the order of /fields."""
    path = Path(directory)
    if comm.rank == 0:
        path.mkdir(parents=True, exist_ok=True)
    comm.Barrier()
    scale = rhs.duplicate()
    scale.set(1.0)
    ctx = system.context
    q0, q1, l0, l1 = ctx.dofs.owned()
    if ctx.relations.nrows:
        scale.array[q1 - q0:] = ctx.relations.col_scale[:l1 - l0]
    viewer = PETSc.Viewer().createBinary(str(path / "system.dat"), "w", comm=comm)
    for obj in (mat, rhs, scale):
        obj.view(viewer)
    viewer.destroy()
    viewer = PETSc.Viewer().createBinary(str(path / "fields.dat"), "w", comm=comm)
    for iset in list(system.index_sets()) + list(field_index_sets(comm, system).values()):
        iset.view(viewer)
    viewer.destroy()


def field_index_sets(comm, system: SaddleSystem) -> dict[str, PETSc.IS]:
    """One index set per field (its DOFs among this rank's rows), named after the field."""
    ctx, out = system.context, {}
    for f in ctx.fields:
        idx = ctx.dofs.field_rows(ctx.fields.columns(f.name))
        iset = PETSc.IS().createGeneral(idx.astype(PETSc.IntType), comm=comm)
        iset.setName(f.name)
        out[f.name] = iset
    return out
