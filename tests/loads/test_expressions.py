"""Loads given as expressions of (x, y, z, t), and gravity from the materials' density, against
closed forms: a hydrostatic pressure on a wall and a pure bending moment as a linear traction
(resultants exact), a column and a cantilever under their own weight, and a load moving along a
simply supported beam (reactions exact at every step)."""

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.model import build_model
from parsolve.scene import parse_scene

WALL = """
[mesh]
generator = "rectangle"
lx = 0.5
ly = 3.0
nx = 2
ny = {ny}
cell = "{cell}"
[model]
hypothesis = "plane_strain"
thickness = 0.2
[[materials]]
E = 1.0
nu = 0.3
[[loads]]
name = "water"
region = "left"
pressure = "9.81 * (3 - y)"
"""


def model_of(text):
    return build_model(parse_scene(tomllib.loads(text), "s.toml", text), MPI.COMM_WORLD)


def totals(model, vector):
    """Σ f and Σ y f_x over the whole mesh (each owned node once)."""
    m = model.mesh
    f = vector.reshape(-1, 2)[:m.n_owned]
    y = m.points[:m.n_owned, 1]
    return MPI.COMM_WORLD.allreduce(np.r_[f.sum(axis=0), (y * f[:, 0]).sum()])


@pytest.mark.parametrize("cell, ny", [("quad", 3), ("triangle", 5), ("triangle6", 2)])
def test_hydrostatic_wall(cell, ny):
    """p = ρ g (H - y) on the left face: F_x = ρ g H² / 2 × thickness pushing the wall along
    +x (against the outward normal), its moment about the base ρ g H³ / 6 × thickness."""
    model = model_of(WALL.format(cell=cell, ny=ny))
    fx, fy, moment = totals(model, model.patterns["water"].vector())
    np.testing.assert_allclose([fx, fy, moment], [9.81 * 9 / 2 * 0.2, 0.0, 9.81 * 27 / 6 * 0.2],
                               rtol=1e-13, atol=1e-12)


BEAM = """
[mesh]
generator = "rectangle"
lx = 4.0
ly = 0.5
nx = 8
ny = 2
cell = "triangle6"
[model]
hypothesis = "plane_stress"
thickness = 0.1
[regions]
mid = {{ point = [0.0, 0.25] }}
[[materials]]
E = 200.0
nu = 0.3
[[loads]]
name = "moment"
region = "right"
traction = ["-{M} * (y - 0.25) / {I}", 0.0]
[[relations]]
name = "left"
type = "dirichlet"
region = "left"
components = ["x"]
[[relations]]
name = "pin"
type = "dirichlet"
region = "mid"
components = ["y"]
"""


def test_pure_bending_by_linear_traction(run):
    """σ_xx = -M y'/I on the end: no resultant force, moment M exactly; the displacement of
    pure bending is quadratic, so six-node triangles give κ L² / 2 at the tip to round-off."""
    M, inertia = 0.3, 0.1 * 0.5**3 / 12
    text = BEAM.format(M=M, I=inertia)
    model = model_of(text)
    vec = model.patterns["moment"].vector().reshape(-1, 2)[:model.mesh.n_owned]
    y = model.mesh.points[:model.mesh.n_owned, 1]
    mine = np.r_[vec.sum(axis=0), -((y - 0.25) * vec[:, 0]).sum()]
    fx, fy, moment = MPI.COMM_WORLD.allreduce(mine)
    np.testing.assert_allclose([fx, fy, moment], [0.0, 0.0, M], atol=1e-14 * M / 0.25, rtol=1e-13)
    res = run(text)
    pts, u = res["mesh/points"], res["fields/displacement"][-1]
    kappa = M / (200.0 * inertia)
    tip = np.flatnonzero(np.isclose(pts[:, 0], 4.0) & np.isclose(pts[:, 1], 0.25))
    np.testing.assert_allclose(u[tip, 1], kappa * 16 / 2, rtol=1e-9)
    np.testing.assert_allclose(u[:, 0], -kappa * pts[:, 0] * (pts[:, 1] - 0.25), atol=1e-9 * kappa)


COLUMN = """
[mesh]
generator = "rectangle"
lx = {lx}
ly = {ly}
nx = {nx}
ny = {ny}
cell = "triangle6"
[model]
hypothesis = "plane_stress"
thickness = 0.1
[regions]
corner = {{ point = [0.0, 0.0] }}
[[materials]]
E = 1000.0
nu = {nu}
density = 2.5
[[loads]]
gravity = {g}
[[relations]]
name = "{fixed}"
type = "dirichlet"
region = "{fixed}"
components = {components}
"""


def test_column_under_self_weight(run):
    """A column standing on a sliding base (u_y = 0, ν = 0): u_y = -ρ g (H y - y²/2) / E,
    quadratic, so exact at every node; the base carries the weight ρ g × volume."""
    text = COLUMN.format(lx=0.5, ly=3.0, nx=2, ny=4, nu=0.0, g="[0, -9.81]", fixed="bottom",
                         components='["y"]')
    text += ('[[relations]]\nname = "corner"\ntype = "dirichlet"\nregion = "corner"\n'
             'components = ["x"]\n')
    res = run(text)
    pts, u = res["mesh/points"], res["fields/displacement"][-1]
    y = pts[:, 1]
    np.testing.assert_allclose(u[:, 1], -2.5 * 9.81 * (3.0 * y - y**2 / 2) / 1000.0,
                               atol=1e-12)
    np.testing.assert_allclose(res["relations/bottom/resultant"][-1][:2],
                               [0.0, 2.5 * 9.81 * 0.5 * 3.0 * 0.1], atol=1e-12)


def test_cantilever_under_self_weight(run):
    """A slender cantilever (L/h = 20, ν = 0) clamped at x = 0: the clamp carries the weight
    exactly, and the tip deflection is Timoshenko's q L⁴ / (8 E I) + q L² / (2 κ G A) (κ = 5/6,
    G = E / 2) within 1e-4 (measured 5.7e-5 on these 40 × 2 six-node triangles, 7.3e-6 on
    80 × 4); Euler-Bernoulli's alone is 0.2 % short (the shear)."""
    L, h, t, rho, g, E = 4.0, 0.2, 0.1, 2.5, 9.81, 1000.0
    text = COLUMN.format(lx=L, ly=h, nx=40, ny=2, nu=0.0, g=f"[0, -{g}]", fixed="left",
                         components='["x", "y"]')
    res = run(text)
    np.testing.assert_allclose(res["relations/left/resultant"][-1][:2], [0.0, rho * g * L * h * t],
                               rtol=1e-9, atol=1e-9 * rho * g * L * h * t)
    pts, u = res["mesh/points"], res["fields/displacement"][-1]
    tip = u[np.isclose(pts[:, 0], L), 1].mean()
    q, inertia = rho * g * h * t, t * h**3 / 12
    bending = -q * L**4 / (8 * E * inertia)
    np.testing.assert_allclose(tip, bending - q * L**2 / (2 * 5 / 6 * E / 2 * h * t), rtol=1e-4)
    assert 1.5e-3 < tip / bending - 1 < 2.5e-3


MOVING = """
[mesh]
generator = "rectangle"
lx = 4.0
ly = 0.5
nx = 8
ny = 2
cell = "quad"
[model]
hypothesis = "plane_stress"
thickness = 0.1
[regions]
a = {point = [0.0, 0.0]}
b = {point = [4.0, 0.0]}
[[materials]]
E = 200.0
nu = 0.3
[[loads]]
name = "truck"
region = "top"
traction = [0.0, "-5 * (1 + (x - t) / 2)"]
[[relations]]
name = "a"
type = "dirichlet"
region = "a"
components = ["x", "y"]
[[relations]]
name = "b"
type = "dirichlet"
region = "b"
components = ["y"]
[steps]
times = [0.5, 1.5, 2.0, 3.5]
"""


def test_moving_load_reactions(run):
    """q(x, t) = -5 (1 + (x - t)/2) per unit area on the top face of a simply supported beam:
    at every step the supports carry (upwards) R_b = -∫ q x dx t/L and R_a = -∫ q dx t - R_b
    (linear in x: the facet rule is exact)."""
    res = run(MOVING)
    t = res["steps/time"]
    L, thick = 4.0, 0.1
    total = 5 * thick * (L + (L**2 / 2 - t * L) / 2)          # -∫ q dx × thickness
    first = 5 * thick * (L**2 / 2 + (L**3 / 3 - t * L**2 / 2) / 2)   # -∫ q x dx × thickness
    rb = first / L
    np.testing.assert_allclose(res["relations/b/resultant"][:, 1], rb, rtol=1e-10)
    np.testing.assert_allclose(res["relations/a/resultant"][:, 1], total - rb, rtol=1e-10)


BLOCK = """
[mesh]
generator = "box"
lx = 2.0
ly = 1.0
lz = 0.5
nx = 3
ny = 2
nz = 2
cell = "{cell}"
[model]
hypothesis = "3d"
[[materials]]
E = 1.0
nu = 0.3
density = 2.0
[[loads]]
name = "top"
region = "zmax"
pressure = "3 + x"
[[loads]]
name = "closed"
region = "all"
pressure = 5.0
[[loads]]
name = "weight"
gravity = [0.0, 0.0, -10.0]
"""


@pytest.mark.parametrize("cell", ["hexahedron", "tetra", "tetra10"])
def test_resultants_in_3d(cell):
    """On a 2 × 1 × 0.5 block: p = 3 + x on the top pushes down by ∫ p = 8; a uniform pressure
    on the whole closed surface has no resultant; ρ g × volume = 2 × 10 × 1 downwards."""
    model = model_of(BLOCK.format(cell=cell))
    n = model.mesh.n_owned
    for name, expected in (("top", [0, 0, -8.0]), ("closed", [0, 0, 0]),
                           ("weight", [0, 0, -20.0])):
        mine = model.patterns[name].vector().reshape(-1, 3)[:n].sum(axis=0)
        total = MPI.COMM_WORLD.allreduce(mine)
        np.testing.assert_allclose(total, expected, atol=1e-13 * 20)


FIELDS = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 1.0
nx = 4
ny = 3
cell = "{cell}"
[model]
hypothesis = "plane_stress"
thickness = 0.1
[[materials]]
E = 1.0
nu = 0.3
[[loads]]
name = "weight"
body = ["3 * x * t", "2 + y"]
[[loads]]
name = "pins"
region = "top"
nodal = ["x * t", "-1 - y"]
"""


@pytest.mark.parametrize("cell", ["quad", "triangle", "triangle6"])
def test_body_forces_and_nodal_loads_as_expressions(cell):
    """body = (3 x t, 2 + y) per unit volume on a 2 × 1 plate 0.1 thick: ∫ f dV = (0.6 t, 0.5)
    and ∫ x f_y dV = 0.5 at every t (the rule is exact on these polynomials); nodal = (x t,
    -1 - y) at the top's nodes (y = 1): Σ = (t Σ x_i, -2 × their number), the pattern
    assembled again at each t (evolution "constant": the expression carries the time)."""
    from parsolve.loads.base import Instant

    model = model_of(FIELDS.format(cell=cell))
    mesh = model.mesh
    n = mesh.n_owned
    x = mesh.points[:n, 0]
    top_x = np.linspace(0.0, 2.0, 5 if cell != "triangle6" else 9)
    for t in (0.5, 2.0):
        weight = model.patterns["weight"].at(Instant(t)).reshape(-1, 2)[:n]
        pins = model.patterns["pins"].at(Instant(t)).reshape(-1, 2)[:n]
        got = MPI.COMM_WORLD.allreduce(np.r_[weight.sum(axis=0), (x * weight[:, 1]).sum(),
                                            pins.sum(axis=0)])
        np.testing.assert_allclose(got, [0.6 * t, 0.5, 0.5, t * top_x.sum(), -2.0 * top_x.size],
                                   rtol=1e-13, atol=1e-14)
    assert [p.term.timed for p, _ in model.patterns["pins"].parts] == [True]


AXISYMMETRIC_COLUMN = """
[mesh]
generator = "rectangle"
lx = 0.5
ly = 3.0
nx = 2
ny = 4
cell = "triangle6"
[model]
hypothesis = "axisymmetric"
[[materials]]
E = 1000.0
nu = 0.0
density = 2.5
[[loads]]
gravity = [0.0, -9.81]
[[relations]]
name = "bottom"
type = "dirichlet"
region = "bottom"
components = ["y"]
"""


def test_axisymmetric_column_under_self_weight(run):
    """A solid cylinder (radius 0.5, height 3, ν = 0) standing on a sliding base: u_z = -ρ g
    (H z - z²/2) / E, u_r = 0, quadratic, so exact at every node of six-node triangles; the
    base carries the whole cylinder's weight ρ g π R² H (the body force integrated over the
    revolved volume, 2π r)."""
    res = run(AXISYMMETRIC_COLUMN)
    pts, u = res["mesh/points"], res["fields/displacement"][-1]
    z = pts[:, 1]
    np.testing.assert_allclose(u[:, 1], -2.5 * 9.81 * (3.0 * z - z**2 / 2) / 1000.0,
                               atol=1e-12)
    np.testing.assert_allclose(u[:, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(res["relations/bottom/resultant"][-1][:2],
                               [0.0, 2.5 * 9.81 * np.pi * 0.25 * 3.0], rtol=1e-12, atol=1e-12)
