"""Contact scenes that scripts/bench_friction.py measures: the 3D sheared box and the V-wedge of
docs/contact.md section 7, with exact answers in parsolve.contact.references.

The same scenes as tests/effects/test_contact.py (which checks them to round-off); a copy here
because a benchmark imports nothing from tests/ (tests change for their own reasons, and a
benchmark must run from a plain checkout). Imported as ``import bench_scenes`` (scripts/ is the
script's folder, first on sys.path: see bench_harness).
"""

from __future__ import annotations

import numpy as np

from make_ironing_2d_mesh import DIE as IRONING_DIE, SLAB as IRONING_SLAB, base_and_die

E, NU = 1000.0, 0.3
LAM, G = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))   # plane strain


def sheared_box_scene(delta_end: float, e: np.ndarray, t_star: float, p: float, mu: float, mode: str,
                      height: float) -> str:
    """3D: a box on the rigid plane z = 0, top pressed by p and moved by delta(t) e (e a unit
    vector in the plane), the sides loaded by the homogeneous stress: sigma_xx = sigma_yy
    (constant) and (sigma_xz, sigma_yz) = min(G delta / H, mu p) e."""
    gz = -p / (LAM + 2 * G)
    s_n, tau = LAM * gz, mu * p * e
    loads = "".join(f"""
[[loads]]
name = "{name}"
region = "{region}"
traction = [{v[0]!r}, {v[1]!r}, {v[2]!r}]
evolution = "{evo}"
""" for name, region, v, evo in (
        ("press", "zmax", (0.0, 0.0, -p), "constant"),
        ("xn_hi", "xmax", (s_n, 0.0, 0.0), "constant"), ("xn_lo", "xmin", (-s_n, 0.0, 0.0), "constant"),
        ("yn_hi", "ymax", (0.0, s_n, 0.0), "constant"), ("yn_lo", "ymin", (0.0, -s_n, 0.0), "constant"),
        ("xt_hi", "xmax", (0.0, 0.0, tau[0]), "shear"), ("xt_lo", "xmin", (0.0, 0.0, -tau[0]), "shear"),
        ("yt_hi", "ymax", (0.0, 0.0, tau[1]), "shear"), ("yt_lo", "ymin", (0.0, 0.0, -tau[1]), "shear")))
    return f"""
[mesh]
generator = "box"
lx = 1.0
ly = 1.0
lz = {height}
nx = 3
ny = 3
nz = 2
cell = "hexahedron"
[model]
hypothesis = "3d"
[[materials]]
E = {E}
nu = {NU}
{loads}
[[relations]]
name = "shift_x"
type = "dirichlet"
region = "zmax"
component = "x"
value = {delta_end * e[0]!r}
[[relations]]
name = "shift_y"
type = "dirichlet"
region = "zmax"
component = "y"
value = {delta_end * e[1]!r}
[[contact]]
name = "base"
slave = "zmin"
obstacle = {{ plane = {{ origin = [0.0, 0.0, 0.0], normal = [0.0, 0.0, 1.0] }} }}
friction = {mu}
direction = "{mode}"
[evolutions.shear]
times = [0.0, {t_star}, 2.0]
values = [0.0, 1.0, 1.0]
[steps]
count = 6
[nonlinear]
max_iterations = 60
"""



def _patch(corners: np.ndarray, nx: int, ny: int) -> np.ndarray:
    """Bilinear map of an (ny+1, nx+1) grid onto the quadrilateral corners (4, 2) ordered
    (xi, eta) = (0, 0), (1, 0), (1, 1), (0, 1): points (ny+1, nx+1, 2)."""
    xi, eta = np.meshgrid(np.linspace(0, 1, nx + 1), np.linspace(0, 1, ny + 1))
    w = np.stack([(1 - xi) * (1 - eta), xi * (1 - eta), xi * eta, (1 - xi) * eta], -1)
    return w @ corners


def wedge_mesh(path, beta: float, n1: int = 4, n2: int = 3, ny: int = 4, a: float = 1.0,
               b: float = 0.8, h: float = 1.0) -> None:
    """A block on a V-wedge: patch 1 above face 1 (y = 0, 0 <= x <= a), patch 2 above face 2
    (from the apex along e2 = (-cos b, sin b), length b), sharing the edge from the apex up.
    Groups: face1, face2 (facets), face2_slave (face 2's nodes but the apex), right, top, left."""
    import meshio

    e2 = np.array([-np.cos(beta), np.sin(beta)])
    bx = b * e2
    p1 = _patch(np.array([[0, 0], [a, 0], [a, h], [0, h]], float), n1, ny)
    p2 = _patch(np.array([bx, [0, 0], [0, h], [bx[0], h]], float), n2, ny)
    ids1 = np.arange(p1.shape[0] * p1.shape[1]).reshape(p1.shape[:2])
    ids2 = np.full(p2.shape[:2], -1)
    ids2[:, -1] = ids1[:, 0]                               # the shared edge
    ids2[:, :-1] = ids1.size + np.arange(p2.shape[0] * (p2.shape[1] - 1)).reshape(p2.shape[0], -1)
    points = np.vstack([p1.reshape(-1, 2), p2[:, :-1].reshape(-1, 2)])

    def quads(ids):
        return np.stack([ids[:-1, :-1], ids[:-1, 1:], ids[1:, 1:], ids[1:, :-1]], -1).reshape(-1, 4)

    def edges(line):
        return np.stack([line[:-1], line[1:]], -1)

    groups = {"face1": edges(ids1[0]), "face2": edges(ids2[0]), "right": edges(ids1[:, -1]),
              "top": np.vstack([edges(ids2[-1]), edges(ids1[-1])]), "left": edges(ids2[:, 0])}
    blocks = [("quad", np.vstack([quads(ids1), quads(ids2)]))]
    blocks += [("line", f) for f in groups.values()]
    blocks += [("vertex", ids2[0, :-1, None])]
    tags = [1] + [10 + i for i in range(len(groups))] + [30]
    phys = [np.full(len(blk[1]), tag) for blk, tag in zip(blocks, tags)]
    field = {"block": np.array([1, 2]), "face2_slave": np.array([30, 0])}
    field.update({name: np.array([10 + i, 1]) for i, name in enumerate(groups)})
    mesh = meshio.Mesh(np.column_stack([points, np.zeros(len(points))]), blocks,
                       cell_data={"gmsh:physical": phys, "gmsh:geometrical": phys},
                       field_data=field)
    meshio.write(str(path), mesh, file_format="gmsh22", binary=False)


def wedge_scene(mesh, ref) -> str:
    """The V-wedge scene of docs/contact.md §7 on ``mesh`` (see ``wedge_mesh``): the other
    faces loaded by the traction of the exact homogeneous stress of ``ref``."""
    loads = "".join(f"""
[[loads]]
name = "{side}"
region = "{side}"
traction = [{tx!r}, {ty!r}]
""" for side, (tx, ty) in (("right", ref.traction(np.array([[1.0, 0.0]]))[0]),
                           ("top", ref.traction(np.array([[0.0, 1.0]]))[0]),
                           ("left", ref.traction(np.array([[-1.0, 0.0]]))[0])))
    n2 = ref.normal2
    return f"""
[mesh]
file = "{mesh}"
[model]
hypothesis = "plane_strain"
[[materials]]
E = {E}
nu = {NU}
{loads}
[[contact]]
name = "one"
slave = "face1"
obstacle = {{ plane = {{ origin = [0.0, 0.0], normal = [0.0, 1.0] }} }}
friction = {ref.mu!r}
[[contact]]
name = "two"
slave = "face2_slave"
obstacle = {{ plane = {{ origin = [0.0, 0.0], normal = [{n2[0]!r}, {n2[1]!r}] }} }}
friction = {ref.mu!r}
[steps]
count = 3
"""


# ----------------------------------------------------------------------------- refined scenes
# (scripts/bench_friction.py's iterations against refinement: the shipped scenes, their cell
# counts multiplied by ``factor`` along each surface direction, so the cells by factor²)

def _shipped(name: str) -> dict:
    import tomllib
    from pathlib import Path

    with open(Path(__file__).resolve().parents[1] / "configs" / name, "rb") as f:
        scene = tomllib.load(f)
    scene.pop("output", None)   # the benchmark names its own result file
    return scene


def _dumps(scene: dict) -> str:
    from parsolve.batch.toml_write import dumps

    return dumps(scene)


def friction_3d_scene(factor: int) -> str:
    """configs/contact_friction_3d.toml with nx, ny × factor (nz kept: the contact surface
    refined, factor² the cells, the 0.25 thickness still two layers)."""
    scene = _shipped("contact_friction_3d.toml")
    scene["mesh"]["nx"] *= factor
    scene["mesh"]["ny"] *= factor
    return _dumps(scene)


def hertz_scene(factor: int) -> str:
    """configs/contact_hertz_cylinder.toml with nx, ny × factor: its contact zone forms from
    nothing in one step on a surface of 160 × factor cells."""
    scene = _shipped("contact_hertz_cylinder.toml")
    scene["mesh"]["nx"] *= factor
    scene["mesh"]["ny"] *= factor
    return _dumps(scene)


def ironing_2d_scene(folder, factor: int) -> str:
    """configs/contact_ironing_2d.toml on a generated equivalent of its mesh, the slab's and
    the die's quads × factor along x and y (written into ``folder``)."""
    from pathlib import Path

    (lx, ly, nx, ny), (dlx, dly, dnx, dny, x0) = IRONING_SLAB, IRONING_DIE   # the shipped mesh's
    mesh = Path(folder) / f"ironing_2d_{factor}.msh"
    base_and_die(mesh, (lx, ly, nx * factor, ny * factor),
                      (dlx, dly, dnx * factor, dny * factor, x0))
    scene = _shipped("contact_ironing_2d.toml")
    scene["mesh"] = {"file": str(mesh)}
    return _dumps(scene)


def ironing_3d_scene(factor: int) -> str | None:
    """configs/contact_ironing_3d.toml if it exists (else None): a generated mesh with nx, ny
    × factor (nz kept); a mesh file only at factor 1 (None otherwise: no generator to refine)."""
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "configs" / "contact_ironing_3d.toml"
    if not path.exists():
        return None
    scene = _shipped(path.name)
    mesh = scene["mesh"]
    if "file" in mesh:
        if factor != 1:
            return None
        mesh["file"] = str(path.parent / mesh["file"])
    else:
        for key in ("nx", "ny"):
            if key in mesh:
                mesh[key] *= factor
    return _dumps(scene)
