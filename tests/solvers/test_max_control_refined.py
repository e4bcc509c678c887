"""Maximum control past the onset of localization on a refined mesh (issue 8: the refined
control plate stopped at step 6 with null pivots).

Where damage localizes, the enforced row of the maximum group moves from cell to cell during a
full step's Newton iterations. When it wanted to come back to a row it had left, the active
set's cycling fallback (which knew single rows only) changed nothing yet reported a change at
every iteration: a row below the maximum stayed enforced, the iterates ran away (strains of
1e-2 to 10), Mazars' damage reached exactly 1 in whole cells, the nodes surrounded by them
lost all stiffness and MUMPS reported their null pivots (or, when the iterates did converge,
"active set did not settle"). A maximum group now fails the step at once when it would go
back to a row it left, so that the stepper cuts it; other groups cycle one change at a time.
"""

import numpy as np
import pytest
from mpi4py import MPI

from helpers.control import plate, plate_newton
from parsolve.errors import SolverError
from parsolve.relations import Relation
from parsolve.solvers.active_set import ActiveSet


def group(n: int, maximum: bool = True) -> ActiveSet:
    rel = Relation("max", n, np.arange(n), np.arange(n), np.ones(n), np.zeros(n), sense="<=",
                   maximum=maximum, groups=None if maximum else np.zeros(n, dtype=np.int64))
    aset = ActiveSet([rel], max_changes=6)
    aset.start_step()
    return aset


def test_maximum_group_does_not_go_back_to_a_row_it_left():
    aset = group(3)
    assert np.flatnonzero(aset.active).tolist() == [0]
    # an early iterate: row 1 is the largest, the group moves there
    assert aset.update(np.array([0.0, 0.2, -1.0]), np.zeros(3), 1e-12, 1e-12)
    assert np.flatnonzero(aset.active).tolist() == [1]
    # then row 2 (never enforced in this step): allowed
    assert aset.update(np.array([-0.3, 0.0, 0.1]), np.zeros(3), 1e-12, 1e-12)
    assert np.flatnonzero(aset.active).tolist() == [2]
    # row 0 exceeds the enforced row: the group would go back, the step fails at once
    with pytest.raises(SolverError, match=r"'max'.* from row 2 to row 0, which it left"):
        aset.update(np.array([0.1, -0.2, 0.0]), np.zeros(3), 1e-12, 1e-12)
    # a new step may enforce any row again
    aset.start_step()
    assert aset.update(np.array([0.1, -0.2, 0.0]), np.zeros(3), 1e-12, 1e-12)
    assert np.flatnonzero(aset.active).tolist() == [0]


def test_local_group_cycles_one_change_at_a_time():
    """A group that is not a maximum (solubility's states of a node) may come back to a row;
    the cycling fallback moves it (it used to leave it and report a change anyway)."""
    aset = group(2, maximum=False)
    assert aset.update(np.array([0.0, 0.2]), np.zeros(2), 1e-12, 1e-12)
    assert aset.update(np.array([0.1, 0.0]), np.zeros(2), 1e-12, 1e-12)
    assert np.flatnonzero(aset.active).tolist() == [0]
    assert not aset.update(np.array([0.0, -0.05]), np.zeros(2), 1e-12, 1e-12)
    assert aset.changes == 2
    with pytest.raises(SolverError, match="did not settle after 6 changes"):
        for _ in range(20):  # rows that exceed each other in turn forever: bounded
            aset.update(np.where(aset.active, 0.0, 0.1), np.zeros(2), 1e-12, 1e-12)


def test_full_step_at_the_onset_of_localization():
    """The plate refined 2× per direction, full steps (no cut). Steps 1-5: the enforced row at
    its value, no row above it, equilibrium F + D λ = f_int checked apart from Newton's own
    residual. Step 6 (t = 0.2), where damage localizes, converges in one full step with row 368
    still enforced at its value (it used to fail: the enforced row moved 368 → 352 and would
    have gone back; see test_max_control_localization.py)."""
    comm = MPI.COMM_WORLD
    scene, model, system, newton, rel, free = plate_newton(2, 6)
    problem = newton.problem
    ids = rel.row_ids()   # (the rows each rank holds: its cells')

    def enforced() -> list:
        """The group's enforced rows over every rank, by number."""
        return np.concatenate(comm.allgather(ids[problem.active.active])).tolist()

    def value_at(values: np.ndarray, row: int = 368) -> float:
        here = values[ids == row]
        return comm.allreduce(float(here[0]) if here.size else 0.0)

    lams = []
    for t in scene.times[:5]:
        states = problem.states
        newton.step(t)
        b = 1.2e-3 * t
        values = system.context.relation_primal(rel, problem.q)
        assert enforced() == [368]
        np.testing.assert_allclose(value_at(values), b, rtol=1e-9)
        assert comm.allreduce(float(values.max(initial=-np.inf)), op=MPI.MAX) <= b * (1 + 1e-7)
        lam = comm.allreduce(float(problem.rset.per_relation(problem.lam)[rel.name].sum()))
        # f_int from this rank's cells is exact on the DOFs it owns
        f_int = system.composition.evaluate(problem.q, states, False)[1]
        dofs, pattern = rel.shared_dual
        force = model.external_load(t)
        force += system.context.local_vector(dofs, pattern * lam)   # (input DOFs to this rank's)
        mine = system.dofmap.owned_dofs[free[system.dofmap.owned_dofs]]
        r2, f2 = comm.allreduce(np.array([np.sum((force - f_int)[mine] ** 2),
                                          np.sum(f_int[mine] ** 2)]))
        assert np.sqrt(r2 / f2) < 1e-8
        lams.append(lam)
    # steps 1 and 2 are elastic (no damage below eps_d0 = 1e-4): the load doubles exactly
    np.testing.assert_allclose(lams[1], 2 * lams[0], rtol=1e-10)
    newton.step(scene.times[5])  # the onset of localization in one full step
    assert enforced() == [368]
    np.testing.assert_allclose(value_at(system.context.relation_primal(rel, problem.q)),
                               1.2e-3 * scene.times[5], rtol=1e-9)


def test_refined_plate_follows_localization_with_cut_steps(run):
    """The plate refined 3× per direction through t = 11/30 with the stepper's cuts: it
    failed at t = 0.334 before (Newton stalled in a two-cycle after 4 cuts); now every step
    finishes, each with one enforced row at its value and no row above it."""
    steps = 11
    res = run(plate(3, steps), name="plate3")
    assert res["attrs"]["status"] == "complete"
    t = res["steps/time"]
    np.testing.assert_allclose(t[-1], steps / 30, rtol=1e-12)
    primal = res["relations/max_strain/primal"]
    active = res["relations/max_strain/active"].astype(bool)
    assert np.all(active.sum(axis=1) == 1)
    b = 1.2e-3 * t
    np.testing.assert_allclose(primal[active], b, rtol=1e-9)
    assert np.all(primal.max(axis=1) <= b * (1 + 1e-7))
    lam = res["relations/max_strain/multiplier"][active]
    np.testing.assert_allclose(lam[1], 2 * lam[0], rtol=1e-10)
    assert lam.max() > 1.5 * lam[1] > 0  # the load went on growing past the elastic range
