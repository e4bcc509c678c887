"""The independent finite-volume reference for gas solubility checks itself: tridiagonal solve,
well-mixed exactness, mass balance to round-off, growth then shrinkage of the saturated zone,
and convergence under refinement."""

import numpy as np
import pytest

from tests.reference.solubility_fv import Problem1D, fine_grow_shrink, grow_shrink_problem, \
    grow_shrink_times, run, tridiag_solve, well_mixed

# Serial numerics (numpy, PETSc.COMM_SELF): running them on every rank would add nothing.
pytestmark = pytest.mark.serial


def test_tridiag_solve():
    rng = np.random.default_rng(0)
    n = 37
    a, c = rng.uniform(-1, 0, n), rng.uniform(-1, 0, n)
    b = 2.5 + rng.uniform(0, 1, n)
    d = rng.normal(size=n)
    A = np.diag(b) + np.diag(a[1:], -1) + np.diag(c[:-1], 1)
    assert np.abs(tridiag_solve(a, b, c, d) - np.linalg.solve(A, d)).max() < 1e-14


@pytest.mark.parametrize("grid", ["cell", "vertex"])
def test_well_mixed_exact(grid):
    """Uniform source, closed walls: every volume follows m_{n+1} = m_n + Δt S(t_{n+1}),
    c_s = min(m, c_sat), c_g = max(0, m − c_sat), loading then unloading."""
    rate = lambda t: 3.0 if t <= 1.0 + 1e-12 else -2.0  # noqa: E731
    times = np.linspace(0.0, 2.0, 41)
    p = Problem1D(length=2.0, n=16, D_s=0.7, D_g=0.2, c_sat=1.5, m0=0.25, grid=grid,
                  source=lambda t, x: rate(t) * np.ones_like(x))
    r = run(p, times)
    w = well_mixed(0.25, 1.5, times, rate)
    assert w["c_g"].max() > 1.0 and w["c_g"][-1] == 0.0 and w["c_s"][-1] < 1.5  # both ways
    assert np.abs(r["c_s"] - w["c_s"][:, None]).max() < 1e-13
    assert np.abs(r["c_g"] - w["c_g"][:, None]).max() < 1e-13


@pytest.mark.parametrize("grid", ["cell", "vertex"])
@pytest.mark.parametrize("D_g", [0.0, 0.03])
def test_grow_shrink_balance(grid, D_g):
    """The shipped scene: the saturated zone grows while the source is on, shrinks after and
    vanishes; the mass balance closes to round-off at every step."""
    times = grow_shrink_times()
    r = run(grow_shrink_problem(80, grid, D_g), times)
    sat = r["saturated"]
    k_on = np.searchsorted(times, 0.5)
    assert sat[:10].max() == 0 and sat[k_on] >= 10
    assert np.all(np.diff(sat[k_on + 2:]) <= 0) and sat[-1] == 0
    assert np.all(np.diff(sat[: k_on + 1]) >= 0)
    assert r["balance_error"].max() < 1e-13
    assert np.all(r["c_g"] >= 0) and np.all(r["c_s"] <= 1.0 + 1e-15)
    # the total injected is 4 × 1/4 × 1/2 = 1/2; what is not left has drained through x = 1
    assert abs(r["source_in"].sum() - 0.5) < 1e-13
    assert abs(r["mass"][-1] - 0.5 - r["boundary_in"].sum()) < 1e-13


def _restrict(fine: dict, coarse: dict, grid: str, key: str) -> np.ndarray:
    if grid == "cell":  # mean of the fine cells inside each coarse cell
        n = len(coarse["x"])
        return fine[key].reshape(len(fine[key]), n, -1).mean(axis=2)
    return np.array([np.interp(coarse["x"], fine["x"], v) for v in fine[key]])


@pytest.mark.parametrize("grid", ["cell", "vertex"])
def test_grow_shrink_converges(grid):
    """L1 errors in c_s and c_g (max over the steps; same time steps, so this is the spatial
    error) against a 1280-cell solution fall as the grid is refined 20 → 160: mean rate ≈ 1.8
    for c_s; for c_g ≈ 1.8 (cell) and ≈ 1.1 (vertex: nodal c_g across the moving front)."""
    times = grow_shrink_times()
    fine = fine_grow_shrink()
    errors = []
    for n in (20, 40, 80, 160):
        r = run(grow_shrink_problem(n, grid), times)
        errors.append([(np.abs(r[k] - _restrict(fine, r, grid, k)) @ r["V"]).max()
                       for k in ("c_s", "c_g")])
    errors = np.array(errors)
    assert np.all(errors[1:] < errors[:-1])
    rate = np.log2(errors[0] / errors[-1]) / 3
    assert rate[0] > 1.6 and rate[1] > (1.6 if grid == "cell" else 1.0)
    assert errors[-1, 0] < 1e-4 and errors[-1, 1] < (1e-4 if grid == "cell" else 2.5e-3)


def test_two_regions():
    """c_sat 1 on x < 1/2 and 2 beyond, uniform source, closed walls: the left half saturates
    first and gas stays there while the right half is still below its bound (c_s, higher on the
    right, diffuses into the left half and turns to gas there); every node obeys one of the two relations and
    the mass balances."""
    times = np.linspace(0.0, 1.0, 21)
    csat = lambda x: np.where(x < 0.5, 1.0, 2.0)  # noqa: E731
    r = run(Problem1D(length=1.0, n=40, D_s=0.05, c_sat=csat,
                      source=lambda t, x: 1.5 * np.ones_like(x)), times)
    cs, cg, bound = r["c_s"], r["c_g"], r["c_sat"]
    assert np.all(cg >= 0) and np.all(cs <= bound + 1e-15)
    assert np.all((cg == 0) | (cs == bound))              # one of the two relations everywhere
    assert cg[-1, r["x"] < 0.5].min() > 0 and cg[-1, r["x"] > 0.6].max() == 0
    assert r["balance_error"].max() < 1e-13
    assert abs(r["mass"][-1] - 1.5) < 1e-13
