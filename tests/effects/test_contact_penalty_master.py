"""The penalty contact against a deformable master (parsolve/effects/contact_penalty.py): its
force and tangent are node-tuple terms (each slave node with its master facet's nodes), in
the partition's global node numbers, declared by the rank of the slave node alone.

- A flat punch whose slave side refines its master (2D node-to-segment, 3D node-to-face): the
  uniform pressure p is transmitted exactly, every slave's gap is −p/penalty to round-off
  (its tributary area's force p A over its stiffness penalty × A), and the displacement is the
  multiplier contact's with the upper body shifted by that gap: the error is p/penalty.
- A narrower punch (non-uniform pressure, frictionless and with Coulomb friction): the
  penetration and the displacement error against the multiplier contact fall as 1/penalty.
- At 2 and 3 ranks the cells are cut by bisection where the slave and its master facet lie on
  different ranks (checked): the one-rank run's results.
- The tangent of a pair's forces on its slave and master nodes (open, stick, 3D slip) against
  central differences."""

from __future__ import annotations

import tomllib

import meshio
import numpy as np
import pytest
from mpi4py import MPI

from conftest import assert_same_results
from helpers.contact import PATCH
from parsolve.contact.friction import OPEN, SLIP, STICK
from parsolve.mesh.generators import box, rectangle
from parsolve.model import build_model
from parsolve.scene import load_scene

COMM = MPI.COMM_WORLD
P = 10.0


def stacked(path, lower, upper, sides: tuple) -> None:
    """Two meshes (generators' rectangles or boxes) as one Gmsh 2.2 file: cell groups
    lower/upper and facet groups <body>_<side>; the interface nodes distinct."""
    off = lower.num_points
    points = np.vstack([lower.points, upper.points])
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    cell, facet = ("quad", "line") if lower.dim == 2 else ("hexahedron", "quad")
    groups = [(f"{body}_{side}", m.facet_groups[side] + o)
              for body, m, o in (("lower", lower, 0), ("upper", upper, off)) for side in sides]
    blocks = [(cell, lower.cells), (cell, upper.cells + off)] + [(facet, f) for _, f in groups]
    tags = [1, 2] + [10 + i for i in range(len(groups))]
    phys = [np.full(len(b[1]), tag) for b, tag in zip(blocks, tags)]
    dim = lower.dim
    field = {"lower": np.array([1, dim]), "upper": np.array([2, dim])}
    field.update({name: np.array([10 + i, dim - 1]) for i, (name, _) in enumerate(groups)})
    meshio.write(str(path), meshio.Mesh(points, blocks, cell_data={"gmsh:physical": phys,
                                                                   "gmsh:geometrical": phys},
                                        field_data=field), file_format="gmsh22", binary=False)


def punch_2d(path, width: float = 1.0) -> None:
    """A lower block (1 × 1, 4 × ny cells) under an upper one (width × h, 8 × ny_up cells,
    at x = 0): the bisection of 2 ranks cuts at the interface (as many cells each side), of 3
    ranks there too (the lower block twice the upper's cells, and narrower than tall)."""
    ny_up, h_up = (2, 0.25) if COMM.size == 3 else (4, 1.0)
    ny_low = 2 * ny_up if COMM.size == 2 else 4 * ny_up
    lower = rectangle(0.5 if COMM.size == 3 else 1.0, 1.0, 4, ny_low)
    upper = rectangle(width * (0.5 if COMM.size == 3 else 1.0), h_up, 8, ny_up,
                      origin=(0.0, 1.0))
    stacked(path, lower, upper, ("top", "bottom", "left"))


def scene_2d(mesh, contact: str, extra: str = "") -> str:
    text = PATCH.format(mesh=mesh, traction=-P, extra=contact + "\n" + extra)
    return text + '\n[solver]\npartitioner = "bisection"\n'


def written(path_of, writer, *args) -> str:
    if COMM.rank == 0:
        writer(path_of, *args)
    COMM.Barrier()
    return str(path_of)


def split_pairs(effect) -> int:
    """Pairs whose slave node and some master node have different owners (each rank holds
    the pairs of the slave nodes it owns; every rank the count)."""
    p, values = effect.pairing, effect.values
    own, _ = values.owned_nodes(p.master.ravel())
    return COMM.allreduce(int(np.count_nonzero(~own.reshape(p.master.shape).all(axis=1))))


def contact_effect(run):
    return [e for e in build_model(load_scene(run.last.with_suffix(".toml")), COMM).effects
            if getattr(e, "pairing", None) is not None][0]


def rel(a, b) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


# ----------------------------------------------------------------------------- flat punch


def test_flat_punch_2d_transmits_p_with_gap_p_over_penalty(run, shared_tmp):
    mesh = written(shared_tmp / f"punch_{COMM.size}.msh", punch_2d)
    exact = run(scene_2d(mesh, ""), name="punch_rel")
    u_ref = exact["fields/displacement"]
    # the upper body: above the interface, and its slave nodes on it
    upper = (exact["mesh/points"][:, 1] > 1.0 + 1e-9) | (exact["fields/joint_state"][-1, :, 0] >= 0)
    errors = []
    for eps in (1e4, 1e5, 1e6):
        res = run(scene_2d(mesh, f'formulation = "penalty"\npenalty = {eps:g}'),
                  name=f"punch_pen_{eps:g}")
        if COMM.size > 1:   # slaves and their master facets on different ranks (how many:
            assert split_pairs(contact_effect(run)) > 0   # the partition's choice)
        stress = res["fields/stress"][-1]
        np.testing.assert_allclose(stress[:, 1], -P, atol=1e-10 * P)
        np.testing.assert_allclose(stress[:, [0, 2]], 0.0, atol=1e-10 * P)
        state = res["fields/joint_state"][-1, :, 0]
        slave = np.flatnonzero(state >= 0)
        assert slave.size == 9 and np.all(state[slave] == STICK)
        width = np.ptp(res["mesh/points"][slave, 0])
        for k, t in enumerate(res["steps/time"]):   # the press ramps with the steps
            np.testing.assert_allclose(res["fields/joint_gap"][k, slave, 0], -P * t / eps,
                                       rtol=1e-9)
            np.testing.assert_allclose(res["fields/joint_normal_reaction"][k, slave, 0].sum(),
                                       P * t * width, rtol=1e-12)
        shift = np.zeros_like(u_ref)
        shift[:, upper, 1] = -P * res["steps/time"][:, None] / eps
        np.testing.assert_allclose(res["fields/displacement"], u_ref + shift,
                                   atol=1e-9 * np.abs(u_ref).max())
        errors.append(rel(res["fields/displacement"], u_ref))
    np.testing.assert_allclose(np.array(errors[:-1]) / errors[1:], 10.0, rtol=1e-6)


def punch_3d(path) -> None:
    """A lower box (1 × 1 × 0.5, 2 × 2 × nz) under an upper one (4 × 4 × 1): as many cells
    each side at 2 ranks (bisection cuts at the interface along z, the longest side)."""
    lower = box(1.0, 1.0, 1.0, 2, 2, 8)
    upper = box(1.0, 1.0, 1.0, 4, 4, 2, origin=(0.0, 0.0, 1.0))
    stacked(path, lower, upper, ("zmax", "zmin", "xmin", "ymin"))


SCENE_3D = """
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
region = "upper_zmax"
traction = [0.0, 0.0, {p}]
[[relations]]
name = "ground"
type = "dirichlet"
region = "lower_zmin"
component = "z"
{rollers}
[[contact]]
name = "joint"
slave = "upper_zmin"
master = "lower_zmax"
formulation = "penalty"
penalty = {eps}
[solver]
partitioner = "bisection"
"""
ROLLERS = "".join(f'[[relations]]\nname = "roll_{b}_{c}"\ntype = "dirichlet"\n'
                  f'region = "{b}_{c}min"\ncomponent = "{c}"\n'
                  for b in ("lower", "upper") for c in "xy")


def test_flat_punch_3d_node_to_face(run, shared_tmp):
    """The same in 3D (quad faces, the slave side 4 × 4 on the master's 2 × 2): σzz = −p,
    every slave gap −p/penalty, ΣRn = p × area, on 1, 2, 3 ranks (with pairs split over the
    ranks: how many depends on the partition, which follows the mesh reader's slices)."""
    mesh = written(shared_tmp / f"punch3d_{COMM.size}.msh", punch_3d)
    eps = 1e5
    res = run(SCENE_3D.format(mesh=mesh, p=-P, eps=eps, rollers=ROLLERS), name="punch3d")
    if COMM.size > 1:   # the case this test is for: pairs whose nodes two ranks own
        assert 0 < split_pairs(contact_effect(run)) <= 25
    stress = res["fields/stress"][-1]
    np.testing.assert_allclose(stress[:, 2], -P, atol=1e-10 * P)
    np.testing.assert_allclose(stress[:, [0, 1, 3, 4, 5]], 0.0, atol=1e-10 * P)
    state = res["fields/joint_state"][-1, :, 0]
    slave = np.flatnonzero(state >= 0)
    assert slave.size == 25 and np.all(state[slave] == STICK)
    np.testing.assert_allclose(res["fields/joint_gap"][-1, slave, 0], -P / eps, rtol=1e-9)
    np.testing.assert_allclose(res["fields/joint_normal_reaction"][-1, slave, 0].sum(), P,
                               rtol=1e-12)


# ----------------------------------------------------------------------------- narrow punch


@pytest.mark.parametrize("friction", [0.0, 0.3])
def test_narrow_punch_tends_to_the_multiplier_contact_as_one_over_the_penalty(
        run, shared_tmp, friction):
    """An upper block half as wide as the lower one (the pressure peaks at the punch's corner;
    with friction the bodies' different lateral strains stick and slip): as the penalty grows
    ×10 the penetration and the displacement error against the multiplier contact fall ×10;
    ΣRn = p × width always; with friction every node in its cone."""
    mesh = written(shared_tmp / f"narrow_{COMM.size}.msh", punch_2d, 0.5)
    text = scene_2d(mesh, f"friction = {friction}")
    exact = run(text, name=f"narrow_rel_{friction}")
    u_ref = exact["fields/displacement"][-1]
    depth, error = [], []
    for eps in (1e5, 1e6, 1e7):
        res = run(text.replace(f"friction = {friction}",
                               f'friction = {friction}\nformulation = "penalty"\n'
                               f"penalty = {eps:g}"), name=f"narrow_pen_{friction}_{eps:g}")
        assert res["attrs"]["status"] == "complete"
        if COMM.size > 1:
            assert split_pairs(contact_effect(run)) > 0
        state = res["fields/joint_state"][-1, :, 0]
        slave = np.flatnonzero(state >= 0)
        rn = res["fields/joint_normal_reaction"][-1, slave, 0]
        width = np.ptp(res["mesh/points"][slave, 0])
        np.testing.assert_allclose(rn.sum(), P * width, rtol=1e-10)
        if friction:
            rt = res["fields/joint_tangential_reaction"][-1, slave, 0]
            assert np.all(np.abs(rt) <= friction * rn * (1 + 1e-10))
            print("states", np.unique(state[slave], return_counts=True))
        depth.append(-res["fields/joint_gap"][-1, slave, 0].min())
        error.append(rel(res["fields/displacement"][-1], u_ref))
    depth, error = np.array(depth), np.array(error)
    print("penetration", depth, "error", error)
    np.testing.assert_allclose(depth[:-1] / depth[1:], 10.0, rtol=0.05)
    np.testing.assert_allclose(error[:-1] / error[1:], 10.0, rtol=0.05)


# ----------------------------------------------------------------------------- parts, AL


def test_narrow_punch_with_friction_on_parts_is_the_one_rank_run(run, shared_tmp):
    """The narrow punch with friction on the ranks' parts (pairs split between them): the
    one-rank run's results to 1e-10, states exactly, the same iterations."""
    mesh = written(shared_tmp / f"narrow_{COMM.size}.msh", punch_2d, 0.5)
    text = scene_2d(mesh, 'friction = 0.3\nformulation = "penalty"\npenalty = 1e6')
    parts = run(text, name="narrow_parts")
    whole = run(text, name="narrow_whole", comm=MPI.COMM_SELF)
    assert_same_results(parts, whole)
    np.testing.assert_array_equal(parts["steps/iterations"], whole["steps/iterations"])


def test_augmented_lagrangian_on_a_deformable_master_gives_the_multiplier_answer(run,
                                                                              shared_tmp):
    """The augmented Lagrangian (the same contact elements, Uzawa multipliers) closes the
    gap: the narrow punch with friction as the multiplier contact gives it, to its
    tolerance (the states too)."""
    mesh = written(shared_tmp / f"narrow_{COMM.size}.msh", punch_2d, 0.5)
    exact = run(scene_2d(mesh, "friction = 0.3"), name="narrow_al_rel")
    res = run(scene_2d(mesh, 'friction = 0.3\nformulation = "augmented_lagrangian"\n'
                             "augmentation_tolerance = 1e-10"), name="narrow_al")
    u_ref = exact["fields/displacement"]
    assert rel(res["fields/displacement"], u_ref) < 1e-8
    # (the corner node x = 0: held sideways on both bodies, its friction is the rollers' too,
    # shared by the multiplier contact as its dependent rows make it)
    free = exact["mesh/points"][:, 0] > 1e-9
    for field in ("normal_reaction", "tangential_reaction"):
        assert rel(res[f"fields/joint_{field}"][:, free],
                   exact[f"fields/joint_{field}"][:, free]) < 1e-7, field
    assert -res["fields/joint_gap"].min() < 1e-10 * np.abs(u_ref).max()
    np.testing.assert_array_equal(res["fields/joint_state"], exact["fields/joint_state"])


# ----------------------------------------------------------------------------- tangent


@pytest.mark.parametrize("dim", [2, 3])
def test_tangent_of_a_pair_is_the_derivative_of_its_forces(shared_tmp, dim):
    """Each pair's consistent tangent on its slave and master nodes' DOFs (open, stick, slip;
    in 3D the slip direction turning) against central differences of its tuple forces, at
    random displacements of both bodies' contact nodes and a committed friction force."""
    if dim == 2:
        mesh = written(shared_tmp / f"narrow_{COMM.size}.msh", punch_2d, 0.5)
        text = scene_2d(mesh, 'friction = 0.3\nformulation = "penalty"\npenalty = 1e4')
    else:
        mesh = written(shared_tmp / f"punch3d_{COMM.size}.msh", punch_3d)
        text = SCENE_3D.format(mesh=mesh, p=-P, eps=1e4, rollers=ROLLERS).replace(
            "formulation", "friction = 0.4\nformulation")
    path = shared_tmp / f"tangent_{dim}.toml"
    if COMM.rank == 0:
        path.write_text(text)
    COMM.Barrier()
    effect = [e for e in build_model(load_scene(path), MPI.COMM_SELF).effects
              if getattr(e, "pairing", None) is not None][0]
    p = effect.pairing
    n, dm1 = len(p), dim - 1
    ids = np.concatenate([p.slave[:, None], p.master], axis=1)
    rng = np.random.default_rng(7)
    u = np.zeros((effect.mesh.num_points, dim))
    u[np.unique(ids)] = rng.normal(size=(np.unique(ids).size, dim)) * 1e-5
    # the slaves into the master or away from it, sliding far or little along it
    u[p.slave, -1] += rng.uniform(-2e-3, 5e-4, n)
    u[p.slave, :-1] += rng.normal(size=(n, dm1)) * np.where(np.arange(n) % 2, 1e-2, 1e-6)[:, None]
    state = {"gT": rng.normal(size=(n, dm1)) * 1e-4}
    lam_t = rng.normal(size=(n, dm1)) * 0.05

    def forces(uu):
        f = effect.forces(uu, state, np.zeros(n), lam_t)
        return effect.tuple_forces(f).reshape(n, -1), f

    info = forces(u)[1]
    assert {OPEN, STICK, SLIP} <= set(info["state"].tolist()), info["state"]
    k = effect.node_tangents(info)
    h = 1e-8
    fd = np.zeros_like(k)
    for i in range(n):
        for a, node in enumerate(ids[i]):
            for c in range(dim):
                du = np.zeros_like(u)
                du[node, c] = h
                fd[i, :, a * dim + c] = (forces(u + du)[0][i] - forces(u - du)[0][i]) / (2 * h)
    np.testing.assert_allclose(k, fd, atol=1e-6 * np.abs(k).max())


# ----------------------------------------------------------------------------- finite sliding


def slide_scene(mesh, contact: str) -> str:
    """The narrow punch pressed by p from the first step, its left edge then moved along the
    base by 0.3 of the base's width over 6 steps: its slaves cross the master's facets."""
    width = 0.5 if COMM.size == 3 else 1.0
    text = scene_2d(mesh, 'sliding = "finite"\n' + contact)
    text = text.replace('region = "upper_left"\ncomponent = "x"',
                        f'region = "upper_left"\ncomponent = "x"\nvalue = {0.3 * width}\n'
                        'evolution = "slide"')
    text = text.replace(f"traction = [0.0, {-P}]", f'traction = [0.0, {-P}]\n'
                        'evolution = "constant"')
    return text.replace("count = 2", "count = 6\n[evolutions.slide]\ntimes = [0.0, 1.0]\n"
                                     "values = [0.0, 1.0]")


def test_finite_sliding_penalty_moves_its_tuples_and_tends_to_the_multiplier_contact(
        run, shared_tmp):
    """The narrow punch slid along its base (finite sliding, frictionless): the pairs made
    again on the current configuration move slaves onto other master facets (new tuples, the
    pattern derived again: /timings/pattern); as the penalty grows ×10 the displacement error
    against the multiplier contact's finite sliding and the penetration fall ×10 (2 %), the
    normal force tends to its resultant. (Small sliding's pairs, held from the start, are 2 %
    off whatever the penalty.) On 2 and 3 ranks the pairs are split between ranks."""
    mesh = written(shared_tmp / f"narrow_{COMM.size}.msh", punch_2d, 0.5)
    exact = run(slide_scene(mesh, ""), name="slide_rel")
    u_ref = exact["fields/displacement"][-1]
    force = exact["relations/joint_normal/normal_force"][-1, 0]
    error, depth, force_error = [], [], []
    for eps in (1e5, 1e6, 1e7):
        res = run(slide_scene(mesh, f'formulation = "penalty"\npenalty = {eps:g}'),
                  name=f"slide_pen_{eps:g}")
        assert res["attrs"]["status"] == "complete" and "timings/pattern" in res
        effect = contact_effect(run)
        if COMM.size > 1:
            assert split_pairs(effect) > 0
        np.testing.assert_allclose(res["steps/time"][-1], 1.0)
        slave = np.flatnonzero(res["fields/joint_state"][-1, :, 0] >= 0)
        error.append(rel(res["fields/displacement"][-1], u_ref))
        depth.append(-res["fields/joint_gap"][-1, slave, 0].min())
        force_error.append(abs(res["fields/joint_normal_reaction"][-1, slave, 0].sum() / force - 1))
    print("error", error, "penetration", depth, "force error", force_error)
    error, depth = np.array(error), np.array(depth)
    np.testing.assert_allclose(error[:-1] / error[1:], 10.0, rtol=0.02)
    np.testing.assert_allclose(depth[:-1] / depth[1:], 10.0, rtol=0.02)
    assert error[-1] < 1e-5 and force_error[-1] < 1e-8
    small = run(slide_scene(mesh, 'formulation = "penalty"\npenalty = 1e7').replace(
        'sliding = "finite"\n', ""), name="slide_small")
    assert rel(small["fields/displacement"][-1], u_ref) > 1e-2


def test_finite_sliding_penalty_on_parts_is_the_one_rank_run(run, shared_tmp):
    """The same slide with friction on the ranks' parts: the one-rank run's results (1e-10),
    states, steps and iterations exactly."""
    mesh = written(shared_tmp / f"narrow_{COMM.size}.msh", punch_2d, 0.5)
    text = slide_scene(mesh, 'friction = 0.3\nformulation = "penalty"\npenalty = 1e6')
    parts = run(text, name="slide_parts")
    whole = run(text, name="slide_whole", comm=MPI.COMM_SELF)
    assert_same_results(parts, whole)
    for key in ("steps/iterations", "steps/time"):
        np.testing.assert_array_equal(parts[key], whole[key])


def test_finite_sliding_penalty_3d_node_to_face_tends_to_the_multiplier_contact(
        run, shared_tmp):
    """A box (0.5 × 0.5 × 0.5, 4 × 4 × 2) pressed on a larger one (2 × 2 × 4) and slid by 0.3
    along x, frictionless, finite sliding: its slaves cross the master's faces (the pattern
    derived again); the displacement error against the multiplier contact falls ×10 as the
    penalty grows ×10 (2 %; measured 3.8e-4, 3.8e-5)."""
    def write(path):
        stacked(path, box(1.0, 1.0, 1.0, 2, 2, 4),
                box(0.5, 0.5, 0.5, 4, 4, 2, origin=(0.0, 0.0, 1.0)),
                ("zmax", "zmin", "xmin", "ymin"))
    mesh = written(shared_tmp / "slide3d.msh", write)
    rollers = ROLLERS.replace('region = "upper_xmin"\ncomponent = "x"',
                              'region = "upper_xmin"\ncomponent = "x"\nvalue = 0.3\n'
                              'evolution = "slide"')
    text = SCENE_3D.format(mesh=mesh, p=-P, eps="{eps}", rollers=rollers).replace(
        f"traction = [0.0, 0.0, {-P}]", f'traction = [0.0, 0.0, {-P}]\nevolution = "constant"')
    text += '[steps]\ncount = 4\n[evolutions.slide]\ntimes = [0.0, 1.0]\nvalues = [0.0, 1.0]\n'
    text = text.replace('formulation = "penalty"\npenalty = {eps}', 'sliding = "finite"\n{form}')
    exact = run(text.replace("{form}", ""), name="slide3d_rel")
    u_ref = exact["fields/displacement"][-1]
    error = []
    for eps in (1e5, 1e6):
        res = run(text.replace("{form}", f'formulation = "penalty"\npenalty = {eps:g}'),
                  name=f"slide3d_pen_{eps:g}")
        assert res["attrs"]["status"] == "complete" and "timings/pattern" in res
        error.append(rel(res["fields/displacement"][-1], u_ref))
    print("error", error)
    np.testing.assert_allclose(error[0] / error[1], 10.0, rtol=0.02)
    assert error[1] < 5e-5


def test_finite_sliding_penalty_restarts_where_it_stopped(shared_tmp):
    """The slide with friction stopped after 3 of its 6 steps and restarted: the results
    those of the whole run (bitwise on one rank, 1e-10 on parts): the pairs and the committed
    friction's tangents come back with the restart."""
    import parsolve
    from conftest import read_results

    mesh = written(shared_tmp / f"narrow_{COMM.size}.msh", punch_2d, 0.5)
    text = slide_scene(mesh, 'friction = 0.3\nformulation = "penalty"\npenalty = 1e6')
    times = [(i + 1) / 6 for i in range(6)]

    def scene(k: int):
        return parsolve.Scene.from_dict(
            {**tomllib.loads(text), "steps": {"times": times[:k]}}, source="slide.toml",
            base=shared_tmp)

    parsolve.run(scene(6), shared_tmp / "full.h5", COMM, log=None)
    parsolve.run(scene(3), shared_tmp / "first.h5", COMM, log=None)
    parsolve.run(scene(6), shared_tmp / "rest.h5", COMM, restart=shared_tmp / "first.h5",
                 log=None)
    full, rest = read_results(shared_tmp / "full.h5"), read_results(shared_tmp / "rest.h5")
    for name in ("fields/displacement", "fields/joint_normal_reaction",
                 "fields/joint_tangential_reaction", "fields/joint_state"):
        a, b = full[name], rest[name]
        assert a.shape == b.shape
        if COMM.size == 1:
            assert np.array_equal(a, b), name
        else:
            # (the penalty, 1e3 times the bodies' stiffness, scales the round-off up)
            np.testing.assert_allclose(b, a, rtol=0, atol=1e-10 * np.abs(a).max())
