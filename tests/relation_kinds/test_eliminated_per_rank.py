"""Eliminated Dirichlet rows held by the rank owning their DOF, never gathered: a rank lifts
its own rows and reads the other ranks' prescribed values (and, in Newton, q there) only
where its operator rows name them. A plate whose left side is held at a value varying along
it, pulled by a control whose row (the mean x of every node) names every held DOF, so that
its owner reads held DOFs of every rank: the same answers as one rank, to round-off, at 1, 2,
3 ranks, and the closed forms (the control's value; the left side's reactions balance the
control load)."""

import numpy as np
from mpi4py import MPI

from helpers.plate import PLATE, dirichlet, mean
from helpers.scene import scene

COMM = MPI.COMM_WORLD
SCENE = scene(PLATE, mesh={"nx": 16, "ny": 8}, regions={"corner": {"point": [0.0, 0.0]}},
              materials=[{"E": 1e9, "nu": 0.3}], steps={"count": 3},
              relations=[dirichlet("left_x", "left", "x", value="1e-5 * y"),
                         dirichlet("corner_y", "corner", "y"),
                         mean("control", "all", 2e-4, dual="pull")])


def test_the_held_rows_per_rank_answer_as_one_rank(run):
    world = run(SCENE, name="held")
    alone = run(SCENE, name="held_alone", comm=MPI.COMM_SELF)
    assert world["attrs"]["status"] == alone["attrs"]["status"] == "complete"
    t = world["steps/time"]
    # the closed forms: the control's value, the reactions balancing its load along x
    np.testing.assert_allclose(world["relations/control/primal"][:, 0], 2e-4 * t, rtol=1e-12)
    load = world["relations/control/multiplier"][:, 0]
    assert np.all(load > 0)
    np.testing.assert_allclose(world["relations/left_x/resultant"][:, 0], -load, rtol=1e-9)
    # the left side at its values: u_x = 1e-5 y t
    pts = world["mesh/points"]
    left = np.isclose(pts[:, 0], 0.0)
    np.testing.assert_allclose(world["fields/displacement"][:, left, 0],
                               1e-5 * t[:, None] * pts[None, left, 1], rtol=1e-14, atol=0)
    # the same as one rank (a multiplier zero in exact arithmetic, the corner's, against the
    # multipliers' size)
    force = np.abs(alone["relations/control/multiplier"]).max()
    for key, scale in (("fields/displacement", np.abs(alone["fields/displacement"]).max()),
                       ("relations/left_x/multiplier", force),
                       ("relations/corner_y/multiplier", force),
                       ("relations/control/multiplier", force)):
        assert np.abs(world[key] - alone[key]).max() <= 1e-12 * scale, key
