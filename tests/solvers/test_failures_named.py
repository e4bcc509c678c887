"""Failures named the same way whatever the partition (parsolve/solvers/stability.py
``check_path``, parsolve/driver.py ``_final_failure``).

The localization bar pulled by a prescribed end displacement (tests/solvers/test_control.py):
elastic up to its peak at step 10 (t = 10/24, δ = 1e-4), where the 15th column starts to
soften. Under a prescribed displacement the path turns back (a snap-back) only 3.6e-6 of strain
past the peak: no equilibrium near the peak carries it on. On main a secant step from there
jumped, on one rank, to the ruptured bar (an "11×" warning, then null pivots) and failed, on
two and three, on Newton's non-convergence at t = 0.417318: three messages for one cause. The
consistent tangent with the end held has a negative eigenvalue along the step's predictor just
past the peak, which the run now says at every rank count, after the same 10 steps.

An arc-length run that passes a bifurcation (several negative eigenvalues at once, where a
limit point gives one) stops there, named (``ArcWatch``).

A first step that fails after all its cuts says that no step converged, down to which time,
what the last attempt failed on, and the way out."""

import numpy as np
import pytest

from conftest import read_results
from helpers.control import BAR, E, H, L, displacement_control, end_delta, without_control
from test_distributed_arc_length import softening_bar

from parsolve.errors import SolverError

PEAK = 10 / 24


def test_displacement_control_past_the_snap_back_is_named(run):
    with pytest.raises(SolverError) as info:
        run(displacement_control(), name="snap")
    message = str(info.value)
    assert message.startswith(f"the equilibrium path turns back just past t = {PEAK:.6g}: ")
    assert "a snap-back" in message and "arc-length" in message
    res = read_results(run.last)
    assert res["attrs"]["status"] == f"failed: {message}"
    # the 10 elastic steps up to the peak, and no step past it (neither a jump nor a cut step)
    np.testing.assert_allclose(res["steps/time"], np.arange(1, 11) / 24, rtol=1e-12)
    force = -res["relations/end_displacement/multiplier"][:, 0]
    np.testing.assert_allclose(force, 1e3 * np.arange(1, 11), rtol=1e-9)
    np.testing.assert_allclose(end_delta(res), 1e-5 * np.arange(1, 11), rtol=1e-9)


def _not_held() -> str:
    """The bar under a load, its left end not held along x: singular at any load."""
    text = without_control(BAR).replace("total_force = [1.0, 0.0]", "total_force = [1e3, 0.0]")
    text = text.replace('name = "left_x"\ntype = "dirichlet"\nregion = "left"\n'
                        'components = ["x"]', 'name = "left_x"\ntype = "dirichlet"\n'
                        'region = "left"\ncomponents = ["y"]')
    return text.replace("count = 24", "count = 4")


FIRST = {"not_held": (_not_held, "singular system: MUMPS found 1 null pivot(s)")}


@pytest.mark.parametrize("case", sorted(FIRST))
def test_a_first_step_that_fails_for_good_says_why(run, case):
    make, cause = FIRST[case]
    with pytest.raises(SolverError) as info:
        run(make(), name=case)
    message = str(info.value)
    # the scene's first step t = 1/4, halved 6 times
    assert message.startswith(f"no step converged: the first step failed down to t = "
                              f"{0.25 / 64:.6g} (after 6 cuts); the last attempt: {cause}")
    assert "the way out: check that the supports hold the body" in message
    res = read_results(run.last)
    assert res["attrs"]["status"] == f"failed: {message}"
    assert res["steps/time"].size == 0


def test_arc_length_bifurcation_is_named(run):
    """The 3-column softening bar of test_distributed_arc_length with every cell Mazars: the
    bar stays homogeneous up to its peak, where each column may soften alone: with the end
    load dead, each column's stretch is a direction of negative stiffness, 3 at once (a limit
    point alone gives one). The run stops there, named, after the 8 elastic steps; the
    3-column bar with one Mazars column passes its limit point (one at a time) and completes
    (test_distributed_arc_length)."""
    text = softening_bar()
    first = text.index("[[materials]]")
    text = text[:first] + text[text.index("[[materials]]", first + 1):].replace(
        'region = "middle"\n', "")
    with pytest.raises(SolverError) as info:
        run(text, name="arc_bifurcation")
    message = str(info.value)
    res = read_results(run.last)
    mu = res["steps/time"]
    assert mu.size == 8 and np.all(np.diff(mu) > 0)
    # elastic: equal load increments, the end at μ L / (E H)
    np.testing.assert_allclose(np.diff(mu), mu[0], rtol=1e-9)
    np.testing.assert_allclose(end_delta(res), mu * L / (E * H), rtol=1e-9)
    assert message.startswith(f"arc-length passed a bifurcation at step 9 (load factor "
                              f"{mu[-1]:.6g} to ")
    assert "went from 0 to 3 negative eigenvalues at once" in message
    assert res["attrs"]["status"] == f"failed: {message}"
