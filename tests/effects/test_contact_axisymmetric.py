"""Axisymmetric contact: a stiff flat punch of radius a pressed by δ on an elastic foundation
(a cylinder R = H = 40 a, held at its base), node-to-segment rows between the punch face and
the foundation's top. Forces are for the whole ring (2π): the punch force tends to
Boussinesq's F = 2 E* a δ (E* = E / (1 - ν²)) as the mesh is refined (the edge singularity of
the pressure, p ~ (a² - r²)^-1/2, gives the force an O(h) error; the finite foundation and
punch stiffness leave the rest, under 2 %)."""

from pathlib import Path

import meshio
import numpy as np
from mpi4py import MPI

from parsolve.mesh.generators import rectangle

E, NU, A, R, H, GAP, DELTA = 1000.0, 0.3, 1.0, 40.0, 40.0, 1e-3, 1e-2


def graded(m: int, fine: float, length: float, grow: float = 1.25) -> np.ndarray:
    """Node positions on [0, length]: cells a/m up to ``fine``, then growing by ``grow``."""
    x = list(np.linspace(0.0, fine, int(round(fine * m / A)) + 1))
    h = A / m
    while x[-1] < length - 1e-12:
        h *= grow
        x.append(min(x[-1] + h, length))
    if length - x[-2] < 0.5 * (x[-2] - x[-3]):   # no sliver cell at the end
        x.pop(-2)
    return np.array(x)


def write_mesh(m: int, path: Path) -> None:
    """The foundation (graded towards the punch's edge and the surface) and the punch (a × a/2,
    m × m/2 cells) GAP above it, two bodies in one file."""
    xs, ys = graded(m, 2 * A, R), H - graded(m, A, H)[::-1]
    f = rectangle(1.0, 1.0, len(xs) - 1, len(ys) - 1, cell="quad")
    fp = np.column_stack([np.interp(f.points[:, 0], np.linspace(0, 1, len(xs)), xs),
                          np.interp(f.points[:, 1], np.linspace(0, 1, len(ys)), ys)])
    p = rectangle(A, 0.5 * A, m, m // 2, cell="quad", origin=(0.0, H + GAP))
    if MPI.COMM_WORLD.rank == 0:
        meshio.write(str(path), meshio.Mesh(np.vstack([fp, p.points]),
                                            [("quad", np.vstack([f.cells, p.cells + len(fp)]))]))
    MPI.COMM_WORLD.Barrier()


SCENE = """
[mesh]
file = "{mesh}"
[model]
hypothesis = "axisymmetric"
[regions]
foundation = "y < {mid}"
punch = "y > {mid}"
axis = "x == 0"
base = "y == 0"
surface = "y == {H}"
punch_face = "y > {mid} and y < {face}"
punch_top = "y > {top}"
[[materials]]
region = "foundation"
E = {E}
nu = {nu}
[[materials]]
region = "punch"
E = {Ep}
nu = {nu}
[[relations]]
name = "axis"
type = "dirichlet"
region = "axis"
components = ["x"]
[[relations]]
name = "base"
type = "dirichlet"
region = "base"
components = ["y"]
[[relations]]
name = "press"
type = "dirichlet"
region = "punch_top"
components = ["y"]
value = {push}
[[contact]]
name = "face"
slave = "punch_face"
master = "surface"
"""


def test_flat_punch_converges_to_boussinesq(run, shared_tmp):
    forces = []
    for m in (8, 16, 32):
        path = shared_tmp / f"punch_{m}.vtu"
        write_mesh(m, path)
        text = SCENE.format(mesh=path, mid=H + GAP / 2, face=H + 1.5 * GAP, H=H,
                            top=H + GAP + 0.5 * A - 1e-9, E=E, nu=NU, Ep=1e3 * E,
                            push=-(GAP + DELTA))
        res = run(text, name=f"punch_{m}")
        force = -res["relations/press/resultant"][-1][1]
        # the whole punch face is in contact (a flat punch: compressive everywhere) and the
        # contact forces carry the punch's load
        assert res["relations/face_normal/active"][-1].all()
        lam = res["relations/face_normal/multiplier"][-1]
        assert abs(-lam.sum() - force) < 1e-10 * force
        forces.append(force)
    boussinesq = 2 * E / (1 - NU ** 2) * A * DELTA
    ratio = np.array(forces) / boussinesq
    steps = -np.diff(ratio)
    assert np.all(steps > 0), ratio                        # from above, monotonically
    assert 0.8 < np.log2(steps[0] / steps[1]) < 1.3, ratio  # O(h)
    extrapolated = ratio[-1] - steps[-1]                   # Richardson, first order
    assert abs(extrapolated - 1.0) < 0.02 and abs(ratio[-1] - 1.0) < 0.03, (ratio, extrapolated)


def test_rough_punch_sticks_as_bonded(run, shared_tmp):
    """With enough friction every node of the punch face sticks: the force is the bonded
    punch's, Mossakovskii's (1 - ν) ln(3 - 4ν) / (1 - 2ν) times the frictionless one (1.0286
    for ν = 0.3); μ = 0.3 lets the outermost nodes slip, a force in between."""
    path = shared_tmp / "punch_rough.vtu"
    write_mesh(16, path)
    text = SCENE.format(mesh=path, mid=H + GAP / 2, face=H + 1.5 * GAP, H=H,
                        top=H + GAP + 0.5 * A - 1e-9, E=E, nu=NU, Ep=1e3 * E, push=-(GAP + DELTA))
    force, state = {}, {}
    for mu in (0.0, 0.3, 3.0):
        res = run(text + (f"friction = {mu}\n" if mu else ""), name=f"punch_mu{mu}")
        force[mu] = -res["relations/press/resultant"][-1][1]
        if mu:
            s = res["fields/face_state"][-1][:, 0]
            state[mu] = s[s >= 0]                         # the punch face's nodes
    bonded = (1 - NU) * np.log(3 - 4 * NU) / (1 - 2 * NU)
    assert abs(force[3.0] / force[0.0] / bonded - 1.0) < 2e-3, force
    assert np.all(state[3.0] == 1)                         # every node sticks
    assert force[0.0] < force[0.3] < force[3.0]
    assert np.any(state[0.3] == 2) and np.any(state[0.3] == 1)   # slip at the edge, stick inside
