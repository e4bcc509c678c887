"""One run in its folder: the command, its environment, its outcome file and its status.

A run folder holds ``scene.toml`` (the effective scene), ``spec.json`` (what was asked: ranks,
arguments, parameters), ``result.h5``, ``stdout.txt``, ``stderr.txt`` and, once the process
has ended, ``outcome.json`` (exit code, seconds). The status is read back from these files
only, so the local executor, a SLURM task and a later ``--collect`` agree on it.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

SCENE, RESULT, SPEC, OUTCOME = "scene.toml", "result.h5", "spec.json", "outcome.json"
PID, SLURM_JOB = "pid", "slurm_job"
STDOUT, STDERR = "stdout.txt", "stderr.txt"

# What scripts/mpirun.sh sets: root may run mpirun, more ranks than cores.
MPI_ENV = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMPI_MCA_rmaps_base_oversubscribe": "1", "OMPI_MCA_btl_vader_single_copy_mechanism": "none"}


def command(ranks: int, args: tuple[str, ...] | list[str]) -> list[str]:
    """``parsolve run scene.toml -o result.h5 ARGS``, under ``mpirun -n k`` when k > 1."""
    cmd = [sys.executable, "-m", "parsolve", "run", SCENE, "-o", RESULT, *map(str, args)]
    if ranks > 1:
        cmd = [shutil.which("mpirun") or "mpirun", "-n", str(ranks)] + cmd
    return cmd


def environment() -> dict[str, str]:
    """This process's environment without its own MPI job's variables (a parent that imported
    mpi4py is an MPI singleton: its child must start its own job), plus ``MPI_ENV``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    env.update(MPI_ENV)
    env.setdefault("OMP_NUM_THREADS", "1")
    return env


def write_json(path: Path, data: dict) -> None:
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=1))
    os.replace(tmp, path)  # readers never see half a file


def read_json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def prepare(folder: Path, scene_text: str, ranks: int, args, params: dict) -> None:
    """Write the run's inputs and remove what a previous attempt left."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in (RESULT, OUTCOME, STDOUT, STDERR, PID, SLURM_JOB):
        (folder / name).unlink(missing_ok=True)
    (folder / SCENE).write_text(scene_text)
    write_json(folder / SPEC, {"ranks": ranks, "args": list(map(str, args)), "params": params})


def start(folder: Path) -> subprocess.Popen:
    """Start the run prepared in ``folder``, in its own process group (so that stopping it
    reaches mpirun and every rank, and a terminal's Ctrl-C reaches only the batch)."""
    spec = read_json(folder / SPEC)
    out = open(folder / STDOUT, "w")
    err = open(folder / STDERR, "w")
    try:
        proc = subprocess.Popen(command(spec["ranks"], spec["args"]), cwd=folder, env=environment(),
                                stdout=out, stderr=err, stdin=subprocess.DEVNULL,
                                start_new_session=True)
        (folder / PID).write_text(f"{proc.pid}\n")  # the process group to signal, for whoever needs to
        return proc
    finally:
        out.close()
        err.close()


def finish(folder: Path, exit_code: int, seconds: float) -> None:
    write_json(folder / OUTCOME, {"exit_code": exit_code, "seconds": round(seconds, 3),
                                  "finished": time.time(), "host": os.uname().nodename})


def stop(proc: subprocess.Popen, grace: float = 10.0) -> int:
    """Ask the run to stop (parsolve keeps its finished steps and exits 143), SIGKILL to its
    process group after ``grace`` seconds. One rank: SIGTERM to the group. Under mpirun:
    SIGUSR2 to mpirun alone, which forwards it to every rank at once and which parsolve reads
    as SIGTERM — a SIGTERM to mpirun would reach the ranks as SIGTERM after 1 s and SIGKILL
    soon after, killing a rank in the middle of a step with its file open."""
    first = (signal.SIGUSR2, lambda sig: os.kill(proc.pid, sig)) if _under_mpirun(proc) else \
        (signal.SIGTERM, lambda sig: os.killpg(proc.pid, sig))
    for (sig, send), wait in ((first, grace),
                              ((signal.SIGKILL, lambda sig: os.killpg(proc.pid, sig)), 5.0)):
        try:
            send(sig)
        except ProcessLookupError:
            pass
        try:
            return proc.wait(wait)
        except subprocess.TimeoutExpired:
            continue
    return proc.wait()


def _under_mpirun(proc: subprocess.Popen) -> bool:
    return Path(str(proc.args[0])).name == "mpirun"


def run_here(folder: Path) -> int:
    """Run a prepared folder to its end in the foreground (a SLURM task); SIGTERM / SIGINT
    (scancel, time limit) stop the run and are recorded."""
    t0 = time.perf_counter()
    proc = start(folder)

    def forward(signum, frame):
        raise KeyboardInterrupt

    old = {s: signal.signal(s, forward) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        code = proc.wait()
    except KeyboardInterrupt:
        code = stop(proc)  # parsolve's 143, or -9 after SIGKILL (recorded as 137)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    finish(folder, exit_status(code), time.perf_counter() - t0)
    return code


def exit_status(code: int) -> int:
    return 128 - code if code < 0 else code  # killed by signal n → 128 + n, as a shell says


def active(folder: Path) -> bool:
    """Whether another batch is still running this run: no outcome yet, and its process group
    alive on this machine, or its SLURM task still listed."""
    if (folder / OUTCOME).exists() or not (folder / SPEC).exists():
        return False
    try:
        os.killpg(int((folder / PID).read_text()), 0)
        return True
    except (OSError, ValueError):
        pass
    try:
        job = (folder / SLURM_JOB).read_text().strip()
    except OSError:
        return False
    from parsolve.batch.slurm import listed

    try:
        return listed([job])
    except (OSError, subprocess.SubprocessError):
        return False


def result_status(path: Path) -> str | None:
    """The result file's ``status`` attribute; None when there is no file, a message when the
    file cannot be read."""
    if not path.exists():
        return None
    try:
        import h5py

        with h5py.File(path, "r") as f:
            status = f.attrs.get("status", "no status")
        return status.decode() if isinstance(status, bytes) else str(status)
    except Exception as exc:  # noqa: BLE001 -- a truncated or locked file is a failed run
        return f"unreadable result ({type(exc).__name__})"


def status_of(folder: Path) -> tuple[str, int | None, float | None]:
    """(status, exit code, seconds) of a run folder: "complete" only when the process exited 0
    and the result file says "complete"; "missing" when it never ran; "failed: ..." otherwise."""
    outcome = read_json(folder / OUTCOME)
    result = result_status(folder / RESULT)
    if outcome is None:
        if result is None:
            return "missing", None, None
        return f"incomplete: no exit code (result: {result})", None, None
    code, seconds = outcome.get("exit_code"), outcome.get("seconds")
    if code == 0 and result == "complete":
        return "complete", code, seconds
    if code in (130, 143):
        return f"interrupted: exit {code}" + (f" ({result})" if result else ""), code, seconds
    why = result if result and result not in ("complete", "running") else _last_line(folder / STDERR)
    return f"failed: exit {code}" + (f" ({why})" if why else ""), code, seconds


def _last_line(path: Path) -> str:
    try:
        lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return lines[-1][:200] if lines else ""
