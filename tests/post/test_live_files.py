"""post on a result a run is writing now, in both output modes, at 1, 2 and 3 ranks.

The run (a linear scene, 4 steps) stops between steps 2 and 3 until the test lets it go on:
every rank waits after step 2's progress line, its lock held, the parallel-output file closed
between steps, the swmr file open for writing. Meanwhile every ``post`` command is run on it:

- ``--derive`` and ``--recover`` are refused in both modes (exit 2, one line naming the lock),
  the file untouched, nothing written beside it;
- curve and ``--summary`` read a parallel-output file's finished steps (the linear solution:
  step 2 is twice step 1, after the rest); a swmr file is open for writing, and they say so
  in one line naming the lock and the way to follow it (exit 2; HDF5's words would say to
  h5clear it, which would harm the run).

Then the run goes on and completes (the reads harmed nothing: status complete, 4 steps), and
the same commands read it. No signal, no timing: the pause is a file the test creates."""

import hashlib
import os
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from conftest import ROOT
from helpers.xdmf import SCENE_2D
from parsolve.post.cli import main

pytestmark = pytest.mark.serial   # each test starts its own ranks

ENV = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
SCENE = SCENE_2D.replace("count = 3", "count = 4")
PAUSED = """
import os, sys, time
from mpi4py import MPI
from parsolve import driver
original = driver.progress
def paused(log, comm, step, *args, **kw):
    original(log, comm, step, *args, **kw)
    if step == 2:                      # every rank waits here, after step 2 is written
        if comm.rank == 0:
            open(sys.argv[-1] + ".paused", "w").close()
        while not os.path.exists(sys.argv[-1] + ".go"):
            time.sleep(0.05)
driver.progress = paused
from parsolve.cli import main
sys.exit(main(sys.argv[1:-1]))
"""
CURVE = ["--x", "time", "--y", "field:displacement:x@2,1"]


def _digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _post(args, capsys) -> tuple[int, str, list[str]]:
    code = main(args)
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err, captured.err
    return code, captured.out, captured.err.strip().splitlines()


def _curve(out: str) -> np.ndarray:
    """(time, u_x) rows of a curve's output (a header, then: file, step, x, y)."""
    return np.array([[float(v) for v in line.split("\t")[2:]] for line in out.splitlines()[1:]])


@pytest.mark.parametrize("ranks", [1, 2, 3])
@pytest.mark.parametrize("mode", ["parallel", "swmr"])
def test_post_on_a_file_being_written(mode, ranks, tmp_path, capsys):
    (tmp_path / "scene.toml").write_text(SCENE)
    out, pause = tmp_path / "live.h5", tmp_path / "pause"
    cmd = ["bash", str(ROOT / "scripts" / "mpirun.sh"), "-n", str(ranks), sys.executable, "-c",
           PAUSED, "run", str(tmp_path / "scene.toml"), "-o", str(out), "--output-mode", mode,
           str(pause)]
    proc = subprocess.Popen(cmd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=tmp_path)
    try:
        deadline = time.time() + 300
        while not pause.with_suffix(".paused").exists():
            assert proc.poll() is None and time.time() < deadline, proc.communicate()
            time.sleep(0.1)
        lock = f"lock held on {out}.lock"
        before, listing = _digest(out), sorted(p.name for p in tmp_path.iterdir())
        for args in (["--derive", str(tmp_path / "d.h5")], ["--recover"]):
            code, printed, err = _post([str(out)] + args, capsys)
            assert code == 2 and printed == "" and len(err) == 1, (args, printed, err)
            assert err[0].startswith(f"parsolve post: {out}: {args[0]}: a run is writing it "
                                     f"now ({lock}): "), err[0]
        code, printed, err = _post([str(out), "--summary"], capsys)
        if mode == "parallel":   # closed between steps: its finished steps read
            assert code == 0, err
            assert f"{out}: status running, 2 steps" in printed, printed
            code, printed, err = _post([str(out)] + CURVE, capsys)
            assert code == 0, err
            rows = _curve(printed)
            assert rows.shape == (3, 2), printed   # the rest, then the 2 finished steps
            np.testing.assert_allclose(rows[:, 0], [0.0, 0.25, 0.5], rtol=1e-12)
            np.testing.assert_allclose(rows[:, 1], np.array([0.0, 1.0, 2.0]) * rows[1, 1], rtol=1e-9)
            assert rows[1, 1] < 0
        else:                    # open for writing: named, with the lock
            for args in (["--summary"], CURVE):
                code, printed, err = _post([str(out)] + args, capsys)
                assert code == 2 and printed == "" and len(err) == 1, (args, err)
                assert err[0] == f"parsolve post: {out}: a run is writing it now ({lock}, the " \
                    "file open for writing): post reads it once the run has ended; meanwhile " \
                    "h5py.File(path, 'r', swmr=True) follows it", err[0]
        assert _digest(out) == before                                       # untouched
        assert sorted(p.name for p in tmp_path.iterdir()) == listing        # nothing beside it
        assert proc.poll() is None   # still waiting: every command above met a live run
        pause.with_suffix(".go").touch()
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            pause.with_suffix(".go").touch()
            proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "complete" and len(f["steps/time"]) == 4
    code, printed, err = _post([str(out), "--summary"], capsys)
    assert code == 0 and f"{out}: status complete, 4 steps" in printed, (err, printed)
    code, printed, err = _post([str(out)] + CURVE, capsys)
    rows = _curve(printed)
    np.testing.assert_allclose(rows[:, 0], [0.0, 0.25, 0.5, 0.75, 1.0], rtol=1e-12)
    np.testing.assert_allclose(rows[:, 1], rows[:, 0] / 0.25 * rows[1, 1], rtol=1e-9)
    assert _post([str(out), "--derive", str(tmp_path / "d.h5")], capsys)[0] == 0
    code, printed, err = _post([str(out), "--recover"], capsys)
    assert code == 0 and "nothing to recover" in printed, (err, printed)
