"""Crisfield's arc-length on the distributed mesh: the same steps, fields and multipliers as
on one rank alone (1e-10, active rows exactly), through a limit point, and the analytic
softening bar's numbers on the parts.

The softening bar is the localization bar of ``test_control`` (its closed form, same Mazars
column) with 3 columns of cells instead of 29: then the damaged column's softening is too
weak to make the bar snap back (δ keeps growing, d δ / d ε_d ≥ (1 - 2 · e⁻¹) L / 3 > 0), and
the path turns at a limit point, the closed form's peak load E H εd0 = 1e4 at ε_d = εd0, which
Crisfield's arc-length passes (on 29 columns it stalls at the snap-back: bench_control)."""

import numpy as np
from mpi4py import MPI
import pytest

from conftest import assert_same_results
from helpers.control import ARC_BAR, BAR, E, H, L, closed_form, end_delta, without_control

COLUMNS = 3
EPS_D0 = 1e-4   # the Mazars column's damage threshold: the closed form's peak


def softening_bar(max_iterations: int = 30, steps: int = 20) -> str:
    """The localization bar, 3 columns, its end load driven by arc-length (tangent matrix)."""
    text = without_control(BAR)
    for old, new in (("nx = 29", f"nx = {COLUMNS}"),
                     ('middle = "x > 14/29 and x < 15/29"', 'middle = "x > 1/3 and x < 2/3"'),
                     ('matrix = "secant"', 'matrix = "tangent"'),
                     ("count = 24", f"count = {steps}"),
                     ("[nonlinear]\n", f'[nonlinear]\nmethod = "arc_length"\nmax_iterations = '
                                       f'{max_iterations}\narc_length = {{ pattern = "pull", '
                                       'length = 3e-5 }\n')):
        assert old in text, old
        text = text.replace(old, new)
    return text


def column_strain(res) -> np.ndarray:
    """ε_xx of the damaged (middle) column at each step, from its edges' displacements."""
    x = res["mesh/points"][:, 0]
    u = res["fields/displacement"][..., 0]
    left, right = (u[:, np.isclose(x, c * L / COLUMNS)].mean(axis=1) for c in (1, 2))
    return (right - left) * COLUMNS / L


@pytest.mark.parametrize("max_iterations, steps", [(30, 20), (3, 12)])
def test_limit_point_same_on_the_parts(run, max_iterations, steps):
    """Through the limit point on both meshes; with at most 3 iterations the steps at and past
    the peak are cut (halved arcs, retried from the saved state) on both alike."""
    text = softening_bar(max_iterations, steps)
    whole = run(text, name=f"whole{max_iterations}", comm=MPI.COMM_SELF)
    parts = run(text, name=f"parts{max_iterations}")
    assert_same_results(parts, whole)
    mu = parts["steps/time"]
    assert np.diff(mu)[0] > 0 and np.diff(mu)[-1] < 0   # up to the limit point, then down
    if max_iterations == 3:
        assert parts["steps/iterations"].max() > 3      # some steps were cut


def test_softening_bar_closed_form_on_the_parts(run):
    """Every step on the closed form: the load factor is the force of the damaged column at
    its strain, the end moves by the damaged column's stretch plus the elastic columns'; the
    load rises to the limit load E H εd0 and falls past it, while the end keeps moving."""
    res = run(softening_bar(), name="softening")
    assert res["attrs"]["status"] == "complete"
    mu, eps_d = res["steps/time"], column_strain(res)
    np.testing.assert_allclose(mu, closed_form(eps_d)[1], rtol=1e-8)
    delta = eps_d * L / COLUMNS + mu / (E * H) * L * (COLUMNS - 1) / COLUMNS
    np.testing.assert_allclose(end_delta(res), delta, rtol=1e-8)
    limit = closed_form(np.array([EPS_D0]))[1][0]
    assert limit == pytest.approx(E * H * EPS_D0, rel=1e-12)        # 1e4
    peak = int(np.argmax(mu))
    assert mu[peak] < limit and eps_d[peak - 1] < EPS_D0 < eps_d[peak + 1]
    assert np.all(np.diff(mu[:peak + 1]) > 0) and np.all(np.diff(mu[peak:]) < 0)
    assert np.all(np.diff(end_delta(res)) > 0)   # a limit point, not a snap-back
    assert mu[-1] < 0.1 * limit                   # far down the softening branch
    # the elastic steps: equal arcs of the whole displacement vector (||Δq|| = Δl)
    step = np.diff(res["fields/displacement"][:peak], axis=0).reshape(peak - 1, -1)
    np.testing.assert_allclose(np.linalg.norm(step, axis=1), 3e-5, rtol=1e-10)


def test_multiplied_support_on_the_parts(run):
    """The elastic bar with its supports as multipliers (not eliminated): the clamp's
    multiplier balances the load factor, the same on both meshes."""
    whole = run(ARC_BAR, name="bar_whole", comm=MPI.COMM_SELF, solver={"eliminate": False})
    parts = run(ARC_BAR, name="bar_parts", solver={"eliminate": False})
    assert_same_results(parts, whole)
    mu = parts["steps/time"]
    np.testing.assert_allclose(parts["relations/clamp/multiplier"].sum(axis=1), mu, rtol=1e-10)
    np.testing.assert_allclose(parts["fields/displacement"][..., 0].max(axis=1),
                               mu * 1.0 / (1e3 * 0.1), rtol=1e-10)
