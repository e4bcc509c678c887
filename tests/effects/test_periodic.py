"""The periodic relation: each node of a region tied to the node of a target region at its
position + a translation (u_a - u_b = 0 per component, associated). The shipped laminate
cell in simple shear gives the laminate's exact answer (the tie is what makes it
homogeneous along x) on the parts as alone; a node without a partner is an input error
naming the file and the key. Run at 1, 2 and 3 ranks."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from conftest import CONFIGS, assert_same_results
from helpers.laminate import U, check_laminate, laminate_ux
from helpers.scene import DROP, merge, scene, shipped
from parsolve.errors import InputError
from parsolve.model import build_model
from parsolve.scene import load_scene

def test_laminate_cell_on_parts_and_alone(run):
    parts = run(CONFIGS / "periodic_shear_laminate.toml", name="laminate_parts")
    check_laminate(parts)
    alone = run(CONFIGS / "periodic_shear_laminate.toml", name="laminate_alone",
                comm=MPI.COMM_SELF)
    assert_same_results(parts, alone, tol=1e-10)


LAMINATE = shipped("periodic_shear_laminate.toml")


def laminate(**edits: dict) -> str:
    """The shipped laminate with keys of the relations named by ``edits`` replaced (``DROP``
    removes a key): ``laminate(cell={"target": DROP})``."""
    assert set(edits) <= {r["name"] for r in LAMINATE["relations"]}
    return scene(LAMINATE, relations=[merge(r, edits.get(r["name"], {})) for r in LAMINATE["relations"]])


def test_without_the_tie_the_cell_is_not_homogeneous(run):
    """The control: the same cell without the periodic relation is far from the laminate."""
    assert LAMINATE["relations"][-1]["name"] == "cell" and LAMINATE["steps"] == {"count": 1}
    text = scene(LAMINATE, relations=LAMINATE["relations"][:-1])
    res = run(text, name="laminate_untied")
    y = res["mesh/points"][:, 1]
    assert np.abs(res["fields/displacement"][-1][:, 0] - laminate_ux(y)).max() > 1e-2 * U


def test_a_node_without_partner_is_an_input_error(shared_tmp):
    text = laminate(cell={"translation": [1.0, 0.03]})
    path = shared_tmp / "periodic_lost.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.Barrier()
    with pytest.raises(InputError) as exc:
        build_model(load_scene(path), MPI.COMM_WORLD)
    assert exc.value.source == str(path) and exc.value.key == "relations[3].target"
    assert "has no node of region 'right_side'" in exc.value.message


@pytest.mark.parametrize("key, value, message", [
    ("translation", [1.0], "expected 2 numbers"),
    ("value", 1.0, "has no value"),
    ("target", DROP, "missing required key"),
])
def test_scene_keys(shared_tmp, key, value, message):
    text = laminate(cell={key: value})
    path = shared_tmp / f"periodic_{key}.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.Barrier()
    with pytest.raises(InputError) as exc:
        load_scene(path)
    assert exc.value.key == f"relations[3].{key}" and message in exc.value.message


WHOLE_SIDES = {"region": "left", "target": "right"}   # the tie of the whole sides, corners included


def test_held_corners_are_left_out_of_the_tie(run):
    """Tying the whole sides: the corners' rows join DOFs that the top and bottom conditions
    hold to the same values; they are dropped (14 rows, not 18) and the answer is the
    laminate's."""
    res = run(laminate(cell=WHOLE_SIDES), name="laminate_corners")
    check_laminate(res)


def test_held_corners_that_disagree_are_an_input_error(shared_tmp):
    text = laminate(cell=WHOLE_SIDES, top_shear={"value": "0.01 * x"})
    path = shared_tmp / "periodic_clash.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.Barrier()
    with pytest.raises(InputError) as exc:
        build_model(load_scene(path), MPI.COMM_WORLD)
    assert exc.value.key == "relations[3].region" and "different values" in exc.value.message


CUBE = """
[mesh]
generator = "box"
lx = 1.0
ly = 1.0
lz = 1.0
nx = 2
ny = 3
nz = 2
cell = "{cell}"
[model]
hypothesis = "3d"
[regions]
# the x tie leaves out the edge x = 0, y = 1: the y tie already joins it to the edge x = 0,
# y = 0, which the x tie joins to x = 1, y = 0 (four ties around a vertical edge would be
# one too many)
x_side = "x < 1e-9 and y < 1 - 1e-9"
[[materials]]
E = 200.0
nu = 0.3
[[relations]]
name = "base"
type = "dirichlet"
region = "zmin"
components = ["x", "y", "z"]
[[relations]]
name = "lid_x"
type = "dirichlet"
region = "zmax"
components = ["x"]
value = 0.02
[[relations]]
name = "lid_yz"
type = "dirichlet"
region = "zmax"
components = ["y", "z"]
[[relations]]
name = "tie_x"
type = "periodic"
region = "x_side"
target = "xmax"
translation = [1.0, 0.0, 0.0]
[[relations]]
name = "tie_y"
type = "periodic"
region = "ymin"
target = "ymax"
translation = [0.0, 1.0, 0.0]
"""


@pytest.mark.parametrize("cell", ["hexahedron", "tetra"])
def test_periodic_cube_in_simple_shear(run, cell):
    """A cube tied along x and y, its lid moved by 0.02 along x: simple shear u_x = 0.02 z
    exactly, the held rows of the lid and the base left out of the ties."""
    res = run(CUBE.format(cell=cell), name=f"periodic_cube_{cell}")
    pts, u = res["mesh/points"], res["fields/displacement"][-1]
    np.testing.assert_allclose(u[:, 0], 0.02 * pts[:, 2], rtol=0, atol=1e-14)
    np.testing.assert_allclose(u[:, 1:], 0.0, atol=1e-14)
    # σ_xz = G γ alone: no tie carries x or y forces; the x tie carries the shear force of
    # the rows of xmax left at z = 1/2 (y = 0, 1/3, 2/3; the edge y = 0 also takes, through
    # the y tie, the edge y = 1's), the y tie only the edge's ± G γ / 12 (hexahedra: the
    # tributary areas of a uniform traction)
    Gg = 200.0 / 2.6 * 0.02
    lam_x = res["relations/tie_x/multiplier"][-1].reshape(-1, 3)
    lam_y = res["relations/tie_y/multiplier"][-1].reshape(-1, 3)
    np.testing.assert_allclose(lam_x[:, :2], 0.0, atol=1e-12)
    np.testing.assert_allclose(lam_y[:, :2], 0.0, atol=1e-12)
    if cell == "hexahedron":
        np.testing.assert_allclose(lam_x[:, 2], Gg / 6, rtol=1e-12)
        np.testing.assert_allclose(np.sort(lam_y[:, 2]), [-Gg / 12, 0.0, Gg / 12], atol=1e-12)


CELL = LAMINATE["relations"][-1]
REPEATED_TIES = {  # a second relation -> the words of the refusal
    "the same tie twice": (merge(CELL, {"name": "cell_again"}),
                           "relations 'cell' and 'cell_again' both tie"),
    "the tie both ways": (merge(CELL, {"name": "cell_back", "region": CELL["target"],
                                       "target": CELL["region"], "translation": [-1.0, 0.0]}),
                          "relations 'cell' and 'cell_back' both tie"),
}


@pytest.mark.parametrize("case", sorted(REPEATED_TIES))
def test_a_repeated_tie_is_an_input_error_naming_both(shared_tmp, case):
    """A tie given twice or both ways: each pair of DOFs twice in the system, which would be
    singular (MUMPS null pivots): refused before any solve, naming both relations."""
    extra, words = REPEATED_TIES[case]
    text = scene(LAMINATE, relations=LAMINATE["relations"] + [extra])
    path = shared_tmp / "periodic_repeated.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.Barrier()
    with pytest.raises(InputError) as exc:
        build_model(load_scene(path), MPI.COMM_WORLD)
    assert exc.value.source == str(path) and exc.value.key == "relations[4]"
    # the first pair: u.x of the lowest side node (0, 1/8), 7 on rows of 7 nodes, and (1, 1/8)
    assert words in exc.value.message and "u.x of nodes 7 and 13" in exc.value.message, \
        exc.value.message
    n = len(CELL["components"]) * 7   # the left side's 7 nodes (ny = 8, corners left out)
    assert f"({n} such pairs" in exc.value.message, exc.value.message
