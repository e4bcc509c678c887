"""Maximum control past the peak, where damage localizes (issue 8: the control plate refined 8×
and 16× stopped near t = 0.18).

At a converged state no material point is loading, so the first tangent of a step was the
unloading one in every cell: the control load could only grow, the first iterate loaded every
cell of the band next to the enforced one, and the next tangent, softening in all of them, was
nearly singular; the enforced row wandered from cell to cell (or came back, which fails the step)
and cut steps ended in null pivots. Now the first tangent has the enforced cell on its loading
branch and the others unloading, and the per-step predictor follows the enforced row's own
branch: past its peak (its rate under the control load negative), its value grows as the load
falls while the other rows unload.
"""


import numpy as np
import pytest
from mpi4py import MPI

from helpers.control import plate_newton
from parsolve.fem.element_matrices import BlockMatrices, ElementMatrices
from parsolve.solvers.policies import _branch_reach, _CellReplaced


def test_branch_reach_rising_and_past_the_peak():
    room = np.array([0.0, 1.0, 2.0, 4.0])   # s (b - A q): the enforced row 0 is at its value
    rate = np.array([2.0, 4.0, -1.0, 0.5])
    # the enforced row still rising: rows with r > 0 reach b at room / r
    np.testing.assert_array_equal(_branch_reach(rate, room, 2.0, 4.0), [0.0, 0.25, np.inf, 8.0])
    # past its peak (r < 0): only rows whose value grows as the load falls reach b
    rate = np.array([-2.0, 4.0, -1.0, 0.5])
    np.testing.assert_array_equal(_branch_reach(rate, room, -2.0, 4.0), [0.0, np.inf, 2.0, np.inf])


def test_cell_replaced_reduces_like_the_mixed_element_matrices():
    """Two evaluations' element matrices, cells 1 and 3 taken from the second: the same node
    blocks as a BlockMatrices built from the mixed values (one factored part, one full)."""
    rng = np.random.default_rng(3)
    nen, nc, npairs = 3, 5, 7
    slots = rng.integers(0, npairs + 1, size=(nen, nen, nc))  # npairs: owned elsewhere
    geo = rng.normal(size=(4, nen, nen, nc))
    tensors = rng.normal(size=(2, 4, 4))
    mat = np.array([0, 1, 1, 0, 1])
    base = BlockMatrices(2, [([0, 1], [0, 1], ElementMatrices(geometric=geo, tensors=tensors,
                                                              cell_material=mat), 1.0),
                             ([1], [1], ElementMatrices(values=rng.normal(size=(1, nen, nen, nc))),
                              0.5)])
    other = BlockMatrices(2, [([0, 1], [0, 1], ElementMatrices(values=rng.normal(size=(4, nen, nen, nc))), 1.0),
                              ([1], [1], ElementMatrices(values=rng.normal(size=(1, nen, nen, nc))), 0.5)])
    cells = np.array([1, 3])
    full0 = np.einsum("ckm,kabc->mabc", tensors[mat], geo)
    mixed = []
    for (ci, cj, m0, fac), (_, _, m1, _) in zip(base.parts, other.parts):
        v = (full0 if m0.values is None else m0.values).copy()
        v[..., cells] = m1.values[..., cells]
        mixed.append((ci, cj, ElementMatrices(values=v), fac))
    expected = BlockMatrices(2, mixed).reduce(slots, npairs)
    got = _CellReplaced(base, other, cells).reduce(slots, npairs)
    np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-13)


def test_plate_full_steps_through_the_peak():
    """The plate refined 2× per direction, 10 full steps (no cut) to t = 1/3. It used to fail at
    step 6 (t = 0.2): the enforced row moved 368 → 352 and would have gone back. Now every
    step converges with row 368 enforced at its value, no row above it, equilibrium
    F + D λ = f_int checked apart from Newton's residual; the load doubles in the elastic
    steps, peaks, then falls (softening) while the controlled strain keeps growing. Past the
    peak, the enforced row's rate under the control load is negative with its loading
    tangent (positive with the unloading one: the branch the first tangent used to take)."""
    comm = MPI.COMM_WORLD
    scene, model, system, newton, rel, free = plate_newton(2, 10)
    problem, policies = newton.problem, newton.problem.policies
    mine = system.dofmap.owned_dofs[free[system.dofmap.owned_dofs]]
    group, ids = problem.active.groups[0], problem.active.group_ids[0]

    def at(values: np.ndarray, row: int = 368) -> float:
        """A group row's value (``values``: per relation row held here) from its holder."""
        here = values[group][ids == row]
        return comm.allreduce(float(here[0]) if here.size else 0.0)

    lams, iterations = [], []
    for t in scene.times:
        states = problem.states
        iterations.append(newton.step(t).iterations)
        b = 1.2e-3 * t
        values = system.context.relation_primal(rel, problem.q)   # (the rows held here)
        enforced = np.concatenate(comm.allgather(ids[problem.active.active[group]]))
        assert enforced.tolist() == [368]
        np.testing.assert_allclose(at(problem.rset.primal_values(problem.q)), b, rtol=1e-9)
        assert comm.allreduce(float(values.max(initial=-np.inf)), op=MPI.MAX) <= b * (1 + 1e-7)
        lam = comm.allreduce(float(problem.rset.per_relation(problem.lam)[rel.name].sum()))
        f_int = system.composition.evaluate(problem.q, states, False)[1]
        dofs, pattern = rel.shared_dual
        force = model.external_load(t)
        force += system.context.local_vector(dofs, pattern * lam)   # (input DOFs to this rank's)
        r2, f2 = comm.allreduce(np.array([np.sum((force - f_int)[mine] ** 2),
                                          np.sum(f_int[mine] ** 2)]))
        assert np.sqrt(r2 / f2) < 1e-8
        lams.append(lam)
    lams = np.array(lams)
    np.testing.assert_allclose(lams[1], 2 * lams[0], rtol=1e-10)  # elastic below eps_d0
    peak = int(np.argmax(lams))
    assert 4 <= peak <= 7 and np.all(np.diff(lams[peak:]) < 0) and lams[-1] < 0.98 * lams[peak]
    assert max(iterations) <= 8

    # the branch past the peak: the enforced row's rate with either first tangent
    kmat = problem.form().kmat
    f = policies.dual_column(0)
    rset = system.context.relations
    unloading = at(rset.primal_values(policies.unit_response(kmat, group, f)))
    loading_tangent = policies.loading_tangent(kmat, problem.q, problem.states, problem.t_prev)
    loading = at(rset.primal_values(policies.unit_response(loading_tangent, group, f)))
    assert unloading > 0 > loading
    input_cells = model.mesh.global_cells[system.local_cells]
    np.testing.assert_array_equal(policies.enforced_cells(), np.flatnonzero(input_cells == 368))
