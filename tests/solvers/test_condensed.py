"""The condensed preconditioner (solvers.condensed): with an exact solve of the condensed
operator it is M⁻¹ itself — hard rows, compliant rows and a non-associated dual included —
and the iterative preset chooses it, giving the direct solve's answer; rows that tie several
nodes (controls, periodic ties) are condensed on a slave node each (solvers.tied, tested in
test_condensed_tied.py)."""

import numpy as np
from mpi4py import MPI
import pytest
from petsc4py import PETSc

from conftest import dense, solve_in_process
from helpers.scene import scene, shipped
from parsolve.solvers import options as opt
from parsolve.solvers.condensed import CondensedPreconditioner


def _friction(comm, petsc: dict | None = None):
    text = scene(shipped("contact_friction_3d.toml"), steps={"count": 1},
                 solver={"preset": "iterative", "petsc": petsc or {}})
    return solve_in_process(text, comm, options={})


def _variant(mat: PETSc.Mat, system) -> PETSc.Mat:
    """M with every third multiplier row compliant (C = 0.5 k on its diagonal), every fifth
    open (its A row and B column zero, C = k), and the other rows' dual B scaled per
    component by (1, 1.3, 0.7): a non-associated dual on the rows' own nodes."""
    comm, dm, k = system.comm, system.dofmap, system.kscale
    q0, q1, _, _ = dm.owned()
    nq, start = q1 - q0, dm.offset
    lam = np.concatenate([np.arange(dm.offsets[r] + dm.owned(r)[1] - dm.owned(r)[0],
                                    dm.offsets[r] + dm.owned(r)[1] - dm.owned(r)[0]
                                    + dm.owned(r)[3] - dm.owned(r)[2])
                          for r in range(comm.size)])
    row_of = np.full(dm.offsets[-1], -1)
    row_of[lam] = np.arange(lam.size)   # a multiplier column → its relation row (global)
    indptr, cols, vals = mat.getValuesCSR()
    vals = vals.copy()
    rows = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    relation = row_of[cols]                       # -1: a primal column
    soft, open_ = relation % 3 == 1, relation % 5 == 2
    in_b = (rows < nq) & (relation >= 0)
    vals[in_b] *= np.where(open_[in_b], 0.0, np.array([1.0, 1.3, 0.7])[rows[in_b] % 3])
    mine = rows >= nq                             # this rank's multiplier rows
    own = row_of[rows + start]
    vals[mine & (relation < 0) & (own % 5 == 2)] = 0.0
    diagonal = mine & (cols == rows + start)
    vals[diagonal] = np.where(own[diagonal] % 5 == 2, k, np.where(own[diagonal] % 3 == 1, 0.5 * k,
                                                                  0.0))
    n = indptr.size - 1
    return PETSc.Mat().createAIJ(size=((n, None), (n, None)), csr=(indptr, cols, vals), comm=comm)


def test_exact_condensation_is_the_inverse(comm):
    """With LU on the condensed operator S, the preconditioner applied to r is M⁻¹ r, on the
    friction box's operator made to hold hard, compliant and open rows and a non-associated
    dual (dense solve as the reference)."""
    system, solver, mat, rhs, x = _friction(comm)
    variant = _variant(mat, system)
    is_q, is_l = system.index_sets()
    pre = CondensedPreconditioner(comm, 3, is_q, is_l, "exact_")
    with opt.inserted("exact_", {"condensed_pc_type": "lu",
                                 "condensed_pc_factor_mat_solver_type": "mumps"}):
        assert pre.update(variant) is None
    assert pre.w.max() > 0 and pre.hard.size   # (both kinds of rows are there)
    pre.setUp(None)
    r = rhs.duplicate()
    r.setRandom()
    z = r.duplicate()
    pre.apply(None, r, z)
    M = dense(variant, comm)
    reference = np.linalg.solve(M, np.concatenate(comm.allgather(r.array.copy())))
    got = np.concatenate(comm.allgather(z.array.copy()))
    assert np.abs(got - reference).max() <= 1e-9 * np.abs(reference).max()


def test_preset_chooses_condensation_and_gives_the_direct_answer(comm):
    """The friction box on the iterative preset: the condensed preconditioner is chosen, GMRES
    converges in a few iterations, and x solves M x = b (dense solve) to 1e-10."""
    system, solver, mat, rhs, x = _friction(comm)
    assert solver.choice == "condensed"
    assert solver.ksp.getPC().getType() == "python"
    assert solver.ksp.getIterationNumber() <= 15
    M = dense(mat, comm)
    reference = np.linalg.solve(M, np.concatenate(comm.allgather(rhs.array.copy())))
    xs = np.concatenate(comm.allgather(x.array.copy()))
    assert np.abs(xs - reference).max() <= 1e-10 * np.abs(reference).max()


@pytest.mark.parametrize("name", ["two_controls.toml", "periodic_shear_laminate.toml"])
def test_rows_of_several_nodes_are_condensed_on_a_slave_node(comm, name):
    """A control (its row the mean displacement of an end, its column a load on the same end)
    and a periodic tie (a row on two nodes) are condensed on one node of each row
    (solvers.tied), and GMRES gives M x = b's answer (dense solve)."""
    text = scene(shipped(name), solver={"preset": "iterative"})
    system, solver, mat, rhs, x = solve_in_process(text, comm, options={})
    assert solver.choice == "condensed"
    assert solver.condensed.H is not None   # (the tied rows' triple product)
    M = dense(mat, comm)
    reference = np.linalg.solve(M, np.concatenate(comm.allgather(rhs.array.copy())))
    xs = np.concatenate(comm.allgather(x.array.copy()))
    assert np.abs(xs - reference).max() <= 1e-10 * np.abs(reference).max()


def test_turned_off_by_option(comm):
    """-condensed false: the augmented form on a system that could be condensed."""
    system, solver, mat, rhs, x = _friction(comm, {"condensed": "false"})
    assert solver.choice == "augmented: condensation turned off"


def _nodal_transform(pre: CondensedPreconditioner, M: np.ndarray, comm) -> np.ndarray:
    """G (K + dk) H + k on the constrained slots, from the dense M and the preconditioner's
    per-node blocks (gathered): the condensed operator by dense products."""
    nc = pre.nc
    q = np.concatenate([pre.starts[r] + np.arange(pre.nqs[r]) for r in range(comm.size)])
    K = M[np.ix_(q, q)]
    n = K.shape[0] // nc
    G, H, DK = (np.broadcast_to(np.eye(nc), (n, nc, nc)).copy() for _ in range(3))
    DK[:] = 0.0
    keep = np.zeros((n, nc))
    first = pre.q_start // nc
    for part in comm.allgather((pre.nodes + first, pre.g, pre.h, pre.dk, pre.keep)):
        nodes, g, h, dk, kp = part
        G[nodes], H[nodes], DK[nodes], keep[nodes] = g, h, dk, kp

    def block_diagonal(blocks):
        out = np.zeros_like(K)
        for a in range(nc):
            for b in range(nc):
                out[np.arange(n) * nc + a, np.arange(n) * nc + b] = blocks[:, a, b]
        return out

    S = block_diagonal(G) @ (K + block_diagonal(DK)) @ block_diagonal(H)
    return S + pre.kscale * np.diag(keep.reshape(-1))


def test_condensed_operator_is_the_nodal_transform(comm):
    """S, made by transforming K's rows and columns in place, equals G (K + dk) H + k on the
    constrained slots by dense products, on the variant operator (hard, compliant and open
    rows; a non-associated dual), and again after the operator's values changed (S's storage
    reused)."""
    system, solver, mat, rhs, x = _friction(comm)
    variant = _variant(mat, system)
    is_q, is_l = system.index_sets()
    pre = CondensedPreconditioner(comm, 3, is_q, is_l, "transform_")
    for scale in (1.0, 2.0):
        variant.scale(scale)
        assert pre.update(variant) is None
        S = dense(pre.S, comm)
        reference = _nodal_transform(pre, dense(variant, comm), comm)
        assert np.abs(S - reference).max() <= 1e-13 * np.abs(reference).max()
        assert np.abs(pre.h - np.eye(3)).max() > 0.1   # (frames that move the columns)


def test_stiffness_not_in_nodal_blocks_is_not_condensed(comm):
    """A stiffness whose rows of a node have different column lists (here: each node's
    entries (x, y) and (y, z) left out of the pattern) cannot be transformed node block by
    node block: the reason, the same on every rank."""
    system, solver, mat, rhs, x = _friction(comm)
    nq = system.dofmap.owned()[1] - system.dofmap.owned()[0]
    start = mat.getOwnershipRange()[0]
    indptr, cols, vals = mat.getValuesCSR()
    rows = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    keep = ~((rows < nq) & (rows % 3 < 2) & (cols == rows + start + 1))
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows[keep], minlength=indptr.size - 1))])
    n = indptr.size - 1
    holed = PETSc.Mat().createAIJ(size=((n, None), (n, None)),
                                  csr=(indptr.astype(PETSc.IntType), cols[keep], vals[keep]),
                                  comm=comm)
    is_q, is_l = system.index_sets()
    pre = CondensedPreconditioner(comm, 3, is_q, is_l, "holed_")
    why = "the stiffness is not made of whole nodal blocks at a condensed node"
    assert pre.update(holed) == why


def test_coupled_rows_read_from_the_pattern(comm):
    """The rows S changes are found from K's pattern, not from K's values: with every entry of
    the other nodes' rows in the condensed nodes' columns an exact zero (stored: a sum that
    cancels at assembly), each such row is still found, and S is still the nodal transform."""
    system, solver, mat, rhs, x = _friction(comm)
    is_q, is_l = system.index_sets()
    pre = CondensedPreconditioner(comm, 3, is_q, is_l, "pattern_")
    assert pre.update(mat) is None
    condensed = np.concatenate(comm.allgather(
        pre.starts[comm.rank] + (pre.nodes[:, None] * 3 + np.arange(3)).reshape(-1)))
    own = (pre.nodes[:, None] * 3 + np.arange(3)).reshape(-1)
    indptr, cols, vals = mat.getValuesCSR()
    vals = vals.copy()
    rows = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    coupled = (rows < pre.nq) & np.isin(cols, condensed)
    others = coupled & ~np.isin(rows, own)
    vals[others] = 0.0   # (kept in the pattern)
    assert comm.allreduce(int(others.sum())) > 0
    n = indptr.size - 1
    cancelled = PETSc.Mat().createAIJ(size=((n, None), (n, None)), csr=(indptr, cols, vals),
                                      comm=comm)
    assert np.array_equal(cancelled.getValuesCSR()[1], cols)   # (the zeros stored)
    assert pre.update(cancelled) is None
    assert np.array_equal(pre._near_rows(cancelled), np.unique(rows[coupled]))
    S = dense(pre.S, comm)
    reference = _nodal_transform(pre, dense(cancelled, comm), comm)
    assert np.abs(S - reference).max() <= 1e-13 * np.abs(reference).max()


def _block_matrix(comm, shape, first_row: int, first_col: int, nc: int, n: int,
                  nodes: np.ndarray, blocks: np.ndarray) -> PETSc.Mat:
    """A distributed AIJ matrix of ``shape`` ((local, global) rows, (local, global) columns)
    holding an nc × nc block on each of the n local primal nodes: ``blocks`` on ``nodes``
    (local node numbers), the identity on the others; node i's row a at first_row + i nc + a,
    its column b at first_col + i nc + b."""
    full = np.broadcast_to(np.eye(nc), (n, nc, nc)).copy()
    full[nodes] = blocks
    mat = PETSc.Mat().createAIJ(size=shape, nnz=(nc, nc), comm=comm)
    rows = first_row + np.arange(n)[:, None] * nc + np.arange(nc)
    cols = (first_col + np.arange(n)[:, None] * nc + np.arange(nc)).reshape(-1)
    for a in range(nc):   # (row a of every node's block)
        mat.setValuesIJV(np.arange(n + 1, dtype=PETSc.IntType) * nc,
                         cols.astype(PETSc.IntType), full[:, a, :].reshape(-1),
                         rowmap=rows[:, a].astype(PETSc.IntType))
    mat.assemble()
    return mat


def _product_operator(pre: CondensedPreconditioner, mat: PETSc.Mat) -> PETSc.Mat:
    """The condensed operator as PETSc's products make it: R M P with R = [G, 0] (primal rows ×
    saddle columns) and P = [H; 0], plus G dk H + k on the constrained slots (per node)."""
    comm, nc, nq, nl = pre.comm, pre.nc, pre.nq, pre.nl
    primal, saddle, n = (nq, int(pre.nqs.sum())), (nq + nl, int(pre.starts[-1])), nq // nc
    R = _block_matrix(comm, (primal, saddle), pre.q_start, pre.start, nc, n, pre.nodes, pre.g)
    P = _block_matrix(comm, (saddle, primal), pre.start, pre.q_start, nc, n, pre.nodes, pre.h)
    S = R.matMult(mat.matMult(P))
    extra = pre.g @ pre.dk @ pre.h + pre.kscale * pre.keep[:, :, None] * np.eye(nc)
    E = _block_matrix(comm, (primal, primal), pre.q_start, pre.q_start, nc, n, pre.nodes, extra)
    zero = np.ones(n, dtype=bool)
    zero[pre.nodes] = False
    E.zeroRows((pre.q_start + np.flatnonzero(zero)[:, None] * nc
                + np.arange(nc)).reshape(-1).astype(PETSc.IntType), diag=0.0)
    S.axpy(1.0, E, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    return S


def test_condensed_operator_equals_the_product(comm):
    """S transformed in place equals R M P (PETSc's triple product, the way S was first made)
    plus the folded rows and k on the constrained slots, entry by entry to 1e-14 of its
    largest entry, on the variant operator (hard, compliant and open rows; a non-associated
    dual) and on the friction box's own operator."""
    system, solver, mat, rhs, x = _friction(comm)
    is_q, is_l = system.index_sets()
    for name, operator in (("variant", _variant(mat, system)), ("plain", mat)):
        pre = CondensedPreconditioner(comm, 3, is_q, is_l, f"product_{name}_")
        assert pre.update(operator) is None
        reference = _product_operator(pre, operator)
        largest = comm.allreduce(float(np.abs(reference.getValuesCSR()[2]).max()), op=MPI.MAX)
        difference = pre.S.copy()
        difference.axpy(-1.0, reference, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        values = difference.getValuesCSR()[2]
        worst = comm.allreduce(float(np.abs(values).max(initial=0.0)), op=MPI.MAX)
        assert worst <= 1e-14 * largest
        assert comm.allreduce(pre.nodes.size) > 0 and np.abs(pre.h - np.eye(3)).max() > 0.1
