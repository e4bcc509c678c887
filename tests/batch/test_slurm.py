"""A real single-node SLURM (scripts/slurm_cluster.sh: slurm-wlm 22.05 + munge, no systemd):
a small batch end to end through sbatch job arrays and the afterok post-processing job."""

import csv
import os
import shutil
import socket
import subprocess
import time

import pytest

from batch_helpers import ROOT, check_bar, jobs_file, parsolve

pytestmark = [pytest.mark.serial, pytest.mark.slow]  # one cluster, subprocesses (~30 s)

SCRIPT = ROOT / "scripts" / "slurm_cluster.sh"


def _free_port_pair() -> int:
    """A port p with p + 1 free too (slurmctld, slurmd): an already running cluster on the
    default ports is left alone."""
    for _ in range(50):
        with socket.socket() as s:
            s.bind(("", 0))
            port = s.getsockname()[1]
        if port < 65000:
            try:
                with socket.socket() as s:
                    s.bind(("", port + 1))
                return port
            except OSError:
                continue
    return 16817


@pytest.fixture(scope="session")
def slurm(tmp_path_factory):
    """Start a cluster of our own (state under a temporary folder), wait for an idle node,
    stop it at the end. Skipped, with the reason, where the daemons cannot start."""
    if os.geteuid() != 0 and not shutil.which("sudo"):
        pytest.skip("SLURM test: needs root (or sudo) to start munged, slurmctld and slurmd")
    folder = tmp_path_factory.mktemp("slurm")
    env = dict(os.environ, PARSOLVE_SLURM_DIR=str(folder), PARSOLVE_SLURM_PORT=str(_free_port_pair()))
    start = subprocess.run(["bash", str(SCRIPT), "start"], capture_output=True, text=True,
                           env=env, timeout=900)
    if start.returncode != 0:
        logs = "".join(f"\n{p.name}: " + " | ".join(p.read_text().splitlines()[-3:])
                       for p in folder.glob("*.log"))
        subprocess.run(["bash", str(SCRIPT), "stop"], env=env, capture_output=True, timeout=120)
        pytest.skip(f"SLURM daemons could not start: {start.stderr.strip()[-500:]}{logs}")
    old = os.environ.get("SLURM_CONF")
    os.environ["SLURM_CONF"] = str(folder / "slurm.conf")
    yield folder
    if old is None:
        os.environ.pop("SLURM_CONF", None)
    else:
        os.environ["SLURM_CONF"] = old
    subprocess.run(["bash", str(SCRIPT), "stop"], env=env, capture_output=True, timeout=120)


def manifest(root):
    with open(root / "manifest.csv", newline="") as f:
        return {r["name"]: r for r in csv.DictReader(f)}


JOBS = ('executor = "slurm"\n[grid]\n"materials[0].E" = [1e9, 2e9]\n"steps.count" = [2]\n'
        '[[runs]]\n"mesh.nx" = 10\n[[runs]]\n"mesh.nx" = 20\nranks = 2\n'
        '[slurm]\ntime = "00:05:00"\nthrottle = 2\npoll = 0.3\n')


def test_batch_through_slurm(slurm, tmp_path):
    sinfo = subprocess.run(["sinfo", "-h", "-o", "%T"], capture_output=True, text=True)
    assert sinfo.stdout.split()[0] in ("idle", "mixed"), sinfo
    path = jobs_file(tmp_path, JOBS)
    root = tmp_path / "runs"
    proc = parsolve("batch", path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "4 runs: 4 complete" in proc.stdout, proc.stdout
    # one array per rank count, throttled, and the post-processing job after both
    assert proc.stdout.count("--array=0-1%2") == 2 and "--dependency=afterok:" in proc.stdout
    rows = manifest(root)
    assert len(rows) == 4
    for name, row in rows.items():
        assert row["status"] == "complete" and row["exit_code"] == "0", row
        check_bar(row["result"], float(row["materials[0].E"]), 2)
        assert row["ranks"] == ("2" if row["mesh.nx"] == "20" else "1")
    import h5py

    with h5py.File(rows["nx=20_E=2e+09_ranks=2"]["result"]) as f:
        assert f.attrs["nprocs"] == 2  # mpirun -n 2 inside the SLURM task
    scripts = sorted((root / "slurm").glob("array-*.sh"))
    assert len(scripts) == 2
    assert "--cpus-per-task=1" in scripts[0].read_text() and "--cpus-per-task=2" in scripts[1].read_text()
    collected = list((root / "slurm").glob("collect-*.out"))
    assert len(collected) == 1 and "4 runs: 4 complete" in collected[0].read_text()
    # task logs: one per run
    assert len([p for p in (root / "slurm").glob("*_*.out")]) == 4

    # resume: nothing to submit
    stamps = {n: os.stat(r["result"]).st_mtime_ns for n, r in rows.items()}
    proc = parsolve("batch", path)
    assert proc.returncode == 0 and "4 already complete, 0 to run" in proc.stdout, proc.stdout
    assert "submitted" not in proc.stdout and len(list((root / "slurm").glob("array-*.sh"))) == 2

    # a lost result: only that run is submitted again
    lost = "nx=20_E=1e+09_ranks=2"
    os.unlink(rows[lost]["result"])
    proc = parsolve("batch", path)
    assert proc.returncode == 0 and "3 already complete, 1 to run" in proc.stdout, proc.stdout
    assert "1 runs on 2 rank(s), --array=0-0%2" in proc.stdout
    rows = manifest(root)
    check_bar(rows[lost]["result"], 1e9, 2)
    assert {n: os.stat(r["result"]).st_mtime_ns for n, r in rows.items() if n != lost} == \
        {n: t for n, t in stamps.items() if n != lost}


def test_no_wait_collect_job_refreshes_manifest(slurm, tmp_path):
    path = jobs_file(tmp_path, 'executor = "slurm"\n[grid]\n"materials[0].E" = [3e9, 5e9]\n'
                     '"steps.count" = [2]\n[slurm]\nthrottle = 1\n')
    root = tmp_path / "runs"
    proc = parsolve("batch", path, "--no-wait")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert all(r["status"] != "complete" for r in manifest(root).values())
    # the afterok job rewrites the manifest once the array is done
    deadline = time.time() + 300
    while time.time() < deadline and not list((root / "slurm").glob("collect-*.out")):
        time.sleep(0.5)
    time.sleep(1.0)
    rows = manifest(root)
    assert [r["status"] for r in rows.values()] == ["complete", "complete"], rows
    for row in rows.values():
        check_bar(row["result"], float(row["materials[0].E"]), 2)
