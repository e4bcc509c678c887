"""3D mortar contact through the contact effect (``discretization = "mortar"`` in 3D): the
contact patch test on non-matching interfaces (hexahedra 3×3 against 4×4, distorted, and
tetrahedra), frictionless: the uniform stress and the homogeneous displacement are the
discrete solution to round-off, every slave node carries p ∫φ_i; the same on any number of
ranks (run at 1, 2 and 3)."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from conftest import assert_same_results
from parsolve.contact.friction import SLIP, STICK
from parsolve.mesh.generators import box

E1, NU1, E2, NU2, P = 1000.0, 0.3, 300.0, 0.2, 10.0

PATCH3D = """
title = "3D contact patch test"
[mesh]
file = "{mesh}"
[model]
hypothesis = "3d"
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
traction = [0.0, 0.0, {traction}]
[[relations]]
name = "ground"
type = "dirichlet"
region = "lower_bottom"
component = "z"
{rollers}
[[contact]]
name = "joint"
slave = "upper_bottom"
master = "lower_top"
discretization = "mortar"
[steps]
count = 2
"""

ROLLER = """[[relations]]
name = "roll_{body}_{axis}"
type = "dirichlet"
region = "{body}_{axis}min"
component = "{axis}"
"""
ROLLERS = "".join(ROLLER.format(body=b, axis=a) for b in ("lower", "upper") for a in "xy")
SIDES = {"top": "zmax", "bottom": "zmin", "xmin": "xmin", "ymin": "ymin"}


def block(n: int, nz: int, cell: str, z0: float, rng):
    """The box [0, 1]² × [z0, z0 + ½], n × n × nz cells. Tetrahedra: the nodes strictly inside
    in x and y moved at random in x and y (by up to a fifth of a cell; planes z = const stay
    planes, the sides stay flat). Hexahedra: the grid lines x = const and y = const moved at
    random instead, so that the faces stay rectangles (see ``mortar3d``: the segments of
    non-parallelogram quads are integrated to quadrature accuracy only)."""
    m = box(1.0, 1.0, 0.5, n, n, nz, cell, origin=(0.0, 0.0, z0))
    pts = m.points.copy()
    if cell == "hexahedron":
        for axis in range(2):
            lines = np.linspace(0.0, 1.0, n + 1)
            lines[1:-1] += rng.uniform(-0.2, 0.2, n - 1) / n
            pts[:, axis] = lines[np.rint(pts[:, axis] * n).astype(int)]
        return m, pts
    inner = np.all((pts[:, :2] > 1e-9) & (pts[:, :2] < 1 - 1e-9), axis=1)
    pts[inner, :2] += rng.uniform(-0.2, 0.2, (inner.sum(), 2)) / n
    return m, pts


def two_blocks_3d(path, n_low: int, n_up: int, cell: str, seed: int = 0) -> np.ndarray:
    """Two stacked boxes as one Gmsh 2.2 file: cell groups lower/upper, face groups
    <body>_top/bottom/xmin/ymin; the interface nodes are distinct (no shared node)."""
    import meshio

    rng = np.random.default_rng(seed)
    low, p_low = block(n_low, 2, cell, 0.0, rng)
    up, p_up = block(n_up, 2, cell, 0.5, rng)
    off = low.num_points
    face = {"hexahedron": "quad", "tetra": "triangle", "tetra10": "triangle6"}[cell]
    faces = [(f"{body}_{side}", m.facet_groups[g] + o)
             for body, m, o in (("lower", low, 0), ("upper", up, off))
             for side, g in SIDES.items()]
    blocks = [(cell, low.cells), (cell, up.cells + off)] + [(face, f) for _, f in faces]
    tags = [1, 2] + [10 + i for i in range(len(faces))]
    phys = [np.full(len(b[1]), tag) for b, tag in zip(blocks, tags)]
    field = {"lower": np.array([1, 3]), "upper": np.array([2, 3])}
    field.update({name: np.array([10 + i, 2]) for i, (name, _) in enumerate(faces)})
    mesh = meshio.Mesh(np.vstack([p_low, p_up]), blocks,
                       cell_data={"gmsh:physical": phys, "gmsh:geometrical": phys},
                       field_data=field)
    meshio.write(str(path), mesh, file_format="gmsh22", binary=False)
    return dict(faces)["upper_bottom"]


def write_mesh(path, *args, **kw) -> np.ndarray:
    """Rank 0 writes the mesh; every rank gets the slave faces (upper_bottom, node numbers of
    the file)."""
    faces = two_blocks_3d(path, *args, **kw) if MPI.COMM_WORLD.rank == 0 else None
    return MPI.COMM_WORLD.bcast(faces)


def homogeneous(x: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """The exact displacement: σzz = −P in both bodies, free lateral expansion from the
    rollers at x = 0, y = 0, the lower bottom held, the upper body resting on the lower."""
    u = np.empty_like(x)
    for mask, e, nu in ((~upper, E1, NU1), (upper, E2, NU2)):
        u[mask, :2] = nu * P / e * x[mask, :2]
    u[~upper, 2] = -P / E1 * x[~upper, 2]
    u[upper, 2] = -P / E1 * 0.5 - P / E2 * (x[upper, 2] - 0.5)
    return u


def slave_weights(res, slave: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """∫φ_i dA of the slave nodes from the slave faces' corners (independent of the rows): a
    triangle gives each corner a third of its area; a planar quad, the area of the triangle
    of the corner and its two neighbours over 3 plus the opposite triangle's over 6 (∫ of
    the bilinear corner function, exact for any planar quad)."""
    xy = res["mesh/points"][:, :2]
    w = np.zeros(len(xy))
    k = faces.shape[1]
    for c in range(k):   # a loop over the face's corners
        a, b, d = faces[:, c], faces[:, (c + 1) % k], faces[:, (c - 1) % k]
        own = _area(xy[a], xy[b], xy[d])
        if k == 3:
            np.add.at(w, a, own / 3)
        else:
            opp = _area(xy[faces[:, (c + 2) % k]], xy[d], xy[b])
            np.add.at(w, a, own / 3 + opp / 6)
    return w[slave]


def _area(a, b, c):
    return 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                        - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


@pytest.mark.parametrize("n_low, n_up, cell", [(3, 4, "hexahedron"), (4, 3, "hexahedron"),
                                               (2, 3, "tetra")])
def test_mortar3d_patch_pressure_is_transmitted_exactly(run, shared_tmp, n_low, n_up, cell):
    """Non-matching, distorted interface meshes: the uniform stress σzz = −p and the
    homogeneous displacement are the discrete solution to round-off, every slave node is
    closed and carries p ∫φ_i, the resultant is p × area, one iteration per step."""
    mesh = shared_tmp / f"mortar3d_{n_low}_{n_up}_{cell}.msh"
    faces = write_mesh(mesh, n_low, n_up, cell)
    res = run(PATCH3D.format(mesh=mesh, traction=-P, rollers=ROLLERS),
              name=f"mortar3d_patch_{n_low}_{n_up}_{cell}")
    stress = res["fields/stress"][-1]
    rn = res["fields/joint_normal_reaction"][-1, :, 0]
    print(f"\n3D mortar patch {cell} {n_low}/{n_up}: max |σzz/p + 1| "
          f"{np.abs(stress[:, 2] / P + 1).max():.2e}")
    np.testing.assert_allclose(stress[:, 2], -P, atol=1e-12 * P)
    np.testing.assert_allclose(stress[:, [0, 1, 3, 4, 5]], 0.0, atol=1e-12 * P)
    x = res["mesh/points"]
    upper = np.arange(len(x)) >= 3 * (n_low + 1) ** 2     # the lower block's nodes first
    u = res["fields/displacement"][-1]
    np.testing.assert_allclose(u, homogeneous(x, upper), atol=1e-12 * P / E2)
    state = res["fields/joint_state"][-1, :, 0]
    slave = np.flatnonzero(state >= 0)
    assert slave.size == (n_up + 1) ** 2 and np.all(state[slave] == STICK)
    np.testing.assert_allclose(rn[slave], P * slave_weights(res, slave, faces), rtol=1e-10)
    np.testing.assert_allclose(res["fields/joint_gap"][-1, slave, 0], 0.0, atol=1e-14)
    np.testing.assert_allclose(res["relations/joint_normal/normal_force"][:, 0], [P / 2, P],
                               rtol=1e-12)
    assert np.all(res["steps/iterations"] == 1)


@pytest.mark.parametrize("cell", ["hexahedron", "tetra"])
def test_mortar3d_patch_is_the_same_on_any_partition(run, shared_tmp, cell):
    """The patch on the ranks' parts and on one rank alone (COMM_SELF): the same results
    (1e-10 of each kind of quantity, states and active rows exactly): the rows are built on
    the gathered surfaces in their canonical order."""
    mesh = shared_tmp / f"mortar3d_parts_{cell}.msh"
    write_mesh(mesh, 3, 4, cell, seed=3)
    text = PATCH3D.format(mesh=mesh, traction=-P, rollers=ROLLERS)
    parts = run(text, name=f"mortar3d_parts_{cell}")
    alone = run(text, name=f"mortar3d_alone_{cell}", comm=MPI.COMM_SELF)
    assert_same_results(parts, alone)


FRICTION3D = """
title = "3D block pushed on a meshed rough foundation (mortar)"
[mesh]
file = "{mesh}"
[model]
hypothesis = "3d"
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
traction = [0.0, 0.0, -10.0]
evolution = "constant"
[[relations]]
name = "ground"
type = "dirichlet"
region = "lower_bottom"
components = ["x", "y", "z"]
[[relations]]
name = "shift_x"
type = "dirichlet"
region = "upper_top"
component = "x"
value = 0.03
[[relations]]
name = "shift_y"
type = "dirichlet"
region = "upper_top"
component = "y"
value = 0.015
[[contact]]
name = "base"
slave = "upper_bottom"
master = "lower_top"
friction = 0.3
discretization = "mortar"
[steps]
count = 6
[nonlinear]
max_iterations = 60
"""


@pytest.mark.parametrize("cell, bound", [("hexahedron", 10), ("tetra", 10), ("tetra10", 10)])
def test_mortar3d_friction_block_on_meshed_foundation(run, shared_tmp, cell, bound):
    """A block pressed by p = 10 on a deformable foundation meshed differently (4×4 against
    3×3, distorted) and pushed along (2, 1) by its top, Coulomb friction μ = 0.3 with mortar
    rows: the normal resultant p, the friction balancing the push exactly (the tangents of a
    flat horizontal interface are x and y), every node in its cone and on its boundary when
    sliding, no penetration; sticking first, every closed node sliding at the end with the
    tangential reactions' magnitudes summing to μN. Iterations per step measured: hexahedra
    1, 8, 7, 5, 4, 4; tetrahedra 7, 7, 6, 4, 4, 4; tetra10 (triangle6 faces) 1, 8, 8, 5, 4, 4
    (the slip direction's Newton step with the cross stiffness through the compliant cross
    rows; 1-24, 14-30 with a step cut, and 21-60 with cuts under the fixed point it
    replaced). On triangle6 faces a row's multiplier is not its node's force (docs/contact.md
    §2c): the nodes' Σ|Rt| = μN is not checked there, the resultants are."""
    mesh = shared_tmp / f"mortar3d_friction_{cell}.msh"
    if cell == "tetra10":   # triangle6 faces, midside nodes at their edges' midpoints
        if MPI.COMM_WORLD.rank == 0:
            affine_tetra10_blocks(mesh, 3, 4, seed=5)
        MPI.COMM_WORLD.Barrier()
    else:
        write_mesh(mesh, 3, 4, cell, seed=5)
    res = run(FRICTION3D.format(mesh=mesh), name=f"mortar3d_friction_{cell}")
    mu, p = 0.3, 10.0
    n_force = res["relations/base_normal/normal_force"][:, 0]
    np.testing.assert_allclose(n_force, p, rtol=1e-10)   # (tetra10 on 3 ranks: 1.01e-12)
    push = np.column_stack([res[f"relations/shift_{c}/multiplier"].sum(axis=1) for c in "xy"])
    np.testing.assert_allclose(res["relations/base_normal/tangential_force"], push,
                               atol=1e-10 * p)
    state = res["fields/base_state"][:, :, 0]
    rn = res["fields/base_normal_reaction"][:, :, 0]
    rt = np.linalg.norm(res["fields/base_tangential_reaction"], axis=2)
    assert np.all(mu * rn - rt >= -1e-10 * p)
    slip = state == SLIP
    np.testing.assert_allclose(rt[slip], mu * rn[slip], rtol=1e-9, atol=1e-12 * p)
    assert res["fields/base_gap"].min() >= -1e-12
    closed = state >= STICK
    all_slide = np.array([np.all(s[c] == SLIP) for s, c in zip(state, closed)])
    assert not all_slide[0] and all_slide[-1]
    if cell != "tetra10":   # (triangle6: a row's multiplier is not its node's force, §2c)
        np.testing.assert_allclose(rt[-1].sum(), mu * p, rtol=1e-10)
    its = res["steps/iterations"]
    print(f"\n3D mortar friction ({cell}): iterations per step {its.tolist()}, sliding "
          f"{slip.sum(axis=1).tolist()} of {closed.sum(axis=1).tolist()} closed")
    assert its.max() <= bound, its


def test_node_to_face_fails_the_same_patch(run, shared_tmp):
    """The same hexahedral scene with node-to-face rows: the stress is not uniform (what the
    mortar rows fix)."""
    mesh = shared_tmp / "nts3d_3_4.msh"
    write_mesh(mesh, 3, 4, "hexahedron")
    scene = PATCH3D.format(mesh=mesh, traction=-P, rollers=ROLLERS).replace(
        'discretization = "mortar"', 'discretization = "node_to_segment"')
    res = run(scene, name="nts3d_patch")
    assert np.abs(res["fields/stress"][-1][:, 2] + P).max() > 1e-3 * P


def affine_tetra10_blocks(path, n_low: int, n_up: int, seed: int = 0) -> int:
    """The two blocks in tetra10, the corner nodes moved as ``block`` moves them and the
    midside nodes at their edges' midpoints (flat interface faces with affine maps: the mortar
    integrals exact, so the patch test is met to round-off). Returns the lower block's node
    count (its nodes first)."""
    import meshio

    from parsolve.mesh.generators import make_quadratic
    from parsolve.mesh.mesh import Mesh

    rng = np.random.default_rng(seed)
    bodies = []
    for n, z0 in ((n_low, 0.0), (n_up, 0.5)):
        m, pts = block(n, 2, "tetra", z0, rng)
        bodies.append(make_quadratic(Mesh(pts, "tetra", m.cells, facet_groups=m.facet_groups)))
    (low, up), off = bodies, bodies[0].num_points
    faces = [(f"{body}_{side}", m.facet_groups[g] + o)
             for body, m, o in (("lower", low, 0), ("upper", up, off))
             for side, g in SIDES.items()]
    blocks = [("tetra10", low.cells), ("tetra10", up.cells + off)] + [("triangle6", f)
                                                                      for _, f in faces]
    tags = [1, 2] + [10 + i for i in range(len(faces))]
    phys = [np.full(len(b[1]), tag) for b, tag in zip(blocks, tags)]
    field = {"lower": np.array([1, 3]), "upper": np.array([2, 3])}
    field.update({name: np.array([10 + i, 2]) for i, (name, _) in enumerate(faces)})
    mesh = meshio.Mesh(np.vstack([low.points, up.points]), blocks,
                       cell_data={"gmsh:physical": phys, "gmsh:geometrical": phys},
                       field_data=field)
    meshio.write(str(path), mesh, file_format="gmsh22", binary=False)
    return off


@pytest.mark.parametrize("n_low, n_up", [(2, 3), (3, 2)])
def test_mortar3d_patch_on_triangle6_faces(run, shared_tmp, n_low, n_up):
    """tetra10 blocks, non-matching distorted triangle6 interfaces (the modified dual basis of
    Popp et al. 2012, mortar3d): the uniform stress and the homogeneous displacement are the
    discrete solution to round-off, every row closed at zero gap, the normal resultant p ×
    area (each row counted by its slave share: a midside's row also holds its edge's
    corners), one iteration per step; the same on the ranks' parts and on one rank alone."""
    mesh = shared_tmp / f"mortar3d_tetra10_{n_low}_{n_up}.msh"
    lower = affine_tetra10_blocks(mesh, n_low, n_up, seed=7) if MPI.COMM_WORLD.rank == 0 else None
    lower = MPI.COMM_WORLD.bcast(lower)
    text = PATCH3D.format(mesh=mesh, traction=-P, rollers=ROLLERS)
    res = run(text, name=f"mortar3d_tetra10_{n_low}_{n_up}")
    stress = res["fields/stress"][-1]
    print(f"\n3D mortar patch tetra10 {n_low}/{n_up}: max |σzz/p + 1| "
          f"{np.abs(stress[:, 2] / P + 1).max():.2e}")
    np.testing.assert_allclose(stress[:, 2], -P, atol=1e-11 * P)
    np.testing.assert_allclose(stress[:, [0, 1, 3, 4, 5]], 0.0, atol=1e-11 * P)
    x = res["mesh/points"]
    upper = np.arange(len(x)) >= lower
    u = res["fields/displacement"][-1]
    np.testing.assert_allclose(u, homogeneous(x, upper), atol=1e-11 * P / E2)
    state = res["fields/joint_state"][-1, :, 0]
    slave = np.flatnonzero(state >= 0)
    assert np.all(state[slave] == STICK)
    np.testing.assert_allclose(res["fields/joint_gap"][-1, slave, 0], 0.0, atol=1e-14)
    np.testing.assert_allclose(res["relations/joint_normal/normal_force"][:, 0], [P / 2, P],
                               rtol=1e-12)
    assert np.all(res["steps/iterations"] == 1)
    alone = run(text, name=f"mortar3d_tetra10_alone_{n_low}_{n_up}", comm=MPI.COMM_SELF)
    assert_same_results(res, alone)
