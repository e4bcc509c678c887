"""A hard kill at any point of a step's write, in both output modes, at 1, 2 and 3 ranks: after
``post --recover`` every per-step dataset has the same length, the finished steps are the
linear solution u(t) = t / t1 u(t1), and ``post --summary`` reads the file.

The writer kills itself (parsolve.io.faults, PARSOLVE_KILL_WRITE): a random time after step 2's
write began (SIGALRM, default action: the process ends inside whatever HDF5 call it is in; at
the write's end if it ends first), or after the k-th write action of step 2 (SIGKILL). Points and delays are drawn from a seeded
generator, a different draw for each mode and rank count."""

import os
import subprocess
import sys
import tomllib

import h5py
import numpy as np
import pytest

from conftest import ROOT
from helpers.scene import scene as build
from helpers.xdmf import SCENE_2D
from parsolve.post.cli import main as post_main

pytestmark = pytest.mark.serial  # each test starts its own ranks

ENV = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
MPIRUN = ["bash", str(ROOT / "scripts" / "mpirun.sh"), "-n"]
STEPS = 6
SCENE = build(tomllib.loads(SCENE_2D), steps={"count": STEPS})
DRAWS = 2        # kill points per mode and rank count (after one timed kill)
SEED = int(os.environ.get("KILL_SEED", "32"))   # the loops of many runs vary it


def run(ranks: int, args: list[str], kill: str | None = None) -> subprocess.CompletedProcess:
    env = dict(ENV, PARSOLVE_KILL_WRITE=kill) if kill else ENV
    cmd = MPIRUN + [str(ranks), sys.executable, "-m", "parsolve"] + args
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)


def per_step_lengths(path) -> dict[str, int]:
    lengths = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, o: lengths.__setitem__(name, o.shape[0])
                     if isinstance(o, h5py.Dataset) and o.maxshape[0] is None else None)
    return lengths


def write_points(path, mode: str) -> int:
    """How many write actions a step of this file takes (parsolve.io.faults counts them):
    swmr: one per dataset, two flushes; parallel: room, open and extend, one
    per field slab, the small rows, the flush, the marker, the close."""
    lengths = per_step_lengths(path)
    if mode == "swmr":
        return len(lengths) + 2
    slabs = [n for n in lengths if n.startswith(("fields/", "cell_fields/"))]
    return len(slabs) + 6


def check_whole(out, capsys) -> int:
    """Recover, then: equal lengths, the finished steps' values (the linear solution: step k is
    k times step 1), a summary. The number of finished steps."""
    assert post_main([str(out), "--recover"]) == 0, capsys.readouterr().err
    capsys.readouterr()
    lengths = per_step_lengths(out)
    n = lengths["steps/time"]
    assert n >= 1 and set(lengths.values()) == {n}, lengths
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "interrupted: killed (recovered)"
        t, u = f["steps/time"][()], f["fields/displacement"][()]
        s = f["cell_fields/stress"][()]
    k = np.arange(1, n + 1)
    np.testing.assert_allclose(t, k / STEPS, rtol=1e-12)
    assert np.abs(u[0]).max() > 1e-4 and np.abs(s[0]).max() > 0.1
    np.testing.assert_allclose(u, k[:, None, None] * u[0], rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(s, k[:, None, None] * s[0], rtol=1e-9, atol=1e-9)
    assert post_main([str(out), "--summary"]) == 0
    assert capsys.readouterr().out.startswith(
        f"{out}: status interrupted: killed (recovered), {n} steps")
    return n


@pytest.mark.parametrize("ranks", [1, 2, 3])
@pytest.mark.parametrize("mode", ["swmr", "parallel"])
def test_a_kill_anywhere_in_a_step_leaves_a_whole_file(mode, ranks, tmp_path, capsys):
    """A timed kill first (its recovered file also gives the number of write points), then
    DRAWS kills at write points of step 2."""
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    rng = np.random.default_rng([SEED, ranks, len(mode)])

    def killed_run(kill: str) -> int:
        out = tmp_path / f"k{kill.replace(':', '_').replace('@', 't')}.h5"
        proc = run(ranks, ["run", str(scene), "-o", str(out), "--output-mode", mode], kill)
        assert proc.returncode != 0, (kill, proc.stderr)
        return check_whole(out, capsys)

    timed = f"2:@{rng.uniform(0.0005, 0.02):.4f}"
    assert killed_run(timed) in (1, 2)   # inside step 2's write, or at its end
    points = write_points(tmp_path / f"k{timed.replace(':', '_').replace('@', 't')}.h5", mode)
    kills = [f"2:{k}" for k in rng.choice(np.arange(1, points + 1), DRAWS, replace=False)]
    finished = [killed_run(kill) for kill in kills]
    # killed inside step 2 at a write point: step 1 is there, and step 2 once its marker is
    assert all(n in (1, 2) for n in finished), (kills, finished)
