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
A target out of reach from the first step says so, with the loads it takes, the block stuck."""

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
    assert "every closed node of contact 'base' slides" in status
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


def test_target_out_of_reach_from_the_start(shared_tmp):
    """ν = 0.3: the pressure alone strains the top cells along x beyond the first targets
    (0.004 against 0.002 at most), and the pull strains the cells each side of the middle
    in opposite senses: with the block stuck, the two rows that bound the load ask for loads
    of opposite signs, each far beyond μN = 3. The failure names the two rows and their
    loads (test_no_load_reaches_the_turning_target checks that no load in ±0.97 μN gives
    the target)."""
    code, status, f = _run(shared_tmp, _scene(0.3, VALUE, nu=0.3))
    with f:
        steps = len(f["steps/time"])
    assert code == 3 and steps == 0
    head = "failed: maximum control 'max_strain' cannot reach its value from the first step: "
    assert status.startswith(head), status
    m = re.match(re.escape(head) + r"(\S+) at t = (\S+); with contact 'base' closed and stuck, "
                 r"its row (\d+) stays on its side of that value only for control loads of at "
                 r"least (\S+) and its row (\d+) only for at most (\S+) \(the load that brings "
                 r"one there takes the other beyond it\), and sliding the contact carries no "
                 r"more than μN = (\S+) \(μ = 0.3\)", status)
    target, t, lo, low, hi, high, capacity = (float(x) for x in m.groups())
    assert target == pytest.approx(VALUE * t, rel=1e-5) and t <= 0.1
    assert capacity == pytest.approx(0.3 * PRESSURE, rel=1e-6)
    assert low > capacity and high < -capacity and lo != hi
    assert "raise the target or control another quantity" in status
    assert "likely cause" not in status


def test_turning_back_without_softening(shared_tmp):
    """ν = 0.3, a small target: the pressure alone strains the top cells along x far beyond it
    (0.004 against 3e-6). The maximum group turns back to a row it left; nothing softens, so
    the failure names the control and the value it cannot reach, not damage localizing."""
    code, status, f = _run(shared_tmp, _scene(0.3, VALUE / 10, nu=0.3))
    with f:
        steps = len(f["steps/time"])
    assert code == 3 and steps == 0
    head = "failed: maximum control 'max_strain' can no longer reach its value: "
    assert status.startswith(head), status
    assert "no material of the scene softens" in status and "localizes" not in status
    assert "raise the target or control another quantity" in status
    match = re.match(re.escape(head) + r"(\S+) at t = (\S+) ", status)
    target, t = (float(x) for x in match.groups())
    assert target == pytest.approx(VALUE / 10 * t, rel=1e-5)


def test_no_load_reaches_the_turning_target(shared_tmp):
    """The claim of the test above and of test_target_out_of_reach_from_the_start, computed
    independently: the same block under the pressure and the pull as a given load, ramped to
    0.97 μN in either sense: the largest ε_xx of the cells (from the cell stresses, plane
    strain) stays above 1.5 × the small ramp's last target (t = 1), above 0.002, the large
    ramp's first step's, so no load the block can carry gives any of those targets."""
    base = shipped("contact_control_friction.toml")
    nu, E = 0.3, 1000.0
    for force in (2.9, -2.9):
        loads = [base["loads"][0], {"name": "pull", "region": "top", "total_force": [force, 0.0]}]
        text = scene(base, materials=[{"E": E, "nu": nu}], loads=loads, relations=[],
                     steps={"count": 5})
        code, status, f = _run(shared_tmp, text)
        with f:
            sigma = f["cell_fields/stress"][:]
        assert code == 0, status
        eps_xx = (1 + nu) / E * ((1 - nu) * sigma[..., 0] - nu * sigma[..., 1])
        assert eps_xx.max(axis=1).min() > 1.5 * VALUE / 10


@pytest.mark.parametrize("material, localizes", [("mazars", True), ("elastic", False)])
def test_turning_back_names_localization_only_where_damage_is(shared_tmp, monkeypatch,
                                                                material, localizes):
    """A maximum group turning back from some iteration on (forced: the active set's own
    check called on a row it left), in the localization bar with its damaged column, and in
    the same bar all elastic: the first keeps the localization message, the second names
    the control and the value it cannot reach."""
    from parsolve.solvers.active_set import ActiveSet

    update, calls = ActiveSet.update, {"n": 0}

    def turning(self, *args, **kw):
        calls["n"] += 1
        rows = np.flatnonzero(self.maximum)   # (the bar's one group: its rows held here)
        if calls["n"] > 6 and rows.size:
            left = rows[~self.active[rows]][0]
            self._no_way_back(np.array([left]))
        return update(self, *args, **kw)

    monkeypatch.setattr(ActiveSet, "update", turning)
    base = shipped("localization_bar.toml")
    materials = base["materials"] if material == "mazars" else [base["materials"][0]]
    code, status, f = _run(shared_tmp, scene(base, materials=materials, steps={"count": 12}))
    with f:
        steps = len(f["steps/time"])
    assert code == 3 and steps >= 1
    if localizes:
        assert status.startswith("failed: maximum relation 'max_strain': the enforced row would "
                                 "go back"), status
        assert "where damage localizes" in status
    else:
        assert status.startswith("failed: maximum control 'max_strain' can no longer reach its "
                                 "value"), status
        assert "no material of the scene softens" in status and "localizes" not in status


def test_maximum_control_of_cells_that_do_not_soften_past_the_peak(shared_tmp):
    """The localization bar with its maximum strain control on the cells left of x = 0.4 (all
    elastic; the damaged column is the 15th of 29): their strain is σ/E and the bar's stress
    cannot pass the damaged column's peak E εd0, so no target beyond εd0 = 1e-4 is reached
    (t = 1e-4 / 1.2e-3 = 1/12). The run fails naming the control and the capacity, the last
    step at the peak: strain εd0, load E εd0 × 0.1 = 1e4."""
    base = shipped("localization_bar.toml")
    control = dict(base["relations"][3], region="left_part")
    assert control["name"] == "max_strain" and control["value"] == 1.2e-3
    text = scene(base, regions=dict(base["regions"], left_part="x < 0.4"),
                 relations=base["relations"][:3] + [control])
    code, status, f = _run(shared_tmp, text)
    with f:
        loads = f["relations/max_strain/multiplier"][:].sum(axis=1)
        largest = f["relations/max_strain/primal"][:].max(axis=1)
        times = f["steps/time"][:]
    assert code == 3
    head = "failed: maximum control 'max_strain' can no longer reach its value: "
    assert status.startswith(head), status
    assert "the cells it measures do not soften" in status
    assert "control a quantity that includes the softening cells" in status
    assert "likely cause" not in status
    np.testing.assert_allclose(largest, 1.2e-3 * times, rtol=1e-9)
    assert times[-1] == pytest.approx(1 / 12, rel=1e-9)
    assert largest[-1] == pytest.approx(1e-4, rel=1e-9)
    assert loads[-1] == pytest.approx(1e9 * 1e-4 * 0.1, rel=1e-9)
    m = re.match(re.escape(head) + r"(\S+) at t = (\S+), where it reached (\S+) ", status)
    target, t, reached = (float(x.rstrip(",")) for x in m.groups())
    assert t > 1 / 12 and target == pytest.approx(1.2e-3 * t, rel=1e-5)
    assert reached == pytest.approx(1e-4, rel=1e-5)


def test_two_symmetric_columns_past_the_controlled_maximums_limit_point(shared_tmp):
    """The localization bar with two damaging columns, the 8th and the 22nd of 29 (symmetric
    about the middle), under its maximum strain control (secant matrix). Both soften alike up
    to step 7 (the closed form of one column: the six cells at the maximum), then one column
    takes the damage, from one cell: which one, a symmetric choice, is decided by round-off
    (the 22nd's top or bottom cell at step 8 or 9, by the rank count and the operator's
    pattern). Near t = 0.739 (0.7385 to 0.7399 as the step cuts fall) the path of the
    controlled maximum turns back (the consistent tangent with the rows at the maximum held has
    a negative eigenvalue along the step's predictor): the secant iteration only stalls there,
    cut after cut, which said nothing but "Newton did not converge". The run now names the
    control, the value it could not follow, where (the enforced row's cell), and why, at every
    rank count."""
    from helpers.control import closed_form

    base = shipped("localization_bar.toml")
    regions = dict(base["regions"], middle="(x > 7/29 and x < 8/29) or (x > 21/29 and x < 22/29)")
    code, status, f = _run(shared_tmp, scene(base, regions=regions))
    with f:
        times = f["steps/time"][:]
        loads = f["relations/max_strain/multiplier"][:].sum(axis=1)
        largest = f["relations/max_strain/primal"][:].max(axis=1)
        active = f["relations/max_strain/active"][:]
        damage = f["cell_fields/damage"][:, :, 0]
        centre = f["mesh/points"][:][f["mesh/cells/quad"][:]].mean(axis=1)[:, 0]
    assert code == 3
    head = "failed: maximum control 'max_strain' can no longer follow its value: "
    assert status.startswith(head), status
    m = re.match(re.escape(head) + r"(\S+) at t = (\S+), where it reached (\S+) \(t = (\S+), "
                 r"control load (\S+), its enforced row (\d+), cell (\d+)\); the equilibrium "
                 r"path turns back just past t = (\S+): ", status)
    assert m, status
    target, t, reached, t_prev, load = (float(x.rstrip(",")) for x in m.groups()[:5])
    row, cell, t_back = int(m[6]), int(m[7]), float(m[8].rstrip(":"))
    assert "1 negative eigenvalue(s)" in status and "arc-length" in status
    assert "Newton did not converge" in status   # (the last attempt, kept)
    # where: the last converged step, its load, its enforced row in the 22nd column
    assert t_prev == t_back == pytest.approx(times[-1], rel=1e-5)
    assert 0.738 < t_prev < t < 0.741 and t - t_prev < 2e-3
    assert target == pytest.approx(1.2e-3 * t, rel=1e-5)
    assert reached == pytest.approx(largest[-1], rel=1e-5)
    assert reached == pytest.approx(1.2e-3 * t_prev, rel=1e-5)
    assert load == pytest.approx(loads[-1], rel=1e-5)
    assert row == cell and active[-1, row] and active[-1].sum() == 1
    assert min(abs(centre[cell] - c) for c in (7.5 / 29, 21.5 / 29)) < 1e-12
    # up to step 7 the closed form of one damaging column, both columns alike
    eps = 1.2e-3 * times[:7]
    np.testing.assert_allclose(times[:7], np.arange(1, 8) / 24, rtol=1e-12)
    np.testing.assert_allclose(loads[:7], closed_form(eps)[1], rtol=1e-6)
    damaged = np.abs(centre - 7.5 / 29) < 1e-9, np.abs(centre - 21.5 / 29) < 1e-9
    expected = 1 - np.exp(-1e4 * (np.maximum(eps, 1e-4) - 1e-4))
    for column in damaged:
        assert column.sum() == 3
        np.testing.assert_allclose(damage[:7][:, column], np.repeat(expected[:, None], 3, axis=1),
                                   rtol=1e-6, atol=1e-12)
    assert np.abs(damage[:, ~(damaged[0] | damaged[1])]).max() == 0.0
