"""Finite sliding (``[[contact]] sliding = "finite"``, 2D node-to-segment): the pairing is made
again on the current configuration at each step over row spans (made again, with the
operator's pattern, when a slave nears its span's edge), the slip history carried across
facets.

A deformable base (the slave: its top nodes) under a die (the master: its bottom facets)
that presses it by δ and is dragged by d(t) over more than three of its own facets. The die's
nodes are all held (a rigid die moved by a rigid translation), so the base's field is the
homogeneous one of docs/contact.md §6 turned upside down: stick while G d / H < μ p, then full
slip with σ_xy = μ p; linear, so Q1 reproduces it to round-off at every step whichever die
facet each slave faces."""

from __future__ import annotations

import re

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from conftest import CONFIGS, assert_same_results
from helpers.scripts import load_script
from helpers.scene import scene as build, shipped
from parsolve.contact.friction import OPEN, SLIP, STICK
from parsolve.contact.pairing import pair_nodes
from parsolve.errors import InputError, SolverError
from parsolve.scene import load_scene
from parsolve.solvers.system import SaddleSystem

E, NU = 1000.0, 0.3
LAM, G = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))   # plane strain
HB, DELTA, MU = 0.5, 0.1, 0.5
P = (LAM + 2 * G) * DELTA / HB          # the base's uniform pressure
D_END = 0.55                            # the die's travel: 4.4 of its facets (0.125)


MESHES = load_script("make_ironing_2d_mesh")   # the shipped mesh's generator


def base_and_die(path, base_box=(1.0, HB, 6, 3), die_box=(2.0, 0.25, 16, 1, -0.75)) -> None:
    """The base (nx × ny quads) and the die on top of it (scripts/make_ironing_2d_mesh.py)."""
    MESHES.base_and_die(path, base_box, die_box)


def scene(mesh, sliding: str = "finite", steps: int = 10, **contact) -> str:
    """The base-and-die scene; ``contact`` adds or replaces keys of its [[contact]] entry."""
    gy = -DELTA / HB
    sxx, tau = LAM * gy, MU * P
    t_star = MU * P * HB / (G * D_END)

    def load(name, region, traction, evolution):
        return {"name": name, "region": region, "traction": traction, "evolution": evolution}

    return build(
        mesh={"file": str(mesh)},
        model={"hypothesis": "plane_strain"},
        materials=[{"E": E, "nu": NU}],
        loads=[load("side_n", "base_right", [sxx, 0.0], "constant"),
               load("side_n_left", "base_left", [-sxx, 0.0], "constant"),
               load("side_t", "base_right", [0.0, tau], "shear"),
               load("side_t_left", "base_left", [0.0, -tau], "shear")],
        relations=[{"name": "ground", "type": "dirichlet", "region": "base_bottom",
                    "components": ["x", "y"]},
                   {"name": "drag", "type": "dirichlet", "region": "die", "component": "x",
                    "value": D_END},
                   {"name": "press", "type": "dirichlet", "region": "die", "component": "y",
                    "value": -DELTA, "evolution": "constant"}],
        contact=[{"name": "slide", "slave": "base_top", "master": "die_bottom", "friction": MU,
                  "search_radius": 0.7, "sliding": sliding} | contact],
        evolutions={"shear": {"times": [0.0, t_star, 2.0], "values": [0.0, 1.0, 1.0]}},
        steps={"count": steps},
    )


def exact_base(pts: np.ndarray, d: float) -> tuple[np.ndarray, bool, float]:
    """The base's homogeneous field for the die at d: (u, sliding, σ_xy)."""
    tau = min(G * d / HB, MU * P)
    gx = tau / G
    u = np.column_stack([gx * pts[:, 1], -DELTA / HB * pts[:, 1]])
    return u, G * d / HB > MU * P * (1 + 1e-12), tau


@pytest.fixture
def mesh(shared_tmp):
    path = shared_tmp / "base_and_die.msh"
    if MPI.COMM_WORLD.rank == 0:
        base_and_die(path)
    MPI.COMM_WORLD.Barrier()
    return path


@pytest.mark.parametrize("discretization", ["node_to_segment", "mortar"])
def test_die_dragged_over_four_facets_is_exact(run, mesh, discretization):
    """Node-to-segment and mortar rows alike (mortar: each row re-integrated on the current
    configuration over the die's facets it now overlaps)."""
    res = run(scene(mesh, discretization=discretization), name=f"sliding_die_{discretization}")
    pts = res["mesh/points"]
    base = pts[:, 1] <= HB + 1e-12
    base &= np.arange(len(pts)) < 7 * 4        # the base's nodes come first (7 × 4)
    top = base & np.isclose(pts[:, 1], HB)
    die = np.arange(len(pts)) >= 28
    times = res["steps/time"]
    u_all = res["fields/displacement"]
    slid = []
    for k, t in enumerate(times):
        d = D_END * t
        u_ref, sliding, tau = exact_base(pts[base], d)
        scale = max(np.abs(u_all[k]).max(), 1e-300)
        # the base: the homogeneous field; the die: its rigid translation
        np.testing.assert_allclose(u_all[k][base], u_ref, atol=1e-10 * scale, rtol=0)
        np.testing.assert_allclose(u_all[k][die], np.tile([d, -DELTA], (die.sum(), 1)),
                                   atol=1e-12 * scale, rtol=0)
        state = res["fields/slide_state"][k, :, 0]
        assert np.all(state[top] == (SLIP if sliding else STICK)), (t, state[top])
        n_force = res["relations/slide_normal/normal_force"][k, 0]
        t_force = res["relations/slide_normal/tangential_force"][k, 0]
        np.testing.assert_allclose(n_force, P * 1.0, rtol=1e-10)
        np.testing.assert_allclose(t_force, tau * 1.0, rtol=1e-10)
        if sliding:   # full slip: T = μN
            np.testing.assert_allclose(abs(t_force), MU * n_force, rtol=1e-10)
        # the slip carried across facets: the base top relative to the die
        np.testing.assert_allclose(res["fields/slide_slip"][k, top, 0],
                                   u_ref[top[base]][:, 0] - d, atol=1e-10 * D_END, rtol=0)
        # global equilibrium: the held nodes' reactions balance (the side loads cancel)
        total = res["relations/ground/resultant"][k] + res["relations/drag/resultant"][k] \
            + res["relations/press/resultant"][k]
        np.testing.assert_allclose(total[:2], 0.0, atol=1e-10 * P)
        slid.append(sliding)
    assert not slid[0] and slid[-1]
    assert D_END > 3 * 0.125
    print("iterations per step:", list(res["steps/iterations"]))


# ---------------------------------------------------------------------------- ironing

IRONING = CONFIGS / "contact_ironing_2d.toml"
SLAB, DIE = MESHES.SLAB, MESHES.DIE   # configs/contact_ironing_2d.msh


def test_shipped_mesh_is_the_script_s(shared_tmp):
    """configs/contact_ironing_2d.msh is what scripts/make_ironing_2d_mesh.py writes."""
    out = shared_tmp / f"ironing_2d_{MPI.COMM_WORLD.rank}.msh"
    MESHES.base_and_die(out)
    assert out.read_text() == IRONING.with_suffix(".msh").read_text()


def true_gaps(pts: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The slaves' gaps on the deformed configuration, paired again here (independent of the
    solver's rows): die bottom nodes against the slab's top facets."""
    x = pts[:, :2] + u
    ly = SLAB[1]
    slab_top = np.flatnonzero(np.isclose(pts[:, 1], ly) & (np.arange(len(pts)) < 33 * 9))
    slab_top = slab_top[np.argsort(pts[slab_top, 0])]
    facets = np.column_stack([slab_top[1:], slab_top[:-1]])      # outward (up): right to left
    slaves = np.flatnonzero(np.isclose(pts[:, 1], ly) & (np.arange(len(pts)) >= 33 * 9))
    p = pair_nodes(x, slaves, facets, "line", 0.1)
    assert p.paired.all()
    return p.gap


def mortar_ironing() -> str:
    """The shipped 2D ironing with mortar rows."""
    base = shipped(IRONING.name)
    return build(base, mesh={"file": str(IRONING.with_suffix(".msh"))},
                 contact=[base["contact"][0] | {"discretization": "mortar"}])


@pytest.mark.parametrize("discretization", ["node_to_segment", "mortar"])
def test_ironing_2d(run, discretization):
    """configs/contact_ironing_2d.toml: a stiff die pressed into a slab and dragged by 1.5
    (12 slab facets) along it. Every step: global equilibrium (the held nodes' reactions) to
    1e-10, no penetration (gaps of the deformed configuration paired again), every node in
    the Coulomb cone; in full slip the friction is μ times the normal force (contact frame,
    1e-10); the same results on the parts of 1, 2, 3 ranks as in one process. With mortar
    rows (integrated again on the deformed configuration) the weighted gaps are what is
    enforced: they are ≥ 0 (zero where closed) and the nodes' own gaps are not (the die's
    corner node enters the slab's bent rim by up to 7 % of the press, measured)."""
    mortar = discretization == "mortar"
    text = mortar_ironing() if mortar else IRONING
    res = run(text, name=f"ironing_{discretization}")
    mu = 0.3
    pts = res["mesh/points"]
    die_bottom = np.isclose(pts[:, 1], SLAB[1]) & (np.arange(len(pts)) >= 33 * 9)
    n_force = res["relations/ironing_normal/normal_force"][:, 0]
    t_force = res["relations/ironing_normal/tangential_force"][:, 0]
    total = sum(res[f"relations/{r}/resultant"][:, :2] for r in ("ground", "die_x", "die_y"))
    np.testing.assert_allclose(total, 0.0, atol=1e-10 * n_force.max())
    state = res["fields/ironing_state"][:, die_bottom, 0]
    rn = res["fields/ironing_normal_reaction"][:, die_bottom, 0]
    rt = res["fields/ironing_tangential_reaction"][:, die_bottom, 0]
    assert np.all(rn >= -1e-12 * n_force.max())
    assert np.all(np.abs(rt) <= mu * rn + 1e-10 * n_force.max())
    full = np.array([np.all(s[s != OPEN] == SLIP) and np.any(s == SLIP) for s in state])
    # no penetration, on the deformed configuration paired again: exact while the die slides
    # (the rows' fixed point); while it is pressed, its corner node sits in the kink of the
    # indentation and, held to one facet, crosses the vertex by ~1e-6 into the other one
    # (node-to-segment at a concave vertex: the limit said in docs/contact.md §8)
    worst = np.array([true_gaps(pts, u).min() for u in res["fields/displacement"]])
    if mortar:
        assert res["fields/ironing_gap"][:, die_bottom, 0].min() >= -1e-12 * 0.01
        assert np.all(worst >= -0.1 * 0.01), worst
        assert res["steps/iterations"].max() <= 10
    else:
        assert np.all(worst[full] >= -1e-12 * 0.01), worst              # δ = 0.01
        assert np.all(worst >= -1e-5 * 0.01), worst
        # the geometric stiffness (contact.geometry) makes the sliding steps' iterations
        # converge quadratically: 4–8 per step (10–13 without, a linear rate of ~0.08)
        assert res["steps/iterations"].max() <= 8
    assert full[-1] and full.sum() >= 10
    np.testing.assert_allclose(np.abs(t_force[full]), mu * n_force[full], rtol=1e-10)
    drag = -res["relations/die_x/resultant"][:, 0]
    press = res["relations/die_y/resultant"][:, 1]
    print("iterations per step:", list(res["steps/iterations"]))
    print("drag / (mu press) in full slip:", (drag[full] / (mu * press[full])).round(6))
    print("smallest true gap per step:", worst)
    if MPI.COMM_WORLD.size > 1:
        serial = run(text, name=f"ironing_{discretization}_serial", comm=MPI.COMM_SELF)
        assert_same_results(res, serial)


@pytest.mark.parametrize("edit, words", [
    ({"sliding": "finite"}, None),
    ({"sliding": "large"}, "must be one of"),
    ({"sliding": "finite", "discretization": "mortar"}, None),
])
def test_bad_sliding_names_file_and_key(shared_tmp, mesh, edit, words):
    """``sliding``: "small" (default) or "finite" (a master region, either discretization);
    anything else: exit 2 naming the file and the key."""
    text = scene(mesh, **edit)
    path = shared_tmp / "bad_sliding.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.Barrier()
    if words is None:
        assert load_scene(path).effect_specs["contact"][0].sliding == "finite"
        return
    with pytest.raises(InputError) as err:
        load_scene(path)
    assert err.value.key == "contact[0].sliding" and str(path) in str(err.value)
    assert words in err.value.message


def test_spans_made_again_with_a_step_cut(run, monkeypatch):
    """The shipped ironing in ten steps of at most seven iterations: the steps to t = 0.25 and
    0.3 fail and are cut, their parts retried from the committed state. With a radius of
    0.1 the spans are made again inside the failed attempts too (kept for the retries: they
    are a superset, not a state); with 4.5 (the whole slab) never. The same cuts and
    iterations, the same answers (1e-10)."""
    import parsolve.effects.contact_sliding as sliding
    from parsolve.solvers.newton import NewtonSolver

    base = shipped(IRONING.name)

    def ironing(radius: float) -> str:
        return build(base, mesh={"file": str(IRONING.with_suffix(".msh"))},
                     nonlinear={"max_iterations": 7}, steps={"count": 10},
                     contact=[base["contact"][0] | {"search_radius": radius}])

    ref = run(ironing(4.5), name="cut_ref")
    attempt, failed, respanned = [None], set(), set()
    step, respan = NewtonSolver.step, sliding.respan

    def logged_step(self, t):
        attempt[0] = t
        try:
            return step(self, t)
        except SolverError:
            failed.add(t)
            raise

    monkeypatch.setattr(NewtonSolver, "step", logged_step)
    monkeypatch.setattr(sliding, "respan", lambda *a: respanned.add(attempt[0]) or respan(*a))
    res = run(ironing(0.1), name="cut_respan")
    assert ref["steps/cuts"].sum() >= 2 and np.all(ref["timings/pattern"] == 0.0)
    # spans made again in an attempt that failed (by the ranks holding the die's slaves)
    assert MPI.COMM_WORLD.allreduce(bool(failed & respanned), op=MPI.LOR)
    for key in ("steps/cuts", "steps/time", "steps/iterations", "fields/ironing_state"):
        np.testing.assert_array_equal(res[key], ref[key])
    for key in ("displacement", "ironing_normal_reaction", "ironing_tangential_reaction"):
        f, f_ref = res[f"fields/{key}"], ref[f"fields/{key}"]
        np.testing.assert_allclose(f, f_ref, atol=1e-10 * np.abs(f_ref).max(), rtol=0)


def test_a_slave_in_a_crease_is_named_when_node_to_segment_fails(run, shared_tmp):
    """The hard case of docs/contact.md §8: the shipped ironing pressed five times deeper
    (0.05), frictionless. The die's corner node ends in the concave crease the dent makes at
    the die's edge; node-to-segment holds it on one of the crease's two facets, it slides
    off into the other at each solve and Newton cannot converge (t ≈ 0.1): the failure names
    that node and the way out. Mortar rows run the same press."""
    base = shipped(IRONING.name)
    relations = [r | {"value": -0.05} if r["name"] == "die_y" else r for r in base["relations"]]

    def pressed(discretization: str) -> str:
        return build(base, mesh={"file": str(IRONING.with_suffix(".msh"))}, relations=relations,
                     steps={"count": 4, "end": 0.2}, nonlinear={"max_iterations": 12},
                     contact=[base["contact"][0] | {"friction": 0.0,
                                                    "discretization": discretization}])

    res = run(pressed("mortar"), name="crease_mortar")
    assert res["attrs"]["status"] == "complete"
    with pytest.raises(SolverError) as err:
        run(pressed("node_to_segment"), name="crease_nts")
    pts = res["mesh/points"]
    die_bottom = np.flatnonzero(np.isclose(pts[:, 1], SLAB[1]) & (np.arange(len(pts)) >= 33 * 9))
    corner = die_bottom[np.argmin(pts[die_bottom, 0])]
    message = str(err.value)
    assert re.search(rf"\.toml: contact\[0\]: slave node\(s\) {corner} \(\d+ times\) went "
                     "back and forth between two master facets until the end", message)
    assert 'discretization = "mortar" handles it' in message      # (the scene's file and key)
    # a failure with no slave going back and forth says nothing of it (two iterations at
    # most: the press's first step fails)
    with pytest.raises(SolverError) as err:
        run(build(base, mesh={"file": str(IRONING.with_suffix(".msh"))},
                  nonlinear={"max_iterations": 2}), name="crease_none")
    assert "back and forth" not in str(err.value)


def test_frictionless_ironing_is_the_die_placed_there(run, shared_tmp):
    """Frictionless, the answer does not depend on the path: the die dragged by 1.5625 over
    twelve and a half facets of the deformed slab (finite sliding) ends where a die placed
    there from the start and only pressed ends (the same displacements to 1e-9, the die's
    shifted by its travel; the same contact forces). Small sliding keeps the first pairings
    and does not."""
    travel = 1.5625
    moved = shared_tmp / "ironing_placed.msh"
    if MPI.COMM_WORLD.rank == 0:
        base_and_die(moved, SLAB, DIE[:4] + (DIE[4] + travel,))
    MPI.COMM_WORLD.Barrier()
    base = shipped(IRONING.name)
    assert base["contact"][0]["friction"] == 0.3 and base["contact"][0]["sliding"] == "finite"

    def ironing(drag: float, mesh_file, sliding: str = "finite") -> str:
        """The shipped ironing, frictionless, the die dragged by ``drag`` (shipped: 1.5)."""
        relations = [r | {"value": drag} if r["name"] == "die_x" else r for r in base["relations"]]
        assert [r["value"] for r in base["relations"] if r["name"] == "die_x"] == [1.5]
        return build(base, mesh={"file": str(mesh_file)}, relations=relations,
                     contact=[base["contact"][0] | {"friction": 0.0, "sliding": sliding}])

    dragged = run(ironing(travel, IRONING.with_suffix(".msh")), name="ironing_free")
    placed = run(ironing(0.0, moved), name="ironing_placed")
    u_d, u_p = dragged["fields/displacement"][-1], placed["fields/displacement"][-1]
    die = np.arange(len(u_d)) >= 33 * 9
    shift = np.where(die[:, None], [travel, 0.0], 0.0)
    np.testing.assert_allclose(u_d, u_p + shift, atol=1e-9 * np.abs(u_p).max(), rtol=0)
    rn_d = dragged["fields/ironing_normal_reaction"][-1, die, 0]
    rn_p = placed["fields/ironing_normal_reaction"][-1, die, 0]
    np.testing.assert_allclose(rn_d, rn_p, atol=1e-9 * rn_p.max(), rtol=0)
    small = run(ironing(travel, IRONING.with_suffix(".msh"), "small"), name="ironing_small")
    off = np.abs(small["fields/displacement"][-1] - u_p - shift).max() / np.abs(u_p).max()
    print("dragged vs placed:", np.abs(u_d - u_p - shift).max() / np.abs(u_p).max(),
          "small sliding vs placed:", off, "iterations:", list(dragged["steps/iterations"]))
    assert off > 1e-3


@pytest.mark.parametrize("mu, discretization, radius", [
    (0.0, "node_to_segment", None), (0.3, "node_to_segment", None), (0.3, "mortar", None),
    (0.3, "node_to_segment", 0.3), (0.3, "mortar", 0.3)])
def test_die_dragged_onto_the_slab_from_an_overhang_is_the_die_placed_there(
        run, shared_tmp, mu, discretization, radius):
    """A slave that no facet faces at the start is kept (within the search radius of one) and
    gets its row when a facet faces it: the shipped ironing's die starting at x = −0.2 (its
    two left bottom nodes past the slab's end; with mortar rows, the leftmost one, the other's
    facet overlapping the slab), lifted off by 0.001, dragged by 0.5 onto the slab, then
    pressed by 0.01 (μ = 0 and 0.3), ends as a die placed at x = 0.3 and pressed: the same
    displacements (the die's shifted by 0.5) and contact forces to 1e-9, every bottom node of
    the die closed, none inside the slab (mortar: no weighted gap below zero). Those nodes'
    gaps are reported as inf while no facet faces them. With a search radius of 0.3 rather
    than the shipped 1.6 the spans are made again on the way (the same answers)."""
    mortar = discretization == "mortar"
    base = shipped(IRONING.name)
    meshes = {}
    for name, x0 in (("overhang", -0.2), ("placed", 0.3)):
        meshes[name] = shared_tmp / f"ironing_{name}.msh"
        if MPI.COMM_WORLD.rank == 0:
            base_and_die(meshes[name], SLAB, DIE[:4] + (x0,))
    MPI.COMM_WORLD.Barrier()
    evolutions = {"press": {"times": [0.0, 0.1, 0.6, 1.0], "values": [0.0, -0.1, -0.1, 1.0]},
                  "drag": {"times": [0.0, 0.1, 0.6, 1.0], "values": [0.0, 0.0, 1.0, 1.0]}}

    def ironing(mesh_file, drag: float) -> str:
        relations = [r | {"value": drag} if r["name"] == "die_x" else r for r in base["relations"]]
        return build(base, mesh={"file": str(mesh_file)}, relations=relations,
                     evolutions=evolutions, steps={"count": 10},
                     contact=[base["contact"][0] | {"friction": mu,
                                                    "discretization": discretization}
                              | ({} if radius is None else {"search_radius": radius})])

    tag = f"{mu}_{discretization}_{radius}"
    dragged = run(ironing(meshes["overhang"], 0.5), name=f"ironing_overhang_{tag}")
    placed = run(ironing(meshes["placed"], 0.0), name=f"ironing_overhang_placed_{tag}")
    pts = dragged["mesh/points"]
    die = np.arange(len(pts)) >= 33 * 9
    bottom = die & np.isclose(pts[:, 1], SLAB[1])
    gap0 = dragged["fields/ironing_gap"][0, bottom, 0]
    past = pts[bottom, 0] < (-0.1 if mortar else 0.0)
    assert np.isinf(gap0).sum() == (1 if mortar else 2) and np.all(np.isinf(gap0) == past)
    u_d, u_p = dragged["fields/displacement"][-1], placed["fields/displacement"][-1]
    shift = np.where(die[:, None], [0.5, 0.0], 0.0)
    np.testing.assert_allclose(u_d, u_p + shift, atol=1e-9 * np.abs(u_p).max(), rtol=0)
    for field in ("normal_reaction", "tangential_reaction"):
        f_d = dragged[f"fields/ironing_{field}"][-1, die, 0]
        f_p = placed[f"fields/ironing_{field}"][-1, die, 0]
        np.testing.assert_allclose(f_d, f_p, atol=1e-9 * np.abs(f_p).max(), rtol=0)
    assert np.all(dragged["fields/ironing_state"][-1, bottom, 0] != OPEN)
    if mortar:
        assert dragged["fields/ironing_gap"][-1, bottom, 0].min() >= -1e-12 * 0.01
    else:
        assert true_gaps(pts, u_d).min() >= -1e-12 * 0.01
    if radius is not None:
        assert np.count_nonzero(dragged["timings/pattern"]) >= 1
    print("iterations per step:", list(dragged["steps/iterations"]))


def test_overhanging_die_pressed_in_place(run, shared_tmp):
    """The same die lifted off and pressed where it starts, 0.2 past the slab's end (μ = 0.3,
    no drag): the
    two nodes past the end stay uncovered (gap inf, no force) and the others carry the press
    (global equilibrium 1e-10, the press's reaction their normal force; none inside the slab,
    1e-12 of the press): the waiting rows change nothing, in particular not
    the active set's gap tolerance (a press of 5e-4, a twentieth of the shipped one, is seen)."""
    base = shipped(IRONING.name)
    mesh = shared_tmp / "ironing_overhang_pressed.msh"
    if MPI.COMM_WORLD.rank == 0:
        base_and_die(mesh, SLAB, DIE[:4] + (-0.2,))
    MPI.COMM_WORLD.Barrier()
    relations = [r | {"value": 0.0} if r["name"] == "die_x" else
                 r | {"value": -5e-4} if r["name"] == "die_y" else r for r in base["relations"]]
    # lifted off by 0.001 (every row open), then pressed 5e-4 past touching
    res = run(build(base, mesh={"file": str(mesh)}, relations=relations, steps={"count": 4},
                    evolutions={"press": {"times": [0.0, 0.5, 1.0], "values": [0.0, -2.0, 1.0]},
                                "drag": {"times": [0.0, 1.0], "values": [0.0, 0.0]}}),
              name="ironing_overhang_pressed")
    pts = res["mesh/points"]
    die = np.arange(len(pts)) >= 33 * 9
    bottom = np.flatnonzero(die & np.isclose(pts[:, 1], SLAB[1]))
    past = pts[bottom, 0] < 0.0
    assert past.sum() == 2
    assert np.all(np.isinf(res["fields/ironing_gap"][:, bottom[past], 0]))
    rn = res["fields/ironing_normal_reaction"][:, bottom, 0]
    assert np.all(rn[:, past] == 0.0) and np.all(rn[:2] == 0.0) and np.all(rn[-1, ~past] > 0.0)
    n_force = res["relations/ironing_normal/normal_force"][-1, 0]
    total = sum(res[f"relations/{r}/resultant"][-1, :2] for r in ("ground", "die_x", "die_y"))
    np.testing.assert_allclose(total, 0.0, atol=1e-10 * n_force)
    # the press carried by the contact (its normals tilted by the slab's dent: 1e-4)
    np.testing.assert_allclose(n_force, -res["relations/die_y/resultant"][-1, 1], rtol=1e-3)
    x = pts[:, :2] + res["fields/displacement"][-1]
    slab_top = np.flatnonzero(np.isclose(pts[:, 1], SLAB[1]) & ~die)
    slab_top = slab_top[np.argsort(pts[slab_top, 0])]
    facets = np.column_stack([slab_top[1:], slab_top[:-1]])
    p = pair_nodes(x, bottom[~past], facets, "line", 0.1)
    assert p.paired.all() and p.gap.min() >= -1e-12 * 5e-4


@pytest.mark.petsc_events
@pytest.mark.parametrize("discretization", ["node_to_segment", "mortar"])
@pytest.mark.parametrize("radius", [0.3, 0.1])
@pytest.mark.parametrize("mu", [MU, 0.0])
def test_spans_made_again_as_the_slaves_leave_them(run, mesh, discretization, radius, mu,
                                                   monkeypatch):
    """The rows span the facets within search_radius of the slave when their span was made:
    the die dragged by 0.55 with a radius of 0.3 or 0.1 (less than a die facet, 0.125)
    carries the slaves out of their spans, which are then made again around the current
    configuration and the operator built again on the new pattern (/timings/pattern: some
    steps spend time there), the direct solver analysing each operator it is given once
    (PETSc's symbolic factorizations: one per operator; numeric: one per iteration). The
    answers are those of spans that never change (radius 2.5, the whole die: one pattern):
    displacements and contact forces to 1e-10, the same states and iterations; with
    friction (LU) and without (the normal rows alone)."""
    from parsolve.solvers.linear import LinearSolver

    ref = run(scene(mesh, discretization=discretization, friction=mu, search_radius=2.5),
              name=f"span_ref_{discretization}_{mu}")
    built, given = [], []
    restructure, set_operator = SaddleSystem.restructure, LinearSolver.set_operator
    monkeypatch.setattr(SaddleSystem, "restructure",
                        lambda self: built.append(1) or restructure(self))
    monkeypatch.setattr(LinearSolver, "set_operator",
                        lambda self, mat: given.append(1) or set_operator(self, mat))
    events = [PETSc.Log.Event(f"Mat{k}") for k in ("LUFactorSym", "CholFctrSym",
                                                   "LUFactorNum", "CholFctrNum")]
    before = [int(e.getPerfInfo()["count"]) for e in events]
    res = run(scene(mesh, discretization=discretization, search_radius=radius, friction=mu),
              name=f"span_{discretization}_{radius}_{mu}")
    counts = np.subtract([int(e.getPerfInfo()["count"]) for e in events], before)
    assert np.all(ref["timings/pattern"] == 0.0)
    assert np.count_nonzero(res["timings/pattern"]) >= (2 if radius < 0.125 else 1)
    # every operator built is given to the solver, but one built at a step's last iterate
    assert len(built) >= len(given) - 1 >= np.count_nonzero(res["timings/pattern"]) - 1
    assert counts[:2].sum() == len(given)
    assert counts[2:].sum() == res["steps/iterations"].sum()
    u, u_ref = res["fields/displacement"], ref["fields/displacement"]
    np.testing.assert_allclose(u, u_ref, atol=1e-10 * np.abs(u_ref).max(), rtol=0)
    for key in ("slide_normal_reaction", "slide_tangential_reaction"):
        if f"fields/{key}" in ref:
            f, f_ref = res[f"fields/{key}"], ref[f"fields/{key}"]
            np.testing.assert_allclose(f, f_ref, atol=1e-10 * np.abs(f_ref).max(), rtol=0)
    assert np.abs(res["fields/slide_normal_reaction"]).max() > 0.0
    np.testing.assert_array_equal(res["fields/slide_state"], ref["fields/slide_state"])
    np.testing.assert_array_equal(res["steps/iterations"], ref["steps/iterations"])




def test_shared_surfaces_are_refused(run, shared_tmp):
    """A slave region whose nodes lie in the master's facets (the same region named twice) is
    an input error naming the contact's master key, on every rank whichever owns them."""
    base = shipped(IRONING.name)
    text = build(base, mesh={"file": str(IRONING.with_suffix(".msh"))},
                 contact=[base["contact"][0] | {"slave": "base_top"}])
    with pytest.raises(InputError) as err:
        run(text, name="shared_surfaces")
    message = str(err.value)
    assert re.search(r"master and slave surfaces share \d+ node\(s\) \(first: \d+\)", message)
    assert "contact[0].master" in message, message
