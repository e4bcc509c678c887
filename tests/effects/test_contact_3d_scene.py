"""The shipped 3D friction scene, configs/contact_friction_3d.toml: a box pressed on a rough
rigid plane, its top moved obliquely; partial slip, then the whole base slides."""

from __future__ import annotations

import numpy as np

from conftest import CONFIGS
from parsolve.contact.friction import OPEN, SLIP, STICK
from helpers.contact import coulomb_checks


def test_box_shifted_obliquely_sticks_slips_then_slides(run):
    """The Coulomb conditions at every node and step (cone to 1e-8, no penetration, sticking
    nodes still, sliding ones on the cone with their slip along -Rt); the friction balances the
    forces that move the top; partial slip first, then every node slides; once they all slide
    the friction sums to mu N node by node (sum of |Rt| = mu N to 1e-10) and the resultant
    |T| <= mu N grows towards it as the slip directions align with the shift; iterations per
    step as measured (8-18)."""
    res = run(CONFIGS / "contact_friction_3d.toml", name="friction_3d")
    mu, p = 0.3, 10.0
    pts = res["mesh/points"]
    bottom = np.isclose(pts[:, 2], 0.0)
    state, rn = coulomb_checks(res, "base", mu, bottom)
    n_force = res["relations/base_normal/normal_force"][:, 0]
    np.testing.assert_allclose(n_force, p, rtol=1e-12)
    t_force = res["relations/base_normal/tangential_force"]
    drive = np.column_stack([res["relations/shift_x/multiplier"].sum(axis=1),
                             res["relations/shift_y/multiplier"].sum(axis=1)])
    np.testing.assert_allclose(t_force, drive, atol=1e-10 * p)   # λ is minus the reaction
    resultant = np.linalg.norm(t_force, axis=1)
    assert np.all(resultant <= mu * p * (1 + 1e-10))
    closed = state[:, bottom] > OPEN
    assert np.all(closed)
    all_slide = np.all(state[:, bottom] == SLIP, axis=1)
    assert np.any(state[0, bottom] == STICK) and np.any(state[0, bottom] == SLIP)
    assert not all_slide[0] and all_slide[-1]
    first = int(np.argmax(all_slide))
    assert np.all(all_slide[first:])
    rt = np.linalg.norm(res["fields/base_tangential_reaction"], axis=2)
    np.testing.assert_allclose(rt[all_slide].sum(axis=1), mu * p, rtol=1e-10)
    assert np.all(np.diff(resultant[first:]) > 0) and resultant[-1] > 0.99 * mu * p
    # the friction opposes the shift (2, 1)/sqrt(5) more and more closely
    e = np.array([2.0, 1.0]) / np.sqrt(5.0)
    assert np.all(t_force @ e < 0)
    its = res["steps/iterations"]
    print(f"\ncontact_friction_3d: iterations per step {its.tolist()}, sliding nodes "
          f"{(state[:, bottom] == SLIP).sum(axis=1).tolist()} of {bottom.sum()}, "
          f"|T|/(mu N) {np.round(resultant / (mu * p), 4).tolist()}")
    assert its.max() <= 20, its
