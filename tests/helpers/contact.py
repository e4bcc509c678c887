"""Scenes and checks of the contact tests that several test modules use: the patch, the block
on a plane, the sheared block, the 3D oblique pull and its Coulomb checks, the meshed foundation
and the two-block meshes of the mortar tests, with the material's Lamé constants."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve.contact.friction import SLIP, STICK
from parsolve.mesh.generators import rectangle

E, NU = 1000.0, 0.3
LAM, G = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))   # plane strain


PATCH = """
title = "contact patch test"
[mesh]
file = "{mesh}"
[model]
hypothesis = "plane_strain"
[[materials]]
region = "lower"
E = 1000.0
nu = 0.3
[[materials]]
region = "upper"
E = 300.0
nu = 0.2
[[loads]]
name = "press"
region = "upper_top"
traction = [0.0, {traction}]
[[relations]]
name = "ground"
type = "dirichlet"
region = "lower_bottom"
component = "y"
[[relations]]
name = "roll_low"
type = "dirichlet"
region = "lower_left"
component = "x"
[[relations]]
name = "roll_up"
type = "dirichlet"
region = "upper_left"
component = "x"
[[contact]]
name = "joint"
slave = "upper_bottom"
master = "lower_top"
{extra}
[steps]
count = 2
"""


def sheared_scene(delta_end: float, t_star: float, p: float, mu: float, height: float) -> str:
    """A block of height H on the rigid plane y = 0, top pressed by p and moved by delta(t),
    the sides loaded by the homogeneous stress of docs/contact.md §6: sigma_xx (constant) and
    sigma_xy = min(G delta / H, mu p) (a ramp to mu p at t_star, then constant)."""
    gy = -p / (LAM + 2 * G)
    sxx, tau = LAM * gy, mu * p
    return f"""
[mesh]
generator = "rectangle"
lx = 1.0
ly = {height}
nx = 6
ny = 3
cell = "triangle"
[model]
hypothesis = "plane_strain"
[[materials]]
E = {E}
nu = {NU}
[[loads]]
name = "press"
region = "top"
traction = [0.0, {-p}]
evolution = "constant"
[[loads]]
name = "side_n"
region = "right"
traction = [{sxx}, 0.0]
evolution = "constant"
[[loads]]
name = "side_n_left"
region = "left"
traction = [{-sxx}, 0.0]
evolution = "constant"
[[loads]]
name = "side_t"
region = "right"
traction = [0.0, {tau}]
evolution = "shear"
[[loads]]
name = "side_t_left"
region = "left"
traction = [0.0, {-tau}]
evolution = "shear"
[[relations]]
name = "shift"
type = "dirichlet"
region = "top"
component = "x"
value = {delta_end}
[[contact]]
name = "base"
slave = "bottom"
obstacle = {{ plane = {{ origin = [0.0, 0.0], normal = [0.0, 1.0] }} }}
friction = {mu}
[evolutions.shear]
times = [0.0, {t_star}, 2.0]
values = [0.0, 1.0, 1.0]
[steps]
count = 10
"""


BASE = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 0.5
nx = 4
ny = 2
[model]
hypothesis = "plane_strain"
[[materials]]
E = 1000.0
nu = 0.3
[[contact]]
name = "base"
{contact}
"""


PLANE = 'obstacle = { plane = { origin = [0.0, 0.0], normal = [0.0, 1.0] } }'


def coulomb_checks(res, name: str, mu: float, bottom: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Coulomb conditions at every contact node of every step: Rn >= 0, |Rt| <= mu Rn
    (1e-8), no penetration (1e-10), sticking nodes do not move during the step, sliding nodes
    are on the cone and their slip increment is along -Rt (1e-8 rad). Returns (states, Rn)."""
    state = res[f"fields/{name}_state"][:, :, 0]
    rn = res[f"fields/{name}_normal_reaction"][:, :, 0]
    rt = res[f"fields/{name}_tangential_reaction"]
    slip = res[f"fields/{name}_slip"]
    u = res["fields/displacement"]
    scale = mu * rn.max()
    assert np.all(rn >= -1e-12 * rn.max())
    assert np.all(np.linalg.norm(rt, axis=2) <= mu * rn + 1e-8 * scale)
    assert u[:, bottom, 2].min() >= -1e-10 * np.abs(u).max()          # no penetration
    increment = np.diff(np.concatenate([np.zeros_like(slip[:1]), slip]), axis=0)
    big = np.abs(increment).max()
    stick, sliding = state == STICK, state == SLIP
    assert np.abs(increment[stick]).max(initial=0.0) <= 1e-12 * big
    t, d = rt[sliding], increment[sliding]
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), mu * rn[sliding], atol=1e-8 * scale)
    cross = t[:, 0] * d[:, 1] - t[:, 1] * d[:, 0]
    along = -np.einsum("mj,mj->m", t, d)
    assert np.all(along > 0)
    assert np.all(np.abs(cross) <= 1e-8 * np.linalg.norm(t, axis=1) * np.linalg.norm(d, axis=1))
    return state, rn


OBLIQUE = """
[mesh]
generator = "box"
lx = 1.0
ly = 1.0
lz = 0.25
nx = 6
ny = 6
nz = 2
cell = "{cell}"
[model]
hypothesis = "3d"
[[materials]]
E = {E}
nu = {NU}
[[loads]]
name = "press"
region = "zmax"
traction = [0.0, 0.0, -10.0]
evolution = "constant"
[[loads]]
name = "pull"
region = "zmax"
traction = [{qx!r}, {qy!r}, 0.0]
[[contact]]
name = "base"
slave = "zmin"
obstacle = {{ plane = {{ origin = [0.0, 0.0, 0.0], normal = [0.0, 0.0, 1.0] }} }}
friction = 0.3
[steps]
count = 6
[nonlinear]
max_iterations = 60
"""


def two_blocks(path, nx_low: int, nx_up: int, cell: str = "quad", ny_low: int = 2,
               ny_up: int = 2, seed: int = 0) -> None:
    """Two stacked distorted rectangles [0, 1] × [0, ½] and [0, 1] × [½, 1] as one Gmsh 2.2
    file: cell groups lower/upper, facet groups <body>_top/bottom/left; the interface nodes
    are distinct (the bodies are not connected)."""
    import meshio

    rng = np.random.default_rng(seed)
    low, p_low = distorted(1.0, 0.5, nx_low, ny_low, cell, (0.0, 0.0), rng)
    up, p_up = distorted(1.0, 0.5, nx_up, ny_up, cell, (0.0, 0.5), rng)
    off = low.num_points
    points = np.vstack([p_low, p_up])
    facet = "line" if cell in ("quad", "triangle") else "line3"
    lines = [(f"{body}_{side}", m.facet_groups[side] + o)
             for body, m, o in (("lower", low, 0), ("upper", up, off))
             for side in ("top", "bottom", "left")]
    blocks = [(cell, low.cells), (cell, up.cells + off)] + [(facet, f) for _, f in lines]
    tags = [1, 2] + [10 + i for i in range(len(lines))]
    phys = [np.full(len(b[1]), tag) for b, tag in zip(blocks, tags)]
    field = {"lower": np.array([1, 2]), "upper": np.array([2, 2])}
    field.update({name: np.array([10 + i, 1]) for i, (name, _) in enumerate(lines)})
    mesh = meshio.Mesh(np.column_stack([points, np.zeros(len(points))]), blocks,
                       cell_data={"gmsh:physical": phys, "gmsh:geometrical": phys},
                       field_data=field)
    meshio.write(str(path), mesh, file_format="gmsh22", binary=False)


def write_mesh(path, *args, **kw):
    if MPI.COMM_WORLD.rank == 0:
        two_blocks(path, *args, **kw)
    MPI.COMM_WORLD.Barrier()


FOUNDATION = """
title = "block on a meshed rough foundation"
[mesh]
file = "{mesh}"
[model]
hypothesis = "plane_strain"
[[materials]]
region = "lower"
E = 2000.0
nu = 0.25
[[materials]]
region = "upper"
E = 1000.0
nu = 0.3
[[loads]]
name = "press"
region = "upper_top"
traction = [0.0, -10.0]
evolution = "constant"
[[relations]]
name = "ground"
type = "dirichlet"
region = "lower_bottom"
components = ["x", "y"]
[[relations]]
name = "shift"
type = "dirichlet"
region = "upper_top"
component = "x"
value = 0.02
[[contact]]
name = "base"
slave = "upper_bottom"
master = "lower_top"
friction = 0.3
discretization = "{discretization}"
[steps]
count = 10
"""


def distorted(lx, h, nx, ny, cell, origin, rng):
    """A rectangle mesh whose interior nodes are moved randomly along x (by up to 0.3 of the
    element width; the sides and the interfaces stay straight); quadratic cells keep their
    midside nodes at the middle of straight edges."""
    m = rectangle(lx, h, nx, ny, cell, origin=origin)
    pts = m.points.copy()
    inner = (pts[:, 0] > origin[0] + 1e-9) & (pts[:, 0] < origin[0] + lx - 1e-9)
    pts[inner, 0] += rng.uniform(-0.3, 0.3, inner.sum()) * lx / nx
    for k, (a, b) in enumerate(MIDS.get(cell, [])):
        pts[m.cells[:, 3 + k]] = 0.5 * (pts[m.cells[:, a]] + pts[m.cells[:, b]])
    return m, pts


MIDS = {"triangle6": [(0, 1), (1, 2), (2, 0)]}   # midside node k+3 between corners (a, b)
