"""The local executor end to end: results equal the analytic end force, manifest, resume,
failed runs, Ctrl-C."""

import csv
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from batch_helpers import BAR, check_bar, clean_env, end_force, jobs_file, parsolve
from parsolve.batch import Run, effective_scene, execute, outcomes

pytestmark = pytest.mark.serial  # runs subprocesses


def bar_runs(values, steps=2, ranks=lambda i: 1):
    return [Run(f"E{i}", effective_scene(BAR, {"materials[0].E": E, "steps.count": steps}),
                ranks=ranks(i), params={"materials[0].E": E}) for i, E in enumerate(values)]


def manifest(root):
    with open(root / "manifest.csv", newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("parallel", [1, 2])
def test_execute_resume(parallel, tmp_path):
    values = [1e9, 2e9, 3e9]
    runs = bar_runs(values, ranks=lambda i: 2 if i == 1 else 1)
    lines = []
    out = execute(runs, tmp_path, parallel=parallel, log=lines.append)
    assert [o.status for o in out] == ["complete"] * 3, [o.status for o in out]
    for o, E in zip(out, values):
        check_bar(o.result, E, 2)
        assert o.folder == tmp_path / o.name and o.exit_code == 0 and o.seconds > 0
        assert (o.folder / "scene.toml").read_text() == runs[values.index(E)].scene_text
        assert (o.folder / "stdout.txt").read_text().strip()  # the run's progress lines
    import h5py

    with h5py.File(out[1].result) as f:
        assert f.attrs["nprocs"] == 2  # the run with 2 ranks ran under mpirun -n 2
    rows = manifest(tmp_path)
    assert [r["name"] for r in rows] == ["E0", "E1", "E2"]
    assert [float(r["materials[0].E"]) for r in rows] == values
    assert [r["ranks"] for r in rows] == ["1", "2", "1"]
    assert all(r["status"] == "complete" and r["exit_code"] == "0" and float(r["seconds"]) > 0
               for r in rows)
    assert [r["result"] for r in rows] == [str(o.result) for o in out]
    # resume: nothing to run
    stamps = [o.result.stat().st_mtime_ns for o in out]
    lines.clear()
    again = execute(runs, tmp_path, parallel=parallel, log=lines.append)
    assert "3 already complete, 0 to run" in lines[0] and len(lines) == 1
    assert [o.result.stat().st_mtime_ns for o in again] == stamps
    assert [o.status for o in again] == ["complete"] * 3
    # a lost result runs again, alone
    out[2].result.unlink()
    assert outcomes(tmp_path)[2].status.startswith("failed")
    lines.clear()
    again = execute(runs, tmp_path, parallel=parallel, log=lines.append)
    assert "2 already complete, 1 to run" in lines[0] and lines[1].endswith("E2: complete")
    assert [o.result.stat().st_mtime_ns for o in again[:2]] == stamps[:2]
    check_bar(again[2].result, values[2], 2)
    # a changed scene is not "complete": its run starts again
    changed = bar_runs([1e9], steps=3)
    lines.clear()
    again = execute(changed, tmp_path, parallel=parallel, log=lines.append)
    assert "0 already complete, 1 to run" in lines[0]
    check_bar(again[0].result, 1e9, 3)


def test_failed_run_recorded_and_retried(tmp_path):
    good = bar_runs([1e9])[0]
    bad = Run("bad", good.scene_text.replace("nu = 0.0", 'nu = "magic"'))  # parsolve run: exit 2
    out = execute([good, bad], tmp_path, parallel=2, log=lambda m: None)
    assert out[0].status == "complete"
    assert out[1].status.startswith("failed: exit 2") and out[1].exit_code == 2
    assert "magic" in out[1].status  # the run's one-line error
    rows = manifest(tmp_path)
    assert rows[1]["status"].startswith("failed: exit 2") and rows[1]["exit_code"] == "2"
    lines = []
    execute([good, bad], tmp_path, log=lines.append)
    assert "1 already complete, 1 to run" in lines[0]


def test_cli_local(tmp_path):
    path = jobs_file(tmp_path, 'parallel = 2\n[grid]\n"materials[0].E" = [1e9, 4e9]\n'
                     '"steps.count" = [2]\n')
    proc = parsolve("batch", path)
    assert proc.returncode == 0, proc.stderr
    assert "2 runs: 2 complete" in proc.stdout
    rows = manifest(tmp_path / "runs")
    for row in rows:
        check_bar(row["result"], float(row["materials[0].E"]), 2)
    assert {r["name"] for r in rows} == {"E=1e+09", "E=4e+09"}
    proc = parsolve("batch", path, "--collect")
    assert proc.returncode == 0 and "2 complete" in proc.stdout


@pytest.mark.parametrize("inherited", [signal.SIG_DFL, signal.SIG_IGN], ids=["default", "ignored"])
def test_ctrl_c_stops_children(tmp_path, inherited):
    # long runs (many steps), 2 at a time; SIGINT to the batch as a terminal's Ctrl-C would.
    # "ignored": the batch started from a script's background (`cmd &`), which inherits
    # SIGINT ignored; `kill -INT` stops it all the same, as it does `parsolve run`
    path = jobs_file(tmp_path, 'parallel = 2\n[grid]\n"materials[0].E" = [1e9, 2e9, 3e9]\n'
                     '"steps.count" = [100000]\n')
    proc = subprocess.Popen([sys.executable, "-m", "parsolve", "batch", str(path)], env=clean_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, inherited))
    root = tmp_path / "runs"
    deadline = time.time() + 120
    while time.time() < deadline and len(list(root.glob("*/result.h5"))) < 2:
        time.sleep(0.2)
    time.sleep(1.0)
    pids = [int(p.read_text()) for p in root.glob("*/pid")]
    assert len(pids) == 2
    # meanwhile another batch on the same root leaves the running runs alone
    from parsolve.batch.jobs import load_jobs

    running = [r for r in load_jobs(path).runs if (root / r.name / "pid").exists()]
    lines = []
    out = execute(running, root, log=lines.append)
    assert "0 to run (local), 2 still running elsewhere" in lines[0], lines
    assert [o.status for o in out] == ["running elsewhere"] * 2
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)   # a hang guard (a loaded machine took over 60 s)
    assert proc.returncode == 130, err
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.killpg(pid, 0)  # no process of the run's group is left
    rows = manifest(root)
    states = sorted(r["status"].split(":")[0] for r in rows)
    assert states == ["interrupted", "interrupted", "missing"], rows
    assert {r["exit_code"] for r in rows if r["status"].startswith("interrupted")} <= {"130", "143"}


def test_stop_under_mpirun_lets_every_rank_finish_its_step(tmp_path):
    """A 2-rank run stopped by the batch: SIGUSR2 to mpirun (forwarded at once, read as
    SIGTERM), so every rank ends its step and exits 143 with its file closed and readable —
    not Open MPI's SIGTERM-then-SIGKILL of the ranks."""
    import h5py

    from parsolve.batch import runner

    folder = tmp_path / "run"
    text = BAR.read_text().replace("count = 10", "count = 100000")
    runner.prepare(folder, text, 2, [], {})
    proc = runner.start(folder)
    result = folder / runner.RESULT
    deadline = time.time() + 120
    while time.time() < deadline and not (folder / runner.STDOUT).read_text().count("step"):
        time.sleep(0.2)
    time.sleep(1.0)
    code = runner.stop(proc, grace=60.0)
    assert runner.exit_status(code) == 143, (folder / runner.STDERR).read_text()
    with pytest.raises(ProcessLookupError):
        os.killpg(proc.pid, 0)   # no process of the run's group is left
    with h5py.File(result, "r") as f:
        assert f.attrs["status"].startswith("interrupted: SIGTERM"), f.attrs["status"]
        steps = len(f["steps/time"])
        delta = f["relations/control/primal"][:steps, 0]
    assert steps >= 1
    np.testing.assert_allclose(delta, 1e-4 * np.arange(1, steps + 1) / 100000, rtol=1e-10)
