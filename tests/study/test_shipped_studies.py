"""Every shipped study (configs/studies/) runs in its reduced form and gives its known numbers."""

import csv

import numpy as np
import pytest

from conftest import CONFIGS
from parsolve.study.cli import main
from parsolve.study.config import load_study

STUDIES = CONFIGS / "studies"
TIMOSHENKO = 1000.0 / (3 * 210e3 / 12) + 10.0 / (5 / 6 * 210e3 / 2.6)


def run_reduced(tmp_path, name):
    out = tmp_path / name
    assert main([str(STUDIES / f"{name}.toml"), "--reduced", "--out", str(out), "--parallel", "2"]) == 0
    table = list(csv.DictReader(open(out / "study.csv")))
    assert all(r["status"] == "complete" for r in table)
    return table


def test_every_shipped_study_is_tested_and_valid():
    assert sorted(p.stem for p in STUDIES.glob("*.toml")) == sorted(["kirsch", "cantilever_3d",
                                                                   "controlled_bar", "solubility",
                                                                   "contact_hertz"])
    for path in STUDIES.glob("*.toml"):
        assert len(load_study(path, reduced=True).levels) < len(load_study(path).levels)


@pytest.mark.slow
@pytest.mark.serial
def test_kirsch_reduced(tmp_path):
    table = run_reduced(tmp_path, "kirsch")
    p1 = [r for r in table if r["family"] == "P1 triangles"]
    p2 = [r for r in table if r["family"] == "P2 triangles"]
    assert [int(r["DOFs"]) for r in p2] == [442, 1650, 6370]
    # P2 on the same mesh beats P1 in energy; the stress concentration approaches ~3.02
    for a, b in zip(p1, p2):
        assert float(b["error(energy)"]) < float(a["error(energy)"])
    assert abs(float(p2[-1]["scf"]) - 3.02) < 0.02
    np.testing.assert_allclose(float(p2[-1]["energy"]), 9.580293e-4, rtol=1e-6)  # regression
    assert 0.7 < float(p1[-1]["order(energy)"]) < 1.2


@pytest.mark.serial
def test_cantilever_reduced(tmp_path):
    table = run_reduced(tmp_path, "cantilever_3d")
    tips = {r["family"]: -float(r["tip"]) for r in table if r["level"] == "x2"}
    # P1 tetrahedra lock in bending; P2 is within 1.2 % of Timoshenko on a 20 × 2 × 2 grid
    assert abs(tips["P2 tetra10"] / TIMOSHENKO - 1) < 0.012
    assert tips["P1 tetra"] / TIMOSHENKO < 0.51
    np.testing.assert_allclose(tips["P1 tetra"], 0.0096691398, rtol=1e-7)   # regression


@pytest.mark.slow
@pytest.mark.serial
def test_controlled_bar_reduced(tmp_path):
    table = run_reduced(tmp_path, "controlled_bar")
    err = {(r["family"], r["level"]): float(r["error(force)"]) for r in table}
    assert max(v for (f, _), v in err.items() if f.startswith("direct")) < 1e-12
    # the force's error follows the tolerance within the control row's conditioning. GMRES
    # runs on M x = b itself, its control row condensed on its slave nodes (solvers.tied):
    # 1.4e-9 and 1.2e-8 at rtol 1e-10 (x1, x2), 9.7e-7 and 4.3e-5 at rtol 1e-6; on the
    # augmented Lagrangian form before (T M x = T b, |T⁻¹| <= 1 + γ = 4) 6.5e-10, 4.6e-9 and
    # 1.2e-5, 1.9e-6
    assert max(v for (f, _), v in err.items() if f == "iterative rtol 1e-10") < 3e-8
    assert max(v for (f, _), v in err.items() if f == "iterative rtol 1e-6") < 5e-4


@pytest.mark.slow
@pytest.mark.serial
def test_solubility_reduced(tmp_path):
    """Backward Euler is first order in time: halving the time step (and the cells) halves the
    gas's error, with lumped and with consistent capacity."""
    table = run_reduced(tmp_path, "solubility")
    for family in ("lumped capacity", "consistent capacity"):
        gas = [float(r["gas"]) for r in table if r["family"] == family]
        assert len(gas) == 2 and all(0.83 < g < 0.84 for g in gas)  # the gas at x = 0, t = 0.5
    lumped = [float(r["gas"]) for r in table if r["family"] == "lumped capacity"]
    assert lumped[1] > lumped[0]  # converging from below, by about 2.4e-3 per halving
    np.testing.assert_allclose(lumped[1] - lumped[0], 0.00240157, rtol=1e-4)


@pytest.mark.serial
def test_contact_hertz_reduced(tmp_path):
    """The Hertz load converges with the mesh (first order: a contact edge inside an element);
    the relation is the contact effect's own, found by building the model."""
    table = run_reduced(tmp_path, "contact_hertz")
    load = [float(r["load"]) for r in table]
    assert len(load) == 2 and -5.1 < load[0] < load[1] < -4.9  # compressive, decreasing with h
