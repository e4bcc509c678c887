"""The shared harness of scripts/bench_*.py: paths, smoke mode, child environment, machine
information, running peers, tables and JSON.

How it is imported: every benchmark is run as a plain script from the repository root,

    .venv/bin/python scripts/bench_x.py [options]

and Python puts the script's own folder (scripts/) first on ``sys.path``, so ``import
bench_harness`` (and ``from bench_assembly import ...`` between benchmarks) resolves with no
``sys.path`` edit. Workers that a benchmark starts under mpirun run the same script file, so
they find it the same way. This module uses the standard library only at import (numpy and
petsc4py are imported inside the functions that need them) and never imports parsolve or
tests/: bench_peers.py runs it under Debian's python3 (DOLFINx) and the scikit-fem venv too.

Where results go:
  * ``PUBLISHED`` (scripts/results/): the committed tables, written by full runs only;
  * ``SCRATCH`` (bench_results/): JSON, partial tables and work folders.
In smoke mode (``--smoke`` on the command line, or ``PARSOLVE_BENCH_SMOKE`` set by
scripts/bench_smoke.sh) both point into one temporary folder (``PARSOLVE_BENCH_TMP``, made
here when not given, and inherited by every child), so a smoke run can never overwrite a
published table. Smoke mode is decided at import, before a benchmark computes its paths.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = ROOT / "scripts"
VENV_PY = str(ROOT / ".venv" / "bin" / "python")
DEBIAN_PY = "/usr/bin/python3"                       # DOLFINx 0.5 (scripts/bench_env.sh)
BENCH_VENV = Path(os.environ.get("BENCH_VENV", "/work/bench-venv"))   # scikit-fem
MiB = 2.0 ** 20


def _smoke_from_argv() -> bool:
    return "--smoke" in sys.argv[1:] or bool(os.environ.get("PARSOLVE_BENCH_SMOKE"))


SMOKE = _smoke_from_argv()
if SMOKE:
    # one temporary folder for the whole smoke run, children included (never scripts/results)
    if not os.environ.get("PARSOLVE_BENCH_TMP"):
        os.environ["PARSOLVE_BENCH_TMP"] = tempfile.mkdtemp(prefix="parsolve-bench-smoke-")
    os.environ["PARSOLVE_BENCH_SMOKE"] = "1"
    _TMP = Path(os.environ["PARSOLVE_BENCH_TMP"])
    PUBLISHED = _TMP / "results"
    SCRATCH = _TMP / "bench_results"
    PUBLISHED.mkdir(parents=True, exist_ok=True)
    SCRATCH.mkdir(parents=True, exist_ok=True)
else:
    PUBLISHED = SCRIPTS / "results"
    SCRATCH = ROOT / "bench_results"


def add_smoke(parser: argparse.ArgumentParser) -> None:
    """The ``--smoke`` option every benchmark takes (the mode itself is read at import)."""
    parser.add_argument("--smoke", action="store_true",
                        help="smallest size, peers skipped, tables into a temporary folder "
                             "(CI's smoke stage, scripts/bench_smoke.sh)")


# ------------------------------------------------------------------------------ environment


def child_env(pythonpath: bool = False, strip_mpi: bool = True) -> dict:
    """The environment of a benchmark's child process: one thread per rank (OMP, OpenBLAS), and
    without this process's MPI singleton variables (an mpirun started from a process that
    initialised MPI exits silently otherwise). pythonpath: the repository root on PYTHONPATH
    (for peers' interpreters that do not have parsolve installed)."""
    env = dict(os.environ)
    if strip_mpi:
        env = {k: v for k, v in env.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    if pythonpath:
        env["PYTHONPATH"] = str(ROOT)
    return env


def mpirun(nranks: int, args: list[str], python: str = VENV_PY) -> list[str]:
    """The command running ``python args`` on nranks ranks (scripts/mpirun.sh sets Open MPI's
    root and oversubscribe variables)."""
    return ["bash", str(SCRIPTS / "mpirun.sh"), "-n", str(nranks), python, *args]


# ------------------------------------------------------------------------------ peers


def peer_python(peer: str) -> str:
    """The interpreter that has the peer: DOLFINx in Debian's python3, scikit-fem in the
    bench venv (scripts/bench_env.sh installs both)."""
    return str(BENCH_VENV / "bin" / "python") if peer == "skfem" else DEBIAN_PY


_PEER_MODULE = {"dolfinx": "dolfinx", "skfem": "skfem"}


def peer_available(peer: str) -> bool:
    """Whether the peer code can be imported by its interpreter (a child process: the peer's
    interpreter is not this one)."""
    py = peer_python(peer)
    if not Path(py).exists():
        return False
    try:
        return subprocess.run([py, "-c", f"import {_PEER_MODULE[peer]}"], capture_output=True,
                              timeout=120).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


# ------------------------------------------------------------------------------ machine


def cpu_seconds() -> float:
    """CPU seconds of this process (user + system)."""
    t = os.times()
    return t.user + t.system


def cpu_idle(seconds: float = 1.0) -> float:
    """Fraction of all CPUs idle over the next ``seconds`` (/proc/stat; 1.0 if unavailable)."""
    def stat():
        v = list(map(int, Path("/proc/stat").read_text().split("\n")[0].split()[1:]))
        return sum(v), v[3] + v[4]
    try:
        a = stat()
        time.sleep(seconds)
        b = stat()
        return (b[1] - a[1]) / max(1, b[0] - a[0])
    except OSError:
        return 1.0


def cpu_model() -> str:
    try:
        model = [ln for ln in Path("/proc/cpuinfo").read_text().splitlines()
                 if ln.startswith("model name")]
    except OSError:
        model = []
    return model[0].split(":", 1)[1].strip() if model else (platform.processor() or "?")


def mem_bytes() -> int:
    """Total memory of the machine in bytes (0 if /proc/meminfo is unreadable)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def machine_info() -> dict:
    """What every benchmark records about the machine: CPU model and count, memory,
    architecture, load, date (UTC)."""
    now = datetime.datetime.now(datetime.timezone.utc)
    return dict(cpu=cpu_model(), cpus=os.cpu_count(), mem_gib=round(mem_bytes() / 2 ** 30, 1),
                machine=platform.machine(), loadavg=os.getloadavg()[0],
                loadavg_start=os.getloadavg(), date=now.strftime("%Y-%m-%d %H:%M UTC"))


def load_line(load0, load1) -> str:
    """'load average (1/5/15 min) a/b/c at start, d/e/f at end'."""
    return (f"load average (1/5/15 min) {load0[0]:.2f}/{load0[1]:.2f}/{load0[2]:.2f} at start, "
            f"{load1[0]:.2f}/{load1[1]:.2f}/{load1[2]:.2f} at end")


def utc_now(fmt: str = "%Y-%m-%d %H:%M:%S") -> str:
    return time.strftime(fmt, time.gmtime())


def git_status(path: str = "parsolve") -> str:
    """``git status --short`` of parsolve/ (the benchmarked code is the working tree)."""
    try:
        return subprocess.run(["git", "status", "--short", path], cwd=ROOT, text=True,
                              capture_output=True, timeout=30).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "?"


def proc_memory() -> dict:
    """VmRSS and VmHWM of this process in bytes."""
    out = {"rss": 0, "hwm": 0}
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(("VmRSS:", "VmHWM:")):
                out["rss" if line.startswith("VmRSS") else "hwm"] = int(line.split()[1]) * 1024
    return out


def mat_bytes(A) -> float:
    """Bytes of an assembled AIJ/BAIJ matrix on this rank: allocated nonzeros × (value + column
    index) + row offsets (PETSc 3.18's MatInfo.memory is 0)."""
    import numpy as np
    from petsc4py import PETSc

    info = A.getInfo(PETSc.Mat.InfoType.LOCAL)
    isize = np.dtype(PETSc.IntType).itemsize
    bs = max(int(info["block_size"]), 1)
    rows = A.getLocalSize()[0]
    # a Mat made on the caller's arrays (parsolve's operator) reports nothing allocated
    nz = max(info["nz_allocated"], info["nz_used"])
    return (nz * np.dtype(PETSc.ScalarType).itemsize
            + nz / (bs * bs) * isize + (rows / bs + 1) * isize)


# ------------------------------------------------------------------------------ tables


def fmt(x, spec: str = ".3f", missing: str = "-") -> str:
    return missing if x is None else format(x, spec)


def fmt_rate(x) -> str:
    if x is None:
        return "-"
    return f"{x / 1e6:.2f}M" if x >= 1e6 else f"{x / 1e3:.0f}k"


def mib(x, missing: str = "–") -> str:
    return missing if x is None else f"{x / MiB:,.0f}"


def md_table(head: list[str], rows: list[list[str]], first: str = "---:", rest: str = "---:") -> str:
    """A markdown table; ``first``, ``rest``: the alignment cells of the first and the other
    columns (right-aligned by default)."""
    out = ["| " + " | ".join(head) + " |",
           "|" + "|".join(first if i == 0 else rest for i in range(len(head))) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def text_table(head: list[str], rows: list[list[str]]) -> str:
    """A plain-text table with right-aligned columns (for the terminal)."""
    w = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(head)]

    def line(cells):
        return "  ".join(c.rjust(w[i]) for i, c in enumerate(cells))
    return "\n".join([line(head), "-" * (sum(w) + 2 * (len(w) - 1))] + [line(r) for r in rows])


def publish(name: str, text: str) -> Path:
    """Write a table (markdown) into PUBLISHED (scripts/results/, or the smoke folder)."""
    PUBLISHED.mkdir(parents=True, exist_ok=True)
    path = PUBLISHED / name
    path.write_text(text)
    return path


def write_json(path: Path | str, obj) -> Path:
    """JSON with one-space indentation (every benchmark's format); the parent folder is made."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj, indent=1))
    return path


def read_json(path: Path | str):
    return json.loads(Path(path).read_text())


def scratch(name: str = "") -> Path:
    """A folder under SCRATCH (made)."""
    path = SCRATCH / name if name else SCRATCH
    path.mkdir(parents=True, exist_ok=True)
    return path


def which(cmd: str) -> bool:
    return shutil.which(cmd) is not None
