"""Newton when every force vanishes: the relative residual has no scale there (round-off over
round-off), so the round-off floor ROUNDOFF·k·|q| decides. A von Mises box moved rigidly and a
block resting on a rough rigid plane under no load (held by its sticking contact rows alone)
converge."""

from __future__ import annotations

import tomllib

import numpy as np

from helpers.control import VON_MISES
from helpers.scene import scene
from parsolve.solvers.problem import ROUNDOFF

# the von Mises box of test_control, both ends moved by 1e-3 along x: a rigid translation
_BOX = tomllib.loads(VON_MISES)
assert [r.get("value") for r in _BOX["relations"] if r["name"] in ("sym_x", "pull")] == [None, 4e-3]
TRANSLATED = scene(_BOX, steps={"count": 3}, relations=[
    r | {"value": 1e-3} if r["name"] in ("sym_x", "pull") else r for r in _BOX["relations"]])

APPROACH = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 0.5
nx = 4
ny = 2
cell = "quad"
[model]
hypothesis = "plane_strain"
[[materials]]
E = 1000.0
nu = 0.3
[[relations]]
name = "hold_x"
type = "dirichlet"
region = "left"
component = "x"
[[relations]]
name = "push"
type = "dirichlet"
region = "top"
component = "y"
value = -0.15
[[contact]]
name = "base"
slave = "bottom"
obstacle = { plane = { origin = [0.0, -0.1], normal = [0.0, 1.0] } }
[steps]
count = 4
"""


def test_rigid_translation_of_a_plastic_body_converges(run):
    res = run(TRANSLATED, name="translated")
    assert res["attrs"]["status"] == "complete"
    assert np.all(res["steps/iterations"] == 1)
    u = res["fields/displacement"]
    t = res["steps/time"]
    assert np.allclose(u[:, :, 0], 1e-3 * t[:, None], rtol=0, atol=1e-15)
    assert np.abs(u[:, :, 1:]).max() < 1e-15
    # the stresses are round-off of E·|u|/L (200 MPa · 1e-3 = 0.2): under ROUNDOFF of it
    assert np.abs(res["fields/stress"]).max() < 1e2 * ROUNDOFF * 200e3 * 1e-3


def test_block_moved_onto_a_plane_converges_before_and_after_contact(run):
    """Steps 1-2 move the block rigidly towards the plane (every force zero), steps 3-4 press
    it on: uniform plane-strain compression, σyy = E/(1 - ν²) · δ/h, exact on quads."""
    res = run(APPROACH, name="approach")
    assert res["attrs"]["status"] == "complete"
    assert np.all(res["steps/iterations"] <= 3)
    t = res["steps/time"]
    closing = np.maximum(0.15 * t - 0.1, 0.0)
    force = closing / 0.5 * 1000.0 / (1 - 0.3**2)        # per unit length, width 1
    rn = res["fields/base_normal_reaction"][:, :, 0].sum(axis=1)
    assert np.allclose(rn, force, rtol=1e-10, atol=1e-12)
    assert np.abs(res["fields/base_normal_reaction"][:2]).max() == 0.0
