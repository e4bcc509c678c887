"""The saddle operator against a brute-force dense assembly, on 1, 2 and 3 ranks.

The dense reference adds every cell's element matrix (all cells, input numbering) into a full
array with ``np.add.at`` and writes A and -D entry by entry: no node pattern, no CSR, no
ownership. The operator's own arrays (values, global columns and rows of every stored entry),
the PETSc matrix built on them, a re-assembly with other values, the eliminated rows and
columns, the lifting and the reactions' row products must all match it.
"""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from conftest import saddle_of_input_dofs
from helpers.saddle import SCENE
from helpers.scales import whole_scales

from parsolve.effects.compose import Composition
from parsolve.fem.element_matrices import ElementMatrices, full_values
from parsolve.model import build_model
from parsolve.scene import parse_scene
from parsolve.solvers.system import SaddleSystem

COMM = MPI.COMM_WORLD


def dense(mat: PETSc.Mat) -> np.ndarray:
    """The whole matrix on every rank, from a dense copy (the Mat itself stays as it is: the
    operator keeps writing into its arrays)."""
    rows = mat.convert("dense", PETSc.Mat()).getDenseArray().copy()
    return np.concatenate(COMM.allgather(rows), axis=0)


def system_of(text: str) -> SaddleSystem:
    """The system on COMM's parts, with ``whole`` (the model on the whole mesh, this rank
    alone: the brute-force references) and ``iq`` (the saddle index of every input DOF)."""
    system = SaddleSystem(COMM, build_model(parse_scene(tomllib.loads(text), "t.toml", text), COMM))
    system.whole = build_model(parse_scene(tomllib.loads(text), "t.toml", text))
    system.iq = saddle_of_input_dofs(COMM, system)
    return system


def brute_stiffness(model, factor: float = 1.0) -> np.ndarray:
    """Dense K (input numbering) from the element matrices of every cell."""
    mesh, nc = model.mesh, model.ncomp
    comp = Composition(model, np.arange(mesh.num_cells))
    K = np.zeros((mesh.num_points * nc, mesh.num_points * nc))
    for ci, cj, m, fac in comp.stiffness().parts:
        V = full_values(m)                                      # (len(ci)·len(cj), nen, nen, ncells)
        ci, cj = np.asarray(ci), np.asarray(cj)
        V = V.reshape(len(ci), len(cj), *V.shape[1:])
        nodes = mesh.cells                                      # (ncells, nen)
        for i in range(len(ci)):
            for j in range(len(cj)):
                rows = nodes.T[:, None, :] * nc + ci[i]         # (nen, 1, ncells): row node a
                cols = nodes.T[None, :, :] * nc + cj[j]         # (1, nen, ncells): column node b
                rows, cols = np.broadcast_arrays(rows, cols)
                np.add.at(K, (rows.ravel(), cols.ravel()), factor * fac * V[i, j].ravel())
    return K


def brute_saddle(system: SaddleSystem, factor: float = 1.0) -> np.ndarray:
    """The whole saddle matrix before elimination, in the saddle numbering."""
    iq, il = system.iq, system.dofmap.saddle_of_mult
    S = np.zeros((system.dofmap.size, system.dofmap.size))
    S[np.ix_(iq, iq)] = brute_stiffness(system.whole, factor)
    blk = system.relation_set
    row_scale, col_scale = whole_scales(blk)
    per_rank = np.zeros_like(S)   # relations built per rank or spread: each entry on one rank
    for k, rel in enumerate(system.multiplied):
        rows = il[blk.mult_rows[k]]
        scale = row_scale[blk.mult_rows[k]]
        cscale = col_scale[blk.mult_rows[k]]
        into = S if rel.complete else per_rank   # (a spread one: its entries per rank)
        np.add.at(into, (rows[rel.a_rows], iq[rel.a_dofs]), rel.a_vals * scale[rel.a_rows])
        dofs, drows, dvals = rel.dual_coo()
        np.add.at(into, (iq[dofs], rows[drows]), -dvals * cscale[drows])
    return S + COMM.allreduce(per_rank)


def operator_entries(op) -> np.ndarray:
    """The owned rows of the operator as a dense array, from its stored entries."""
    return np.concatenate(COMM.allgather(op.dense()), axis=0)


def eliminated(S: np.ndarray, rows: np.ndarray, diag: float) -> np.ndarray:
    out = S.copy()
    out[rows, :] = 0.0
    out[:, rows] = 0.0
    out[rows, rows] = diag
    return out


@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_operator_is_the_dense_assembly(cell):
    system = system_of(SCENE.format(cell=cell, preset="direct", eliminate="false"))
    mat = system.assemble()
    S = brute_saddle(system)
    tol = 1e-13 * np.abs(S).max()
    np.testing.assert_allclose(dense(mat), S, rtol=0, atol=tol)
    np.testing.assert_allclose(operator_entries(system.op), S, rtol=0, atol=tol)
    # every stored entry once, exactly where the cells couple two nodes (ncomp² entries), the
    # relations have a coefficient, and on the multiplier diagonal
    op = system.op
    entries = np.arange(op.data.size)
    keys = op.row_of(entries) + op.offset
    keys = keys * op.size + op.global_columns(entries)
    assert np.unique(keys).size == keys.size
    np.testing.assert_array_equal(np.sort(np.concatenate(COMM.allgather(keys))),
                                  np.flatnonzero(structure(system)))


def structure(system: SaddleSystem) -> np.ndarray:
    """Where the saddle matrix has entries, from the cells and the relations' coefficients."""
    mesh, nc = system.whole.mesh, system.model.ncomp
    iq, il = system.iq, system.dofmap.saddle_of_mult
    nodes = np.zeros((mesh.num_points, mesh.num_points), dtype=bool)
    nen = mesh.cells.shape[1]
    nodes[np.repeat(mesh.cells, nen, axis=1).ravel(), np.tile(mesh.cells, nen).ravel()] = True
    out = np.zeros((system.dofmap.size, system.dofmap.size), dtype=bool)
    out[np.ix_(iq, iq)] = np.kron(nodes, np.ones((nc, nc), dtype=bool))
    blk = system.relation_set
    for k, rel in enumerate(system.multiplied):
        rows = il[blk.mult_rows[k]]
        out[rows[rel.a_rows], iq[rel.a_dofs]] = True
        dofs, drows, _ = rel.dual_coo()
        out[iq[dofs], rows[drows]] = True
    out = COMM.allreduce(out.astype(np.int8)) > 0   # (a relation built per rank: on its ranks)
    out[il, il] = True
    return out


def test_reassembly_writes_into_the_petsc_matrix():
    """A second assembly with other element values: the Mat PETSc already holds shows them, and
    a solver set up on the first values is set up again."""
    system = system_of(SCENE.format(cell="quad", preset="direct", eliminate="false"))
    mat = system.assemble()
    ksp = PETSc.KSP().create(COMM)
    ksp.setOperators(mat)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    b, x = mat.createVecLeft(), mat.createVecRight()
    b.setArray(np.random.default_rng(COMM.rank).random(b.getLocalSize()))
    ksp.solve(b, x)
    ke = system.composition.stiffness()
    ci, cj, m, fac = ke.parts[0]
    doubled = ElementMatrices(values=2.0 * fac * full_values(m))
    again = system.assemble(doubled)
    assert again.handle == mat.handle
    S2 = brute_saddle(system, factor=2.0)
    np.testing.assert_allclose(dense(mat), S2, rtol=0, atol=1e-13 * np.abs(S2).max())
    ksp.solve(b, x)
    bb = np.concatenate(COMM.allgather(b.array.copy()))
    xx = np.concatenate(COMM.allgather(x.array.copy()))
    xd = np.linalg.solve(S2, bb)
    assert np.abs(xx - xd).max() <= 1e-10 * np.abs(xd).max()


@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_elimination_lifting_and_reactions(cell):
    system = system_of(SCENE.format(cell=cell, preset="direct", eliminate="true"))
    mat = system.assemble()
    S = brute_saddle(system)
    # each rank holds the eliminated rows of its own DOFs (and reads the others its rows
    # name): every rank's together
    own = system.iq[system.elim_dofs[system.elim_own]]
    assert np.all((own >= system.offset) & (own < system.offset + system.op.nrows))
    rows = np.sort(np.concatenate(COMM.allgather(own)))
    assert rows.size > 0 and np.unique(rows).size == rows.size
    E = eliminated(S, rows, system.kscale)
    np.testing.assert_allclose(dense(mat), E, rtol=0, atol=1e-13 * np.abs(S).max())
    op = system.op
    x = np.random.default_rng(7).random(op.size)          # same on every rank
    lo, n = op.offset, op.nrows
    x_e = np.zeros(op.size)
    x_e[rows] = x[rows]
    np.testing.assert_allclose(op.lifting(x_e), (S @ x_e)[lo:lo + n], rtol=0,
                               atol=1e-13 * np.abs(S).max() * np.abs(x).sum())
    mine = op.elim_rows - lo
    np.testing.assert_allclose(op.eliminated_rows(x)[mine], (S @ x)[op.elim_rows], rtol=0,
                               atol=1e-13 * np.abs(S).max() * np.abs(x).sum())


@pytest.mark.serial
def test_unused_point_gets_a_diagonal(tmp_path):
    """A point no cell uses: its rows are empty in K; the operator gives them a diagonal slot of
    their own, which the elimination sets, so the system is regular and the point stays at 0."""
    import meshio

    pts = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [2, 0], [2, 1], [5, 5]], float)
    quads = np.array([[0, 1, 2, 3], [1, 4, 5, 2]])
    meshio.write(tmp_path / "m.vtu", meshio.Mesh(pts, [("quad", quads)]))
    text = f'''
[mesh]
file = "{tmp_path / 'm.vtu'}"
[model]
hypothesis = "plane_stress"
[regions]
left = "x == 0"
right = "x == 2"
[[materials]]
E = 1.0
nu = 0.3
[[loads]]
region = "right"
total_force = [1.0, 0.0]
[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x", "y"]
'''
    system = system_of(text)
    mat = system.assemble()
    op = system.op
    unused = system.iq[[12, 13]]
    np.testing.assert_array_equal(op.global_columns(op.diag_pos[unused - op.offset]), unused)
    M = dense(mat)
    np.testing.assert_array_equal(M[unused][:, unused], system.kscale * np.eye(2))
    assert np.abs(M[unused]).sum() == 2 * system.kscale
    S = brute_saddle(system)
    rows = system.iq[system.elim_dofs]
    np.testing.assert_allclose(M, eliminated(S, rows, system.kscale), rtol=0, atol=1e-14)
    b, x_e = system.rhs(1.0)
    x = np.linalg.solve(M, b)
    assert np.all(x[unused] == 0.0)
    # the same strip without the stray point: the same displacements
    meshio.write(tmp_path / "m2.vtu", meshio.Mesh(pts[:6], [("quad", quads)]))
    other = system_of(text.replace("m.vtu", "m2.vtu"))
    M2 = dense(other.assemble())
    x2 = np.linalg.solve(M2, other.rhs(1.0)[0])
    q, q2 = x[system.iq[:12]], x2[other.iq]
    assert np.abs(q).max() > 1.0
    np.testing.assert_allclose(q, q2, rtol=1e-12, atol=0)


def test_block_size_of_a_multiplier_free_operator():
    """Without multiplier rows every rank's rows are whole nodes: the Mat says so (GAMG's set-up
    treated the 3D box as a scalar problem: ~25× its memory); with multipliers it cannot."""
    box = """
[mesh]
generator = "box"
lx = 1.0
ly = 1.0
lz = 1.0
nx = 3
ny = 2
nz = 2
cell = "hexahedron"
[model]
hypothesis = "3d"
[[materials]]
E = 1.0
nu = 0.3
[[relations]]
name = "clamp"
type = "dirichlet"
region = "xmin"
components = ["x", "y", "z"]
[solver]
eliminate = {eliminate}
"""
    eliminated = system_of(box.format(eliminate="true"))
    multiplied = system_of(box.format(eliminate="false"))
    assert eliminated.dofmap.nl == 0 and multiplied.dofmap.nl > 0
    assert eliminated.assemble().getBlockSize() == 3
    assert multiplied.assemble().getBlockSize() == 1
