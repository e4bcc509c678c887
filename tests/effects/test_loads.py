"""Load patterns: resultants of tractions, body forces and normalised tractions."""

import tomllib

import numpy as np

from parsolve.model import build_model
from parsolve.scene import parse_scene

SCENE = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 0.5
nx = 8
ny = 3
cell = "{cell}"
[model]
hypothesis = "plane_stress"
thickness = 0.1
[[materials]]
E = 1.0
nu = 0.3
[[loads]]
name = "edge"
region = "right"
traction = [3.0, -1.0]
[[loads]]
name = "unit"
region = "top"
total_force = [0.0, -7.0]
[[loads]]
name = "weight"
body = [0.0, -2.0]
"""


def patterns(cell):
    text = SCENE.format(cell=cell)
    return build_model(parse_scene(tomllib.loads(text), "s.toml", text)).patterns


def resultant(vec):
    return vec.reshape(-1, 2).sum(axis=0)


def test_resultants():
    for cell in ("quad", "triangle", "triangle6"):
        p = patterns(cell)
        np.testing.assert_allclose(resultant(p["edge"].vector()), [3.0 * 0.5 * 0.1, -1.0 * 0.5 * 0.1])
        np.testing.assert_allclose(resultant(p["unit"].vector()), [0.0, -7.0])
        np.testing.assert_allclose(resultant(p["weight"].vector()), [0.0, -2.0 * 2.0 * 0.5 * 0.1])


def test_p2_edge_load_is_consistent():
    """A uniform traction on a quadratic edge: 1/6, 4/6, 1/6 of each edge's force."""
    p = patterns("triangle6")["edge"].vector().reshape(-1, 2)[:, 0]
    nonzero = np.sort(p[p != 0])
    edge_force = 3.0 * 0.1 * 0.5 / 3  # three edges on the right side
    expected = [1, 1, 2, 2, 4, 4, 4]   # ends, shared vertices (two edges), mid-edge nodes
    np.testing.assert_allclose(nonzero, np.array(expected) * edge_force / 6)


def test_ramp_evolution_scales_applied_loads():
    text = SCENE.format(cell="quad")
    model = build_model(parse_scene(tomllib.loads(text), "s.toml", text))
    np.testing.assert_allclose(model.external_load(0.25), 0.25 * model.external_load(1.0))


def test_two_conditions_meeting_at_a_corner(run):
    """u_x = 0 on the left edge and on the bottom edge fix the corner twice with the same value:
    the corner's row stays with the first relation and the run goes on; different values at
    the corner are an input error."""
    import pytest as _pytest

    from parsolve.errors import InputError

    text = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 4
ny = 4
cell = "quad"
[model]
hypothesis = "plane_stress"
[[materials]]
E = 100.0
nu = 0.3
[[loads]]
name = "pull"
region = "right"
traction = [1.0, 0.0]
[[relations]]
name = "left"
type = "dirichlet"
region = "left"
components = ["x", "y"]
[[relations]]
name = "bottom"
type = "dirichlet"
region = "bottom"
components = ["y"]
value = {value}
"""
    res = run(text.format(value=0.0), name="corner")
    assert res["relations/left/multiplier"].shape[1] == 10   # 5 nodes × 2
    assert res["relations/bottom/multiplier"].shape[1] == 4  # the corner stays with "left"
    # λ = minus the reaction: the left edge holds the unit pull
    np.testing.assert_allclose(res["relations/left/multiplier"][-1][0::2].sum(), 1.0, rtol=1e-10)
    with _pytest.raises(InputError):
        run(text.format(value='"1e-3 * (1 + x)"'), name="corner_bad")
