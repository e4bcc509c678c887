"""parsolve study, pure parts: file, grid, errors, orders, Richardson, Pareto front, expressions."""

import math

import numpy as np
import pytest

from conftest import CONFIGS
from helpers.scene import DROP, merge, shipped, write_scene
from parsolve.errors import InputError
from parsolve.study.config import load_study
from parsolve.study.convergence import error, observed_orders, richardson
from parsolve.study.expression import evaluate_expression
from parsolve.study.grid import expand
from parsolve.study.pareto import cheapest, pareto_front

STUDY = {
    "title": "bar",
    "scene": str(CONFIGS / "controlled_bar.toml"),
    "refine": {"keys": ["mesh.nx", "mesh.ny"], "levels": [1, 2, 4]},
    "vary": {"mesh.cell": ["quad", "triangle"], "solver.preset": ["direct"]},
    "quantities": [{"name": "force", "spec": "relation:control:multiplier",
                    "reference": "1e9 * 0.1 * 1e-4 / 1"}],
    "reduced": {"refine.levels": [1, 2]},
}
FORCE = STUDY["quantities"][0]


def write(tmp_path, name="study.toml", **overrides):
    """The study file (STUDY with these overrides) in tmp_path."""
    return write_scene(tmp_path / name, STUDY, **overrides)


def test_grid_multiplies_the_base_values_per_family(tmp_path):
    study = load_study(write(tmp_path))
    assert study.quantities[0].reference == pytest.approx(1e4, rel=1e-15)
    settings = expand(study)
    assert [(s.family, s.label) for s in settings] == [
        ("cell=quad", "x1"), ("cell=quad", "x2"), ("cell=quad", "x4"),
        ("cell=triangle", "x1"), ("cell=triangle", "x2"), ("cell=triangle", "x4")]
    assert settings[2].changes == {"mesh.cell": "quad", "solver.preset": "direct", "mesh.nx": 116,
                                   "mesh.ny": 12}
    assert 'cell = "triangle"' in settings[4].scene_text and "nx = 58" in settings[4].scene_text
    assert 'preset = "direct"' in settings[4].scene_text
    assert len({s.name for s in settings}) == 6
    reduced = load_study(write(tmp_path), reduced=True)
    assert reduced.levels == [1, 2]


@pytest.mark.parametrize("change, key, message", [
    ({"refine": {"levles": 3}}, "refine.levles", "unknown key"),
    ({"vary": {"solver.preset": DROP, "solver.presett": ["direct"]}}, "vary", "solver.presett: unknown key"),
    ({"refine": {"keys": ["mesh.nz"]}}, "refine.keys", "'mesh.nz' does not exist in the scene"),
    ({"vary": {"mesh.cell": DROP, "materials[3].E": [1.0]}}, "vary", "materials[3] does not exist"),
    ({"quantities": [FORCE | {"reference": "__import__(1)"}]}, "quantities[0].reference", "expected a number"),
    ({}, None, None),
])
def test_bad_study_files_name_file_and_key(tmp_path, change, key, message):
    path = write(tmp_path, **change)
    if key is None:
        expand(load_study(path))
        return
    with pytest.raises(InputError) as exc:
        expand(load_study(path))
    assert exc.value.source == str(path) and exc.value.key == key, exc.value.oneline()
    assert message in exc.value.message, exc.value.message


def test_quantity_naming_a_missing_relation(tmp_path):
    from parsolve.study.execute import check_quantities

    path = write(tmp_path, quantities=[FORCE | {"spec": "relation:contrl:multiplier"}])
    study = load_study(path)
    with pytest.raises(InputError) as exc:
        check_quantities(study, expand(study))
    assert exc.value.key == "quantities[0].spec" and "no relation 'contrl'" in exc.value.message


def test_errors():
    assert error(1.01, 1.0, "relative") == pytest.approx(0.01, rel=1e-12)
    assert error(-2.5, -2.0, "absolute") == pytest.approx(0.5, rel=1e-15)
    assert error(1.0004, 1.0, "energy_norm") == pytest.approx(0.02, rel=1e-10)


def test_orders_and_richardson_of_an_exact_power_law():
    dim, p, qstar = 2, 2.0, 3.25
    dofs = np.array([100.0, 400.0, 1000.0, 3600.0])          # unequal ratios on purpose
    h = dofs ** (-1 / dim)
    q = qstar + 0.7 * h ** p
    errs = [error(v, qstar, "absolute") for v in q]
    orders = observed_orders(errs, dofs, dim)
    assert orders[0] is None
    np.testing.assert_allclose(orders[1:], p, rtol=1e-12)
    value, order = richardson(q, dofs, dim)
    assert value == pytest.approx(qstar, rel=1e-12) and order == pytest.approx(p, rel=1e-9)
    # two runs: the order must be given
    value, order = richardson(q[:2], dofs[:2], dim, order=2.0)
    assert value == pytest.approx(qstar, rel=1e-12) and order is None
    # oscillating values are not asymptotic: the finest value, no order
    assert richardson([1.0, 1.2, 1.1], dofs[:3], dim) == (1.1, None)


def test_pareto_front_and_cheapest():
    cost = [1.0, 2.0, 3.0, 1.5, 4.0, 2.5, math.nan]
    err = [0.1, 0.05, 0.01, 0.2, 0.01, 0.05, 1e-9]
    assert list(pareto_front(cost, err)) == [0, 1, 2]
    assert cheapest(cost, err, 0.05) == 1
    assert cheapest(cost, err, 0.01) == 2
    assert cheapest(cost, err, 1e-3) is None


def test_expressions():
    assert evaluate_expression("1e9 * 0.1 * 1e-4 / 1") == pytest.approx(1e4, rel=1e-15)
    assert evaluate_expression("-2**2 + sqrt(16) + cos(pi)") == pytest.approx(-1.0, rel=1e-15)
    for bad in ("x + 1", "__import__('os')", "(1).real", "[1]"):
        with pytest.raises(ValueError):
            evaluate_expression(bad)


def test_refinement_by_mesh_files(tmp_path):
    import meshio

    from parsolve.mesh.generators import rectangle

    for n in (2, 4):
        m = rectangle(lx=1.0, ly=1.0, nx=n, ny=n, cell="triangle")
        meshio.write(tmp_path / f"m{n}.vtu", meshio.Mesh(m.points, [("triangle", m.cells)]))
    # the controlled bar on the mesh file, its sides named regions (a file has no left/right)
    base = shipped("controlled_bar.toml")
    side = {"right": "rightside", "left": "leftside"}

    def renamed(entries):
        return [e | {"region": side.get(e["region"], e["region"])} for e in entries]

    without_mesh = merge(base, {"mesh": DROP})
    write_scene(tmp_path / "scene.toml", without_mesh, mesh={"file": "m2.vtu"},
                regions={"rightside": "x == 1", "leftside": "x == 0"},
                loads=renamed(base["loads"]), relations=renamed(base["relations"]))
    (tmp_path / "study.toml").write_text("""
scene = "scene.toml"
[refine]
files = ["m2.vtu", "m4.vtu"]
[[quantities]]
name = "force"
spec = "relation:control:multiplier"
reference = 1e4
""")
    settings = expand(load_study(tmp_path / "study.toml"))
    assert [s.label for s in settings] == ["m2.vtu", "m4.vtu"]
    assert settings[1].changes == {"mesh.file": str(tmp_path / "m4.vtu")}
    assert f'file = "{tmp_path / "m4.vtu"}"' in settings[1].scene_text
