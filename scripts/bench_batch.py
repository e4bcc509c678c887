"""Benchmark: what ``parsolve batch`` costs per run, locally and on SLURM.

N small runs (the controlled bar on a 10 × 2 mesh, 2 steps, Young's modulus varied) run four
ways, on this machine:
  one by one      ``parsolve run`` in a loop (a subprocess each), the baseline
  mpirun -n 1     the same loop under ``mpirun -n 1``
  local           ``parsolve.batch.execute(executor="local", parallel=2)``
  slurm           ``execute(executor="slurm")``: a job array on a single-node SLURM
                  (started with scripts/slurm_cluster.sh when none answers), 1 CPU per task
Reported: wall time, throughput (runs per minute), the mean duration of one run's process,
and the executor's overhead per run: slot-seconds per run (wall × slots / N) minus the
baseline's seconds per run. Every result is checked (end force = E·H·δ/L).
Writes scripts/results/bench_batch.md.

    .venv/bin/python scripts/bench_batch.py [--runs 100] [--skip-slurm]
    .venv/bin/python scripts/bench_batch.py --smoke   (2 runs, no SLURM; table in a temp folder)
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

import bench_harness as bh
from parsolve.batch import Run, effective_scene, execute
from parsolve.batch.runner import environment

ROOT = bh.ROOT
BAR = ROOT / "configs" / "controlled_bar.toml"


def runs(n: int) -> list[Run]:
    values = np.linspace(1e9, 2e9, n)
    return [Run(f"r{i:03d}", effective_scene(BAR, {"mesh.nx": 10, "mesh.ny": 2, "steps.count": 2,
                                                   "materials[0].E": float(E)}),
                params={"materials[0].E": float(E)}) for i, E in enumerate(values)]


def check(folder: Path, run: Run) -> None:
    E = run.params["materials[0].E"]
    with h5py.File(folder / "result.h5") as f:
        assert f.attrs["status"] == "complete", folder
        force = f["relations/control/multiplier"][-1, 0]
    assert abs(force - E * 1e-5) <= 1e-9 * E * 1e-5, (folder, force)


def one_by_one(batch: list[Run], root: Path, mpirun: bool) -> tuple[float, list[float]]:
    env = environment()
    seconds = []
    t0 = time.perf_counter()
    for run in batch:
        folder = root / run.name
        folder.mkdir(parents=True)
        (folder / "scene.toml").write_text(run.scene_text)
        cmd = [sys.executable, "-m", "parsolve", "run", "scene.toml", "-o", "result.h5"]
        if mpirun:
            cmd = [shutil.which("mpirun"), "-n", "1"] + cmd
        t = time.perf_counter()
        subprocess.run(cmd, cwd=folder, env=env, check=True, capture_output=True)
        seconds.append(time.perf_counter() - t)
    wall = time.perf_counter() - t0
    for run in batch:
        check(root / run.name, run)
    return wall, seconds


def batched(batch: list[Run], root: Path, executor: str, parallel: int = 1) -> tuple[float, list[float]]:
    t0 = time.perf_counter()
    outcomes = execute(batch, root, executor, parallel=parallel,
                       resources={"poll": 0.5, "cpus_per_task": 1}, log=lambda m: None)
    wall = time.perf_counter() - t0
    assert all(o.status == "complete" for o in outcomes), [o.status for o in outcomes]
    for run in batch:
        check(root / run.name, run)
    return wall, [o.seconds for o in outcomes]


def slurm_up() -> bool:
    return subprocess.run(["sinfo", "-h"], capture_output=True).returncode == 0 if shutil.which("sinfo") else False


def start_slurm() -> bool:
    """Start scripts/slurm_cluster.sh's cluster unless one answers; True when we started it."""
    if os.environ.get("SLURM_CONF") and slurm_up():
        return False
    proc = subprocess.run(["bash", str(ROOT / "scripts" / "slurm_cluster.sh"), "start"],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"cannot start SLURM: {proc.stderr.strip()}")
    os.environ["SLURM_CONF"] = proc.stdout.strip().split("=", 1)[1]
    return True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--skip-slurm", action="store_true")
    bh.add_smoke(ap)
    opts = ap.parse_args()
    if opts.smoke:   # 2 runs each way; SLURM skipped (tests/batch/test_slurm.py runs one)
        opts.runs, opts.skip_slurm = 2, True
    n = opts.runs
    batch = runs(n)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_batch_") as tmp:
        tmp = Path(tmp)
        modes = [("one by one: parsolve run", lambda: one_by_one(batch, tmp / "seq", False), 1),
                 ("one by one: mpirun -n 1 parsolve run", lambda: one_by_one(batch, tmp / "mpi", True), 1),
                 ("parsolve batch, local, parallel 2", lambda: batched(batch, tmp / "local", "local", 2), 2)]
        started = False
        if not opts.skip_slurm:
            started = start_slurm()
            cpus = int(subprocess.run(["sinfo", "-h", "-o", "%c"], capture_output=True,
                                      text=True).stdout.split()[0])
            modes.append((f"parsolve batch, SLURM array ({cpus} CPUs, 1 per task)",
                          lambda: batched(batch, tmp / "slurm", "slurm"), cpus))
        try:
            for label, fn, slots in modes:
                print(f"{label} ...", flush=True)
                wall, seconds = fn()
                rows.append((label, slots, wall, float(np.mean(seconds))))
                print(f"  {wall:.1f} s, {n / wall * 60:.1f} runs/min", flush=True)
        finally:
            if started:
                subprocess.run(["bash", str(ROOT / "scripts" / "slurm_cluster.sh"), "stop"],
                               capture_output=True)
    base = rows[0][2] / n
    lines = [f"# bench_batch: {n} small runs (controlled bar, 10 × 2 quads, 2 steps)", "",
             f"Machine: {os.cpu_count()} cores, {platform.platform()}, Python {platform.python_version()}; "
             f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}.", "",
             "| how | slots | wall (s) | runs / min | one run's process (s) | slot-s per run | overhead per run (s) |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for label, slots, wall, mean in rows:
        per = wall * slots / n
        lines.append(f"| {label} | {slots} | {wall:.1f} | {n / wall * 60:.1f} | {mean:.2f} | "
                     f"{per:.2f} | {per - base:+.2f} |")
    lines += ["", "*one run's process*: a run's subprocess from start to exit (as the executor "
              "measures it; the whole `parsolve run`: Python start, imports, PETSc, solve, output). "
              "*slot-s per run*: wall × slots / runs, the CPU slots a run occupies; *overhead*: "
              "that minus the one-by-one `parsolve run` seconds per run (negative: the slots "
              "overlap what one process leaves idle). Every result checked: end force = E·H·δ/L."]
    text = "\n".join(lines) + "\n"
    print(text)
    print(f"written: {bh.publish('bench_batch.md', text)}")


if __name__ == "__main__":
    main()
