"""The result file survives a run that dies, a full disk, a reader of the old result, and can be
read while the run goes on (DESIGN §5, issue 6 §3). Subprocess and single-writer tests: serial."""

import errno
import os
import subprocess
import sys
import textwrap
import time

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from helpers.disk import fill, mounted
from parsolve.errors import OutputError
from parsolve.io.hdf5 import ResultWriter, open_result
from parsolve.io.recover import recover
from parsolve.mesh.generators import rectangle

pytestmark = pytest.mark.serial

ENV = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}

# A child process that writes steps t = 1, 2, ... with displacement = t everywhere.
CHILD = """
import os, sys, time, numpy as np
from mpi4py import MPI
from parsolve.io.hdf5 import ResultWriter
from parsolve.mesh.generators import rectangle
mesh = rectangle(1.0, 1.0, 2, 2)
w = ResultWriter(MPI.COMM_SELF, r"{out}", mesh, "scene", "3.18", {{"r": (2, True)}})
{patch}
for t in range(1, {nsteps} + 1):
    w.write_step(float(t), 3, 1e-9, {{"displacement": np.full((9, 2), float(t))}},
                 {{"stress": np.full((8, 3), float(t))}},
                 {{"r": {{"multiplier": [t, 0], "primal": [0, t], "active": [1, 0]}}}},
                 {{"total": 0.1}})
    time.sleep({pause})
{end}
"""


def child(out, nsteps=2, patch="", pause=0.0, end="os._exit(1)", wait=True):
    code = textwrap.dedent(CHILD).format(out=out, nsteps=nsteps, patch=patch, pause=pause, end=end)
    args = [sys.executable, "-c", code]
    if not wait:
        return subprocess.Popen(args, env=ENV, stderr=subprocess.PIPE, text=True)
    return subprocess.run(args, env=ENV, capture_output=True, text=True)


def step(w: ResultWriter, t: float, n=9, m=8) -> None:
    w.write_step(t, 1, 0.0, {"displacement": np.full((n, 2), t)}, {"stress": np.full((m, 3), t)},
                 {"r": {"multiplier": [t, 0.0], "primal": [0.0, t]}}, {"total": 0.1})


def writer(path, n=2) -> ResultWriter:
    return ResultWriter(MPI.COMM_SELF, path, rectangle(1.0, 1.0, n, n), "scene", "3.18",
                        {"r": (2, False)})


def test_killed_run_keeps_finished_steps(tmp_path):
    """Two steps, then death without closing: readable with swmr=True, and by anything once
    recovered."""
    out = tmp_path / "r.h5"
    proc = child(out)
    assert proc.returncode == 1, proc.stderr
    with pytest.raises(OSError):                # a plain reader cannot: SWMR flags left set
        h5py.File(out, "r")
    with open_result(out) as f:                 # h5py.File(out, "r", swmr=True)
        assert f.attrs["status"] == "running"   # it never finished
        np.testing.assert_array_equal(f["steps/time"][()], [1.0, 2.0])
        np.testing.assert_array_equal(f["fields/displacement"][1], np.full((9, 2), 2.0))
        np.testing.assert_array_equal(f["relations/r/active"][()], [[1, 0], [1, 0]])
    assert out.with_suffix(".xdmf").exists()
    assert recover(out)[0] == 2
    with h5py.File(out, "r") as f:               # plain reader, no SWMR flag left
        assert f.attrs["status"] == "interrupted: killed (recovered)"
        np.testing.assert_array_equal(f["fields/displacement"][:, 0, 0], [1.0, 2.0])


def test_crash_between_datasets_leaves_finished_steps(tmp_path):
    """Death after the third step's displacement but before its stress and time: two steps."""
    out = tmp_path / "r.h5"
    patch = textwrap.dedent("""
        original = ResultWriter._append
        def dying(self, name, value):
            if name == "cell_fields/stress" and len(self.times) == 2:
                os._exit(7)
            original(self, name, value)
        ResultWriter._append = dying
    """)
    proc = child(out, nsteps=4, patch=patch)
    assert proc.returncode == 7, proc.stderr
    with h5py.File(out, "r", swmr=True) as f:
        n = len(f["steps/time"])
        assert n == 2
        assert f["fields/displacement"].shape[0] in (2, 3)  # the unfinished row may be there...
        for name in ("fields/displacement", "cell_fields/stress", "relations/r/multiplier"):
            np.testing.assert_array_equal(f[name][:n, 0, ...].reshape(n, -1)[:, 0], [1.0, 2.0])
        np.testing.assert_array_equal(f["steps/iterations"][:n], [3, 3])
    import meshio  # ...but the XDMF describes only the finished steps
    with meshio.xdmf.TimeSeriesReader(out.with_suffix(".xdmf")) as r:
        assert r.num_steps == 2


def test_concurrent_reader_sees_growing_consistent_steps(tmp_path):
    """A reader opens the file while a slow writer runs; every count it sees is consistent."""
    out = tmp_path / "r.h5"
    proc = child(out, nsteps=6, pause=0.25, end="w.close('complete')", wait=False)
    counts, deadline = [], time.time() + 30
    try:
        f = None
        while f is None and time.time() < deadline:
            try:
                f = h5py.File(out, "r", swmr=True)
            except OSError:              # not created yet, or not yet in SWMR mode
                time.sleep(0.02)
        assert f is not None
        while time.time() < deadline:
            for name in ("steps/time", "fields/displacement", "cell_fields/stress"):
                f[name].refresh()
            n = len(f["steps/time"])
            if not counts or n != counts[-1]:
                counts.append(n)
            if n:  # every finished step is whole: its rows equal its time
                times = f["steps/time"][:n]
                np.testing.assert_array_equal(times, np.arange(1, n + 1))
                disp = f["fields/displacement"][:n]
                np.testing.assert_array_equal(disp, np.broadcast_to(times[:, None, None], disp.shape))
                stress = f["cell_fields/stress"][:n]
                np.testing.assert_array_equal(stress, np.broadcast_to(times[:, None, None], stress.shape))
            if n == 6 or proc.poll() is not None:
                break
            time.sleep(0.05)
        f.close()
    finally:
        proc.wait(30)
    assert proc.returncode == 0, proc.stderr.read()
    assert counts[-1] == 6 and counts == sorted(counts) and len(counts) >= 3, counts
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "complete"


def test_replacing_a_result_keeps_the_readers_copy(tmp_path):
    out = tmp_path / "r.h5"
    w = writer(out)
    step(w, 1.0)
    step(w, 2.0)
    w.close("complete")
    with h5py.File(out, "r") as old:
        w = writer(out)               # a new run over the same name
        step(w, 5.0)
        assert out.exists()           # under its final name during the run
        w.close("complete")
        np.testing.assert_array_equal(old["steps/time"][()], [1.0, 2.0])
        np.testing.assert_array_equal(old["fields/displacement"][1], np.full((9, 2), 2.0))
    with h5py.File(out, "r") as new:
        np.testing.assert_array_equal(new["steps/time"][()], [5.0])


@pytest.mark.parametrize("given, expected", [("complete", "failed: no step finished"),
                                             ("interrupted: SIGINT", "interrupted: SIGINT"),
                                             ("failed: singular", "failed: singular")])
def test_zero_steps_is_never_complete(tmp_path, given, expected):
    out = tmp_path / "r.h5"
    w = writer(out)
    w.close(given)
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == expected
        assert "steps" not in f or len(f["steps/time"]) == 0


def test_status_given_by_the_caller_is_kept(tmp_path):
    out = tmp_path / "r.h5"
    w = writer(out)
    step(w, 1.0)
    w.close("interrupted: SIGTERM")
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "interrupted: SIGTERM"
        assert len(f["steps/time"]) == 1


def _check_readable(out, times):
    with h5py.File(out, "r") as f:   # closed normally: a plain reader opens it
        assert f.attrs["status"] == "running"   # not rewritten once a write failed
        n = len(f["steps/time"])
        np.testing.assert_array_equal(f["steps/time"][:n], times)
        np.testing.assert_array_equal(f["fields/displacement"][:n, 3, 1], times)
        np.testing.assert_array_equal(f["cell_fields/stress"][:n, 2, 0], times)


def test_injected_enospc_in_hdf5(tmp_path, monkeypatch):
    out = tmp_path / "r.h5"
    w = writer(out)
    step(w, 1.0)
    step(w, 2.0)
    original = ResultWriter._append

    def full(self, name, value):
        if name == "cell_fields/stress":
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        original(self, name, value)

    monkeypatch.setattr(ResultWriter, "_append", full)
    with pytest.raises(OutputError, match=f"{out}.*No space left.*2 finished"):
        step(w, 3.0)
    with pytest.raises(OutputError):   # nothing more is written
        step(w, 4.0)
    w.close("complete")
    assert w.status.startswith("failed: writing step 3")
    _check_readable(out, [1.0, 2.0])
    with h5py.File(out, "r") as f:
        assert f["fields/displacement"].shape[0] == 3   # the half step, not counted


def test_injected_enospc_in_xdmf(tmp_path, monkeypatch):
    import meshio
    import parsolve.io.xdmf as xdmf

    out = tmp_path / "r.h5"
    w = writer(out)
    step(w, 1.0)
    step(w, 2.0)
    real = os.pwrite

    def short(fd, data, offset):        # the disk fills in the middle of the grid
        if len(data) > len(xdmf.TAIL):
            real(fd, data[:len(data) // 2], offset)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, data, offset)

    monkeypatch.setattr(xdmf.os, "pwrite", short)
    with pytest.raises(OutputError, match=f"{out.with_suffix('.xdmf')}.*No space left"):
        step(w, 3.0)
    w.close("complete")
    with h5py.File(out, "r") as f:       # the step reached the result before the XDMF failed
        np.testing.assert_array_equal(f["steps/time"][()], [1.0, 2.0, 3.0])
        assert f.attrs["status"] == "running"
    with meshio.xdmf.TimeSeriesReader(out.with_suffix(".xdmf")) as r:  # a whole document
        r.read_points_cells()
        assert r.num_steps == 2
        assert [r.read_data(k)[0] for k in range(2)] == [1.0, 2.0]


def test_full_tmpfs(tmp_path):
    """A real full disk: a 1 MiB tmpfs filled by 40 kB steps."""
    with mounted(tmp_path / "small", "1m") as mnt:
        out = mnt / "r.h5"
        w = writer(out, n=50)          # 2601 points, 5000 cells: ~160 kB per step
        times = []
        with pytest.raises(OutputError, match=f"{out}.*No space left"):
            for t in range(1, 100):
                step(w, float(t), n=2601, m=5000)
                times.append(float(t))
        assert 2 <= len(times) < 99
        w.close("complete")
        _check_readable(out, times)
        import meshio
        with meshio.xdmf.TimeSeriesReader(out.with_suffix(".xdmf")) as r:
            r.read_points_cells()
            assert r.num_steps == len(times)
            t, point_data, _ = r.read_data(len(times) - 1)
            assert t == times[-1]
            np.testing.assert_array_equal(point_data["displacement"][:, :2], times[-1])


def test_recover_without_room_for_its_copy_says_so(tmp_path, capsys):
    """A killed run's file on a disk with no room left: --recover cannot write its copy. It
    says that (not "damaged", not "use --recover"), the file is unchanged and nothing is left
    beside it; once there is room the same command recovers it."""
    from parsolve.post.cli import main

    with mounted(tmp_path / "small", "256k") as mnt:
        out = mnt / "r.h5"
        assert child(out, nsteps=3).returncode == 1
        before = out.read_bytes()
        listing = sorted(p.name for p in mnt.iterdir())
        fill(mnt)
        assert main([str(out), "--recover"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"parsolve post: {out}: --recover: cannot recover: no room for its copy "
                       f"beside it (No space left on device); the file is unchanged: recovering "
                       f"takes one copy of it ({len(before) / 1e6:.3g} MB), make room and "
                       "recover again"], err
        assert out.read_bytes() == before
        assert sorted(p.name for p in mnt.iterdir()) == sorted(listing + ["fill"])
        (mnt / "fill").unlink()
        assert main([str(out), "--recover"]) == 0
        assert capsys.readouterr().out.startswith(f"{out}: recovered 3 finished step(s)")


def test_exception_between_datasets_is_trimmed_at_close(tmp_path, monkeypatch):
    """Ctrl-C raised in the middle of a step (the signal handler's exception): close cuts the
    unfinished rows, so every per-step dataset has exactly the finished steps."""
    import meshio

    out = tmp_path / "r.h5"
    w = writer(out)
    step(w, 1.0)
    step(w, 2.0)
    original = ResultWriter._append

    def interrupted(self, name, value):
        if name == "cell_fields/stress":
            raise KeyboardInterrupt
        original(self, name, value)

    monkeypatch.setattr(ResultWriter, "_append", interrupted)
    with pytest.raises(KeyboardInterrupt):
        step(w, 3.0)
    w.close("interrupted: SIGINT")
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "interrupted: SIGINT"
        lengths = {}
        f.visititems(lambda n, o: lengths.__setitem__(n, o.shape[0])
                     if isinstance(o, h5py.Dataset) and not n.startswith("mesh") else None)
        assert set(lengths.values()) == {2}, lengths
        np.testing.assert_array_equal(f["fields/displacement"][:, 0, 0], [1.0, 2.0])
    with meshio.xdmf.TimeSeriesReader(out.with_suffix(".xdmf")) as r:
        assert r.num_steps == 2
