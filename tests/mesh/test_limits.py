"""The memory a job really has (parsolve.mesh.limits): MemAvailable, RLIMIT_AS and the
cgroup's limit, the tightest wins; a mesh too large for it is refused with exit 2."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from parsolve.mesh import limits
from helpers.xdmf import SCENE_2D

GIB = 2**30


def fake_root(tmp_path: Path, cgroup: str, files: dict[str, str], available_kb: int) -> Path:
    """A tree with /proc/meminfo, /proc/self/{cgroup,status} and cgroup files."""
    (tmp_path / "proc" / "self").mkdir(parents=True)
    (tmp_path / "proc" / "meminfo").write_text(
        f"MemTotal:       65000000 kB\nMemFree:  1000 kB\nMemAvailable:   {available_kb} kB\n")
    (tmp_path / "proc" / "self" / "status").write_text("Name:\tpython\nVmSize:\t  409600 kB\n")
    (tmp_path / "proc" / "self" / "cgroup").write_text(cgroup)
    for name, text in files.items():
        path = tmp_path / "sys" / "fs" / "cgroup" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return tmp_path


def test_cgroup_v2_limit_minus_usage_without_inactive_cache(tmp_path):
    root = fake_root(tmp_path, "0::/slurm/job_7/step_0\n", {
        "slurm/job_7/memory.max": f"{4 * GIB}\n",
        "slurm/job_7/memory.current": f"{3 * GIB}\n",
        "slurm/job_7/memory.stat": f"anon 100\ninactive_file {GIB // 2}\nactive_file 7\n",
        "slurm/job_7/step_0/memory.max": "max\n",
        "slurm/job_7/step_0/memory.current": "1\n",
        "memory.max": "max\n"}, available_kb=20 * 2**20)
    assert limits.cgroup_headroom(root) == (
        4 * GIB - (3 * GIB - GIB // 2),
        f"the cgroup limit {root}/sys/fs/cgroup/slurm/job_7/memory.max")
    have, bound = limits.available_bytes(root=root)
    if limits.address_space_headroom(root) is None:   # no ulimit -v on this test process
        assert (have, bound) == (int(1.5 * GIB), bound) and "slurm/job_7/memory.max" in bound


def test_cgroup_v1_and_memavailable_when_tighter(tmp_path):
    root = fake_root(tmp_path, "4:memory:/job\n3:cpu:/x\n", {
        "memory/job/memory.limit_in_bytes": f"{8 * GIB}\n",
        "memory/job/memory.usage_in_bytes": f"{2 * GIB}\n",
        "memory/job/memory.stat": "cache 5\ninactive_file 0\ntotal_inactive_file 0\n",
        "memory/memory.limit_in_bytes": "9223372036854771712\n",   # v1's "no limit"
        "memory/memory.usage_in_bytes": "1\n"}, available_kb=2**20)    # 1 GiB available
    assert limits.cgroup_headroom(root)[0] == 6 * GIB
    if limits.address_space_headroom(root) is None:
        assert limits.available_bytes(root=root) == (GIB, "MemAvailable")


def test_no_cgroup_limit_and_a_namespaced_path(tmp_path):
    """A path that does not exist under the mount (cgroup namespace): the root's files."""
    root = fake_root(tmp_path, "0::/not/here\n", {"memory.max": "max\n",
                                                   "memory.current": "5\n"}, available_kb=100)
    assert limits.cgroup_headroom(root) == (None, "")
    root2 = fake_root(tmp_path / "b", "0::/gone\n", {"memory.max": "1000\n",
                                                      "memory.current": "400\n"}, available_kb=100)
    assert limits.cgroup_headroom(root2)[0] == 600


@pytest.mark.serial
def test_address_space_limit_refuses_a_mesh_too_large_for_it(tmp_path):
    """Under prlimit --as=1.5 GiB: a small scene passes the check, a 720 000-DOF one (about
    2 GiB by the estimate) is refused with exit 2, the message naming RLIMIT_AS."""
    small, large = tmp_path / "small.toml", tmp_path / "large.toml"
    small.write_text(SCENE_2D)
    large.write_text(SCENE_2D.replace("nx = 8", "nx = 600").replace("ny = 4", "ny = 600"))
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}

    def check(scene):
        return subprocess.run(["prlimit", f"--as={3 * GIB // 2}", sys.executable, "-m",
                               "parsolve", "run", str(scene), "-o", str(tmp_path / "r.h5")],
                              env=env, capture_output=True, text=True, timeout=120)

    ok = check(small)
    assert ok.returncode == 0, ok.stderr
    refused = check(large)
    assert refused.returncode == 2, refused.stderr
    line, = refused.stderr.splitlines()
    assert line.startswith(f"parsolve: {large}: mesh.generator: too large for this machine")
    assert line.endswith("(bound by the address-space limit RLIMIT_AS (ulimit -v))")
