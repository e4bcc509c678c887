"""The augmented form's matrices (solvers.augmented) hold one copy of the stiffness: the KSP's
operator and preconditioning matrix share their stiffness block, and the Schur fieldsplit's
V-cycle works on that block itself; where Aᵀ A reaches outside K's pattern (rows tying several
nodes: the controls), the block takes both patterns and its entries are still T M's and P's."""

import numpy as np

from conftest import dense, solve_in_process
from helpers.scene import scene, shipped
from solvers.test_iterative_scenes import check_augmented_form


def _form(name: str, comm, **changes):
    """The augmented form, turned on where the preset would condense (solvers.condensed)."""
    text = scene(shipped(name), solver={"preset": "iterative", "petsc": {"condensed": "false"}},
                 **changes)
    system, solver, mat, rhs, x = solve_in_process(text, comm, options={})
    return system, solver, mat, system._augmented


def test_one_stiffness_block_for_operator_pmat_and_v_cycle(comm):
    """The friction box (rows of one node: Aᵀ A inside K's pattern): operator, P and the
    fieldsplit's q block are one matrix, of K's pattern (the entries of M's q rows in q
    columns, explicit zeros included), and no submatrix of K is kept beside it."""
    system, solver, mat, form = _form("contact_friction_3d.toml", comm, steps={"count": 1})
    block = form.pmat.getNestSubMatrix(0, 0)
    assert form.operator.getNestSubMatrix(0, 0).handle == block.handle
    q_ksp = solver.ksp.getPC().getFieldSplitSubKSP()[0]
    assert q_ksp.getOperators()[1].handle == block.handle
    assert form._k is None and form._coupled is None
    dm = system.dofmap
    q = np.concatenate([np.arange(dm.offsets[r], dm.offsets[r] + dm.owned(r)[1] - dm.owned(r)[0])
                        for r in range(comm.size)])
    indptr, cols, _ = mat.getValuesCSR()   # M's pattern, explicit zeros included
    nq = dm.owned()[1] - dm.owned()[0]
    in_k = comm.allreduce(int(np.isin(cols[:indptr[nq]], q).sum()))
    assert int(block.getInfo()["nz_used"]) == in_k   # (summed over the ranks)
    assert block.getBlockSize() == 3   # (GAMG aggregates nodes)


def test_coupled_rows_outside_the_stiffness_pattern_entry_by_entry(comm):
    """two_controls: a control row ties several nodes, its Aᵀ A is outside K's pattern: the
    stiffness block takes both patterns, and the operator is T M and P is T M with the coupled
    rows' γ_c/k Aᵀ A and the Schur fill, entry by entry (dense products)."""
    system, solver, mat, form = _form("two_controls.toml", comm)
    assert form._k is not None and form._coupled is not None
    mat = system.assemble()
    _, _, TM, P = check_augmented_form(system, mat)
    scale = np.abs(TM).max()
    assert np.abs(P - TM).max() > 1e-6 * scale   # (the coupled rows are there)
