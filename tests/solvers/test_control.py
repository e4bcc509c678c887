"""Control ("pilotage") through non-associated relations, against closed forms and baselines."""

import numpy as np
import pytest

from conftest import CONFIGS
from helpers.control import (ARC_BAR, BAR, VON_MISES, E, H, L, N, closed_form,  # noqa: F401
                             displacement_control, end_delta, without_control)
from parsolve.errors import InputError, SolverError


def test_localization_bar_closed_form(run):
    res = run(CONFIGS / "localization_bar.toml", name="bar")
    assert res["attrs"]["status"] == "complete"
    eps_d = 5e-5 * np.arange(1, 25)
    delta, force = closed_form(eps_d)
    assert np.all(np.diff(delta)[2:10] < 0)  # the snap-back
    lam = res["relations/max_strain/multiplier"]
    active = res["relations/max_strain/active"]
    assert np.all(active.sum(axis=1) == 1)  # exactly one enforced row per step
    np.testing.assert_allclose(lam.sum(axis=1), force, rtol=1e-6)
    np.testing.assert_allclose(end_delta(res), delta, rtol=1e-6)
    # past the peak, the enforced row is an element of the damaged column
    middle = np.abs(res["mesh/points"][res["mesh/cells/quad"]].mean(axis=1)[:, 0] - 14.5 / 29) < 1e-9
    assert np.all(middle[np.argmax(active[3:], axis=1)])
    np.testing.assert_allclose(res["cell_fields/damage"][-1][middle],
                               1 - np.exp(-1e4 * (1.2e-3 - 1e-4)), rtol=1e-6)


def test_load_control_stops_at_the_peak(run):
    text = without_control(BAR).replace("total_force = [1.0, 0.0]", "total_force = [1.2e4, 0.0]")
    with pytest.raises(SolverError):
        run(text, name="bar_load")
    from conftest import read_results

    res = read_results(run.last)
    assert res["attrs"]["status"].startswith("failed")
    force = 1.2e4 * res["steps/time"]
    assert len(force) == 20 and force.max() <= 1e4 + 1e-6  # every step below the peak kept
    np.testing.assert_allclose(end_delta(res), force / (E * H), rtol=1e-9)  # elastic until then


def test_displacement_control_stops_at_the_snap_back(run):
    text = displacement_control()
    with pytest.raises(SolverError):
        run(text, name="bar_disp")
    from conftest import read_results

    res = read_results(run.last)
    delta = end_delta(res)
    force = -res["relations/end_displacement/multiplier"][:, 0]
    # up to the peak: the 10 elastic steps; after it the controlled displacement cannot follow
    # the snap-back: the softening branch (forces between 0 and the peak) is never traced.
    # A step that converges after the peak is the ruptured bar (a real equilibrium whose
    # forces vanish: under 1e-9 of the peak), after which the system is singular.
    assert np.allclose(force[:10], 1e3 * np.arange(1, 11), rtol=1e-9)
    assert delta[:10].max() <= 1e-4 + 1e-12
    assert np.all(np.abs(force[10:]) < 1e-9 * force[:10].max())


def test_plate_with_hole_passes_the_peak(run):
    res = run(CONFIGS / "plate_hole_control.toml", name="plate")
    assert res["attrs"]["status"] == "complete"
    force = res["relations/max_strain/multiplier"].sum(axis=1)
    peak = int(np.argmax(force))
    assert 0 < peak < len(force) - 5 and force[-1] < 0.95 * force[peak]
    assert res["cell_fields/damage"][-1].max() > 0.99
    assert np.all(res["steps/residual"] < 1e-8)


def test_two_controls_against_compliance(run):
    """λ solves C λ = targets, C the 2 × 2 compliance of the two patterns (independent runs)."""
    text = (CONFIGS / "two_controls.toml").read_text()
    res = run(CONFIGS / "two_controls.toml", name="two")
    i = text.index('[[relations]]\nname = "stretch"')
    base = text[:i] + text[text.index("[evolutions.up_down]"):]
    C = np.zeros((2, 2))
    for j, pattern in enumerate(("axial", "transverse")):
        other = "transverse" if pattern == "axial" else "axial"
        unit = base.replace(f'name = "{other}"', f'name = "{other}"\nevolution = "zero"') + \
            '\n[evolutions.zero]\ntimes = [0.0]\nvalues = [0.0]\n'
        r = run(unit.replace("count = 4", "times = [1.0]"), name=f"unit_{pattern}")
        pts = r["mesh/points"]
        right = np.isclose(pts[:, 0], 2.0)
        C[:, j] = r["fields/displacement"][-1][right].mean(axis=0)
    t = res["steps/time"]
    targets = np.column_stack([1e-4 * t, 2e-3 * np.interp(t, [0, 0.5, 1], [0, 1, 0.5])])
    lam = np.column_stack([res["relations/stretch/multiplier"][:, 0],
                           res["relations/deflection/multiplier"][:, 0]])
    np.testing.assert_allclose(lam, np.linalg.solve(C, targets.T).T, rtol=1e-9)


BAD = {
    "maximum over a zone without cells": (
        BAR.replace('region = "all"\ncomponent = "xx"', 'region = "corner"\ncomponent = "xx"'),
        "relations[3].region"),
    "maximum over an empty zone": (
        BAR.replace('middle = "x > 14/29 and x < 15/29"', 'middle = "x > 14/29 and x < 15/29"\n'
                    'nowhere = "x > 5"').replace('region = "all"\ncomponent = "xx"',
                                                 'region = "nowhere"\ncomponent = "xx"'),
        "regions.nowhere"),
    "non-positive step": (BAR.replace("count = 24", "count = 0"), "steps.count"),
    "equality maximum": (BAR.replace('sense = "<="', 'sense = "="'), "relations[3].maximum"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_control_input(case, run):
    text, key = BAD[case]
    with pytest.raises(InputError) as err:
        run(text, name="bad")
    assert key in str(err.value)


def test_von_mises_bar_follows_the_bilinear_curve(run):
    """Uniaxial tension with free contraction: σ = E ε, then σ_y + E H/(E + H) (ε - σ_y/E);
    the consistent tangent converges quadratically (4 iterations to 1e-8)."""
    res = run(VON_MISES, name="vm")
    eps = 4e-3 * res["steps/time"]
    Et = 200e3 * 2e3 / (200e3 + 2e3)
    sigma = np.where(eps < 250 / 200e3, 200e3 * eps, 250 + Et * (eps - 250 / 200e3))
    force = res["relations/sym_x/multiplier"].sum(axis=1)  # λ = minus the reaction (at x = 0: -F)
    np.testing.assert_allclose(force, sigma * 0.2 * 0.2, rtol=1e-8)
    assert res["steps/iterations"].max() <= 4  # quadratic: 3e-1, 2e-3, 2e-6, 4e-13
    np.testing.assert_allclose(res["cell_fields/stress"][-1][:, 0], sigma[-1], rtol=1e-8)


def test_automatic_steps_keep_the_strain_increment_near_the_target(run):
    text = (CONFIGS / "plate_hole_control.toml").read_text().replace(
        "count = 30", "count = 30\nautomatic = { strain_increment = 8e-5, max_steps = 60 }")
    res = run(text, name="plate_auto")
    t = res["steps/time"]
    assert res["attrs"]["status"] == "complete" and t[-1] == pytest.approx(1.0)
    assert len(t) < 30  # larger steps than the fixed 4e-5 per step where it is safe


def test_fixed_steps_are_cut_and_retried(run):
    """The plate with a hole needs up to 5 Newton iterations per step; with at most 4 some of
    its fixed steps fail, are cut in two and retried: the intermediate steps are saved (and
    counted in /steps/cuts), the scene's steps are all reached, and the answers at those steps
    agree with the uncut run's (to 1e-3: the maximum group's enforced row may change inside a
    cut step, so the damage history differs slightly)."""
    text = (CONFIGS / "plate_hole_control.toml").read_text()
    cut = run(text.replace("max_iterations = 60", "max_iterations = 4"), name="plate_cut")
    full = run(text, name="plate_full")
    assert cut["attrs"]["status"] == "complete"
    t = cut["steps/time"]
    assert len(t) > 30 and cut["steps/cuts"].max() >= 1 and t[-1] == pytest.approx(1.0)
    scene_steps = np.isin(np.round(t, 12), np.round(full["steps/time"], 12))
    assert scene_steps.sum() == 30
    np.testing.assert_allclose(cut["relations/max_strain/multiplier"][scene_steps].sum(axis=1),
                               full["relations/max_strain/multiplier"].sum(axis=1), rtol=1e-3)


def test_arc_length_on_an_elastic_bar(run):
    """The arc-length baseline on a linear bar: equal load-factor increments (||Δq|| = Δl),
    the end displacement μ L / (E A), the clamp's reaction balancing μ."""
    res = run(ARC_BAR, name="arc")
    assert res["attrs"]["status"] == "complete"
    mu = res["steps/time"]
    np.testing.assert_allclose(np.diff(np.concatenate([[0.0], mu])), mu[0], rtol=1e-10)
    u = res["fields/displacement"][..., 0]
    assert np.all(mu > 0)
    np.testing.assert_allclose(u.max(axis=1), mu * 1.0 / (1e3 * 0.1), rtol=1e-10)
    np.testing.assert_allclose(res["relations/clamp/multiplier"].sum(axis=1), mu, rtol=1e-10)
    step = np.diff(np.concatenate([np.zeros((1,) + res["fields/displacement"].shape[1:]),
                                   res["fields/displacement"]]), axis=0)
    np.testing.assert_allclose(np.linalg.norm(step.reshape(3, -1), axis=1), 1e-3, rtol=1e-10)


MAZARS_AT = ('model = "mazars"\neps_d0 = {}\nAt = 1.0\nBt = 1e4\nAc = 1.2\nBc = 1500.0\n'
             'beta = 1.06\n')


def _controlled_bar(eps_d0: float) -> str:
    """configs/controlled_bar.toml (mean end displacement 1e-4 t, its unit end load) with every
    cell Mazars: Newton's path. Elastic while ε = 1e-4 t stays below eps_d0."""
    text = (CONFIGS / "controlled_bar.toml").read_text()
    return text.replace("E = 1e9\nnu = 0.0\n", "E = 1e9\nnu = 0.0\n" + MAZARS_AT.format(eps_d0))


def _elastic_maximum() -> str:
    """The localization bar without its damaging column: the maximum strain control of an
    elastic bar (Newton's path for the unilateral rows)."""
    return BAR[:BAR.index("[[materials]]\nregion")] + BAR[BAR.index("[[loads]]"):]


# name: (scene, control, t of the first step, linear response λ = target / compliance,
#        converged λ, iterations of the first step)
FIRST_STEP = {
    # δ = 1e-5 at t = 0.1; compliance of the unit end load L / (E H) = 1e-8
    "linear": (lambda: _controlled_bar(1e-2), "control", 0.1, 1e3, 1e3, 1),
    # ε = 1e-5 past εd0 = 2e-6 from the first step: homogeneous softening, At = 1 (ν = 0):
    # σ = E ε exp(-Bt (ε - εd0)); the first iterate is the linear response all the same
    "softening": (lambda: _controlled_bar(2e-6), "control", 0.1, 1e3,
                  1e3 * np.exp(-1e4 * (1e-5 - 2e-6)), 2),
    # ε = 1.2e-3 / 24 = 5e-5 in every cell: λ = E H ε; the maximum's predictor solve counts
    "maximum": (_elastic_maximum, "max_strain", 1 / 24, 5e3, 5e3, 2),
}


@pytest.mark.parametrize("case", sorted(FIRST_STEP))
def test_first_step_load_is_the_linear_response(case):
    """The control load of the first step starts from the linear response, not from zero:
    Newton's unknowns are the total multipliers, so its first solve (the tangent at the
    unloaded state, the control row enforced) gives λ = (b - A q) / (A K⁻¹ G), the target over
    the compliance of the load pattern, exactly. A linear bar converges on it in one
    iteration; a bar softening from the first step goes on from it to its closed form."""
    from helpers.control import newton_of

    make, name, t, linear, converged, iterations = FIRST_STEP[case]
    _, _, _, problem, newton = newton_of(make())
    from parsolve.outputs import every_row
    k = [r.name for r in problem.ctx.multiplied].index(name)
    rows, rel = problem.rset.rows_of(k), problem.ctx.multiplied[k]
    loads, update = [], problem.update

    def recorded(t, x):   # (a maximum's rows: each on its rank, gathered)
        out = update(t, x)
        loads.append(every_row(problem.comm, rel, problem.rset.every_row(problem.lam)[rows]).sum())
        return out

    problem.update = recorded
    result = newton.step(t)
    assert loads[0] == pytest.approx(linear, rel=1e-12)
    assert loads[-1] == pytest.approx(converged, rel=1e-9)
    assert result.iterations == iterations
    assert newton.residual_history[-1] < 1e-12
