"""Maximum control past the onset of localization on a refined mesh (issue 8: the refined
control plate stopped at step 6 with null pivots).

Cause: at the step where damage localizes, the enforced row of the maximum group moves to
another cell during the Newton iterations and must come back to one it left. The set it
comes back to had been seen (at an iterate far from equilibrium), so the active set's cycling
fallback ran; that fallback only knew single rows, not groups: it changed nothing, yet
reported a change at every iteration. The wrong row stayed enforced, the iterates ran away
(strains of 1e-2 to 10), Mazars' damage reached exactly 1 in whole cells, the nodes surrounded
by them lost all stiffness and MUMPS found their null pivots; on a step whose iterates do
converge, the same fallback failed it with "active set did not settle".
"""

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from conftest import CONFIGS
from parsolve.relations import Relation
from parsolve.solvers.active_set import ActiveSet


def group(n: int) -> ActiveSet:
    rel = Relation("max", n, np.arange(n), np.arange(n), np.ones(n), np.zeros(n), sense="<=",
                   maximum=True)
    aset = ActiveSet([rel], max_changes=6)
    aset.start_step()
    return aset


def test_group_returns_to_a_row_it_left():
    aset = group(3)
    assert np.flatnonzero(aset.active).tolist() == [0]
    # an early iterate: row 1 is the largest, the group moves there
    assert aset.update(np.array([0.0, 0.2, -1.0]), np.zeros(3), 1e-12, 1e-12)
    assert np.flatnonzero(aset.active).tolist() == [1]
    # at equilibrium with row 1 enforced, row 0 exceeds it: back to row 0 (a set already seen)
    assert aset.update(np.array([0.1, 0.0, -1.0]), np.zeros(3), 1e-12, 1e-12)
    assert np.flatnonzero(aset.active).tolist() == [0]
    # row 0 enforced, the others below: settled, after two changes
    assert not aset.update(np.array([0.0, -0.05, -1.0]), np.zeros(3), 1e-12, 1e-12)
    assert aset.changes == 2


def test_group_cycling_stays_bounded():
    """Two rows that exceed each other in turn forever: an error after max_changes."""
    aset = group(2)
    from parsolve.errors import SolverError

    with pytest.raises(SolverError, match="did not settle after 6 changes"):
        for _ in range(20):
            gap = np.where(aset.active, 0.0, 0.1)
            aset.update(gap, np.zeros(2), 1e-12, 1e-12)


def plate(level: int, steps: int) -> str:
    text = (CONFIGS / "plate_hole_control.toml").read_text()
    text = text.replace("n_radial = 8", f"n_radial = {8 * level}")
    text = text.replace("n_angular = 12", f"n_angular = {12 * level}")
    return text.replace("count = 30", f"count = {steps}\nend = {steps / 30}")


def test_refined_plate_passes_the_onset_of_localization():
    """The plate refined 2× per direction, six full steps of the scene (no step cut): step 6
    failed with 1 null pivot before. Every step: the enforced row at its value, no row above
    it, and equilibrium F + D λ = f_int checked apart from Newton's own residual."""
    from parsolve.driver import make_solver
    from parsolve.model import build_model
    from parsolve.scene import parse_scene
    from parsolve.solvers.newton import NewtonSolver
    from parsolve.solvers.system import SaddleSystem

    comm = MPI.COMM_WORLD
    text = plate(2, 6)
    scene = parse_scene(tomllib.loads(text), "plate.toml", text)
    model = build_model(scene)
    system = SaddleSystem(comm, model)
    newton = NewtonSolver(comm, system, make_solver(comm, system, {}), scene.nonlinear)
    (rel,) = [r for r in system.multiplied if r.maximum]
    free = np.ones(model.mesh.num_points * model.ncomp, dtype=bool)
    free[system.elim_dofs] = False
    lams = []
    for t in scene.times:
        states = newton.states
        newton.step(t)
        b = rel.rhs(t)[0]
        values = rel.primal(newton.q)
        enforced = np.flatnonzero(newton.active.active)
        assert enforced.size == 1
        np.testing.assert_allclose(values[enforced], b, rtol=1e-9)
        assert values.max() <= b * (1 + 1e-7)
        lam = float(newton.lam[0])
        # f_int from this rank's cells is exact on the DOFs it owns
        f_int = system.composition.evaluate(newton.q, states, False)[1]
        dofs, pattern = rel.shared_dual
        force = model.external_load(t)
        np.add.at(force, dofs, pattern * lam)
        mine = system.owned_input_dofs[free[system.owned_input_dofs]]
        r2, f2 = comm.allreduce(np.array([np.sum((force - f_int)[mine] ** 2),
                                          np.sum(f_int[mine] ** 2)]))
        assert np.sqrt(r2 / f2) < 1e-8
        lams.append(lam)
    # steps 1 and 2 are elastic (no damage below eps_d0 = 1e-4): the load doubles exactly
    np.testing.assert_allclose(lams[1], 2 * lams[0], rtol=1e-10)
    assert len(lams) == 6 and lams[5] > lams[4] > 0
