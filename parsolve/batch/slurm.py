"""The SLURM executor: one ``sbatch`` job array (``--array=0-N%throttle``) whose task i runs
the i-th pending run (``python -m parsolve.batch.task``), and one post-processing job
(``--dependency=afterok:<array>``) that rewrites the manifest (``python -m
parsolve.batch.collect``). Waiting needs no accounting database: a run is over when its folder
holds ``outcome.json`` (written by the task), or when SLURM no longer lists the array.

A task exits 0 once it has recorded its run's outcome, failed run or not, so that the
post-processing job always runs; the run's own exit code is in the manifest.
"""

from __future__ import annotations

import shlex
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

from parsolve.batch import runner

RESOURCES = {"partition": str, "time": str, "cpus_per_task": int, "mem": str, "throttle": int,
             "extra": list, "poll": (int, float), "job_name": str, "account": str, "qos": str}


def execute(root: Path, names: list[str], resources: dict, log: Callable[[str], None],
            wait: bool = True) -> tuple[list[str], str]:
    """Submit the runs ``names`` (folders prepared under ``root``): one job array per number of
    ranks (each task asks for as many CPUs as its run has ranks, unless ``cpus_per_task`` says
    otherwise) and the post-processing job after all of them. Returns the array ids and the
    post-processing job id; waits until every run has ended when ``wait``."""
    unknown = set(resources) - set(RESOURCES)
    if unknown:
        raise ValueError(f"unknown SLURM resource(s): {', '.join(sorted(unknown))}")
    folder = root / "slurm"
    folder.mkdir(exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S") + f"-{time.time_ns() % 10**6:06d}"
    groups: dict[int, list[str]] = {}
    for n in names:
        groups.setdefault(runner.read_json(root / n / runner.SPEC)["ranks"], []).append(n)
    throttle = resources.get("throttle")
    arrays = []
    for ranks, group in sorted(groups.items()):
        tag = f"{stamp}-n{ranks}"
        tasks = folder / f"tasks-{tag}.txt"
        tasks.write_text("".join(f"{n}\n" for n in group))
        script = folder / f"array-{tag}.sh"
        script.write_text(_script(resources, ranks, folder / "%A_%a.out", [
            sys.executable, "-m", "parsolve.batch.task", str(root), str(tasks), "$SLURM_ARRAY_TASK_ID"]))
        spec = f"0-{len(group) - 1}" + (f"%{throttle}" if throttle else "")
        arrays.append(_sbatch([f"--array={spec}", str(script)]))
        for i, n in enumerate(group):  # lets a later call see that the run is under way
            (root / n / runner.SLURM_JOB).write_text(f"{arrays[-1]}_{i}\n")
        log(f"batch: submitted job array {arrays[-1]} ({len(group)} runs on {ranks} rank(s), "
            f"--array={spec})")
    collect = folder / f"collect-{stamp}.sh"
    collect.write_text(_script({k: v for k, v in resources.items() if k in ("partition", "account", "qos")},
                               1, folder / "collect-%j.out",
                               [sys.executable, "-m", "parsolve.batch.collect", str(root)],
                               name=resources.get("job_name", "parsolve-batch") + "-collect"))
    after = "afterok:" + ":".join(arrays)
    collect_id = _sbatch([f"--dependency={after}", "--kill-on-invalid-dep=yes", str(collect)])
    log(f"batch: submitted post-processing job {collect_id} (--dependency={after})")
    if wait:
        _wait(root, names, arrays + [collect_id], float(resources.get("poll", 1.0)), log)
    return arrays, collect_id


def _script(resources: dict, ranks: int, output: Path, cmd: list[str], name: str | None = None) -> str:
    lines = ["#!/bin/bash", f"#SBATCH --job-name={name or resources.get('job_name', 'parsolve-batch')}",
             f"#SBATCH --output={output}", "#SBATCH --ntasks=1",
             f"#SBATCH --cpus-per-task={resources.get('cpus_per_task', ranks)}"]
    for key in ("partition", "time", "mem", "account", "qos"):
        if key in resources:
            lines.append(f"#SBATCH --{key}={resources[key]}")
    lines += [f"#SBATCH {x}" for x in resources.get("extra", [])]
    # the task id is expanded by the shell; everything else is quoted
    line = " ".join(c if c.startswith("$") else shlex.quote(c) for c in cmd)
    return "\n".join(lines + ["", f"exec {line}", ""])


def _sbatch(args: list[str]) -> str:
    try:
        proc = subprocess.run(["sbatch", "--parsable", *args], capture_output=True, text=True,
                              timeout=60)
    except FileNotFoundError:
        raise RuntimeError("sbatch not found: is SLURM installed here? "
                           "(scripts/slurm_cluster.sh starts a single-node cluster)") from None
    if proc.returncode != 0:
        raise RuntimeError(f"sbatch failed: {proc.stderr.strip() or proc.stdout.strip()}")
    return proc.stdout.strip().split(";")[0]


def listed(job_ids: list[str]) -> bool:
    """Whether SLURM still lists any of these jobs as pending or running."""
    proc = subprocess.run(["squeue", "-h", "-o", "%i", "-j", ",".join(job_ids)],
                          capture_output=True, text=True, timeout=60)
    # a job already purged from the controller makes squeue fail: it is not listed
    return proc.returncode == 0 and bool(proc.stdout.strip())


def _wait(root: Path, names: list[str], job_ids: list[str], poll: float,
          log: Callable[[str], None]) -> None:
    left = list(names)
    total = len(names)
    try:
        while True:
            ended = [n for n in left if (root / n / runner.OUTCOME).exists()]
            for n in ended:
                left.remove(n)
                log(f"[{total - len(left)}/{total}] {n}: {runner.status_of(root / n)[0]}")
            if not listed(job_ids):
                break
            time.sleep(poll)
    except KeyboardInterrupt:
        log(f"batch: stopped waiting; the jobs keep running (scancel {' '.join(job_ids)} stops "
            f"them; the post-processing job {job_ids[-1]} refreshes the manifest)")
        raise
    for n in left:  # the task died before recording (scancel, time limit, node failure)
        if not (root / n / runner.OUTCOME).exists():
            log(f"batch: {n}: its SLURM task ended without recording an outcome")
