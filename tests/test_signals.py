"""Ctrl-C and SIGTERM stop a run at once: exit status 130 / 143, status "interrupted: ...",
every finished step readable, never "complete"."""

import os
import signal
import subprocess
import sys
import time

import h5py
import pytest

from helpers.scene import shipped, write_scene

pytestmark = pytest.mark.serial  # spawns a run


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signal_stops_the_run_and_keeps_finished_steps(sig, code, tmp_path):
    scene = write_scene(tmp_path / "long.toml", shipped("solubility_grow_shrink.toml"),
                        steps={"count": 4000, "end": 80.0})
    out = tmp_path / "long.h5"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    proc = subprocess.Popen([sys.executable, "-m", "parsolve", "run", str(scene), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    deadline = time.time() + 120
    while time.time() < deadline:  # wait for a few finished steps, read during the run
        time.sleep(0.2)
        try:
            with h5py.File(out, "r", swmr=True) as f:
                if len(f["steps/time"]) >= 3:
                    break
        except (OSError, KeyError):
            pass
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == code, err
    assert "interrupted" in err and "Traceback" not in err
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == f"interrupted: {signal.Signals(sig).name}"
        n = len(f["steps/time"])
        assert 3 <= n < 4000
        assert f["fields/c_s"].shape[0] == n and f["balance/total/error"].shape[0] == n


# ------------------------------------------------ under mpirun: the signal to mpirun or to a rank
from conftest import ROOT  # noqa: E402

import numpy as np  # noqa: E402

MPIRUN_SH = ["bash", str(ROOT / "scripts" / "mpirun.sh"), "-n"]


def _long_scene(path, count=4000, end=80.0):
    return write_scene(path, shipped("solubility_grow_shrink.toml"), steps={"count": count, "end": end})


def _children(pid: int) -> list[int]:
    out = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout
    return [int(p) for p in out.split()]


@pytest.mark.parametrize("ranks", [2, 3])
@pytest.mark.parametrize("target", ["wrapper", "mpirun", "rank"])
def test_sigterm_under_mpirun_stops_every_rank(ranks, target, tmp_path):
    """SIGTERM to scripts/mpirun.sh (forwarded at once as SIGUSR2: exit 143), to mpirun itself
    (Open MPI relays SIGTERM after odls_base_sigkill_timeout; mpirun exits 1) or to one rank
    (the ranks agree at the step's end: exit 143). Every finished step equals a 1-rank rerun."""
    scene, out = _long_scene(tmp_path / "long.toml"), tmp_path / "long.h5"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    # room for the ranks to close their file between mpirun's SIGTERM and its SIGKILL
    env["OMPI_MCA_odls_base_sigkill_timeout"] = "5"
    proc = subprocess.Popen(MPIRUN_SH + [str(ranks), sys.executable, "-m", "parsolve", "run",
                                         str(scene), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            start_new_session=True)
    deadline = time.time() + 120
    while time.time() < deadline:
        time.sleep(0.2)
        try:
            with h5py.File(out, "r", swmr=True) as f:
                if len(f["steps/time"]) >= 3:
                    break
        except (OSError, KeyError):
            pass
    mpirun = _children(proc.pid)
    assert len(mpirun) == 1
    ranks_pids = _children(mpirun[0])
    assert len(ranks_pids) == ranks
    pid = {"wrapper": proc.pid, "mpirun": mpirun[0], "rank": ranks_pids[-1]}[target]
    os.kill(pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == (1 if target == "mpirun" else 143), err
    assert "interrupted by SIGTERM" in err and "Traceback" not in err
    with h5py.File(out, "r") as f:
        status = f.attrs["status"]
        n = len(f["steps/time"])
        got = {name: f[name][()] for name in ("steps/time", "fields/c_s", "fields/c_g")}
    assert status == ("interrupted: SIGTERM (sent as SIGUSR2)" if target == "wrapper"
                      else "interrupted: SIGTERM")
    assert 3 <= n < 4000
    rerun = tmp_path / "rerun.h5"
    one = subprocess.run([sys.executable, "-m", "parsolve", "run",
                          str(_long_scene(tmp_path / "rerun.toml", n, n * 80.0 / 4000)),
                          "-o", str(rerun)], env=env, capture_output=True, text=True, timeout=300)
    assert one.returncode == 0, one.stderr
    with h5py.File(rerun, "r") as f:
        for name, value in got.items():
            np.testing.assert_allclose(value, f[name][()], rtol=1e-9, atol=1e-12, err_msg=name)
