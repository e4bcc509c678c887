"""The contact baselines (parsolve/effects/contact_penalty.py) on the scenes of the relations
form, with ``formulation`` switched: the penalty solution tends to the relations one as the
penalty grows (penetration and error both ~ 1/ε, measured), the augmented Lagrangian reaches
it to its tolerance; bad input exits 2 naming the file and the key."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from mpi4py import MPI

from conftest import CONFIGS, ROOT, assert_same_results
from parsolve.contact import references
from parsolve.contact.friction import OPEN, SLIP, STICK
from parsolve.errors import InputError
from parsolve.model import build_model
from parsolve.scene import load_scene
from helpers.contact import BASE as CONTACT_BASE, PLANE
from helpers.scripts import load_script

E, NU = 1000.0, 0.3
BLOCK = (CONFIGS / "contact_block_friction.toml").read_text()
# the Hertz scene on a mesh half as fine (its Hertz accuracy is test_contact.py's): the AL is
# compared with the relations form on the same mesh
HERTZ = (CONFIGS / "contact_hertz_cylinder.toml").read_text().replace("nx = 160\nny = 40",
                                                                       "nx = 80\nny = 20")


def switched(text: str, after: str, lines: str) -> str:
    """The scene with ``lines`` added to its [[contact]] section, after the line ``after``."""
    assert after in text
    return text.replace(after, f"{after}\n{lines}", 1).replace('[output]\nfile = ', '# file = ')


def block(run, formulation: str, extra: str = "", name: str = "block") -> dict:
    return run(switched(BLOCK, "friction = 0.3", f'formulation = "{formulation}"\n{extra}'), name=name)


def rel(a, b) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


# ----------------------------------------------------------------------------- block on a plane


def test_penalty_tends_to_the_relations_answer_as_one_over_the_penalty(run):
    """The block of contact_block_friction.toml: as ε grows ×10, the deepest penetration and the
    displacement error against the relations form both fall ×10 (within 3 %); the friction
    resultant stays under μN, and equals it once the block slides."""
    exact = run(CONFIGS / "contact_block_friction.toml", name="block_relations")
    u_ref = exact["fields/displacement"]
    rn_ref = exact["fields/base_normal_reaction"][:, :, 0]
    penetration, error, force_error = [], [], []
    for eps in (1e5, 1e6, 1e7):
        res = block(run, "penalty", f"penalty = {eps:g}", name=f"block_pen_{eps:g}")
        np.testing.assert_array_equal(res["steps/time"], exact["steps/time"])
        penetration.append(-res["fields/base_gap"].min())
        error.append(rel(res["fields/displacement"], u_ref))
        rn = res["fields/base_normal_reaction"][:, :, 0]
        force_error.append(rel(rn, rn_ref))
        n_force = rn.sum(axis=1)
        t_force = res["fields/base_tangential_reaction"][:, :, 0].sum(axis=1)
        np.testing.assert_allclose(n_force, 10.0, rtol=1e-10)      # equilibrium: Σ Rn = pN
        assert np.all(t_force <= 0.3 * n_force * (1 + 1e-10))
        np.testing.assert_allclose(t_force[4:], 3.0, rtol=1e-10)   # sliding: μN exactly
        state = res["fields/base_state"][-1, :, 0]
        assert np.all(state[state > OPEN] == SLIP)
    penetration, error = np.array(penetration), np.array(error)
    # each penetration is the contact force over ε per unit area: ~ 1/ε
    np.testing.assert_allclose(penetration[:-1] / penetration[1:], 10.0, rtol=0.03)
    np.testing.assert_allclose(error[:-1] / error[1:], 10.0, rtol=0.03)
    assert error[-1] < 2e-4 and force_error[-1] < 2e-4


def test_augmented_lagrangian_reaches_the_relations_answer(run):
    """Uzawa augmentations close the gap and stop the sticking nodes: the displacements, the
    contact forces and the states of the relations form to the augmentation tolerance."""
    exact = run(CONFIGS / "contact_block_friction.toml", name="block_relations_al")
    # status cycles of the inner Newton fail some steps of the partial slip spreading (the
    # driver cuts them): fail them after 15 iterations rather than 30
    text = switched(BLOCK, "friction = 0.3",
                    'formulation = "augmented_lagrangian"\naugmentation_tolerance = 1e-9')
    res = run(text + "\n[nonlinear]\nmax_iterations = 15\n", name="block_al")
    times = res["steps/time"]
    keep = [int(np.argmin(np.abs(times - t))) for t in exact["steps/time"]]   # steps cut: extra
    np.testing.assert_allclose(times[keep], exact["steps/time"], rtol=1e-14)
    u = res["fields/displacement"][keep]
    assert rel(u, exact["fields/displacement"]) < 1e-7
    for field in ("normal_reaction", "tangential_reaction"):
        assert rel(res[f"fields/base_{field}"][keep], exact[f"fields/base_{field}"]) < 1e-6
    assert -res["fields/base_gap"].min() < 1e-9 * np.abs(u).max()
    # the states where the relations form is not on a boundary between them
    rn, rt = exact["fields/base_normal_reaction"][:, :, 0], exact["fields/base_tangential_reaction"][:, :, 0]
    clear = np.abs(0.3 * rn - np.abs(rt)) > 1e-6
    np.testing.assert_array_equal(res["fields/base_state"][keep][:, :, 0][clear],
                                  exact["fields/base_state"][:, :, 0][clear])


def test_sheared_block_exact_stick_and_slip_by_augmented_lagrangian(run):
    """docs/contact.md §6 (the sheared block of test_contact.py, 2D): the AL reproduces the
    exact homogeneous field, stick then uniform slip at μp, to the augmentation tolerance."""
    from helpers.contact import G, LAM, sheared_scene

    p, mu, height, t_star = 10.0, 0.3, 0.5, 0.45
    delta_end = mu * p * height / G / t_star
    text = switched(sheared_scene(delta_end, t_star, p, mu, height), f"friction = {mu}",
                    'formulation = "augmented_lagrangian"\naugmentation_tolerance = 1e-10')
    res = run(text, name="sheared_al")
    pts = res["mesh/points"]
    bottom = np.isclose(pts[:, 1], 0.0)
    for k, t in enumerate(res["steps/time"]):
        ref = references.sheared_block(LAM, G, p, mu, height, delta_end * t)
        u = res["fields/displacement"][k]
        np.testing.assert_allclose(u, ref.displacement(pts), atol=1e-8 * np.abs(u).max())
        state = res["fields/base_state"][k, bottom, 0]
        assert np.all(state == (SLIP if ref.sliding else STICK)), (t, state)


@pytest.mark.parametrize("formulation, extra", [
    ("penalty", "penalty = 1e6"),
    ("augmented_lagrangian", "augmentation_tolerance = 1e-9"),
])
def test_block_baselines_through_full_sliding_on_parts_are_the_one_rank_run(run, formulation,
                                                                            extra):
    """contact_block_friction.toml through full sliding (10 steps, the top shifted by 0.02) on
    the ranks' parts: the one-rank run's results to 1e-10, states exactly, the same steps,
    cuts and iterations; T = μN (1e-10) once every closed node slides. In full sliding each
    slid node's committed friction sits on the cone at a step's start, |t_tr| = μ p_N to
    round-off: the tie rule (stick up to μ p_N (1 + 1e-12)) decides it alike in every run,
    where a strict test decided it by the last bits (iterations varied from run to run)."""
    text = switched(BLOCK, "friction = 0.3", f'formulation = "{formulation}"\n{extra}')
    # as above: status cycles of the AL's inner Newton cut some steps of the partial slip
    text += "\n[nonlinear]\nmax_iterations = 15\n"
    parts = run(text, name=f"slide_{formulation}_parts")
    whole = run(text, name=f"slide_{formulation}_whole", comm=MPI.COMM_SELF)
    assert_same_results(parts, whole)
    for key in ("steps/iterations", "steps/cuts", "steps/time"):
        np.testing.assert_array_equal(parts[key], whole[key])
    rn = parts["fields/base_normal_reaction"][:, :, 0]
    rt = parts["fields/base_tangential_reaction"][:, :, 0]
    state = parts["fields/base_state"][:, :, 0]
    sliding = np.all((state == SLIP) | (state <= OPEN), axis=1)
    assert sliding[-3:].all() and not sliding[0]              # sticks first, slides at the end
    np.testing.assert_allclose(rt.sum(axis=1)[sliding], 0.3 * rn.sum(axis=1)[sliding],
                               rtol=1e-10)
    np.testing.assert_allclose(rn.sum(axis=1), 10.0, rtol=1e-10)


# ----------------------------------------------------------------------------- Hertz


def hertz(run, formulation: str, extra: str, name: str) -> dict:
    after = "obstacle = { cylinder = { centre = [0.0, 10.0], radius = 10.0 } }"
    return run(switched(HERTZ, after, f'formulation = "{formulation}"\n{extra}'), name=name)


def test_hertz_cylinder_penalty_and_augmented_lagrangian(run):
    """configs/contact_hertz_cylinder.toml (80×20): the penalty's penetration and its error
    against the relations form fall as 1/ε; the AL gives the relations form's displacements and
    pressures (the peak within 5 % of Hertz's p0 on this mesh, the contact edge within one
    element of its half-width)."""
    assert "nx = 80" in HERTZ
    exact = run(HERTZ.replace("[output]\nfile = ", "# file = "), name="hertz_relations")
    u_ref = exact["fields/displacement"][-1]
    rn_ref = exact["fields/indent_normal_reaction"][-1, :, 0]
    penetration, error = [], []
    for eps in (1e5, 1e6):
        res = hertz(run, "penalty", f"penalty = {eps:g}", f"hertz_pen_{eps:g}")
        penetration.append(-res["fields/indent_gap"][-1].min())
        error.append(rel(res["fields/displacement"][-1], u_ref))
    np.testing.assert_allclose(penetration[0] / penetration[1], 10.0, rtol=0.1)
    np.testing.assert_allclose(error[0] / error[1], 10.0, rtol=0.15)
    res = hertz(run, "augmented_lagrangian", "augmentation_tolerance = 1e-9", "hertz_al")
    assert rel(res["fields/displacement"][-1], u_ref) < 1e-8
    rn = res["fields/indent_normal_reaction"][-1, :, 0]
    assert rel(rn, rn_ref) < 1e-6
    pts = res["mesh/points"]
    load = -exact["relations/indent_normal/resultant"][-1, 1]
    ref = references.hertz_cylinder(load, 10.0, references.effective_modulus(E, NU))
    h = 8.0 / 80
    assert abs(rn.max() / h / ref.p0 - 1.0) < 0.05
    state = res["fields/indent_state"][-1, :, 0]
    edge = np.abs(pts[state > OPEN, 0]).max()
    assert edge <= ref.a < edge + h, (edge, ref.a)
    assert res["steps/iterations"][-1] > exact["steps/iterations"][-1]   # the augmentations


AXISYM_SPHERE = (CONFIGS / "contact_axisym_sphere.toml").read_text().replace(
    "nx = 80\nny = 80", "nx = 40\nny = 40")


def test_axisymmetric_sphere_penalty_and_augmented_lagrangian(run):
    """configs/contact_axisym_sphere.toml (40×40): with the axisymmetric hypothesis the
    baselines' nodal areas are the rings' (2π r ds), so their whole-ring forces are the
    relations form's: the penalty's penetration, its error and its total force's error fall
    as 1/ε; the AL gives the relations form's displacements and forces
    (1e-8, 1e-6)."""
    assert "nx = 40" in AXISYM_SPHERE
    after = "obstacle = { cylinder = { centre = [0.0, 10.0], radius = 10.0 } }"
    exact = run(AXISYM_SPHERE.replace("[output]\nfile = ", "# file = "), name="axisym_relations")
    u_ref = exact["fields/displacement"][-1]
    force_ref = exact["fields/indent_normal_reaction"][-1, :, 0].sum()
    penetration, error, force = [], [], []
    for eps in (1e6, 1e7):
        res = run(switched(AXISYM_SPHERE, after, f'formulation = "penalty"\npenalty = {eps:g}'),
                  name=f"axisym_pen_{eps:g}")
        penetration.append(-res["fields/indent_gap"][-1].min())
        error.append(rel(res["fields/displacement"][-1], u_ref))
        force.append(res["fields/indent_normal_reaction"][-1, :, 0].sum() / force_ref - 1.0)
    np.testing.assert_allclose(penetration[0] / penetration[1], 10.0, rtol=0.1)
    np.testing.assert_allclose(error[0] / error[1], 10.0, rtol=0.15)
    print("penetration", penetration, "error", error, "force error", force)
    np.testing.assert_allclose(force[0] / force[1], 10.0, rtol=0.05)   # measured -1.4e-3, -1.4e-4
    assert abs(force[1]) < 1e-3
    res = run(switched(AXISYM_SPHERE, after,
                       'formulation = "augmented_lagrangian"\naugmentation_tolerance = 1e-9'),
              name="axisym_al")
    assert rel(res["fields/displacement"][-1], u_ref) < 1e-8
    assert rel(res["fields/indent_normal_reaction"][-1, :, 0],
               exact["fields/indent_normal_reaction"][-1, :, 0]) < 1e-6


# ----------------------------------------------------------------------------- V-wedge


def bench_scenes():
    """scripts/bench_scenes.py: the benchmark's V-wedge (the scene that failed) as it runs."""
    return load_script("bench_scenes")


def wedge(run, shared_tmp, keys: str, name: str, **kw) -> tuple[dict, object, list]:
    """The V-wedge of docs/contact.md §7 (face 1 sticks, face 2 — a node group on an inclined
    plane, its initial gaps ±1e-17 — slides on the cone) with ``keys`` in both [[contact]]
    sections: (results, the exact solution, the two contact effects)."""
    sc = bench_scenes()
    beta = np.pi / 4
    ref = references.wedge_stick_slip(sc.LAM, sc.G, beta, -1e-3)
    # a mesh file per run: rank 0 rewriting one shared file raced with ranks still reading it
    # for the previous run's model (a file of size 0 read once under load)
    mesh = shared_tmp / f"{name}.msh"
    if MPI.COMM_WORLD.rank == 0:
        sc.wedge_mesh(mesh, beta)
    MPI.COMM_WORLD.Barrier()
    text = sc.wedge_scene(mesh, ref).replace("friction = ", f"{keys}\nfriction = ")
    res = run(text, name=name, **kw)
    effects = [e for e in build_model(load_scene(run.last.with_suffix(".toml"))).effects
               if getattr(e, "pairing", None) is not None]
    return res, ref, effects


def wedge_error(res: dict, ref) -> float:
    pts = res["mesh/points"]
    exact = np.array([t * ref.displacement(pts) for t in res["steps/time"]])
    return rel(res["fields/displacement"], exact)


def test_wedge_penalty_converges_and_tends_to_the_exact_field(run, shared_tmp):
    """The V-wedge (bench_friction's; it failed: face 2's round-off gaps started open, the
    first iteration sank the block into face 2 and face 1's end node then flipped its slip
    sense at every iteration). Now every step converges in ≤ 3 iterations, no cut; face 1
    sticks, face 2 slides with |Rt| = μ Rn (1e-12); each penetration is Rn/(ε A) to round-off
    (A: the effect's tributary areas); as ε grows ×10 the penetration and the error against the
    exact field (the relations form's, to round-off) both fall ×10 (within 2 %)."""
    errors, depths = [], []
    for eps in (1e5, 1e6, 1e7):
        res, ref, effects = wedge(run, shared_tmp, f'formulation = "penalty"\npenalty = {eps:g}',
                                  f"wedge_pen_{eps:g}")
        assert res["attrs"]["status"] == "complete"
        np.testing.assert_allclose(res["steps/time"], [1 / 3, 2 / 3, 1.0], rtol=1e-14)
        assert res["steps/iterations"].max() <= 3 and int(np.sum(res["steps/cuts"])) == 0
        depth = 0.0
        for effect, state in zip(effects, (STICK, SLIP)):
            name, slave = effect.spec.name, effect.pairing.slave
            rn = res[f"fields/{name}_normal_reaction"][:, slave, 0]
            rt = res[f"fields/{name}_tangential_reaction"][:, slave, 0]
            gap = res[f"fields/{name}_gap"][:, slave, 0]
            assert np.all(res[f"fields/{name}_state"][:, slave, 0] == state), name
            assert np.all(rn > 0)
            assert effect.penalty == eps
            np.testing.assert_allclose(-gap, rn / effect.eps_n, rtol=1e-12, atol=0)
            if state == SLIP:
                np.testing.assert_allclose(rt, ref.mu * rn, rtol=1e-12)
            else:
                assert np.all(np.abs(rt) < 0.9 * ref.mu * rn)        # strictly inside
            depth = max(depth, float(-gap.min()))
        depths.append(depth)
        errors.append(wedge_error(res, ref))
    depths, errors = np.array(depths), np.array(errors)
    np.testing.assert_allclose(depths[:-1] / depths[1:], 10.0, rtol=0.02)
    np.testing.assert_allclose(errors[:-1] / errors[1:], 10.0, rtol=0.02)
    assert errors[-1] < 3e-4


def test_wedge_augmented_lagrangian_gives_the_exact_field(run, shared_tmp):
    """The V-wedge by the augmented Lagrangian (it failed after 25 augmentations): the exact
    field to 1e-10, the gaps closed, face 1 stuck strictly inside its cone, face 2 on it."""
    res, ref, effects = wedge(run, shared_tmp, 'formulation = "augmented_lagrangian"\n'
                              "augmentation_tolerance = 1e-10", "wedge_al")
    assert res["attrs"]["status"] == "complete" and int(np.sum(res["steps/cuts"])) == 0
    assert wedge_error(res, ref) < 1e-10
    u = np.abs(res["fields/displacement"]).max()
    for effect, state in zip(effects, (STICK, SLIP)):
        name, slave = effect.spec.name, effect.pairing.slave
        assert np.all(res[f"fields/{name}_state"][:, slave, 0] == state), name
        assert np.abs(res[f"fields/{name}_gap"][:, slave, 0]).max() < 1e-12 * u
        rn = res[f"fields/{name}_normal_reaction"][:, slave, 0]
        rt = res[f"fields/{name}_tangential_reaction"][:, slave, 0]
        if state == SLIP:
            np.testing.assert_allclose(rt, ref.mu * rn, rtol=1e-12)


@pytest.mark.parametrize("keys", ['formulation = "penalty"',
                                  'formulation = "augmented_lagrangian"'])
def test_wedge_baselines_on_parts_are_the_one_rank_run(run, shared_tmp, keys):
    """The V-wedge by either baseline on the ranks' parts: the one-rank run's results
    (1e-10, states exactly) and the same iterations."""
    tag = keys.split('"')[1]
    parts = wedge(run, shared_tmp, keys, f"wedge_{tag}_parts")[0]
    whole = wedge(run, shared_tmp, keys, f"wedge_{tag}_whole", comm=MPI.COMM_SELF)[0]
    assert_same_results(parts, whole)
    np.testing.assert_array_equal(parts["steps/iterations"], whole["steps/iterations"])


# ----------------------------------------------------------------------------- bad input

# the bad-input scene of test_contact.py, its slave the bottom edge
BASE = CONTACT_BASE.replace("{contact}", 'slave = "bottom"\n{contact}')


@pytest.mark.parametrize("contact, key, words", [
    (f'{PLANE}\nformulation = "penalty"\npenalty = -1.0', "contact[0].penalty", "positive"),
    (f'{PLANE}\nformulation = "penalty"\npenalty = 0.0', "contact[0].penalty", "positive"),
    (f'{PLANE}\nformulation = "penalty"\npenalty_tangential = -5.0',
     "contact[0].penalty_tangential", "positive"),
    (f'{PLANE}\nformulation = "lagrange"', "contact[0].formulation", "one of"),
    (f'{PLANE}\npenalty = 10.0', "contact[0].penalty", "formulation"),
    (f'{PLANE}\nformulation = "penalty"\nmax_augmentations = 3', "contact[0].max_augmentations",
     "augmented_lagrangian"),
    (f'{PLANE}\nformulation = "augmented_lagrangian"\naugmentation_tolerance = 2.0',
     "contact[0].augmentation_tolerance", "(0, 1)"),
    (f'{PLANE}\nformulation = "augmented_lagrangian"\nmax_augmentations = 0',
     "contact[0].max_augmentations", "at least 1"),
    ('master = "top"\nformulation = "penalty"\ndiscretization = "mortar"',
     "contact[0].discretization", "node_to_segment"),
    ('master = "top"\nformulation = "augmented_lagrangian"\nsliding = "finite"',
     "contact[0].sliding", "made once"),
])
def test_bad_input_names_file_and_key(shared_tmp, contact, key, words):
    path = shared_tmp / "bad_baseline.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(BASE.format(contact=contact))
    MPI.COMM_WORLD.Barrier()
    with pytest.raises(InputError) as err:
        build_model(load_scene(path))
    assert err.value.key == key and words in str(err.value) and str(path) in str(err.value)


@pytest.mark.serial
@pytest.mark.parametrize("contact, key", [
    (f'{PLANE}\nformulation = "penalty"\npenalty = -1.0', "contact[0].penalty"),
    (f'{PLANE}\nformulation = "lagrange"', "contact[0].formulation"),
])
def test_bad_baseline_exits_2(tmp_path, contact, key):
    (tmp_path / "scene.toml").write_text(BASE.format(contact=contact))
    proc = subprocess.run([sys.executable, "-m", "parsolve", "check", "scene.toml"],
                          cwd=tmp_path, capture_output=True, text=True,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert proc.returncode == 2, proc.stderr
    line = proc.stderr.strip()
    assert "scene.toml" in line and key in line and "\n" not in line, line


# ----------------------------------------------------------------------------- tangent


BOX = """
[mesh]
generator = "box"
lx = 1.0
ly = 1.0
lz = 0.5
nx = 2
ny = 2
nz = 1
[model]
hypothesis = "3d"
[[materials]]
E = 1000.0
nu = 0.3
[[contact]]
name = "base"
slave = "zmin"
obstacle = { sphere = { centre = [0.5, 0.5, -3.0], radius = 3.0 } }
friction = 0.4
formulation = "penalty"
"""


def test_penalty_tangent_is_the_derivative_of_the_contact_forces(shared_tmp):
    """The consistent tangent of the nodal contact forces (open, stick and 3D slip nodes on a
    curved obstacle, a committed friction force) against central differences of the forces."""
    path = shared_tmp / "penalty_box.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(BOX)
    MPI.COMM_WORLD.Barrier()
    effect = build_model(load_scene(path)).effects[-1]
    p = effect.pairing
    n = len(p)
    rng = np.random.default_rng(3)
    u = np.zeros((effect.mesh.num_points, 3))
    u[p.slave, :2] = rng.normal(size=(n, 2)) * np.where(np.arange(n) % 2, 1e-1, 1e-4)[:, None]
    u[p.slave, 2] = rng.uniform(-0.1, 0.02, n)
    state = {"gT": rng.normal(size=(n, 2)) * 1e-3}
    lam_t = rng.normal(size=(n, 2)) * 0.5

    def force(uu):
        f = effect.forces(uu, state, np.zeros(n), lam_t)
        return -f["pN"][:, None] * p.normal + np.einsum("mjx,mj->mx", p.tangents, f["t"]), f

    f0, info = force(u)
    assert {OPEN, STICK, SLIP} <= set(info["state"].tolist())
    k = effect.node_tangents(info)
    h = 1e-9
    for c in range(3):
        du = np.zeros_like(u)
        du[p.slave, c] = h
        fd = (force(u + du)[0] - force(u - du)[0]) / (2 * h)
        np.testing.assert_allclose(k[:, :, c], fd, atol=1e-5 * np.abs(k).max())
