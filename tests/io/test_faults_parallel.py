"""Faults of real runs in their own processes (mpirun, 1 to 3 ranks): a really full disk
(a small tmpfs) with ``--output-mode parallel``, and two runs writing the same result."""

import os
import signal
import subprocess
import sys
import time
import tomllib

import h5py
import numpy as np
import pytest

from conftest import ROOT
from helpers.disk import mounted
from helpers.scene import scene as build
from helpers.xdmf import SCENE_2D

pytestmark = pytest.mark.serial  # each test starts its own ranks

ENV = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
MPIRUN = ["bash", str(ROOT / "scripts" / "mpirun.sh"), "-n"]
SMALL = tomllib.loads(SCENE_2D)   # 8 × 4 cells, 3 steps
BIG = build(SMALL, mesh={"nx": 60, "ny": 30}, steps={"count": 200})   # ~180 kB a step: a 3 MB disk fills at step 11
BIG_60 = build(SMALL, mesh={"nx": 60, "ny": 30}, steps={"count": 60})


SLOW = """
import sys, time
from parsolve import driver
original = driver.progress
def slow(*args, **kw):       # a step every 0.1 s: the second run starts while the first runs
    original(*args, **kw)
    time.sleep(0.1)
driver.progress = slow
from parsolve.cli import main
sys.exit(main(sys.argv[1:]))
"""


def launch(ranks: int, args: list[str], wait: bool = True, slow: bool = False):
    cmd = MPIRUN + [str(ranks), sys.executable] + (["-c", SLOW] if slow else
                                                   ["-m", "parsolve"]) + args
    if not wait:
        return subprocess.Popen(cmd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, start_new_session=True)
    return subprocess.run(cmd, env=ENV, capture_output=True, text=True, timeout=600)


@pytest.fixture
def small_disk(tmp_path):
    """A 3 MB file system (tmpfs)."""
    with mounted(tmp_path / "disk", "3m") as where:
        yield where


@pytest.fixture
def tiny_disk(tmp_path):
    """A 512 kB file system: less than the lock's 1 MiB reserve."""
    with mounted(tmp_path / "tiny", "512k") as where:
        yield where


@pytest.mark.parametrize("ranks", [1, 2, 3])
@pytest.mark.parametrize("mode", ["parallel", "swmr"])
def test_a_disk_without_room_for_the_reserve_starts_nothing(mode, ranks, tiny_disk, tmp_path):
    """Exit 4 with "No space left on device" before any output: no 0-byte out.h5 (nor an
    HDF5 crash when the disk fills later with no reserve to close the file), no lock left."""
    scene, out = tmp_path / "big.toml", tiny_disk / "out.h5"
    scene.write_text(BIG)
    proc = launch(ranks, ["run", str(scene), "-o", str(out), "--output-mode", mode])
    assert proc.returncode == 4, proc.stderr
    ours = [line for line in proc.stderr.splitlines() if line.startswith("parsolve")]
    assert ours == [f"parsolve: cannot write the results: {out}: No space left on device (disk "
                    f"full): the 1 MiB kept beside the result to close it do not fit in "
                    f"{tiny_disk}; nothing written"], proc.stderr
    assert "Traceback" not in proc.stderr and proc.stdout == ""
    assert list(tiny_disk.iterdir()) == []


@pytest.mark.parametrize("ranks", [1, 2, 3])
@pytest.mark.parametrize("mode", ["parallel", "swmr"])
def test_disk_full_exits_4_everywhere(mode, ranks, small_disk, tmp_path):
    """Every rank stops with exit 4 at the step that does not fit; the file opens with plain
    h5py, says why, and holds the finished steps: the linear solution, u(t) = t / t1 u(t1)."""
    scene, out = tmp_path / "big.toml", small_disk / "out.h5"
    scene.write_text(BIG)
    proc = launch(ranks, ["run", str(scene), "-o", str(out), "--output-mode", mode])
    assert proc.returncode == 4, proc.stderr
    assert "No space left on device" in proc.stderr and "Traceback" not in proc.stderr
    with h5py.File(out, "r") as f:
        status, t = f.attrs["status"], f["steps/time"][()]
        n = len(t)
        u, s = f["fields/displacement"][()], f["cell_fields/stress"][()]
    assert 3 <= n < 200
    assert status.startswith(f"failed: writing step {n + 1} to") and "No space left" in status
    assert u.shape[0] == s.shape[0] == n
    np.testing.assert_allclose(t, 0.005 * np.arange(1, n + 1), rtol=1e-12)
    np.testing.assert_allclose(u, t[:, None, None] / t[0] * u[0], rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(s, t[:, None, None] / t[0] * s[0], rtol=1e-9, atol=1e-9)
    assert np.abs(u[0]).max() > 0
    assert not (small_disk / "out.h5.lock").exists()


def _children(pid: int) -> list[int]:
    out = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout
    return [int(p) for p in out.split()]


def _descendants(pid: int) -> list[int]:
    """pid and every process below it (mpirun's ranks included)."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        todo.extend(_children(p))
    return out


def _locked(path) -> bool:
    import fcntl

    try:
        fd = os.open(path, os.O_RDWR)
    except FileNotFoundError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


@pytest.mark.parametrize("ranks", [1, 2, 3])
def test_a_second_run_on_the_same_output_is_refused(ranks, tmp_path):
    """The second run, started while the first holds the lock and has written steps, exits 2
    at once and touches nothing; the first finishes with its three files whole and agreeing."""
    import meshio

    scene, out = tmp_path / "big.toml", tmp_path / "out.h5"
    scene.write_text(BIG_60)
    first = launch(ranks, ["run", str(scene), "-o", str(out)], wait=False, slow=True)
    xdmf, deadline = out.with_suffix(".xdmf"), time.time() + 120
    while time.time() < deadline and not (
            _locked(tmp_path / "out.h5.lock") and xdmf.exists()
            and xdmf.read_text().count('<Grid Name="step') >= 2):
        time.sleep(0.1)
    assert first.poll() is None
    inode = out.stat().st_ino
    # the first run stopped (its lock held) while the second starts and checks: on a loaded
    # machine the first could otherwise finish before the second has even imported parsolve
    stopped = _descendants(first.pid)
    for pid in stopped:
        os.kill(pid, signal.SIGSTOP)
    try:
        second = launch(ranks, ["run", str(scene), "-o", str(out)])
    finally:
        for pid in stopped:
            os.kill(pid, signal.SIGCONT)
    assert second.returncode == 2, second.stderr
    assert second.stderr.splitlines()[0] == (f"parsolve: command line: -o: {out} is being "
                                             f"written by another run (lock held on {out}.lock)")
    assert second.stdout == ""
    _, err = first.communicate(timeout=300)
    assert first.returncode == 0, err
    assert out.stat().st_ino == inode          # never replaced
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "complete"
        t = f["steps/time"][()]
        u = f["fields/displacement"][()]
    np.testing.assert_allclose(t, np.arange(1, 61) / 60, rtol=1e-12)
    np.testing.assert_allclose(u, t[:, None, None] / t[0] * u[0], rtol=1e-9, atol=1e-14)
    with meshio.xdmf.TimeSeriesReader(xdmf) as r:
        r.read_points_cells()
        assert r.num_steps == 60
        tk, point_data, _ = r.read_data(59)
    assert tk == t[59]
    np.testing.assert_array_equal(point_data["displacement"][:, :2], u[59])
    assert not (tmp_path / "out.h5.lock").exists()


@pytest.mark.parametrize("ranks", [1, 2, 3])
def test_post_recovers_a_killed_runs_file(ranks, tmp_path):
    """kill -9 of every rank and of mpirun in the middle of a swmr run: plain h5py cannot open
    the file and ``post`` says to use --recover; after it every finished step reads, the linear
    solution u(t) = t / t1 u(t1), and the status says what happened."""
    import signal

    scene, out = tmp_path / "big.toml", tmp_path / "out.h5"
    scene.write_text(BIG)
    proc = launch(ranks, ["run", str(scene), "-o", str(out)], wait=False, slow=True)
    deadline = time.time() + 120
    while time.time() < deadline:
        time.sleep(0.1)
        try:
            with h5py.File(out, "r", swmr=True) as f:
                if len(f["steps/time"]) >= 3:
                    break
        except (OSError, KeyError):
            pass
    mpirun = _children(proc.pid)
    for pid in _children(mpirun[0]):      # the ranks (in a process group of their own)
        os.kill(pid, signal.SIGKILL)
    proc.communicate(timeout=300)
    with pytest.raises(OSError):
        h5py.File(out, "r")
    post = [sys.executable, "-m", "parsolve", "post", str(out)]
    summary = subprocess.run(post + ["--summary"], env=ENV, capture_output=True, text=True)
    assert summary.returncode == 2
    assert summary.stderr.strip().endswith(
        f"the run writing it was killed (status running): `parsolve post {out} --recover` "
        "makes its finished steps readable")
    fixed = subprocess.run(post + ["--recover"], env=ENV, capture_output=True, text=True)
    assert fixed.returncode == 0, fixed.stderr
    with h5py.File(out, "r") as f:           # a plain reader now
        status, t = f.attrs["status"], f["steps/time"][()]
        n = len(t)
        u = f["fields/displacement"][()]
        lengths = set()
        f.visititems(lambda name, o: lengths.add(o.shape[0]) if isinstance(o, h5py.Dataset)
                     and not name.startswith("mesh") else None)
    assert status == "interrupted: killed (recovered)"
    assert fixed.stdout.startswith(f"{out}: recovered {n} finished step(s)")
    assert n >= 3 and lengths == {n}
    np.testing.assert_allclose(t, 0.005 * np.arange(1, n + 1), rtol=1e-12)
    np.testing.assert_allclose(u, t[:, None, None] / t[0] * u[0], rtol=1e-9, atol=1e-14)
    again = subprocess.run(post + ["--recover"], env=ENV, capture_output=True, text=True)
    assert again.returncode == 0 and "nothing to recover" in again.stdout
    assert subprocess.run(post + ["--summary"], env=ENV, capture_output=True).returncode == 0
