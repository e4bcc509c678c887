"""The hint of a singular system (parsolve/diagnostics.py): bodies no relation holds, found on
the distributed mesh (each rank its part) as on the whole mesh."""

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.diagnostics import bodies, bodies_distributed
from parsolve.mesh.distribute import distribute
from parsolve.mesh.generators import rectangle
from parsolve.mesh.mesh import Mesh


def three_bodies() -> Mesh:
    """A long strip, an L-shaped strip and a small square, apart (three bodies), the strips
    cut across by any partition several times."""
    a = rectangle(10.0, 0.5, 40, 2, cell="quad")
    b = rectangle(0.5, 6.0, 2, 24, cell="triangle")
    c = rectangle(1.0, 1.0, 2, 2, cell="quad")
    b.points = b.points + [0.0, 2.0]
    c.points = c.points + [5.0, 5.0]
    # one cell type: the quads cut into triangles
    tri = [m if m.cell_type == "triangle" else _triangles(m) for m in (a, b, c)]
    offsets = np.cumsum([0] + [m.num_points for m in tri[:-1]])
    points = np.concatenate([m.points for m in tri])
    cells = np.concatenate([m.cells + o for m, o in zip(tri, offsets)])
    # shuffle the input numbering so that bodies' nodes are interleaved
    perm = np.random.default_rng(3).permutation(points.shape[0])
    inverse = np.argsort(perm)
    return Mesh(points[perm], "triangle", inverse[cells])


def _triangles(m: Mesh) -> Mesh:
    q = m.cells
    return Mesh(m.points, "triangle", np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]]))


@pytest.mark.parametrize("method", ["scotch", "bisection"])
def test_bodies_of_a_distributed_mesh_are_the_whole_meshs(method, comm):
    whole = three_bodies()
    expected = bodies(whole.cells, whole.num_points)
    assert np.unique(expected).size == 3
    part = distribute(comm, whole if comm.rank == 0 else None, method)
    label = bodies_distributed(comm, part)
    assert np.array_equal(label, expected[part.global_nodes])


BODY = """
[mesh]
file = "{path}"
[model]
dimension = 2
[[diffusion]]
field = "h"
[[diffusion.materials]]
conductivity = 1.0
[[loads]]
name = "s"
field = "h"
source = 1.0
[regions]
held = "x < 0.1 and y < 1.0"
[[relations]]
name = "fix"
type = "dirichlet"
region = "held"
field = "h"
"""


def test_the_bodies_no_relation_holds_are_named(run, shared_tmp, comm):
    """Two of three bodies float: the message names them, with their cells in input numbers
    (labelled on the whole mesh by ``bodies``, an independent computation)."""
    import meshio

    from parsolve.errors import SolverError

    whole = three_bodies()
    path = shared_tmp / "three_bodies.vtu"
    if comm.rank == 0:
        meshio.write(path, meshio.Mesh(whole.points, [("triangle", whole.cells)]))
    comm.Barrier()
    label = bodies(whole.cells, whole.num_points)
    held = label[np.flatnonzero((whole.points[:, 0] < 0.1) & (whole.points[:, 1] < 1.0))]
    assert np.unique(held).size == 1
    cell_body = label[whole.cells[:, 0]]
    expected = []
    for b in np.unique(label):
        if b != held[0]:
            ids = np.flatnonzero(cell_body == b)
            expected.append(f"no relation holds field 'h' on body of {ids.size} cells "
                            f"(cells {ids[0]}..{ids[-1]})")
    with pytest.raises(SolverError) as err:
        run(BODY.format(path=path), name="floating")
    assert str(err.value).endswith("likely cause: " + "; ".join(expected)), str(err.value)


BLOCK_ON_PLANE = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 0.5
nx = 8
ny = 4
cell = "quad"
[model]
hypothesis = "plane_strain"
[[materials]]
E = 1000.0
nu = 0.3
[[loads]]
name = "push"
region = "top"
traction = [{tx}, {ty}]
evolution = "{evolution}"
[[contact]]
name = "base"
slave = "bottom"
obstacle = {{ plane = {{ origin = [0.0, 0.0], normal = [0.0, 1.0] }} }}
friction = 0.5
[steps]
count = 2
"""


@pytest.mark.parametrize("degrees, fails", [(30.0, True), (20.0, False)])
def test_a_load_friction_cannot_carry_is_named(run, degrees, fails, monkeypatch):
    """A block on a rough plane (μ = 0.5) under a uniform load at an angle from the normal,
    constant in t: at 30° (tan 30° = 0.577 > μ) no equilibrium exists: the first attempt and
    its half (the same load: the same equations) both end with every closed node sliding, so
    the step is cut once, not 6 times (7 attempts before, 2 now), and the failure names the
    friction capacity; at 20° (0.364 < μ) the block sticks, its friction force the load's
    tangential part."""
    from parsolve.errors import SolverError
    from parsolve.solvers.newton import NewtonSolver

    attempts, step = [], NewtonSolver.step

    def counted(self, t):
        attempts.append(t)
        return step(self, t)

    monkeypatch.setattr(NewtonSolver, "step", counted)
    a = np.radians(degrees)
    text = BLOCK_ON_PLANE.format(tx=10 * np.sin(a), ty=-10 * np.cos(a), evolution="constant")
    if not fails:
        res = run(text, name="friction_ok")
        force = res["relations/base_normal/tangential_force"][-1, 0]
        assert abs(force) == pytest.approx(10 * np.sin(a), rel=1e-10)
        assert attempts == [0.5, 1.0] and not res["steps/cuts"].any()
        return
    with pytest.raises(SolverError) as err:
        run(text, name="friction_impossible")
    message = str(err.value)
    assert attempts == [0.5, 0.25]
    assert "contact[0]: every closed node of 'base' slides" in message, message
    assert "the tangential load exceeds the friction capacity μN (μ = 0.5); hold it, lower the " \
        "tangential load or raise the friction" in message, message   # the cause and the way out
    assert message.startswith(
        "no step converged: the first step failed down to t = 0.25 (after 1 cut, then no more: "
        "every smaller step takes the same loads, and at the last two sizes every closed node of "
        "'base' slides); "), message
    # the cause before the generic advice, which no longer offers smaller steps
    assert message.index("likely cause: ") < message.index("otherwise, the way out: check "
                                                            "that the supports"), message
    assert message.endswith("(smaller steps cannot help: no state carries these loads)"), message


def test_a_growing_load_beyond_friction_is_cut_as_before(run, monkeypatch):
    """The same block at 30° with the load growing from 0 (a ramp): a smaller step takes a
    smaller load, so nothing proves that smaller steps fail (though here they do, the load's
    angle and not its size being beyond μ): the step is cut its 6 times, as before."""
    from parsolve.errors import SolverError
    from parsolve.solvers.newton import NewtonSolver

    attempts, step = [], NewtonSolver.step

    def counted(self, t):
        attempts.append(t)
        return step(self, t)

    monkeypatch.setattr(NewtonSolver, "step", counted)
    a = np.radians(30.0)
    text = BLOCK_ON_PLANE.format(tx=10 * np.sin(a), ty=-10 * np.cos(a), evolution="ramp")
    with pytest.raises(SolverError) as err:
        run(text, name="friction_ramp")
    message = str(err.value)
    np.testing.assert_allclose(attempts, 0.5 ** np.arange(1, 8), rtol=0, atol=0)
    assert message.startswith(f"no step converged: the first step failed down to t = "
                              f"{0.5 ** 7:.6g} (after 6 cuts); the last attempt: "), message
    assert "every closed node of 'base' slides at the last iterate" in message, message
