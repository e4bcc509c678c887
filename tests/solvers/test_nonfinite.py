"""A non-finite value is a solver failure on every path (linear, Newton, arc-length, transient
linear and nonlinear): exit 3, the file's status names what and at which step, the steps before
it are written and nothing after. NaN is injected into the linear solve's output from a given
call on, into the internal forces of one rank, or into a cell output of one rank (the others
must stop with it: no rank is left waiting)."""

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from conftest import CONFIGS, ROOT

import parsolve.driver
import parsolve.outputs
from parsolve.cli import main
from parsolve.effects.compose import Composition
from parsolve.solvers.linear import LinearSolver

LINEAR = (CONFIGS / "controlled_bar.toml").read_text().replace("count = 10", "count = 5")
MAZARS = 'model = "mazars"\neps_d0 = 1e-4\nAt = 1.0\nBt = 1e4\nAc = 1.2\nBc = 1500.0\nbeta = 1.06\n'
NEWTON = LINEAR.replace("E = 1e9\nnu = 0.0", "E = 1e9\nnu = 0.0\n" + MAZARS).replace(
    "value = 1e-4", "value = 2e-5")
ARC = (ROOT / "tests/docs/scenes/nonlinear_arc_length.toml").read_text().replace(
    "automatic = { strain_increment = 8e-5, max_steps = 60 }\n", "").replace("count = 10", "count = 5")
DIFFUSION = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 4
ny = 4
cell = "triangle"
[model]
dimension = 2
[[diffusion]]
field = "c"
[[diffusion.materials]]
conductivity = 1.0
capacity = 1.0
[[loads]]
name = "source"
field = "c"
source = 1.0
[time]
mass = "lumped"
[steps]
count = 5
end = 0.5
"""
SOLUBILITY = (CONFIGS / "solubility_well_mixed.toml").read_text().replace(
    "count = 39\nend = 3.9", "count = 5\nend = 0.5")

SCENES = {"linear": LINEAR, "newton": NEWTON, "arc_length": ARC, "transient_linear": DIFFUSION,
          "transient_newton": SOLUBILITY}
FROM = 3   # the first step (linear) or solve (nonlinear) that goes wrong


def _run(tmp, text: str, mode: str) -> tuple[int, str, int]:
    """(exit status, the file's status, steps written) of ``parsolve run``, in this process."""
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        (tmp / "scene.toml").write_text(text)
    comm.Barrier()
    code = main(["run", str(tmp / "scene.toml"), "-o", str(tmp / "out.h5"), "--output-mode", mode])
    comm.Barrier()   # (the file closed on every rank)
    with h5py.File(tmp / "out.h5", "r") as f:
        return code, str(f.attrs["status"]), len(f["steps/time"])


@pytest.fixture
def solve_nan(monkeypatch):
    """NaN in the linear solve's output from its FROM-th call on."""
    calls = {"n": 0}
    solve = LinearSolver.solve

    def poisoned(self, rhs, x):
        its = solve(self, rhs, x)
        calls["n"] += 1
        if calls["n"] >= FROM:
            x.array[:] = np.nan
        return its
    monkeypatch.setattr(LinearSolver, "solve", poisoned)


@pytest.mark.parametrize("mode", ["swmr", "parallel"])
@pytest.mark.parametrize("path", list(SCENES))
def test_nan_solution_fails_the_run(path, mode, shared_tmp, solve_nan):
    code, status, steps = _run(shared_tmp, SCENES[path], mode)
    assert code == 3, status
    assert status.startswith("failed: "), status
    if path in ("linear", "transient_linear"):   # one solve per step: step FROM fails
        assert "non-finite values in the solution at step 3" in status, status
        assert steps == FROM - 1
    else:   # a failed iteration: cut, then given up
        assert "non-finite residual" in status, status
        assert steps < 5


@pytest.mark.parametrize("mode", ["swmr", "parallel"])
@pytest.mark.parametrize("path", ["newton", "arc_length", "transient_newton"])
def test_nan_internal_force_on_one_rank_fails_the_run(path, mode, shared_tmp, monkeypatch):
    """A material that gives NaN on the last rank's part from the FROM-th evaluation on."""
    comm = MPI.COMM_WORLD
    calls = {"n": 0}
    evaluate = Composition.evaluate

    def poisoned(self, *args, **kwargs):
        total, *rest = evaluate(self, *args, **kwargs)
        calls["n"] += 1
        if calls["n"] >= FROM and comm.rank == comm.size - 1:
            total = np.full_like(total, np.nan)
        return (total, *rest)
    monkeypatch.setattr(Composition, "evaluate", poisoned)
    code, status, steps = _run(shared_tmp, SCENES[path], mode)
    assert code == 3 and "non-finite residual" in status, status
    assert steps < 5


@pytest.mark.parametrize("mode", ["swmr", "parallel"])
@pytest.mark.parametrize("path", list(SCENES))
def test_nan_output_on_one_rank_fails_the_run(path, mode, shared_tmp, monkeypatch):
    """A cell output (a stress, a material state; a flux) NaN on the last rank at step FROM:
    that step is not written, every rank stops."""
    comm = MPI.COMM_WORLD
    calls = {"n": 0}
    outputs = parsolve.outputs.step_outputs

    def poisoned(*args, **kwargs):
        fields, cells, rel = outputs(*args, **kwargs)
        calls["n"] += 1
        name = sorted(cells)[0]
        # the last rank that holds cells (a small scene leaves some rank without any)
        last = comm.allreduce(comm.rank if len(cells[name].values) else -1, op=MPI.MAX)
        if calls["n"] == FROM and comm.rank == last:
            cells[name] = type(cells[name])(np.full_like(cells[name].values, np.nan))
        return fields, cells, rel
    monkeypatch.setattr(parsolve.outputs, "step_outputs", poisoned)
    monkeypatch.setattr(parsolve.driver, "step_outputs", poisoned)
    code, status, steps = _run(shared_tmp, SCENES[path], mode)
    assert code == 3, status
    assert f"non-finite values in the cell fields (stresses, material states) at step {FROM}" \
        in status, status
    assert steps == FROM - 1
