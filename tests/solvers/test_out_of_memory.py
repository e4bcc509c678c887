"""A factorization that does not fit in memory (MUMPS INFOG(1) = -13, made real here by an
address-space limit and a workspace margin of 2·10⁶ %) stops at once with what MUMPS needs and
what is available: no retry with a larger margin, no step cut (linear and Newton paths, 1, 2 and
3 ranks)."""

import os
import re
import resource
import subprocess
import sys

import h5py
import pytest

from conftest import CONFIGS, ROOT

pytestmark = pytest.mark.serial   # the runs start their own ranks

MAZARS = 'model = "mazars"\neps_d0 = 1e-4\nAt = 1.0\nBt = 1e4\nAc = 1.2\nBc = 1500.0\nbeta = 1.06\n'
LINEAR = (CONFIGS / "controlled_bar.toml").read_text().replace("nx = 29", "nx = 200").replace(
    "ny = 3", "ny = 20").replace("count = 10", "count = 3") + \
    "\n[solver.petsc]\nmat_mumps_icntl_14 = 2000000\n"
NEWTON = LINEAR.replace("E = 1e9\nnu = 0.0", "E = 1e9\nnu = 0.0\n" + MAZARS).replace(
    "value = 1e-4", "value = 2e-5")
LIMIT = 6 << 30   # bytes of address space: far below what the margin asks


def _limited():
    resource.setrlimit(resource.RLIMIT_AS, (LIMIT, LIMIT))


@pytest.mark.parametrize("ranks", [1, 2, 3])
@pytest.mark.parametrize("scene", ["linear", "newton"])
def test_factor_that_does_not_fit_stops_with_the_sizes(scene, ranks, tmp_path):
    (tmp_path / "scene.toml").write_text({"linear": LINEAR, "newton": NEWTON}[scene])
    cmd = [sys.executable, "-m", "parsolve", "run", "scene.toml", "-o", "out.h5"]
    if ranks > 1:
        cmd = ["bash", str(ROOT / "scripts" / "mpirun.sh"), "-n", str(ranks)] + cmd
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    proc = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300,
                          env=env, preexec_fn=_limited)
    assert proc.returncode == 3, proc.stderr
    line, = [x for x in proc.stderr.splitlines() if x.startswith("parsolve:")]
    found = re.search(r"does not fit in memory: MUMPS needs ([\d.e+]+) GB .*, ([\d.e+]+) GB "
                      r"available", line)
    assert found, line
    need, available = map(float, found.groups())
    assert need > LIMIT / 1e9 > available > 0, line
    assert line.endswith("more memory per process, more nodes, or the iterative preset"), line
    assert "retrying" not in proc.stdout and "margin raised" not in proc.stdout, proc.stdout
    with h5py.File(tmp_path / "out.h5", "r") as f:
        assert f.attrs["status"].startswith("failed: the factorization does not fit")
        assert "steps/cuts" not in f or not f["steps/cuts"][()].any()
        assert len(f["steps/time"]) == 0
