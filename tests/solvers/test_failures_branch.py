"""The branch-jump warning is the solution path's, not the steps'.

A step that fails is cut in two until it passes; with the scene's fixed steps the rest of the
step is then taken whole: cut four times, a step leaves an intermediate step of 1/16 and a rest
of 15/16, whose increments on one and the same branch differ about 15×. Compared plainly, that
read as a jump to another branch ("the increment is 14× the previous one") on the rank count
where the step happened to be cut, and not on another. The increments are compared per unit of
the load parameter: the cut run follows the uncut run's branch and warns on no step, whatever
the ranks; a real jump (an increment per unit of the parameter ten times the previous one)
still warns."""

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from helpers.scene import scene, shipped

from parsolve.cli import main
from parsolve.driver import BranchWatch
from parsolve.errors import SolverError
from parsolve.solvers.newton import NewtonSolver

COUNT = 24
CUT_AFTER = 4      # the scene's step after which the next one fails four times
CUTS = 4


def test_watch_compares_increments_per_unit_of_the_parameter():
    watch = BranchWatch(nonlinear=True)
    assert watch.check(2.0, None, 1.0) is None
    assert watch.check(2.0 / 16, None, 1.0 / 16) is None        # a cut step: same rate
    assert watch.check(2.0 * 15 / 16, None, 15.0 / 16) is None  # its rest, 15× larger
    assert "14× the previous one" in watch.check(28.0, None, 1.0)   # a real jump
    assert "negative pivots went from 0 to 1" in _pivots()


def _pivots() -> str:
    watch = BranchWatch(nonlinear=True)
    watch.check(1.0, 0, 1.0)
    return watch.check(1.0, 1, 1.0)


def _run(tmp, name: str) -> tuple[int, dict]:
    comm = MPI.COMM_WORLD
    text = scene(shipped("localization_bar.toml"), steps={"count": COUNT})
    if comm.rank == 0:
        (tmp / f"{name}.toml").write_text(text)
    comm.Barrier()
    code = main(["run", str(tmp / f"{name}.toml"), "-o", str(tmp / f"{name}.h5")])
    comm.Barrier()
    with h5py.File(tmp / f"{name}.h5", "r") as f:
        out = {k: f[k][()] for k in ("steps/time", "steps/cuts", "steps/branch_warning",
                                     "fields/displacement")}
        out["status"] = str(f.attrs["status"])
        out["warnings"] = str(f.attrs.get("warnings", ""))
    return code, out


def test_a_cut_step_is_no_branch_jump(shared_tmp, monkeypatch):
    """The localization bar (secant matrix, maximum strain control) past its peak, with the
    step after step 4 failing four times (as a partition-dependent failure would): the run
    completes on the uncut run's branch, the rest of the cut step is >10× the intermediate
    step in plain increment, and no step warns."""
    code, plain = _run(shared_tmp, "uncut")
    assert code == 0 and plain["status"] == "complete"
    step, failed = NewtonSolver.step, {"n": 0}

    def failing(self, t):
        if np.isclose(self.problem.t_prev, CUT_AFTER / COUNT) and failed["n"] < CUTS:
            failed["n"] += 1
            raise SolverError("injected: this attempt fails")
        return step(self, t)

    monkeypatch.setattr(NewtonSolver, "step", failing)
    code, cut = _run(shared_tmp, "cut")
    assert code == 0 and cut["status"] == "complete"
    t = cut["steps/time"]
    assert len(t) == COUNT + 1
    k = CUT_AFTER   # the intermediate step's row
    assert t[k] == pytest.approx((CUT_AFTER + 1 / 2 ** CUTS) / COUNT, rel=1e-12)
    assert cut["steps/cuts"][k] == CUTS
    u = cut["fields/displacement"]
    du = np.linalg.norm((u[k + 1] - u[k]).ravel()) / np.linalg.norm((u[k] - u[k - 1]).ravel())
    assert du > 10     # plain increments (14.4 here, the "14×" once warned); per unit: 0.96
    assert not cut["steps/branch_warning"].any() and "increment is" not in cut["warnings"]
    assert not plain["steps/branch_warning"].any()
    # the same branch: the scene's steps agree with the uncut run's to its convergence
    same = np.delete(np.arange(COUNT + 1), k)
    scale = np.abs(plain["fields/displacement"]).max()
    np.testing.assert_allclose(u[same], plain["fields/displacement"], rtol=0, atol=1e-6 * scale)
