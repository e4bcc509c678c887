"""The classical baseline (scripts/baselines/solubility_ssn.py: persistent c_s, c_g and a
semi-smooth Newton on min(c_g, c_sat − c_s) = 0, PETSc LU on one rank) against exact and
independent answers. Serial: one rank, PETSc.COMM_SELF."""

import importlib.util
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from parsolve.mesh.generators import rectangle
from tests.reference.solubility_fv import GROW_SHRINK, Problem1D, fine_grow_shrink, \
    grow_shrink_problem, grow_shrink_source, grow_shrink_times, run, well_mixed

# Serial numerics (numpy, PETSc.COMM_SELF): running them on every rank would add nothing.
pytestmark = pytest.mark.serial

ROOT = Path(__file__).resolve().parents[2]


@lru_cache(maxsize=1)
def baseline():
    spec = importlib.util.spec_from_file_location(
        "solubility_ssn", ROOT / "scripts" / "baselines" / "solubility_ssn.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def strip(n: int, cell: str = "quad"):
    return rectangle(GROW_SHRINK["length"], 0.05, n, 1, cell=cell)


def scene_params(**extra) -> dict:
    p = {"D_s": GROW_SHRINK["D_s"], "c_sat": GROW_SHRINK["c_sat"],
         "source": lambda t, xc: grow_shrink_source(t, xc[:, 0]), "dirichlet": {"right": 0.0}}
    p.update(extra)
    return p


def on_grid(values: np.ndarray, mesh, n: int) -> np.ndarray:
    """FV vertex values (steps, n+1) at the mesh nodes (abscissa i h)."""
    return values[:, np.round(mesh.points[:, 0] / GROW_SHRINK["length"] * n).astype(int)]


@pytest.mark.parametrize("cell", ["quad", "triangle", "triangle6"])
def test_well_mixed_exact(cell):
    """Uniform source loading then unloading a closed square: c_s = min(m, c_sat),
    c_g = max(0, m − c_sat) at every node and step (triangle6: HRZ lumping with the lumped
    source), mass balance to round-off, one or two LU solves per step."""
    rate = lambda t: 2.0 if t <= 1.0 + 1e-12 else -1.5  # noqa: E731
    times = np.linspace(0.0, 2.0, 41)
    params = {"D_s": 1.0, "D_g": 0.3, "c_sat": 1.2, "c_s0": 0.1,
              "source": lambda t, xc: np.full(len(xc), rate(t)), "thickness": 0.5}
    r = baseline().run_baseline(rectangle(1.0, 1.0, 4, 3, cell=cell), params, times)
    w = well_mixed(0.1, 1.2, times, rate)
    assert w["c_g"].max() > 0.5 and w["c_g"][-1] == 0 and w["c_s"][-1] < 1.2
    assert np.abs(r["c_s"] - w["c_s"][:, None]).max() < 1e-13
    assert np.abs(r["c_g"] - w["c_g"][:, None]).max() < 1e-13
    assert r["balance_error"].max() < 1e-13
    assert r["iterations"][1:].min() >= 1 and r["iterations"].max() <= 2


@pytest.mark.parametrize("D_g", [0.0, 0.03])
def test_matches_vertex_fv_on_a_strip(D_g):
    """Q1 with lumped capacity on a one-cell-thick strip is the vertex-centred finite-volume
    scheme: the baseline and the reference agree to solver round-off at every step."""
    n = 40
    mesh = strip(n)
    times = grow_shrink_times()
    r = baseline().run_baseline(mesh, scene_params(D_g=D_g), times)
    f = run(grow_shrink_problem(n, "vertex", D_g), times)
    assert f["saturated"].max() > 4                          # the switch is exercised
    assert np.abs(r["c_s"] - on_grid(f["c_s"], mesh, n)).max() < 1e-11
    assert np.abs(r["c_g"] - on_grid(f["c_g"], mesh, n)).max() < 1e-11
    assert np.abs(r["mass"] / 0.05 - f["mass"]).max() < 1e-13
    assert r["balance_error"].max() < 1e-13


def test_boundary_inflow_and_two_regions():
    """Inflow through the left end instead of a source, a mobile gas, c_sat 1 on x < 0.3 and
    1.5 beyond: same answer as the vertex reference; the gas zone grows up to the region
    boundary and stops there (c_s < 1 < 1.5 beyond it); one relation holds at each node."""
    n = 40
    mesh = strip(n)
    times = np.linspace(0.0, 1.5, 61)
    q = lambda t: 2.0 if t <= 0.6 + 1e-12 else 0.0  # noqa: E731
    csat = lambda x: np.where(x < 0.3 - 1e-12, 1.0, 1.5)  # noqa: E731
    r = baseline().run_baseline(mesh, {"D_s": 0.05, "D_g": 0.02, "c_sat": lambda p: csat(p[:, 0]),
                                       "flux": {"left": q}, "dirichlet": {"right": 0.0}}, times)
    f = run(Problem1D(length=1.0, n=n, D_s=0.05, D_g=0.02, c_sat=csat, left=("flux", q),
                      right=("dirichlet", 0.0), grid="vertex"), times)
    assert f["saturated"].max() == 12                       # x = 0 … 0.275: all of region 1
    assert r["c_g"][:, mesh.points[:, 0] > 0.3].max() == 0.0
    assert np.abs(r["c_s"] - on_grid(f["c_s"], mesh, n)).max() < 1e-11
    assert np.abs(r["c_g"] - on_grid(f["c_g"], mesh, n)).max() < 1e-11
    bound = csat(mesh.points[:, 0])
    assert np.all((np.abs(r["c_g"]) < 1e-13) | (np.abs(r["c_s"] - bound) < 1e-13))
    assert r["balance_error"].max() < 1e-13


@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_against_fine_reference(cell):
    """On 80 elements along the strip the baseline is within the discretisation error of the
    1280-cell reference: L1 (per unit width) ≤ 5e-4 for c_s and ≤ 5e-3 for c_g at every step.
    Measured (c_s, c_g): Q1 2.3e-4, 4.4e-3; P1 4.0e-4, 4.4e-3; on 40 / 160 elements Q1 gives
    8.7e-4, 9.5e-3 / 7.6e-5, 1.9e-3 (c_s ~2nd order, c_g ~1.2: the gas front is nodal)."""
    n = 80
    mesh = strip(n, cell)
    times = grow_shrink_times()
    r = baseline().run_baseline(mesh, scene_params(), times)
    fine = fine_grow_shrink()
    weights = r["lumped"] / 0.05
    for key, tol in (("c_s", 5e-4), ("c_g", 5e-3)):
        # the fine cell-centred values, with the wall values (closed left: the first cell's,
        # drained right: 0) so that nodes on the walls are not extrapolated
        xs = np.concatenate([[0.0], fine["x"], [1.0]])
        ref = np.array([np.interp(mesh.points[:, 0], xs, np.concatenate([v[:1], v, [0.0]]))
                        for v in fine[key]])
        # each strip node carries half its column's weight: the L1 norm per unit width
        assert (np.abs(r[key] - ref) @ weights).max() < tol
    assert r["balance_error"].max() < 1e-13
    assert r["saturated"].any(axis=1).sum() > 10


def test_two_dimensional_balance():
    """A 2D square with a corner source and a drained side: the mass balance closes to
    round-off and each node obeys one relation, on triangles."""
    mesh = rectangle(1.0, 1.0, 12, 12, cell="triangle")
    times = np.linspace(0.0, 1.0, 21)
    src = lambda t, xc: np.where((xc[:, 0] < 0.3) & (xc[:, 1] < 0.3) & (t <= 0.5), 10.0, 0.0)  # noqa
    r = baseline().run_baseline(mesh, {"D_s": 0.05, "c_sat": 1.0, "source": src,
                                       "dirichlet": {"right": 0.0, "top": 0.0}}, times)
    assert r["saturated"].sum(axis=1).max() > 5
    assert r["balance_error"].max() < 1e-13
    assert np.all((np.abs(r["c_g"]) < 1e-13) | (np.abs(r["c_s"] - 1.0) < 1e-13))
    assert r["c_g"].min() > -1e-13 and r["c_s"].max() < 1.0 + 1e-13
