"""parsolve post: interpolation, curves, summary, derived fields, bad input (known numbers)."""

import csv
import re

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from conftest import CONFIGS
from parsolve.errors import InputError
from parsolve.post.cli import main
from parsolve.post.derive import full_tensor, principal, von_mises
from parsolve.post.result import Result
from parsolve.post.spec import series

# u = a + G x on the whole boundary: the FE solution is this linear field exactly (patch test)
A, G = np.array([1e-3, -2e-3]), np.array([[2e-3, 1e-3], [-5e-4, 3e-3]])
PATCH = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 1.0
nx = 5
ny = 3
cell = "{cell}"
[model]
hypothesis = "plane_stress"
[[materials]]
E = 100.0
nu = 0.25
[regions]
boundary = "x == 0 or x == 2 or y == 0 or y == 1"
""" + "".join(f"""
[[relations]]
name = "boundary_{c}"
type = "dirichlet"
region = "boundary"
components = ["{c}"]
value = "{A[i]} + {G[i, 0]} * x + {G[i, 1]} * y"
""" for i, c in enumerate("xy")) + """
[steps]
count = 2
"""


def exact(x, t=1.0):
    return t * (A + G @ np.asarray(x))


@pytest.mark.parametrize("cell", ["quad", "triangle6"])
def test_field_at_point_is_the_linear_field(run, cell):
    run(PATCH.format(cell=cell), name=f"patch_{cell}")
    with Result(run.last) as res:
        for x in ([0.3, 0.71], [1.999999, 0.5], [0.0, 0.0], [1.234, 0.987]):
            for i, c in enumerate("xy"):
                got = series(res, f"field:displacement:{c}@{x[0]},{x[1]}")
                np.testing.assert_allclose(got, [exact(x, 0.5)[i], exact(x, 1.0)[i]], rtol=0, atol=1e-12)
        # the cell stress is constant: σ = C ε with ε from G (plane stress, E = 100, ν = 0.25)
        e = np.array([G[0, 0], G[1, 1], G[0, 1] + G[1, 0]])
        C = 100.0 / (1 - 0.25 ** 2) * np.array([[1, 0.25, 0], [0.25, 1, 0], [0, 0, 0.375]])
        np.testing.assert_allclose(series(res, "cell_field:stress:xy@1.5,0.5")[-1], (C @ e)[2], rtol=1e-10)
        np.testing.assert_allclose(series(res, "time"), [0.5, 1.0])
        # L2 norm of the linear field over [0, 2] × [0, 1], exact by 2D Gauss quadrature
        g, w = np.polynomial.legendre.leggauss(3)
        X, Y = np.meshgrid(1 + g, 0.5 + 0.5 * g)
        W = np.outer(0.5 * w, w)
        ref = np.sqrt(sum((W * (A[i] + G[i, 0] * X + G[i, 1] * Y) ** 2).sum() for i in range(2)))
        np.testing.assert_allclose(series(res, "norm:field:displacement")[-1], ref, rtol=1e-12)
        np.testing.assert_allclose(series(res, "maxabs:field:displacement:y")[-1],
                                   np.abs([exact(p)[1] for p in res.points]).max(), rtol=1e-12)


def test_relation_series_and_energy(run):
    run(CONFIGS / "controlled_bar.toml", name="bar")
    with Result(run.last) as res:
        force = series(res, "relation:control:multiplier")
        np.testing.assert_allclose(force, 1e4 * np.arange(1, 11) / 10, rtol=1e-10)
        np.testing.assert_allclose(series(res, "relation:left_x:multiplier:sum"), force, rtol=1e-10)
        np.testing.assert_allclose(series(res, "relation:left_x:multiplier:mean"), force / 4, rtol=1e-10)
        # strain energy ½ F δ of the bar
        delta = series(res, "relation:control:primal")
        np.testing.assert_allclose(series(res, "energy"), 0.5 * force * delta, rtol=1e-10)
        # ux = δ x / L: its largest value over the left edge is 0, over everything δ
        np.testing.assert_allclose(series(res, "max:field:displacement:x@left"), 0.0, atol=1e-18)
        np.testing.assert_allclose(series(res, "max:field:displacement:x"), delta, rtol=1e-10)
        with pytest.raises(InputError, match="unknown region 'lft'"):
            series(res, "max:field:displacement:x@lft")


def test_von_mises_and_principal_of_known_tensors():
    rng = np.random.default_rng(1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    T = q @ np.diag([3.0, 1.0, -2.0]) @ q.T
    voigt = np.array([T[0, 0], T[1, 1], T[2, 2], T[1, 2], T[0, 2], T[0, 1]])
    full = full_tensor(voigt, 3)
    np.testing.assert_allclose(full, T, atol=1e-15)
    np.testing.assert_allclose(principal(full), [3.0, 1.0, -2.0], atol=1e-13)
    np.testing.assert_allclose(von_mises(full), np.sqrt(0.5 * (2 ** 2 + 3 ** 2 + 5 ** 2)), rtol=1e-13)
    uniaxial = full_tensor(np.array([-7.0, 0.0, 0.0]), 2)
    np.testing.assert_allclose(von_mises(uniaxial), 7.0, rtol=1e-14)        # |σ|
    pure_shear = full_tensor(np.array([0.0, 0.0, 2.0]), 2)
    np.testing.assert_allclose(von_mises(pure_shear), 2.0 * np.sqrt(3.0), rtol=1e-14)
    np.testing.assert_allclose(principal(pure_shear), [2.0, 0.0, -2.0], atol=1e-14)


LAYERS = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 1.0
nx = 4
ny = 4
cell = "triangle"
[model]
hypothesis = "plane_stress"
[regions]
lower = "y <= 0.5"
upper = "y >= 0.5"
corner = { point = [0.0, 0.0] }
[[materials]]
region = "lower"
E = 100.0
nu = 0.0
[[materials]]
region = "upper"
E = 300.0
nu = 0.0
[[relations]]
name = "pull"
type = "dirichlet"
region = "right"
components = ["x"]
value = 2e-3
[[relations]]
name = "hold"
type = "dirichlet"
region = "left"
components = ["x"]
[[relations]]
name = "corner"
type = "dirichlet"
region = "corner"
components = ["y"]
"""


def test_derive_per_region_stress_and_uniaxial_fields(run, shared_tmp):
    """Two layers (E = 100 below, 300 above) stretched by ε = 1e-3: σxx = E ε on each side of
    the interface y = 0.5, where the smeared nodal stress would mix both."""
    run(LAYERS, name="layers")
    out = shared_tmp / f"derived_{MPI.COMM_WORLD.rank}.h5"
    assert main([str(run.last), "--derive", str(out)]) == 0
    with h5py.File(out, "r") as f:
        y = f["mesh/points"][:, 1]
        lower, upper = f["fields/stress_lower"][-1], f["fields/stress_upper"][-1]
        inter = np.isclose(y, 0.5)
        np.testing.assert_allclose(lower[y <= 0.5 + 1e-12, 0], 0.1, rtol=1e-10)
        np.testing.assert_allclose(upper[y >= 0.5 - 1e-12, 0], 0.3, rtol=1e-10)
        assert np.isnan(lower[y > 0.6]).all() and np.isnan(upper[y < 0.4]).all()
        assert inter.sum() == 5 and not np.allclose(f["fields/stress"][-1][inter, 0], 0.1)
        sxx = f["cell_fields/stress"][-1][:, 0]
        np.testing.assert_allclose(f["cell_fields/von_mises"][-1][:, 0], np.abs(sxx), rtol=1e-10)
        np.testing.assert_allclose(f["cell_fields/principal_stress"][-1][:, 0], sxx, rtol=1e-10)
        np.testing.assert_allclose(f["cell_fields/principal_stress"][-1][:, 1:], 0, atol=1e-12)
        np.testing.assert_allclose(f["cell_fields/strain"][-1], [[1e-3, 0, 0]] * len(sxx), atol=1e-15)
    xdmf = out.with_suffix(".xdmf").read_text()
    assert "stress_upper" in xdmf and "von_mises" in xdmf and out.with_suffix(".xdmf.h5").name + ":/cell_fields/strain/0" in xdmf


def test_curves_of_several_files_to_csv_and_png(run, shared_tmp):
    run(PATCH.format(cell="quad"), name="c1")
    first = run.last
    run(PATCH.format(cell="triangle6").replace("count = 2", "count = 4"), name="c2")
    rank = MPI.COMM_WORLD.rank
    table, png = shared_tmp / f"curve{rank}.csv", shared_tmp / f"curve{rank}.png"
    assert main([str(first), str(run.last), "--x", "time", "--y", "field:displacement:x@0.5,0.5",
                 "--csv", str(table), "--png", str(png)]) == 0
    rows = list(csv.DictReader(table.open()))
    # each curve starts at the unloaded state (step 0, t = 0: the scene starts from rest)
    assert [r["file"] for r in rows] == ["c1"] * 3 + ["c2"] * 5
    assert [int(r["step"]) for r in rows] == [0, 1, 2, 0, 1, 2, 3, 4]
    got = np.array([float(r["field:displacement:x@0.5,0.5"]) for r in rows])
    t = np.array([float(r["time"]) for r in rows])
    np.testing.assert_allclose(t, [0, 0.5, 1, 0, 0.25, 0.5, 0.75, 1], atol=1e-15)
    np.testing.assert_allclose(got, t * exact([0.5, 0.5])[0], atol=1e-13)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_summary(run, capsys):
    run(CONFIGS / "controlled_bar.toml", name="bar_summary")
    assert main([str(run.last), "--summary"]) == 0
    text = capsys.readouterr().out
    assert "status complete, 10 steps" in text
    assert "control: 1 rows, multiplier [10000]" in text
    # the reaction of the clamped edge balances the end force, and its moment about the origin
    assert "left_x: 4 rows" in text and "resultant [fx -10000, fy 0, mz 500]" in text
    assert "resultants: forces, then moments about the origin" in text
    # |ux| = 1e-4 on the whole right edge x = 1 (nodes 29, 59, 89, 119): any of them, by
    # round-off, located by its coordinates and its number
    node = re.search(r"fields/displacement: max \|value\| x 0\.0001 at \(1, ([0-9.e-]+)\), "
                     r"node (\d+);", text)
    assert node and int(node.group(2)) in (29, 59, 89, 119), text
    with Result(run.last) as res:
        np.testing.assert_allclose(res.points[int(node.group(2))], [1.0, float(node.group(1))],
                                   rtol=1e-5)
    # a cell field's extreme: the cell's centroid and number
    cell = re.search(r"cell_fields/stress: max \|value\| xx 100000 at \(([0-9.e-]+), ([0-9.e-]+)\), "
                     r"cell (\d+);", text)
    with Result(run.last) as res:
        centroid = res.points[res.cells[int(cell.group(3))]].mean(axis=0)
    np.testing.assert_allclose(centroid, [float(cell.group(1)), float(cell.group(2))], rtol=1e-5)


@pytest.mark.parametrize("args, message", [
    (["missing.h5", "--summary"], "missing.h5: cannot open result file"),
    (["{f}", "--x", "time", "--y", "relation:nope:multiplier"], "{f}: relation:nope:multiplier: no relation 'nope'"),
    (["{f}", "--x", "time", "--y", "field:temperature:x@0,0"], "{f}: field:temperature:x@0,0: no field 'temperature'"),
    (["{f}", "--x", "time", "--y", "field:displacement:x@5,0.05"], "{f}: field:displacement:x@5,0.05: point (5.0, 0.05) is outside the mesh"),
    (["{f}", "--x", "time", "--y", "relation:left_x:multiplier"], "{f}: relation:left_x:multiplier: relation 'left_x' has 4 rows"),
    (["{f}", "--x", "time", "--y", "relation:control:resultant:z"], "{f}: relation:control:resultant:z: no resultant component 'z' (known: x, y, mz)"),
    (["{f}", "--x", "time", "--y", "field:displacement:q@0,0"], "{f}: field:displacement:q@0,0: no component 'q'"),
    (["{f}", "--x", "tim", "--y", "time"], "--x: tim: invalid spec"),
    (["{f}", "--derive", "{f}"], "{f}: --derive: --derive writes a copy"),
])
def test_bad_input_exits_2_with_file_and_spec(run, capsys, args, message):
    run(CONFIGS / "controlled_bar.toml", name="bar_bad")
    f = str(run.last)
    assert main([a.format(f=f) for a in args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("parsolve post: " + message.format(f=f)), err
    assert len(err.splitlines()) == 1
