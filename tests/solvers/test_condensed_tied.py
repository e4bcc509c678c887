"""Rows tying a slave node to master nodes (solvers.tied), condensed on the slave: on the 3D
ironing's node-to-face rows (friction: a non-associated dual) and the coarsened mortar sphere's
dual mortar rows, with an exact solve of S the preconditioner is M⁻¹ (dense solve as the
reference), S is G K H + k on the constrained slots with G and H made densely from M, and a
row whose master holds hard rows of its own (a chain) is refused with its reason."""

import numpy as np
import pytest
from petsc4py import PETSc

from conftest import CONFIGS, dense, solve_in_process
from helpers.scene import scene, shipped
from parsolve.solvers import options as opt
from parsolve.solvers.condensed import REASONS, CondensedPreconditioner


def _ironing() -> str:
    data = shipped("contact_ironing_3d.toml")
    data["mesh"]["file"] = str(CONFIGS / data["mesh"]["file"])
    return scene(data, steps={"times": [0.05]}, solver={"preset": "iterative"})


def _mortar() -> str:
    return scene(shipped("contact_mortar_sphere_3d.toml"), solver={"preset": "iterative"},
                 mesh={"n_fine": 4, "n_coarse": 2, "n_depth": 3})


SCENES = {"ironing": _ironing, "mortar": _mortar}


def _exact(comm, system, mat, prefix: str) -> CondensedPreconditioner:
    """The condensed preconditioner on ``mat`` with LU (MUMPS) on S."""
    is_q, is_l = system.index_sets()
    pre = CondensedPreconditioner(comm, 3, is_q, is_l, prefix)
    with opt.inserted(prefix, {"condensed_pc_type": "lu",
                               "condensed_pc_factor_mat_solver_type": "mumps"}):
        assert pre.update(mat) is None
    return pre


def _primal(pre, comm) -> np.ndarray:
    """The saddle indices of every rank's primal rows (S's numbering, in order)."""
    return np.concatenate([pre.starts[r] + np.arange(pre.nqs[r]) for r in range(comm.size)])


def _multipliers(pre, comm) -> np.ndarray:
    return np.concatenate([pre.starts[r] + pre.nqs[r]
                           + np.arange(pre.starts[r + 1] - pre.starts[r] - pre.nqs[r])
                           for r in range(comm.size)])


@pytest.mark.parametrize("name", sorted(SCENES))
def test_exact_condensation_is_the_inverse(comm, name):
    """The preset condenses the tied rows, and with LU on S the preconditioner applied to a
    random r is M⁻¹ r."""
    system, solver, mat, rhs, x = solve_in_process(SCENES[name](), comm, options={})
    assert solver.choice == "condensed"
    pre = _exact(comm, system, mat, f"tied_{name}_")
    assert comm.allreduce(pre.hard.size) > 0 and comm.allreduce(pre.tie_a[0].size) > 0
    r = rhs.duplicate()
    r.setRandom()
    z = r.duplicate()
    pre.apply(None, r, z)
    reference = np.linalg.solve(dense(mat, comm), np.concatenate(comm.allgather(r.array.copy())))
    got = np.concatenate(comm.allgather(z.array.copy()))
    # (the coarsest mortar sphere's S has a condition number of 1.5e8: master weights
    # M_ia / w_i up to 248 at barely covered slave nodes, and LU on S is exact to about that)
    assert np.abs(got - reference).max() <= 1e-8 * np.abs(reference).max()


def _frames(pre, comm, M: np.ndarray):
    """G and H (dense, primal × primal) from the dense M and the per-node blocks: the nodal
    frames, H's slave rows − lift A_m (each hard row's A off its slave), G's master rows
    − B_m dual (its dual off the slave)."""
    nc = pre.nc
    q, lam = _primal(pre, comm), _multipliers(pre, comm)
    n = q.size
    G, H = np.eye(n), np.eye(n)
    A, B = M[np.ix_(lam, q)], M[np.ix_(q, lam)]
    first = pre.q_start // nc
    l_first = [int(sum(pre.starts[s + 1] - pre.starts[s] - pre.nqs[s] for s in range(r)))
               for r in range(comm.size + 1)]
    parts = comm.allgather((pre.nodes + first, pre.g, pre.h, pre.lift, pre.dual, pre.keep,
                            pre.hard + l_first[comm.rank], pre.hard_at, pre.hard_pos))
    for nodes, g, h, *_ in parts:
        for a in range(nc):
            for b in range(nc):
                G[nodes * nc + a, nodes * nc + b] = g[:, a, b]
                H[nodes * nc + a, nodes * nc + b] = h[:, a, b]
    keep = np.zeros(n)
    for nodes, g, h, lift, dual, kp, rows, at, pos in parts:
        keep[(nodes[:, None] * nc + np.arange(nc))[kp]] = 1.0
        for row, k, p in zip(rows, at, pos):
            dofs = nodes[k] * nc + np.arange(nc)
            off = np.ones(n, dtype=bool)
            off[dofs] = False
            H[np.ix_(dofs, off)] -= np.outer(lift[k][:, p], A[row, off])
            G[np.ix_(off, dofs)] -= np.outer(B[off, row], dual[k][p, :])
    return G, H, keep


@pytest.mark.parametrize("name", sorted(SCENES))
def test_condensed_operator_is_the_product(comm, name):
    """S (PETSc's triple product of the sparse G, K, H) equals G K H + k on the constrained
    slots with G and H made densely from M, entry by entry to 1e-13 of its largest entry;
    G ≠ Hᵀ where the dual is not associated (the ironing's friction)."""
    system, solver, mat, rhs, x = solve_in_process(SCENES[name](), comm, options={})
    pre = _exact(comm, system, mat, f"product_{name}_")
    M = dense(mat, comm)
    G, H, keep = _frames(pre, comm, M)
    q = _primal(pre, comm)
    reference = G @ M[np.ix_(q, q)] @ H + pre.kscale * np.diag(keep)
    S = dense(pre.S, comm)
    assert np.abs(S - reference).max() <= 1e-13 * np.abs(reference).max()
    assert np.abs(dense(pre.G, comm) - G).max() <= 1e-13 * np.abs(G).max()
    assert np.abs(H - np.eye(q.size)).max() > 0.1   # (frames and ties that move the columns)


def test_a_master_with_hard_rows_is_a_chain(comm):
    """The ironing's operator with one hard row given an entry (in M's pattern) on another
    row's slave node: that node becomes a master holding hard rows, the reason is the chain's,
    the same on every rank."""
    system, solver, mat, rhs, x = solve_in_process(_ironing(), comm, options={})
    pre = _exact(comm, system, mat, "chain_probe_")
    slaves = np.concatenate(comm.allgather(pre.q_start // 3 + pre.nodes[pre.keep.any(axis=1)]))
    assert slaves.size >= 2
    target = slaves[1]   # (a slave node; its first DOF's saddle index)
    owner = np.searchsorted(np.cumsum(pre.nqs) // 3, target, side="right")
    column = pre.starts[owner] + (target * 3 - pre.nqs[:owner].sum())
    indptr, cols, vals = mat.getValuesCSR()
    vals = vals.copy()
    n = indptr.size - 1
    rows = np.repeat(np.arange(n), np.diff(indptr))
    # the first hard row of slave 0 (on its rank) gets the entry: in a new pattern
    first = slaves[0]
    mine = pre.q_start // 3 <= first < (pre.q_start + pre.nq) // 3
    extra_row = -1
    if mine:
        k = int(np.searchsorted(pre.nodes, first - pre.q_start // 3))
        extra_row = pre.nq + int(pre.hard[np.flatnonzero(pre.hard_at == k)[0]])
    keys = np.concatenate([rows * np.int64(mat.getSize()[1]) + cols,
                           [extra_row * np.int64(mat.getSize()[1]) + column]
                           if extra_row >= 0 else []]).astype(np.int64)
    values = np.concatenate([vals, [0.5 * pre.kscale] if extra_row >= 0 else []])
    order = np.argsort(keys)
    keys, values = keys[order], values[order]
    width = np.int64(mat.getSize()[1])
    counts = np.bincount(keys // width, minlength=n)
    tied = PETSc.Mat().createAIJ(size=((n, None), (n, None)), comm=comm,
                                 csr=(np.concatenate([[0], np.cumsum(counts)]).astype(
                                     PETSc.IntType), (keys % width).astype(PETSc.IntType),
                                      values))
    is_q, is_l = system.index_sets()
    chained = CondensedPreconditioner(comm, 3, is_q, is_l, "chain_")
    assert chained.update(tied) == REASONS[9]


@pytest.mark.parametrize("cleared", [False, True], ids=["kept", "cleared"])
@pytest.mark.parametrize("name", sorted(SCENES))
def test_operator_reused_while_the_pattern_stays(comm, name, cleared):
    """A second update on new values in the same pattern (K's diagonal raised, every tied
    row's master entries × 1.1: X, hence H, changes) fills G, H and X in place and reuses S's
    triple product (the same matrices); S then equals G K H + k of the new M, made densely, to
    1e-13 of its largest entry. With the user's ``-mat_product_clear`` (the product's data
    freed, which PETSc cannot reuse: it aborted) S is made anew instead, equal alike."""
    options = PETSc.Options()
    if cleared:
        options["mat_product_clear"] = "true"
    try:
        _reused(comm, name, cleared)
    finally:
        if cleared:
            options.delValue("mat_product_clear")


def _reused(comm, name: str, cleared: bool) -> None:
    system, solver, mat, rhs, x = solve_in_process(SCENES[name](), comm, options={})
    pre = _exact(comm, system, mat, f"reuse_{name}_")
    handles = [m.handle for m in (pre.G, pre.H, pre.X)]
    S = pre.S   # (held: a new S cannot take its Python identity, as it could its address)
    H0 = dense(pre.H, comm)
    mat = mat.copy()
    lo = mat.getOwnershipRange()[0]
    rows = (lo + np.arange(pre.nq)).astype(PETSc.IntType)
    for i, row in enumerate(rows):
        mat.setValue(row, row, (0.1 + 0.05 * (i % 3)) * pre.kscale, addv=True)
    mat.assemble()
    r, g, v = pre.tie_a
    owner = np.searchsorted(np.cumsum(pre.nqs), g, side="right")
    cols = pre.starts[owner] + g - np.concatenate([[0], np.cumsum(pre.nqs)])[owner]
    for row, col, value in zip(pre.start + pre.nq + r, cols, v):
        mat.setValue(int(row), int(col), 1.1 * value)
    mat.assemble()
    with opt.inserted(f"reuse_{name}_", {"condensed_pc_type": "lu",
                                         "condensed_pc_factor_mat_solver_type": "mumps"}):
        pre._handle = mat.handle   # (the operator's copy stands for the same operator)
        assert pre.update(mat) is None
    assert [m.handle for m in (pre.G, pre.H, pre.X)] == handles
    assert (pre.S is not S) == cleared
    M = dense(mat, comm)
    G, H, keep = _frames(pre, comm, M)
    q = _primal(pre, comm)
    reference = G @ M[np.ix_(q, q)] @ H + pre.kscale * np.diag(keep)
    assert np.abs(dense(pre.S, comm) - reference).max() <= 1e-13 * np.abs(reference).max()
    assert np.abs(dense(pre.H, comm) - H).max() <= 1e-13 * np.abs(H).max()
    assert comm.allreduce(v.size) == 0 or np.abs(H - H0).max() > 1e-3 * np.abs(H0).max()
