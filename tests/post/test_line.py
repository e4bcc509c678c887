"""``parsolve post --line P0 P1 N``: profiles of a known linear displacement field (the patch
test's u = t (a + G x), which P1, Q1 and P2 elements represent exactly), of a constant cell
stress, at one step and over all steps; points outside the mesh; bad input."""

import csv

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.post.cli import main

from post.test_post import A, G, PATCH, exact


def rows_of(path):
    return list(csv.DictReader(path.open()))


@pytest.mark.parametrize("cell", ["quad", "triangle", "triangle6"])
def test_profile_of_a_linear_field_is_exact(run, shared_tmp, cell):
    run(PATCH.format(cell=cell), name=f"line_{cell}")
    rank = MPI.COMM_WORLD.rank
    table, png = shared_tmp / f"line_{cell}{rank}.csv", shared_tmp / f"line_{cell}{rank}.png"
    # a slanted segment that crosses cells anywhere, ends on the boundary included
    p0, p1, n = np.array([0.0, 0.1]), np.array([2.0, 0.93]), 17
    assert main([str(run.last), "--line", "0,0.1", "2,0.93", str(n), "--y", "field:displacement:x",
                 "--y", "field:displacement:y", "--y", "cell_field:stress:xy", "--step", "all",
                 "--csv", str(table), "--png", str(png)]) == 0
    rows = rows_of(table)
    assert len(rows) == 2 * n and [int(r["step"]) for r in rows] == [1] * n + [2] * n
    s = np.array([float(r["s"]) for r in rows])
    x = np.column_stack([[float(r["x"]) for r in rows], [float(r["y"]) for r in rows]])
    np.testing.assert_allclose(s[:n], np.linspace(0, np.linalg.norm(p1 - p0), n), rtol=1e-14)
    np.testing.assert_allclose(x[:n], p0 + np.linspace(0, 1, n)[:, None] * (p1 - p0), atol=1e-15)
    for k, t in enumerate((0.5, 1.0)):
        part = slice(k * n, (k + 1) * n)
        want = np.array([exact(p, t) for p in x[part]])
        np.testing.assert_allclose(float(rows[k * n]["time"]), t)
        for i, c in enumerate("xy"):
            got = np.array([float(r[f"field:displacement:{c}"]) for r in rows[part]])
            np.testing.assert_allclose(got, want[:, i], rtol=0, atol=1e-13)
        # the cell stress is constant: every point, whatever cell holds it
        sxy = np.array([float(r["cell_field:stress:xy"]) for r in rows[part]])
        C33 = 100.0 / (1 - 0.25 ** 2) * 0.375
        np.testing.assert_allclose(sxy, t * C33 * (G[0, 1] + G[1, 0]), rtol=1e-10)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_profile_at_one_step_and_points_outside(run, shared_tmp, capsys):
    run(PATCH.format(cell="quad"), name="line_out")
    # from x = -1 (outside) to 1: the outside half is NaN, the inside exact; default: last step
    assert main([str(run.last), "--line", "-1,0.5", "1,0.5", "5", "--y", "field:displacement:x"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].split("\t") == ["file", "step", "time", "s", "x", "y", "field:displacement:x"]
    values = [line.split("\t") for line in lines[1:]]
    assert [int(v[1]) for v in values] == [2] * 5
    got = np.array([float(v[-1]) for v in values])
    assert np.isnan(got[:2]).all()
    np.testing.assert_allclose(got[2:], [exact([x, 0.5])[0] for x in (0.0, 0.5, 1.0)], atol=1e-13)
    assert main([str(run.last), "--line", "0,0.5", "1,0.5", "3", "--y", "field:displacement:x",
                 "--step", "1"]) == 0
    first = [line.split("\t") for line in capsys.readouterr().out.strip().splitlines()[1:]]
    np.testing.assert_allclose([float(v[-1]) for v in first],
                               [exact([x, 0.5], 0.5)[0] for x in (0.0, 0.5, 1.0)], atol=1e-13)


@pytest.mark.parametrize("args, fragment", [
    (["--line", "5,5", "6,6", "4", "--y", "field:displacement:x"], "--line: the line from (5.0, 5.0) to (6.0, 6.0) is outside the mesh"),
    (["--line", "0,0", "1,1", "1", "--y", "field:displacement:x"], "--line: N = '1'"),
    (["--line", "0,0", "1,x", "4", "--y", "field:displacement:x"], "--line: point '1,x' is not numbers"),
    (["--line", "0,0,0", "1,1,1", "4", "--y", "field:displacement:x"], "--line: the line's points need 2 coordinates"),
    (["--line", "0,0", "1,1", "4", "--y", "field:displacement:x@0,0"], "field:displacement:x@0,0: invalid spec: with --line"),
    (["--line", "0,0", "1,1", "4", "--y", "field:temperature"], "field:temperature: no field 'temperature'"),
    (["--line", "0,0", "1,1", "4", "--y", "field:displacement:x", "--step", "9"], "--step: --step '9': a step 1..2"),
    (["--line", "0,0", "1,1", "4", "--x", "time", "--y", "time"], "--x: --line draws against the distance"),
    (["--line", "0,0", "1,1", "4"], "--line: --x and --line need at least one --y"),
    (["--y", "time"], "--y: --y needs --x"),
])
def test_bad_line_input_exits_2(run, capsys, args, fragment):
    run(PATCH.format(cell="quad"), name="line_bad")
    assert main([str(run.last)] + args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and fragment in err, err


G3 = np.array([[1e-3, 2e-3, -1e-3], [0.0, -2e-3, 1e-3], [3e-3, 0.0, 1e-3]])
PATCH3 = """
[mesh]
generator = "box"
lx = 2.0
ly = 1.0
lz = 1.0
nx = 3
ny = 2
nz = 2
cell = "{cell}"
[model]
hypothesis = "3d"
[[materials]]
E = 100.0
nu = 0.25
[regions]
boundary = "x == 0 or x == 2 or y == 0 or y == 1 or z == 0 or z == 1"
""" + "".join(f"""
[[relations]]
name = "boundary_{c}"
type = "dirichlet"
region = "boundary"
components = ["{c}"]
value = "{G3[i, 0]} * x + {G3[i, 1]} * y + {G3[i, 2]} * z"
""" for i, c in enumerate("xyz"))


@pytest.mark.parametrize("cell", ["tetra", "hexahedron"])
def test_profile_in_3d_is_exact(run, shared_tmp, cell):
    run(PATCH3.format(cell=cell), name=f"line3_{cell}")
    table = shared_tmp / f"line3_{cell}{MPI.COMM_WORLD.rank}.csv"
    assert main([str(run.last), "--line", "0.1,0.05,0.9", "1.9,0.97,0.12", "13", "--y",
                 "field:displacement:x", "--y", "field:displacement:z", "--csv", str(table)]) == 0
    rows = rows_of(table)
    x = np.array([[float(r[a]) for a in "xyz"] for r in rows])
    want = x @ G3.T
    np.testing.assert_allclose([float(r["field:displacement:x"]) for r in rows], want[:, 0], atol=1e-13)
    np.testing.assert_allclose([float(r["field:displacement:z"]) for r in rows], want[:, 2], atol=1e-13)
