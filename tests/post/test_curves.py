"""Curves of ``parsolve post``: several --y in one table, the unloaded state first when the
scene starts from rest (and only then)."""

import csv

import numpy as np
from mpi4py import MPI

from conftest import CONFIGS
from parsolve.post.cli import main
from parsolve.post.result import Result
from parsolve.post.scene_model import starts_from_rest


def test_several_y_are_all_kept(run, shared_tmp, capsys):
    """The controlled bar: F = 1e4 t, δ = 1e-4 t, the clamped edge's reaction -F; every --y
    is a column (a second --y used to replace the first)."""
    run(CONFIGS / "controlled_bar.toml", name="bar_curves")
    table = shared_tmp / f"bar_curves{MPI.COMM_WORLD.rank}.csv"
    ys = ["relation:control:multiplier", "relation:control:primal",
          "relation:left_x:resultant:x", "max:field:displacement:x"]
    argv = [str(run.last), "--x", "time"] + [w for y in ys for w in ("--y", y)]
    assert main(argv + ["--csv", str(table)]) == 0
    rows = list(csv.DictReader(table.open()))
    assert list(rows[0]) == ["file", "step", "time"] + ys
    t = np.array([float(r["time"]) for r in rows])
    np.testing.assert_allclose(t, np.arange(11) / 10, atol=1e-15)      # from t = 0: at rest
    assert [int(r["step"]) for r in rows] == list(range(11))
    col = {y: np.array([float(r[y]) for r in rows]) for y in ys}
    np.testing.assert_allclose(col[ys[0]], 1e4 * t, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(col[ys[1]], 1e-4 * t, rtol=1e-10, atol=1e-18)
    np.testing.assert_allclose(col[ys[2]], -1e4 * t, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(col[ys[3]], 1e-4 * t, rtol=1e-10, atol=1e-18)
    # printed: the same table, tab-separated
    capsys.readouterr()
    assert main(argv) == 0
    printed = [line.split("\t") for line in capsys.readouterr().out.strip().splitlines()]
    assert printed[0] == ["file", "step", "time"] + ys and len(printed) == 12
    np.testing.assert_allclose([float(p[3]) for p in printed[1:]], col[ys[0]], rtol=1e-9, atol=1e-9)


def test_no_unloaded_state_when_the_scene_does_not_start_from_rest(run):
    """A pressure applied whole from the first step ("constant"), or a contact (its gaps at
    t = 0): the curve starts at the first saved step."""
    bar = (CONFIGS / "controlled_bar.toml").read_text()
    run(bar, name="rest_yes")
    with Result(run.last) as res:
        assert starts_from_rest(res)
    run(CONFIGS / "contact_block_friction.toml", name="rest_contact")
    with Result(run.last) as res:
        assert not starts_from_rest(res)
    held = bar.replace("[steps]", '[evolutions]\nheld = { times = [0.0, 1.0], values = [1.0, 1.0] }\n'
                                   "[steps]", 1).replace('name = "control"', 'name = "control"\nevolution = "held"', 1)
    run(held, name="rest_no")
    with Result(run.last) as res:
        assert not starts_from_rest(res)
    assert main([str(run.last), "--x", "time", "--y", "relation:control:primal", "--csv",
                 str(run.last.with_name(f"held{MPI.COMM_WORLD.rank}.csv"))]) == 0
    rows = list(csv.DictReader(run.last.with_name(f"held{MPI.COMM_WORLD.rank}.csv").open()))
    assert [int(r["step"]) for r in rows] == list(range(1, 11))
    np.testing.assert_allclose([float(r["relation:control:primal"]) for r in rows], 1e-4, rtol=1e-10)
