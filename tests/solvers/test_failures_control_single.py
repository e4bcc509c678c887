"""A single-row control that no load gives from the start fails naming that cause.

The block of configs/contact_control_friction.toml (pressed by p = 10 on a rough plane, μ = 0.3,
so N = 10 and μN = 3; E = 1000, here ν = 0) is pulled along x on its top by a load whose
intensity is the multiplier of a mean strain control over the whole block. Two controls fail at
the first step, each on a singular solve, and the failure (exit 3) names the cause instead:

- the mean ε_xx: a shear load on the top of a block stuck at its bottom changes no mean normal
  strain (by symmetry: the axial force of every section is zero); at the start the pull does
  not move the controlled quantity (A K⁻¹ G = 0), so the controlled operator is singular.
  Once the contact slides in part the symmetry is gone, but the mean ε_xx then falls, in
  either sense of the pull: the positive targets are reached by no load;
- the mean n·ε·n with n = (1, 1)/√2, (ε_xx + ε_yy)/2 + ε_xy: the pressure alone gives
  ε_yy = -p/E = -0.01, i.e. -0.005, and the first target (≥ 0) takes ε_xy = 0.005, a shear
  τ = 2 G ε_xy = 5 on the top, beyond μN = 3: no load the friction can carry gives it.

Both claims are checked independently with load-controlled runs (the pull a given force,
below μN in either sense): from the cell stresses, the mean ε_xx stays zero while the cells
strain, and the mean n·ε·n stays far below the first target. In a linear model (the controlled
bar, its control on a displacement its load does not move) the failure says that no intensity
of the load gives the target."""

import re

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from helpers.scene import scene, shipped

from parsolve.cli import main

E, PRESSURE, MU = 1000.0, 10.0, 0.3
COUNT = 10


def _control(**kw) -> dict:
    return {"name": "drive", "type": "strain", "region": "all", "dual": "pull", **kw}


def _scene(relations: list, **over) -> str:
    base = shipped("contact_control_friction.toml")
    return scene(base, **{"materials": [{"E": E, "nu": 0.0}], "relations": relations,
                          "steps": {"count": COUNT}, **over})


def _run(tmp, text: str, name: str = "scene") -> tuple[int, str, h5py.File]:
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        (tmp / f"{name}.toml").write_text(text)
    comm.Barrier()
    code = main(["run", str(tmp / f"{name}.toml"), "-o", str(tmp / f"{name}.h5")])
    comm.Barrier()
    f = h5py.File(tmp / f"{name}.h5", "r")
    return code, str(f.attrs["status"]), f


def _loaded_strains(tmp, force: float) -> np.ndarray:
    """The cell strains (ε_xx, ε_yy, ε_xy) of the block under the pressure and a given pull
    (plane strain, ν = 0: ε = σ / E, ε_xy = τ / (2 G) = τ / E); the cells are equal squares,
    so their mean is the region's."""
    base = shipped("contact_control_friction.toml")
    loads = [base["loads"][0], {"name": "pull", "region": "top", "total_force": [force, 0.0]}]
    code, status, f = _run(tmp, _scene([], loads=loads, steps={"count": 4}), "loaded")
    with f:
        sigma = f["cell_fields/stress"][-1]
    assert code == 0, status
    return sigma / E


def _unmoved(status: str, head: str) -> tuple[float, float]:
    """(how far a unit of the load moves the body, how much it changes the controlled
    quantity) from an "is not moved by its load" status starting with ``head``."""
    assert status.startswith(head), status
    m = re.match(re.escape(head) + r"(\S+) and changes the controlled quantity by (\S+) "
                 r"\(round-off\)", status)
    return float(m.group(1)), float(m.group(2))


def test_control_its_load_does_not_move(shared_tmp):
    code, status, f = _run(shared_tmp, _scene([_control(component="xx", value=0.02)]))
    with f:
        steps = len(f["steps/time"])
    assert code == 3 and steps == 0
    head = ("failed: control 'drive' is not moved by its load 'pull' at the step's start (t = 0, "
            "the contact closed and stuck): a unit of 'pull' displaces the body by up to ")
    largest, rate = _unmoved(status, head)
    assert abs(rate) < 1e-12 * largest and largest > 1e-3
    assert "control a quantity that 'pull' moves" in status
    assert "likely cause" not in status
    # independently: stuck (every node, up to a pull of about 1), the pull strains the cells
    # along x (bending) and their mean stays zero; sliding in part (2.9), the mean falls
    for force in (1.0, -1.0):
        eps = _loaded_strains(shared_tmp, force)
        assert np.abs(eps[:, 0]).max() > 5e-4
        assert abs(eps[:, 0].mean()) < 1e-12 * np.abs(eps[:, 0]).max()
    for force in (2.9, -2.9):
        assert _loaded_strains(shared_tmp, force)[:, 0].mean() < -5e-4


def test_control_beyond_friction_from_the_first_step(shared_tmp):
    code, status, f = _run(shared_tmp, _scene([_control(direction=[1.0, 1.0], value=0.002)]))
    with f:
        steps = len(f["steps/time"])
    assert code == 3 and steps == 0
    head = "failed: control 'drive' cannot reach its value from the first step: "
    assert status.startswith(head), status
    m = re.match(re.escape(head) + r"(\S+) at t = (\S+); with contact 'base' closed and stuck, "
                 r"that value takes a control load of (\S+) and a tangential reaction of (\S+), "
                 r"beyond the friction capacity μN = (\S+) \(μ = 0.3, N = (\S+)\)", status)
    target, t, load, tangential, capacity, normal = (float(x.rstrip(";)")) for x in m.groups())
    assert target == pytest.approx(0.002 * t, rel=1e-5) and t <= 1 / COUNT
    assert normal == pytest.approx(PRESSURE, rel=1e-6)
    assert capacity == pytest.approx(MU * PRESSURE, rel=1e-6)
    # the stuck block: the pull balances the tangential reaction; τ = E (target + 0.005) ≈ 5
    assert load == pytest.approx(tangential, rel=1e-5)
    assert load == pytest.approx(E * (target + PRESSURE / E / 2), rel=0.02)
    assert "bring the target nearer -0.005 (the other loads alone)" in status
    assert "likely cause" not in status
    # independently: under any pull the friction carries (either sense, up to 0.97 μN) the
    # mean (ε_xx + ε_yy)/2 + ε_xy stays far below the first step's target (0.002 / COUNT)
    for force in (2.9, -2.9, 0.0):
        eps = _loaded_strains(shared_tmp, force)
        value = ((eps[:, 0] + eps[:, 1]) / 2 + eps[:, 2]).mean()
        assert value < -1e-3 < 0.002 / COUNT


def test_linear_control_its_load_does_not_move(shared_tmp):
    """configs/controlled_bar.toml (ν = 0, pulled along x by its control's load) with the
    control on the mean u_y of the right edge: the pull moves no point along y, so the saddle
    operator is singular; the model is linear, so no intensity gives the target."""
    base = shipped("controlled_bar.toml")
    control = dict(base["relations"][2], component="y")
    assert control["name"] == "control" and control["value"] == 1e-4
    text = scene(base, relations=base["relations"][:2] + [control])
    code, status, f = _run(shared_tmp, text)
    with f:
        steps = len(f["steps/time"])
    assert code == 3 and steps == 0
    head = ("failed: control 'control' is not moved by its load 'pull': a unit of 'pull' "
            "displaces the body by up to ")
    assert status.startswith(head), status
    m = re.match(re.escape(head) + r"(\S+) and changes the controlled quantity by (\S+) "
                 r"\(round-off\); the model is linear, so the quantity is (\S+) whatever the "
                 r"intensity of 'pull' \(the other loads' answer\) and its value (\S+) at "
                 r"t = (\S+) is out of reach", status)
    largest, rate, alone, target, t = (float(x) for x in m.groups())
    # a unit force on the 1 × 0.1 bar: u_x = L / (E A) = 1e-8 at its end
    assert largest == pytest.approx(1e-8, rel=1e-9)
    assert abs(rate) < 1e-12 * largest and alone == 0.0
    assert t == pytest.approx(0.1) and target == pytest.approx(1e-5)
    # independently: the bar pulled by given forces, either sense: the right edge's u_y is 0
    for force in (1e4, -1e4):
        loads = [dict(base["loads"][0], total_force=[force, 0.0])]
        code, status, f = _run(shared_tmp, scene(base, loads=loads,
                                                 relations=base["relations"][:2]), "loaded")
        with f:
            u = f["fields/displacement"][-1]
            right = np.isclose(f["mesh/points"][:, 0], 1.0)
        assert code == 0, status
        assert abs(u[right, 0].mean()) == pytest.approx(abs(force) * 1e-8, rel=1e-9)
        assert np.abs(u[right, 1]).max() < 1e-12 * abs(force) * 1e-8


def test_softening_control_its_load_does_not_move(shared_tmp):
    """configs/localization_bar.toml (secant Newton, a damaging column; ν = 0) with a control
    on the mean u_y of the right edge instead of its maximum strain: the pull moves no point
    along y, the first step fails on a singular solve, and the failure says so (the Newton
    path: probed at the step's start)."""
    base = shipped("localization_bar.toml")
    control = {"name": "drive", "type": "mean", "region": "right", "component": "y",
               "value": 1e-4, "dual": "pull"}
    code, status, f = _run(shared_tmp, scene(base, relations=base["relations"][:3] + [control]))
    with f:
        steps = len(f["steps/time"])
    assert code == 3 and steps == 0
    head = ("failed: control 'drive' is not moved by its load 'pull' at the step's start "
            "(t = 0): a unit of 'pull' displaces the body by up to ")
    largest, rate = _unmoved(status, head)
    assert largest == pytest.approx(1e-8, rel=1e-9)   # L / (E A), undamaged
    assert abs(rate) < 1e-12 * largest
    assert "likely cause" not in status
    # independently: pulled by a given force up to half the peak E εd0 A = 1e4, the right
    # edge moves along x by F L / (E A) and not at all along y
    loads = [dict(base["loads"][0], total_force=[5e3, 0.0])]
    code, status, f = _run(shared_tmp, scene(base, loads=loads,
                                             relations=base["relations"][:3]), "loaded")
    with f:
        u = f["fields/displacement"][-1]
        right = np.isclose(f["mesh/points"][:, 0], 1.0)
    assert code == 0, status
    assert u[right, 0].mean() == pytest.approx(5e3 * 1e-8, rel=1e-9)
    assert np.abs(u[right, 1]).max() < 1e-12 * 5e3 * 1e-8


def test_single_row_control_past_the_friction_capacity(shared_tmp):
    """ν = 0.3: the pressure strains the block less along (1, 1)/√2 (-0.0026), so the mean
    n·ε·n reaches its first targets with the block stuck; its load rises with the ramp to μN,
    where the block slides as a whole and the quantity grows no more. The failure names the
    control, the value reached and μN (the steps kept: the load under μN, each on target)."""
    text = _scene([_control(direction=[1.0, 1.0], value=0.002)],
                  materials=[{"E": E, "nu": 0.3}])
    code, status, f = _run(shared_tmp, text)
    with f:
        loads = f["relations/drive/multiplier"][:, 0]
        values = f["relations/drive/primal"][:, 0]
        times = f["steps/time"][:]
    assert code == 3 and len(times) > 5
    head = "failed: control 'drive' can no longer reach its value: "
    assert status.startswith(head), status
    assert "every closed node of contact 'base' slides" in status
    assert "friction capacity μN (μ = 0.3)" in status and "likely cause" not in status
    m = re.match(re.escape(head) + r"(\S+) at t = (\S+), where it reached (\S+) "
                 r"\(t = (\S+), control load (\S+)\)", status)
    target, t, reached, t_prev, load = (float(x.rstrip(",;")) for x in m.groups())
    np.testing.assert_allclose(values, 0.002 * times, rtol=1e-9)
    assert np.all(np.diff(loads) > 0) and loads[-1] <= MU * PRESSURE * (1 + 1e-9)
    assert loads[-1] > 0.99 * MU * PRESSURE
    assert load == pytest.approx(loads[-1], rel=1e-5)
    assert reached == pytest.approx(values[-1], rel=1e-5) and t_prev == pytest.approx(times[-1])
    assert target == pytest.approx(0.002 * t, rel=1e-5) and target > reached
