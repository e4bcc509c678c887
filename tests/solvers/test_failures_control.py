"""A maximum control that can no longer reach its value fails naming that cause and the way out.

The block of configs/contact_control_friction.toml (pressed by p = 10 on a rough plane, so
N = 10 and the friction capacity is μN) is pulled by a load whose intensity is the multiplier
of a maximum strain control (the largest ε_xx of the cells follows a ramp; ν = 0, so the
pressure alone strains nothing along x). The strains grow with the pull until the block slides;
at μN the load cannot grow and the block slides as a whole, which strains nothing more: a
target beyond the largest strain at μN has no solution. The run then fails (exit 3) saying so
— the control, the value it could not reach, the value reached, μN — instead of the solve's
null pivot or friction's "tangential load exceeds the friction capacity" (the load is the
control's unknown here, not the scene's). The steps reached are kept, their load just under μN.
A target out of reach from the first step (the load never approached μN) keeps the solver's
own message and hints: nothing says the capacity was reached."""

import re

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from helpers.scene import scene, shipped

from parsolve.cli import main

PRESSURE = 10.0   # on the top, 1 wide: N = 10
VALUE = 0.02      # the control's target at t = 1 (10 steps: 0.002 a step)


def _scene(mu: float, value: float, nu: float = 0.0) -> str:
    base = shipped("contact_control_friction.toml")
    control = {"name": "max_strain", "type": "strain", "region": "all", "component": "xx",
               "per_cell": True, "maximum": True, "sense": "<=", "value": value, "dual": "pull"}
    contact = dict(base["contact"][0], friction=mu)
    return scene(base, materials=[{"E": 1000.0, "nu": nu}], relations=[control],
                 contact=[contact])


def _run(tmp, text: str) -> tuple[int, str, h5py.File]:
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        (tmp / "scene.toml").write_text(text)
    comm.Barrier()
    code = main(["run", str(tmp / "scene.toml"), "-o", str(tmp / "out.h5")])
    comm.Barrier()
    f = h5py.File(tmp / "out.h5", "r")
    return code, str(f.attrs["status"]), f


@pytest.mark.parametrize("mu, value", [(0.3, VALUE), (0.5, 1.5 * VALUE)])
def test_maximum_control_beyond_the_friction_capacity(shared_tmp, mu, value):
    code, status, f = _run(shared_tmp, _scene(mu, value))
    with f:
        loads = f["relations/max_strain/multiplier"][:].sum(axis=1)
        largest = f["relations/max_strain/primal"][:].max(axis=1)
        times = f["steps/time"][:]
    assert code == 3
    head = "failed: maximum control 'max_strain' can no longer reach its value: "
    assert status.startswith(head), status
    assert f"every closed node of contact 'base' slides" in status
    assert f"friction capacity μN (μ = {mu:g})" in status
    assert "reduce the target" in status and "control a quantity that grows" in status
    assert "the last attempt: " in status and "likely cause" not in status
    m = re.match(re.escape(head) + r"(\S+) at t = (\S+), where it reached (\S+) "
                 r"\(t = (\S+), control load (\S+)\)", status)
    target, t, reached, t_prev, load = (float(x.rstrip(",;")) for x in m.groups())
    capacity = mu * PRESSURE
    # the steps kept: the load rose to just under μN, the strain with it, each step on target
    assert np.all(np.diff(loads) > 0) and np.all(loads <= capacity * (1 + 1e-9))
    assert loads[-1] > 0.995 * capacity
    np.testing.assert_allclose(largest, value * times, rtol=1e-9)
    assert reached == pytest.approx(largest[-1], rel=1e-5)
    assert load == pytest.approx(loads[-1], rel=1e-5)
    # the failing step's target is the ramp's, beyond the last one reached
    assert target == pytest.approx(value * t, rel=1e-5) and t > t_prev
    assert target > reached


def test_reachable_maximum_control_completes(shared_tmp):
    """The same control to a target under the capacity: the run completes, the load under μN."""
    code, status, f = _run(shared_tmp, _scene(0.3, VALUE / 10))
    with f:
        loads = f["relations/max_strain/multiplier"][:].sum(axis=1)
        largest = f["relations/max_strain/primal"][:].max(axis=1)
    assert code == 0 and status == "complete"
    np.testing.assert_allclose(largest, VALUE / 100 * np.arange(1, 11), rtol=1e-9)
    assert loads[-1] < 0.3 * PRESSURE


def test_target_out_of_reach_from_the_start_is_not_named(shared_tmp):
    """ν = 0.3: the pressure alone strains the top beyond the first targets; the block never
    began to slide at a converged state, so the failure keeps the solver's message and hints."""
    code, status, f = _run(shared_tmp, _scene(0.3, VALUE, nu=0.3))
    with f:
        steps = len(f["steps/time"])
    assert code == 3 and steps == 0
    assert "can no longer reach" not in status
    assert "likely cause" in status
