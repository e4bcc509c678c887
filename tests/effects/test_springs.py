"""Discrete springs ([[springs]]): node to ground and node to node, a stiffness per component,
2D and 3D, against closed forms (ν = 0: a bar is a chain of springs, exactly): a bar held at
one end on a spring at the other (parallel, u = F / (EA/L + k)), a bar held only by springs
(series, u = F/k + F L/EA), two nodes coupled across a segment, each axis of a 3D bar with
the other components' stiffnesses in play; the same results on the parts as alone; the
effect keeps the scene symmetric; input errors name the file and the key. 1, 2, 3 ranks."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from conftest import CONFIGS, assert_same_results
from parsolve.errors import InputError
from parsolve.loads.base import Instant
from parsolve.model import build_model
from parsolve.scene import load_scene

E, F = 100.0, 1.0

BAR_2D = """
[mesh]
generator = "rectangle"
lx = {L}
ly = 1.0
nx = {n}
ny = 1
cell = "quad"
[model]
hypothesis = "plane_stress"
[regions]
section = "abs(x - {x_c}) < 1e-9"
[[materials]]
E = 100.0
nu = 0.0
[[loads]]
name = "pull"
region = "right"
total_force = [1.0, 0.0]
{rest}
"""

CLAMP = """
[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x", "y"]
"""


def ux_at(res: dict, x: float) -> np.ndarray:
    pts = res["mesh/points"]
    return res["fields/displacement"][-1][np.isclose(pts[:, 0], x), 0]


def test_parallel_spring_to_ground(run):
    """Held at x = 0, a spring k per node of the loaded end (2 nodes): u(L) = F / (EA/L + 2k),
    linear along the bar."""
    L, k = 4.0, 6.0
    rest = CLAMP + """
[[springs]]
region = "right"
stiffness = [6.0, 0.0]
"""
    res = run(BAR_2D.format(L=L, n=4, x_c=3.0, rest=rest), name="springs_parallel")
    u_end = F / (E * 1.0 / L + 2 * k)
    np.testing.assert_allclose(ux_at(res, L), u_end, rtol=1e-12)
    pts, u = res["mesh/points"], res["fields/displacement"][-1]
    np.testing.assert_allclose(u[:, 0], u_end * pts[:, 0] / L, rtol=0, atol=1e-14)
    np.testing.assert_allclose(u[:, 1], 0.0, atol=1e-14)
    # the springs' force on each node (zero off their region); the clamp carries the rest
    force = res["fields/springs0_force"][-1]
    end = np.isclose(pts[:, 0], L)
    np.testing.assert_allclose(force[end], [[-k * u_end, 0.0]] * 2, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(force[~end], 0.0, atol=0)
    np.testing.assert_allclose(res["relations/clamp/resultant"][-1][0], -(F - 2 * k * u_end),
                               rtol=1e-12)


def test_series_springs_hold_the_bar(run):
    """Held along x only by springs k per node at x = 0: the springs and the bar in series,
    u(0) = F / 2k, u(L) = F / 2k + F L / EA."""
    L, k = 4.0, 2.5
    rest = """
[[relations]]
name = "guide"
type = "dirichlet"
region = "left"
components = ["y"]
[[springs]]
region = "left"
stiffness = [2.5, 0.0]
"""
    res = run(BAR_2D.format(L=L, n=4, x_c=3.0, rest=rest), name="springs_series")
    np.testing.assert_allclose(ux_at(res, 0.0), F / (2 * k), rtol=1e-12)
    np.testing.assert_allclose(ux_at(res, L), F / (2 * k) + F * L / E, rtol=1e-12)


def test_two_nodes_coupled_across_a_segment(run):
    """Springs k_c from each node of x = 3 to its neighbour at x = 4 (translation (1, 0)),
    parallel to the last segment: u(3) = F / (EA/3), u(4) = u(3) + F / (EA/1 + 2 k_c)."""
    kc = 7.0
    rest = CLAMP + """
[[springs]]
name = "brace"
region = "section"
target = "right"
translation = [1.0, 0.0]
stiffness = [7.0, 4.0]
"""
    res = run(BAR_2D.format(L=4.0, n=4, x_c=3.0, rest=rest), name="springs_coupled")
    u3 = F / (E / 3.0)
    np.testing.assert_allclose(ux_at(res, 3.0), u3, rtol=1e-12)
    np.testing.assert_allclose(ux_at(res, 4.0), u3 + F / (E + 2 * kc), rtol=1e-12)
    # equal and opposite on the two ends of each spring, named by the scene
    force = res["fields/brace_force"][-1]
    x = res["mesh/points"][:, 0]
    np.testing.assert_allclose(force[np.isclose(x, 3.0), 0], kc * F / (E + 2 * kc), rtol=1e-12)
    np.testing.assert_allclose(force[np.isclose(x, 4.0), 0], -kc * F / (E + 2 * kc), rtol=1e-12)
    np.testing.assert_allclose(force[:, 1], 0.0, atol=1e-14)
    np.testing.assert_allclose(force[(x < 2.5)], 0.0, atol=0)


def network(res: dict) -> None:
    """The shipped scene's two-spring network, solved by hand."""
    ea, kg, kc = E * 1.0, 5.0, 7.0
    k1, k2 = ea / 3.0, ea / 1.0 + 2 * kc
    u3, u4 = np.linalg.solve([[k1 + k2, -k2], [-k2, k2 + 2 * kg]], [0.0, F])
    np.testing.assert_allclose(ux_at(res, 3.0), u3, rtol=1e-12)
    np.testing.assert_allclose(ux_at(res, 4.0), u4, rtol=1e-12)
    pts, u = res["mesh/points"], res["fields/displacement"][-1]
    x = pts[:, 0]
    np.testing.assert_allclose(u[:, 0], np.where(x <= 3.0, u3 * x / 3.0, u3 + (u4 - u3) * (x - 3.0)),
                               rtol=0, atol=1e-14)
    np.testing.assert_allclose(u[:, 1], 0.0, atol=1e-14)


def test_shipped_scene_on_parts_and_alone(run):
    parts = run(CONFIGS / "springs_bar_supports.toml", name="springs_parts")
    network(parts)
    alone = run(CONFIGS / "springs_bar_supports.toml", name="springs_alone", comm=MPI.COMM_SELF)
    assert_same_results(parts, alone, tol=1e-10)


def test_springs_keep_the_scene_symmetric():
    model = build_model(load_scene(CONFIGS / "springs_bar_supports.toml"))
    assert model.symmetric() and not model.nonlinear
    assert "springs" in model.scene.effects


BAR_3D = """
[mesh]
generator = "box"
lx = {lx}
ly = {ly}
lz = {lz}
nx = {nx}
ny = {ny}
nz = {nz}
[model]
hypothesis = "3d"
[[materials]]
E = 100.0
nu = 0.0
[[loads]]
name = "pull"
region = "{end}"
total_force = {force}
[[relations]]
name = "clamp"
type = "dirichlet"
region = "{start}"
components = ["x", "y", "z"]
[[springs]]
region = "{end}"
stiffness = {stiffness}
[[springs]]
region = "{start}"
target = "{end}"
translation = {translation}
stiffness = {stiffness}
"""


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_3d_bar_along_each_axis(run, axis):
    """A 3D bar (L = 2 along the axis, one cell across: its end nodes take equal shares)
    pulled by F along the axis, clamped at its start, its 4 end nodes on springs to the
    ground and, in a 1-cell bar, each start node coupled to its end node: the springs'
    other components (stiffer, unloaded) do nothing, u(L) = F / (EA/L + 4 k)."""
    L, k = 2.0, 3.0
    names = "xyz"
    dims = {f"l{c}": (L if i == axis else 1.0) for i, c in enumerate(names)}
    counts = {f"n{c}": 1 for c in names}
    force = [0.0, 0.0, 0.0]
    force[axis] = F
    stiffness = [20.0, 30.0, 40.0]
    stiffness[axis] = k
    translation = [0.0, 0.0, 0.0]
    translation[axis] = L
    text = BAR_3D.format(**dims, **counts, end=f"{names[axis]}max", start=f"{names[axis]}min",
                         force=force, stiffness=stiffness, translation=translation)
    res = run(text, name=f"springs_3d_{axis}")
    pts, u = res["mesh/points"], res["fields/displacement"][-1]
    end = np.isclose(pts[:, axis], L)
    # ground springs (4 k) and node-to-node ones between clamped start and end (4 k more)
    expected = F / (E * 1.0 / L + 8 * k)
    np.testing.assert_allclose(u[end, axis], expected, rtol=1e-12)
    others = [c for c in range(3) if c != axis]
    np.testing.assert_allclose(u[:, others], 0.0, atol=1e-14)


def check_error(shared_tmp, text: str, key: str, words: str) -> None:
    path = shared_tmp / "springs_bad.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.Barrier()
    with pytest.raises(InputError) as exc:
        build_model(load_scene(path), MPI.COMM_WORLD)
    assert exc.value.source == str(path) and exc.value.key == key, exc.value.oneline()
    assert words in exc.value.message, exc.value.message


@pytest.mark.parametrize("change, key, words", [
    (("stiffness = [5.0, 0.0]", "stiffness = [5.0]"), "springs[0].stiffness", "expected 2 numbers"),
    (("stiffness = [5.0, 0.0]", "stiffness = [-5.0, 1.0]"), "springs[0].stiffness", ">= 0"),
    (("stiffness = [5.0, 0.0]", "stiffness = [0.0, 0.0]"), "springs[0].stiffness", "> 0"),
    (("translation = [1.0, 0.0]", "translation = [1.0, 0.5]"), "springs[1].target",
     "has no node of region 'right'"),
    (("translation = [1.0, 0.0]", "translation = [0.0, 0.0]"), "springs[1].target",
     "has no node of region 'right'"),
    (('target = "right"\n', ""), "springs[1].translation", "'target'"),
    (('region = "right"            #', 'region = "nowhere"            #'), "springs[0].region",
     "unknown region"),
    (('region = "right"            #', 'name = "a b"\nregion = "right"  #'), "springs[0].name",
     "plain name"),
])
def test_input_errors(shared_tmp, change, key, words):
    text = (CONFIGS / "springs_bar_supports.toml").read_text()
    assert change[0] in text
    check_error(shared_tmp, text.replace(change[0], change[1], 1), key, words)


def test_springs_need_a_displacement(shared_tmp):
    text = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 2
ny = 2
[model]
dimension = 2
[[diffusion]]
field = "h"
[[diffusion.materials]]
conductivity = 1.0
[[springs]]
region = "right"
stiffness = [1.0, 1.0]
"""
    check_error(shared_tmp, text, "springs[0]", "[[materials]]")


def test_the_springs_are_one_declared_term():
    """The springs are a term on node tuples (a node to the ground, or a pair): symmetric
    [[K, −K], [−K, K]] blocks whose product with any u is K (u_a − u_b) on a and its opposite
    on b (K u_a to the ground), the springs' own law; the element product a θ-scheme step
    asks of the blocks (``Composition.product``) is the same."""
    from parsolve.effects.compose import Composition
    from parsolve.effects.springs import Springs
    from parsolve.fem.element_matrices import TermMatrices

    model = build_model(load_scene(CONFIGS / "springs_bar_supports.toml"))
    cells = np.arange(model.mesh.num_cells)
    u = np.random.default_rng(3).normal(size=(model.mesh.num_points, 2))
    springs = [e for e in model.effects if isinstance(e, Springs)]
    assert springs
    for effect in springs:
        (term, m), = effect.linear_values(cells)
        assert isinstance(m, TermMatrices) and m.term is term and term in effect.terms()
        assert term.test == term.trial == "u" and not term.on_cells
        k = effect.k
        a, b = effect.pairs[:, 0], effect.pairs[:, 1]
        expected = np.zeros_like(u)
        if effect.spec.target is None:
            np.add.at(expected, a, k * u[a])
        else:
            np.add.at(expected, a, k * (u[a] - u[b]))
            np.add.at(expected, b, k * (u[b] - u[a]))
        forces, = effect.evaluate(cells, {"u": u}, None, False, Instant(1.0))[0]["u"]
        got = np.zeros_like(u)
        np.add.at(got, forces.nodes.ravel(), forces.values.reshape(-1, 2))
        np.testing.assert_allclose(got, expected, rtol=1e-14, atol=1e-14)
        V = m.values                                    # (4, m, m, k): symmetric blocks
        mm = V.shape[1]
        np.testing.assert_array_equal(V, V.reshape(2, 2, mm, mm, -1).transpose(1, 0, 3, 2, 4)
                                      .reshape(V.shape))
    composition = Composition(model, cells)
    blocks = [v for e in springs for v in e.linear_values(cells)]
    product = composition.product(blocks, u.ravel()).reshape(u.shape)
    total = np.zeros_like(u)
    for effect in springs:
        forces, = effect.evaluate(cells, {"u": u}, None, False, Instant(1.0))[0]["u"]
        np.add.at(total, forces.nodes.ravel(), forces.values.reshape(-1, 2))
    np.testing.assert_allclose(product, total, rtol=1e-14, atol=1e-14)


TWO_BODIES = """
[mesh]
file = "{mesh}"
[model]
hypothesis = "plane_stress"
[regions]
origin = {{ point = [0.0, 0.0] }}
bottom1 = "y == 0"
top2 = "y == 2.5"
inner1 = "y == 1 and x > 0 and x < 6"
ends1 = "y == 1 and (x == 0 or x == 6)"
face2 = "y == 1.5"
[[materials]]
E = 200.0
nu = 0.0
[[loads]]
name = "pull"
region = "top2"
total_force = [0.0, 12.0]
[[relations]]
name = "bottom"
type = "dirichlet"
region = "bottom1"
components = ["y"]
[[relations]]
name = "origin"
type = "dirichlet"
region = "origin"
components = ["x"]
[[springs]]
name = "inner"
region = "inner1"
target = "face2"
translation = [0.0, 0.5]
stiffness = [{k}, {k}]
[[springs]]
name = "ends"
region = "ends1"
target = "face2"
translation = [0.0, 0.5]
stiffness = [{k2}, {k2}]
"""


def two_bodies(path) -> None:
    """Two 6 x 1 strips of 6 quads each, y in [0, 1] and [1.5, 2.5]: no node, no cell in
    common (the springs alone join them)."""
    import meshio

    x = np.arange(7.0)
    pts, quads = [], []
    for y0 in (0.0, 1.5):
        start = sum(len(p) for p in pts)
        pts.append(np.stack([np.tile(x, 2), np.repeat([y0, y0 + 1.0], 7)], axis=1))
        i = np.arange(6) + start
        quads.append(np.stack([i, i + 1, i + 8, i + 7], axis=1))
    meshio.write(str(path), meshio.Mesh(np.concatenate(pts), [("quad", np.concatenate(quads))]))


@pytest.mark.parametrize("method", ["linear", "arc_length"])
def test_two_bodies_joined_by_springs_alone(run, shared_tmp, method):
    """Facing nodes of two strips 0.5 apart joined by springs (kk per unit length: kk Δx on
    the inner nodes, kk Δx / 2 on the end ones): in series, the pulled strip's top rises by
    F h / (E L) + F / (kk L) + F h / (E L); uniform σ_yy = F / L, u_x = 0. Arc-length (the
    springs' internal forces, F = μ times the pull): the same at its last load factor μ."""
    kk, L, h = 30.0, 6.0, 1.0
    mesh = shared_tmp / "two_bodies.vtu"
    if MPI.COMM_WORLD.rank == 0:
        two_bodies(mesh)
    MPI.COMM_WORLD.Barrier()
    text = TWO_BODIES.format(mesh=mesh, k=kk, k2=kk / 2)
    if method == "arc_length":
        text += '[nonlinear]\nmethod = "arc_length"\narc_length = { pattern = "pull", ' \
                'length = 0.02 }\n[steps]\ncount = 2\n'
    res = run(text, name=f"springs_two_bodies_{method}")
    force = 12.0 * (res["steps/time"][-1] if method == "arc_length" else 1.0)
    assert force > 0
    pts, u = res["mesh/points"], res["fields/displacement"][-1]
    y = pts[:, 1]
    bar, gap = force * h / (200.0 * L), force / (kk * L)
    expected = np.where(y <= 1.0, bar * y, bar + gap + bar * (y - 1.5))
    np.testing.assert_allclose(u[:, 1], expected, rtol=0, atol=1e-12 * bar)
    np.testing.assert_allclose(u[:, 0], 0.0, atol=1e-12 * bar)
    # each spring's force: its share of F, upwards on the lower face, downwards on the upper
    f = res["fields/inner_force"][-1][:, 1] + res["fields/ends_force"][-1][:, 1]
    share = np.where(np.isclose(pts[:, 0], 0) | np.isclose(pts[:, 0], L), 0.5, 1.0) * force / L
    np.testing.assert_allclose(f, np.select([y == 1.0, y == 1.5], [share, -share], 0.0),
                               rtol=0, atol=1e-12 * force)


@pytest.mark.skipif(MPI.COMM_WORLD.size == 1, reason="a pair split over ranks needs parts")
def test_pair_split_over_ranks_is_refused(shared_tmp):
    """The bar's two ends (4 apart, no common cell) on different ranks' parts: exit 2, the
    springs' target named, the reason said."""
    text = (CONFIGS / "springs_bar_supports.toml").read_text()
    text = text.replace('region = "section"', 'region = "left"', 1) \
        .replace("translation = [1.0, 0.0]", "translation = [4.0, 0.0]")
    check_error(shared_tmp, text, "springs[1].target", "different ranks' parts")
