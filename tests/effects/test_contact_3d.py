"""3D contact and Coulomb friction: a block pressed on a rough rigid plane under a growing
oblique tangential load (partial slip spreading from the edges, the Coulomb conditions at every
node, iterations per step), and Hertz's sphere on a plane (a quarter model with symmetry
relations, on two graded meshes)."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from helpers.contact import OBLIQUE, coulomb_checks  # noqa: F401
from parsolve.contact import references
from parsolve.contact.friction import SLIP, STICK
from parsolve.mesh.generators import box

E, NU = 1000.0, 0.3


@pytest.mark.parametrize("cell, bound", [("hexahedron", 20), ("tetra", 30)])
def test_oblique_pull_partial_slip_spreads_from_the_edges(run, cell, bound):
    """A box pressed by p = 10 on a rigid plane (mu = 0.3) and pulled on its top by a traction
    along (2, 1)/sqrt(5) growing to 0.9 mu p: the friction balances the pull exactly, the slip
    zone starts at the edges (the pressure alone makes the bottom spread) and grows, some nodes
    stick to the end; every node satisfies the Coulomb conditions, in a bounded number of
    iterations per step (measured: hexahedra 7-17, tetrahedra 10-27; the most where the slip
    zone covers most of the surface)."""
    mu, p = 0.3, 10.0
    e = np.array([2.0, 1.0]) / np.sqrt(5.0)
    q = 0.9 * mu * p * e
    res = run(OBLIQUE.format(cell=cell, E=E, NU=NU, qx=q[0], qy=q[1]), name=f"oblique_{cell}")
    pts, times = res["mesh/points"], res["steps/time"]
    bottom = np.isclose(pts[:, 2], 0.0)
    state, rn = coulomb_checks(res, "base", mu, bottom)
    n_force = res["relations/base_normal/normal_force"][:, 0]
    np.testing.assert_allclose(n_force, p, rtol=1e-12)
    # the friction balances the pull (a box of unit area: the total pull is q t)
    np.testing.assert_allclose(res["relations/base_normal/tangential_force"],
                               -np.outer(times, q), atol=1e-10 * p)
    sliding = (state[:, bottom] == SLIP).sum(axis=1)
    assert np.all((state[:, bottom] == STICK).sum(axis=1) > 0)       # partial slip
    assert sliding[0] > 0 and np.all(np.diff(sliding[1:]) >= 0) and sliding[-1] > sliding[1]
    its = res["steps/iterations"]
    print(f"\n3D oblique pull ({cell}): iterations per step {its.tolist()}, "
          f"sliding nodes {sliding.tolist()} of {bottom.sum()}")
    assert its.max() <= bound, its


# ----------------------------------------------------------------------------- Hertz sphere


def axis(h: float, fine: float, length: float, grow: int) -> np.ndarray:
    """Node coordinates from 0 to length: spacing h up to ``fine``, then ``grow`` intervals
    growing geometrically to ``length``."""
    x = list(np.arange(int(round(fine / h)) + 1) * h)
    lo, hi = 1.0, 4.0
    for _ in range(200):   # ratio r with h (r + r^2 + ... + r^grow) = length - fine
        r = 0.5 * (lo + hi)
        lo, hi = (r, hi) if h * r * (r**grow - 1) / (r - 1) < length - x[-1] else (lo, r)
    x = np.concatenate([x, x[-1] + h * np.cumsum(r ** np.arange(1, grow + 1))])
    x[-1] = length
    return x


def quarter_block(path, h: float, a: float) -> None:
    """The quarter [0, 6a]² × [-6a, 0] of a block under a sphere, hexahedra of size h near
    the contact (up to 1.25 a across, 0.75 a deep), graded beyond; facet groups sym_x (x = 0),
    sym_y (y = 0), base (z = -6a), top (z = 0)."""
    import meshio

    xs, zs = axis(h, 1.25 * a, 6 * a, 6), axis(h, 0.75 * a, 6 * a, 6)
    n, nz = len(xs) - 1, len(zs) - 1
    m = box(1.0, 1.0, 1.0, n, n, nz)
    i, k = np.rint(m.points[:, :2] * n).astype(int), np.rint(m.points[:, 2] * nz).astype(int)
    points = np.column_stack([xs[i[:, 0]], xs[i[:, 1]], -zs[::-1][k]])
    groups = {"sym_x": "xmin", "sym_y": "ymin", "base": "zmin", "top": "zmax"}
    blocks = [("hexahedron", m.cells)] + [("quad", m.facet_groups[g]) for g in groups.values()]
    tags = [1] + [10 + j for j in range(len(groups))]
    phys = [np.full(len(b[1]), tag) for b, tag in zip(blocks, tags)]
    field = {"block": np.array([1, 3])}
    field.update({name: np.array([10 + j, 2]) for j, name in enumerate(groups)})
    meshio.write(str(path), meshio.Mesh(points, blocks, cell_data={
        "gmsh:physical": phys, "gmsh:geometrical": phys}, field_data=field),
        file_format="gmsh22", binary=False)


HERTZ = """
[mesh]
file = "{mesh}"
[model]
hypothesis = "3d"
[[materials]]
E = {E}
nu = {NU}
[[relations]]
name = "sym_x"
type = "dirichlet"
region = "sym_x"
component = "x"
[[relations]]
name = "sym_y"
type = "dirichlet"
region = "sym_y"
component = "y"
[[relations]]
name = "lift"
type = "dirichlet"
region = "base"
component = "z"
value = {lift!r}
[[contact]]
name = "indent"
slave = "top"
obstacle = {{ sphere = {{ centre = [0.0, 0.0, {R!r}], radius = {R!r} }} }}
[steps]
count = 1
"""

RADIUS, A = 10.0, 1.0


def tributary(x: np.ndarray) -> dict:
    """Half the spacings on each side of each coordinate of a graded axis."""
    xs = np.unique(np.round(x, 12))
    d = np.diff(xs)
    w = np.zeros(xs.size)
    w[:-1] += d / 2
    w[1:] += d / 2
    return w[np.searchsorted(xs, np.round(x, 12))]


def hertz_errors(res) -> dict:
    """Peak pressure (centre node's force over its tributary area) and contact radius (least
    squares fit of p² = p0² (1 - r²/a²) through the nodes with p > 0.3 p_max inside 0.8 a) of
    the quarter model, against Hertz for the computed load."""
    pts = res["mesh/points"]
    load = 4.0 * res["relations/indent_normal/normal_force"][-1, 0]
    ref = references.hertz_sphere(load, RADIUS, references.effective_modulus(E, NU))
    state = res["fields/indent_state"][-1, :, 0]
    top = state >= 0
    x, y = pts[top, 0], pts[top, 1]
    p = res["fields/indent_normal_reaction"][-1, top, 0] / (tributary(x) * tributary(y))
    r = np.hypot(x, y)
    peak = p[r < 1e-12][0]
    fit = (p > 0.3 * peak) & (r < 0.8 * ref.a)
    c = np.linalg.lstsq(np.column_stack([np.ones(fit.sum()), r[fit] ** 2]), p[fit] ** 2,
                        rcond=None)[0]
    edge = r[(state[top] > 0) & np.isclose(y, 0.0)].max()
    return {"load": load, "ref": ref, "peak": peak / ref.p0 - 1.0,
            "radius": np.sqrt(-c[0] / c[1]) / ref.a - 1.0, "edge": edge,
            "iterations": int(res["steps/iterations"][0])}


@pytest.fixture(scope="module")
def hertz_runs(tmp_path_factory):
    """The quarter model on two meshes (h = a/4, a/6), the base lifted by a²/R."""
    from conftest import run_scene
    from pathlib import Path

    folder = Path(MPI.COMM_WORLD.bcast(str(tmp_path_factory.mktemp("hertz3d")), root=0))
    out = {}
    for per in (4, 6):
        mesh = folder / f"quarter_{per}.msh"
        if MPI.COMM_WORLD.rank == 0:
            quarter_block(mesh, A / per, A)
        MPI.COMM_WORLD.Barrier()
        text = HERTZ.format(mesh=mesh, E=E, NU=NU, lift=A * A / RADIUS, R=RADIUS)
        out[per] = hertz_errors(run_scene(text, folder / f"hertz_{per}.h5"))
    return out


def test_hertz_sphere_peak_pressure_and_radius(hertz_runs):
    """A rigid sphere (R = 10) pressed into an elastic block (frictionless), a quarter model
    with symmetry relations: peak pressure and contact radius within 3 % of Hertz's for the
    computed load, on both meshes; the last closed node on the axis within one element of a."""
    for per, e in hertz_runs.items():
        print(f"\nHertz sphere h = a/{per}: P = {e['load']:.3f}, a = {e['ref'].a:.4f}, "
              f"p0 = {e['ref'].p0:.3f}; peak {e['peak']:+.4f}, radius {e['radius']:+.4f}, "
              f"{e['iterations']} iterations")
        assert abs(e["peak"]) < 0.03 and abs(e["radius"]) < 0.03
        assert e["edge"] <= e["ref"].a < e["edge"] + A / per + 1e-12
        assert e["iterations"] <= 6


def test_hertz_sphere_converges_under_refinement(hertz_runs):
    """The contact radius error shrinks from h = a/4 to a/6 (measured -1.6 % -> -0.9 %); the
    peak pressure stays within 1 % (its error, +0.5-0.7 %, is the finite block's, not the
    mesh's); both meshes carry the same load to 1 %."""
    coarse, fine = hertz_runs[4], hertz_runs[6]
    assert abs(fine["radius"]) < 0.7 * abs(coarse["radius"])
    assert abs(fine["peak"]) < 0.01 and abs(coarse["peak"]) < 0.01
    assert abs(fine["load"] / coarse["load"] - 1.0) < 0.01
