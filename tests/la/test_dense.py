"""The distributed saddle system of a small non-associated scene, gathered and solved densely."""

import numpy as np
import pytest
from mpi4py import MPI

from conftest import dense, saddle_of_input_dofs, solve_in_process, whole_points
from helpers.saddle import SCENE
from helpers.scene import CONFIGS
from helpers.scales import whole_scales
from parsolve.outputs import every_row

@pytest.mark.parametrize("preset, eliminate", [("direct", "true"), ("direct", "false"),
                                               ("iterative", "true"), ("iterative", "false")])
def test_matches_dense_numpy_solve(preset, eliminate):
    """(Without elimination the stiffness block is singular, every Dirichlet row a
    multiplier: the iterative preset's augmented preconditioner holds it.)"""
    comm = MPI.COMM_WORLD
    system, solver, mat, rhs, x = solve_in_process(
        SCENE.format(cell="quad", preset=preset, eliminate=eliminate))
    M = dense(mat)
    b = np.concatenate(comm.allgather(rhs.array.copy()))
    xs = np.concatenate(comm.allgather(x.array.copy()))
    xd = np.linalg.solve(M, b)
    assert np.abs(xs - xd).max() <= 1e-10 * np.abs(xd).max()
    assert not np.allclose(M, M.T)  # the control relation makes it unsymmetric


def test_operator_blocks_are_what_the_relations_say():
    """In input numbering: K symmetric with rigid modes in its kernel, A and -D as defined."""
    system, solver, mat, rhs, x = solve_in_process(SCENE.format(cell="triangle", preset="direct",
                                                                eliminate="false"))
    M = dense(mat)
    iq, il = saddle_of_input_dofs(MPI.COMM_WORLD, system), system.dofmap.saddle_of_mult
    K = M[np.ix_(iq, iq)]
    assert np.abs(K - K.T).max() <= 1e-12 * np.abs(K).max()
    pts = whole_points(MPI.COMM_WORLD, system.model.mesh)
    rigid = np.column_stack([np.tile([1.0, 0.0], len(pts)), np.tile([0.0, 1.0], len(pts)),
                             np.column_stack([-pts[:, 1], pts[:, 0]]).ravel()])
    assert np.abs(K @ rigid).max() <= 1e-11 * np.abs(K).max()
    blk = system.relation_set
    row_scale, col_scale = whole_scales(blk)
    for k, rel in enumerate(system.multiplied):   # (a relation built per rank: its rows here)
        if rel.nrows == 0:
            continue
        rows = il[blk.mult_rows[k]]
        a_entries, d_entries = (rel.a_rows, rel.a_dofs, rel.a_vals), rel.dual_coo()
        if rel.spread:   # (its entries on their DOFs' owners: every rank's)
            a_entries, d_entries = ([np.concatenate(MPI.COMM_WORLD.allgather(x)) for x in e]
                                    for e in (a_entries, d_entries))
        A = np.zeros((rel.nrows, len(iq)))
        np.add.at(A, (a_entries[0], a_entries[1]), a_entries[2])
        scale = row_scale[blk.mult_rows[k]]
        np.testing.assert_allclose(M[np.ix_(rows, iq)], A * scale[:, None], rtol=0, atol=1e-12 * scale.max())
        D = np.zeros((len(iq), rel.nrows))
        dofs, drows, dvals = d_entries
        np.add.at(D, (dofs, drows), dvals)
        cs = col_scale[blk.mult_rows[k]]
        np.testing.assert_allclose(M[np.ix_(iq, rows)], -D * cs[None, :], rtol=0, atol=1e-12 * cs.max())


#: the periodic laminate with its Dirichlet rows multiplied: ties across the ranks (a tie's
#: D column and A row on another rank's DOF) and Dirichlet rows, each built on its rank
PERIODIC = (CONFIGS / "periodic_shear_laminate.toml").read_text(encoding="utf-8") \
    + "\n[solver]\neliminate = false\n"


@pytest.mark.parametrize("scene", ["saddle", "periodic"])
def test_operator_does_not_depend_on_rank_count(scene):
    """The same matrix, in input numbering, on this communicator and on one rank alone; the
    same solution."""
    text = SCENE.format(cell="quad", preset="direct", eliminate="false") if scene == "saddle" \
        else PERIODIC
    par = solve_in_process(text, MPI.COMM_WORLD)
    ser = solve_in_process(text, MPI.COMM_SELF)

    def in_input_order(system, mat, comm):
        M = dense(mat, comm)
        # multipliers in stacking order (their numbering follows their owners)
        mult = system.dofmap.saddle_of_mult[stacking_order(system.relation_set, comm)]
        order = np.concatenate([saddle_of_input_dofs(comm, system), mult])
        return M[np.ix_(order, order)]

    Mp = in_input_order(par[0], par[2], MPI.COMM_WORLD)
    Ms = in_input_order(ser[0], ser[2], MPI.COMM_SELF)
    assert np.abs(Mp - Ms).max() <= 1e-13 * np.abs(Ms).max()
    # the multipliers by relation, every row from its rank: those of one rank alone
    for k, r in enumerate(par[0].multiplied):
        lam_p = par[0].relation_set.relation_values(k, par[0].multipliers(par[0].gather(
            par[4].array)))
        lam_p = every_row(MPI.COMM_WORLD, r, lam_p)
        lam_s = ser[0].relation_set.relation_values(k, ser[0].multipliers(ser[0].gather(
            ser[4].array)))
        np.testing.assert_allclose(lam_p, lam_s, rtol=0, atol=1e-12 * np.abs(lam_s).max())


def stacking_order(rs, comm) -> np.ndarray:
    """Every multiplier row in stacking order (relation by relation, each relation's rows in
    their order over every rank), each from its owner (a relation built per rank holds its
    rows on their ranks). Collective."""
    first = np.concatenate([[0], np.cumsum([r.total for r in rs.relations])])
    key = np.concatenate([first[k] + r.row_ids() for k, r in enumerate(rs.relations)])
    mine = rs.owned_relrows
    pairs = np.concatenate(comm.allgather(np.column_stack([key[mine], rs.mult_of_row[mine]])))
    return pairs[np.argsort(pairs[:, 0]), 1]


def test_singular_system_is_an_error_not_garbage():
    """mean ux(right) - 2 mean ux(mid) vanishes for any uniform stretch, which the pull produces:
    the saddle system is singular. MUMPS must say so (null pivot), never return garbage."""
    from parsolve.errors import SolverError

    text = SCENE.format(cell="quad", preset="direct", eliminate="true").replace(
        "coefficient = -1.0, mean = true", "coefficient = -2.0, mean = true")
    with pytest.raises(SolverError, match="singular"):
        solve_in_process(text)


def test_elimination_and_multipliers_agree(run):
    """Single-DOF conditions eliminated or multiplied: same displacements, same reactions."""
    text = SCENE.format(cell="triangle", preset="direct", eliminate="{eliminate}")
    a = run(text.replace("{eliminate}", "true"), name="elim")
    b = run(text.replace("{eliminate}", "false"), name="mult")
    u = a["fields/displacement"]
    assert np.abs(u - b["fields/displacement"]).max() <= 1e-10 * np.abs(u).max()
    for name in ("left_x", "corner_y", "top_flat", "opening"):
        x, y = a[f"relations/{name}/multiplier"], b[f"relations/{name}/multiplier"]
        assert np.abs(x - y).max() <= 1e-9 * max(np.abs(y).max(), 1e-300), name
