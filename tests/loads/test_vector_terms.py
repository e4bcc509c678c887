"""Every load is a declared vector term: the scene's ``[[loads]]`` declare theirs on their
region's facets, cells or nodes with their pattern and evolution (``loads.build.SceneLoads``),
and the patterns built from the declarations (``loads.base.load_patterns``) hold the loads'
resultants exactly; a part whose values name t is assembled again at each instant (the last
two kept), the others once. At 1, 2, 3 ranks (resultants summed over owned rows)."""

from __future__ import annotations

import tomllib

import numpy as np
from mpi4py import MPI

from parsolve.loads.base import Instant
from parsolve.loads.build import SceneLoads
from parsolve.model import build_model
from parsolve.scene import parse_scene

COMM = MPI.COMM_WORLD
TEXT = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 0.5
nx = 8
ny = 3
cell = "quad"
[model]
hypothesis = "plane_stress"
thickness = 0.1
[[materials]]
E = 1e3
nu = 0.25
density = 4.0
[[loads]]
name = "side"
region = "right"
traction = ["3 * t", 1.0]
evolution = "constant"
[[loads]]
name = "weight"
gravity = [0.0, -10.0]
[[loads]]
name = "side"
region = "top"
nodal = [0.0, -0.5]
[[relations]]
name = "fixed"
type = "dirichlet"
region = "left"
components = ["x", "y"]
[steps]
times = [1.0, 2.0]
"""


def resultant(model, vector: np.ndarray) -> np.ndarray:
    """Σ over this rank's owned nodes, summed over the ranks: (fx, fy)."""
    owned = vector.reshape(-1, 2)[:model.mesh.n_owned]
    return COMM.allreduce(owned.sum(axis=0))


def test_scene_loads_are_vector_terms_and_patterns_their_sums():
    model = build_model(parse_scene(tomllib.loads(TEXT), "t.toml", TEXT), COMM)
    regions = model.regions()
    loads = SceneLoads(model.mesh, model.scene, regions, model.fields)
    kinds = [(t.on_facets, t.on_cells, t.on_nodes, t.pattern, t.timed) for t in loads.terms()]
    assert kinds == [(True, False, False, "side", True), (False, True, False, "weight", False),
                     (False, False, True, "side", False)]
    assert all(t.vector for t in loads.terms())
    assert list(model.patterns) == ["side", "weight"]
    top = COMM.allreduce(int(np.count_nonzero(regions("top", "t").nodes < model.mesh.n_owned)))
    assert top == 9
    # weight: ρ g × area × thickness, ramped: half of it at t = 0.5
    np.testing.assert_allclose(resultant(model, model.patterns["weight"].at(0.5)),
                               [0.0, -0.5 * 4.0 * 10.0 * 2.0 * 0.5 * 0.1], rtol=1e-13, atol=1e-13)
    # side: traction (3t, 1) over the right edge (0.5 × 0.1), nodal -0.5 at 9 nodes ramped
    for t in (1.0, 2.0, 1.0):
        expected = [3 * t * 0.05, 0.05 - 0.5 * 9 * min(t, 1.0)]   # (the ramp holds at 1)
        np.testing.assert_allclose(resultant(model, model.patterns["side"].at(Instant(t))),
                                   expected, rtol=1e-13)
    timed, constant = (p for p, _ in model.patterns["side"].parts)
    assert len(timed.cache) == 2 and set(timed.cache) == {Instant(1.0), Instant(2.0)}
    assert list(constant.cache) == [None]   # assembled once
