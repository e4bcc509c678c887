"""A secant-matrix run stops, named, at the first unstable equilibrium, at the same step on
every rank count (parsolve/solvers/stability.py).

The localization bar (configs/localization_bar.toml) with every cell Mazars, pulled by a mean
end-displacement control (or a prescribed end displacement): the bar stays homogeneous, elastic
up to ε = εd0 = 1e-4 at step 10, then softens everywhere alike. That branch is unstable (any
column may localize), and a secant iteration followed it until round-off pulled it off, at a
step and onto a branch that depended on the partition: on main the run warned of a branch
jump on one rank count and failed with null pivots on another. The consistent tangent with the
relations held tells at step 11 on every rank count; the count is compared with a dense
eigenvalue computation of the same tangent on the null space of the enforced rows.

A maximum control holds every row at its value, the enforced one as an equality and the others
one-sided: the check holds them all (a count that is then at most the one-sided problem's, so
an unstable count is unstable for sure). The localization bar with its maximum control is
stable at every step by that count (test_control's closed form runs under the check)."""

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from conftest import read_results
from helpers.control import BAR, E, H, L, newton_of
from helpers.scene import DROP, scene, shipped

from parsolve.errors import SolverError
from parsolve.solvers.stability import SHIFT, at_maximum, negative_pivots, owned_row_entries, \
    unstable_modes

STEPS, PEAK = 24, 10            # ε = 1e-5 a step: εd0 = 1e-4 at step 10
MAZARS = {"model": "mazars", "E": E, "nu": 0.0, "eps_d0": 1e-4, "At": 1.0, "Bt": 1e4,
          "Ac": 1.2, "Bc": 1500.0, "beta": 1.06}
BASE = shipped("localization_bar.toml")
HELD = BASE["relations"][:3]    # left_x, corner_y, right_rigid
MEAN = {"name": "control", "type": "mean", "region": "right", "component": "x",
        "value": 2.4e-4, "dual": "pull"}
END = {"name": "end_displacement", "type": "dirichlet", "region": "end", "components": ["x"],
       "value": 2.4e-4}
MODES = 56                      # the homogeneous softening bar's, at step 11 (dense count)


def damaged_everywhere(control: str) -> str:
    """Every cell Mazars; ``control``: "mean" (a controlled pull) or "end" (a prescribed
    displacement of the end's corner, the end rigid in x)."""
    if control == "mean":
        return scene(BASE, materials=[MAZARS], relations=HELD + [MEAN], output=DROP)
    regions = {"corner": BASE["regions"]["corner"], "end": {"point": [1.0, 0.0]}}
    return scene(BASE, materials=[MAZARS], relations=HELD + [END], regions=regions,
                 loads=DROP, output=DROP)


@pytest.mark.parametrize("control", ["mean", "end"])
def test_the_run_stops_at_the_first_unstable_step(run, control):
    with pytest.raises(SolverError) as info:
        run(damaged_everywhere(control), name=control)
    message = str(info.value)
    assert message.startswith(f"the equilibrium at step {PEAK + 1} (t = "
                              f"{(PEAK + 1) / STEPS:.6g}) is unstable")
    assert f"has {MODES} negative eigenvalue(s)" in message
    assert f"after t = {PEAK / STEPS:.6g}" in message
    res = read_results(run.last)
    assert res["attrs"]["status"] == f"failed: {message}"
    # the stable steps are kept: the elastic bar up to the peak, the support's reaction
    # E H δ / L
    t = res["steps/time"]
    np.testing.assert_allclose(t, np.arange(1, PEAK + 1) / STEPS, rtol=1e-12)
    force = np.abs(res["relations/left_x/multiplier"].sum(axis=1))
    np.testing.assert_allclose(force, E * H * 2.4e-4 * t / L, rtol=1e-9)
    assert np.abs(res["cell_fields/damage"]).max() < 1e-12   # (the peak: round-off)


def test_a_maximum_control_holds_every_row_at_its_value():
    """The localization bar under its maximum control, stepped through the Newton solver past
    its peak (step 2, ε = 1e-4): from step 3 on, the damaged column's three cells are at the
    maximum, one enforced. With the enforced row alone held, the other two could soften past
    it: one negative eigenvalue, a stable localization read as unstable. With the two held as
    well (one-sided in the run: they may not pass the value) none: the run goes on. Each count
    equal to a dense eigenvalue computation on the null space of the rows held."""
    _, _, system, problem, newton = newton_of(BAR)
    counts = []
    for step in range(1, 5):
        states = problem.snapshot()[3]
        newton.step(step / STEPS)
        extra = np.flatnonzero(at_maximum(problem, problem.q))   # (the rows held here)
        counts.append((MPI.COMM_WORLD.allreduce(extra.size), unstable_modes(problem, states),
                       _dense_count(problem, states, extra), _dense_count(problem, states)))
    assert counts[2:] == [(2, 0, 0, 1), (2, 0, 0, 1)]


def test_the_count_is_the_tangents_on_the_held_space():
    """Stepped through the Newton solver: 0 at the peak (the damaged cells' tangent vanishes
    there: eigenvalues of round-off, which the shift leaves out), 56 at the step after it, each
    equal to the count of a dense eigenvalue computation."""
    _, _, system, problem, newton = newton_of(damaged_everywhere("mean"))
    counts = []
    for step in range(1, PEAK + 2):
        states = problem.snapshot()[3]
        newton.step(step / STEPS)
        if step >= PEAK:
            counts.append((unstable_modes(problem, states), _dense_count(problem, states)))
    assert counts == [(0, 0), (MODES, MODES)]


def _dense_count(problem, states, extra=()) -> int:
    """Eigenvalues below -δ k of Zᵀ (K + Kᵀ)/2 Z, K the consistent tangent assembled, Z an
    orthonormal basis of the null space of the enforced rows and the relation rows ``extra``
    (numpy, on every rank)."""
    comm, system = MPI.COMM_WORLD, problem.system
    kmat = system.composition.evaluate(problem.q, states, False, system.rate)[2]
    mat = problem.jacobian(kmat)
    whole = np.concatenate(comm.allgather(mat.convert("dense", PETSc.Mat()).getDenseArray()))
    is_q, is_l = system.index_sets()
    iq = np.concatenate(comm.allgather(is_q.getIndices()))
    il = np.concatenate(comm.allgather(is_l.getIndices()))
    k, a = whole[np.ix_(iq, iq)], whole[np.ix_(il, iq)]
    a = a[np.abs(a).sum(axis=1) > 0]                    # the enforced rows
    a = np.vstack([a, _primal_rows(problem, np.asarray(extra, dtype=np.int64), iq)])
    _, sv, vt = np.linalg.svd(a)
    z = vt[np.count_nonzero(sv > 1e-12 * sv.max()):].T
    ev = np.linalg.eigvalsh(z.T @ (0.5 * (k + k.T)) @ z)
    return int(np.count_nonzero(ev < -SHIFT * system.kscale))


def _primal_rows(problem, rows: np.ndarray, iq: np.ndarray) -> np.ndarray:
    """The relation rows ``rows`` (held here; each rank its own) as A on the primal block's
    columns (their held DOFs left out; every rank's rows gathered here for the dense
    check)."""
    order = np.argsort(iq)
    out = []
    for got in MPI.COMM_WORLD.allgather(owned_row_entries(problem, rows)):
        for place in np.unique(got["row"]):
            row = got[got["row"] == place]
            where = order[np.searchsorted(iq, row["saddle"], sorter=order)]
            out.append(np.zeros(iq.size))
            np.add.at(out[-1], where, row["val"])
    return np.array(out).reshape(-1, iq.size)


@pytest.mark.parametrize("diagonal, count", [([1.0, -1.0, -2.0, 3.0], 2),
                                             ([1.0, -1.0, 0.0, 3.0], None)])
def testnegative_pivots_or_none_when_singular(diagonal, count):
    """The LDLᵀ's inertia of a diagonal matrix spread over the ranks; a null pivot: None."""
    comm = MPI.COMM_WORLD
    n = len(diagonal)
    mat = PETSc.Mat().createAIJ((n, n), nnz=1, comm=comm)
    lo, hi = mat.getOwnershipRange()
    for i in range(lo, hi):
        mat.setValue(i, i, diagonal[i])
    mat.assemble()
    assert negative_pivots(comm, mat) == count
