"""Gas solubility (the paper's fourth use) through switched non-associated relations: exact
answers of a well-mixed domain, an independent finite-volume reference, mass to round-off."""

import numpy as np

from conftest import CONFIGS
from tests.reference.solubility_fv import GROW_SHRINK, Problem1D, grow_shrink_problem, \
    grow_shrink_times, run as reference


def along_strip(res, name):
    """Values of a scalar field on the strip's bottom nodes, ordered by x: (nsteps, nx + 1)."""
    pts = res["mesh/points"]
    bottom = np.flatnonzero(np.isclose(pts[:, 1], 0.0))
    return res[f"fields/{name}"][:, bottom[np.argsort(pts[bottom, 0])], 0]


def test_well_mixed_is_exact_on_loading_and_unloading(run):
    res = run(CONFIGS / "solubility_well_mixed.toml", name="well_mixed")
    t = res["steps/time"]
    rate = np.where(t <= 2.0 + 1e-12, 1.0, -1.0)           # the source at each step's end
    m = np.cumsum(np.diff(np.concatenate([[0.0], t])) * rate)
    cs, cg = res["fields/c_s"][..., 0], res["fields/c_g"][..., 0]
    np.testing.assert_allclose(cs, np.minimum(m, 1.0)[:, None] + 0 * cs, atol=1e-13)
    np.testing.assert_allclose(cg, np.maximum(m - 1.0, 0.0)[:, None] + 0 * cg, atol=1e-13)
    state = res["fields/solubility_state"][..., 0]
    saturated = m > 1.0 + 1e-9
    assert np.all(state[saturated] == 1) and np.all(state[m < 1.0 - 1e-9] == 0)
    assert saturated[:25].any() and not saturated[-5:].any()  # gas appears, then is exhausted


def test_grow_shrink_matches_the_finite_volume_reference(run):
    """Q1 with lumped capacity on a one-cell strip is the reference's vertex scheme: the same
    numbers to round-off, at every step, on any number of ranks."""
    res = run(CONFIGS / "solubility_grow_shrink.toml", name="grow_shrink")
    ref = reference(grow_shrink_problem(80, "vertex"), grow_shrink_times())
    np.testing.assert_allclose(along_strip(res, "c_s"), np.array(ref["c_s"])[1:], atol=1e-11)
    np.testing.assert_allclose(along_strip(res, "c_g"), np.array(ref["c_g"])[1:], atol=1e-11)
    saturated = (along_strip(res, "solubility_state") == 1).sum(axis=1)
    grows, peak = saturated[:25], saturated.argmax()
    assert saturated[10] == 0 and saturated[peak] >= 10 and saturated[-1] == 0  # grows, shrinks
    assert np.all(np.diff(grows) >= 0) and 20 <= peak <= 30
    assert res["steps/iterations"].max() <= 4


def test_mass_is_conserved_to_round_off(run):
    res = run(CONFIGS / "solubility_grow_shrink.toml", name="balance")
    storage = res["balance/total/storage"]
    assert np.abs(res["balance/total/error"]).max() <= 1e-12 * storage.max()
    assert np.abs(res["balance/total/step_error"]).max() <= 1e-13 * storage.max()  # each step
    # the injected 0.5 per unit width, less what the drain took, is what is stored
    injected = GROW_SHRINK["source"] * GROW_SHRINK["source_region"] * 0.5 * 0.05
    drained = -(res["balance/c_s/supplied"][-1] + res["balance/c_g/supplied"][-1] - injected)
    assert abs(storage[-1] - (injected - drained)) <= 1e-14
    # the gas has no source and no boundary: all of it came through the phase exchange
    np.testing.assert_allclose(res["balance/c_g/reactions"], res["balance/c_g/storage"],
                               atol=1e-15)
    assert res["balance/c_g/storage"].max() > 1e-3
    # each phase's balance closes with the exchange in it
    assert np.abs(res["balance/c_s/error"]).max() <= 1e-12 * storage.max()
    assert np.abs(res["balance/c_g/error"]).max() <= 1e-12 * storage.max()


def test_two_regions_of_different_saturation(run):
    res = run(CONFIGS / "solubility_two_regions.toml", name="two_regions")
    c_sat = lambda x: np.where(x >= 0.5 - 1e-12, 0.5, 1.0)  # noqa: E731
    problem = Problem1D(length=1.0, n=80, D_s=0.1, c_sat=c_sat,
                        source=lambda t, x: np.where(t <= 0.5 + 1e-12, 3.0, 0.0) + 0 * x,
                        left=("flux", 0.0), right=("dirichlet", 0.0), grid="vertex")
    ref = reference(problem, grow_shrink_times())
    np.testing.assert_allclose(along_strip(res, "c_s"), np.array(ref["c_s"])[1:], atol=1e-11)
    np.testing.assert_allclose(along_strip(res, "c_g"), np.array(ref["c_g"])[1:], atol=1e-11)
    x = np.sort(res["mesh/points"][np.isclose(res["mesh/points"][:, 1], 0.0), 0])
    cs = along_strip(res, "c_s")
    assert np.all(cs <= c_sat(x)[None, :] + 1e-12)          # never above its region's limit
    gas = along_strip(res, "c_g")
    assert gas[:, x > 0.5].max() > 0 and gas[:, x < 0.5].max() > 0
