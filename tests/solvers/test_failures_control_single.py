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
strain, and the mean n·ε·n stays far below the first target."""

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


def test_control_its_load_does_not_move(shared_tmp):
    code, status, f = _run(shared_tmp, _scene([_control(component="xx", value=0.02)]))
    with f:
        steps = len(f["steps/time"])
    assert code == 3 and steps == 0
    head = ("failed: control 'drive' is not moved by its load 'pull' at the step's start (t = 0, "
            "the contact closed and stuck): a unit of 'pull' changes ")
    assert status.startswith(head), status
    rate, terms = (float(x) for x in re.match(
        re.escape(head) + r"the controlled quantity by (\S+), terms of (\S+) that cancel",
        status).groups())
    assert abs(rate) < 1e-12 * terms and terms > 1e-4
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
    assert "reduce the target" in status and "likely cause" not in status
    # independently: under any pull the friction carries (either sense, up to 0.97 μN) the
    # mean (ε_xx + ε_yy)/2 + ε_xy stays far below the first step's target (0.002 / COUNT)
    for force in (2.9, -2.9, 0.0):
        eps = _loaded_strains(shared_tmp, force)
        value = ((eps[:, 0] + eps[:, 1]) / 2 + eps[:, 2]).mean()
        assert value < -1e-3 < 0.002 / COUNT
