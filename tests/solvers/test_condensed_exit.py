"""A process whose condensed preconditioner (a python PC) is still alive at exit, held by an
uncaught exception's traceback (Python keeps it as sys.last_* past the exit handlers) or by a
module's global, exits with its own status, not a segmentation fault: the PC destroyed in the
interpreter's teardown called into a finished interpreter (the 3D ironing refined 8x, whose
run ends in a Newton failure, ended so on the iterative preset). Run as processes, on 1 and 2
ranks."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from helpers.scene import scene, shipped

pytestmark = pytest.mark.serial   # (the processes start their own ranks)

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = textwrap.dedent("""
    import sys
    sys.path[:0] = [{tests!r}]
    from conftest import solve_in_process

    def held():
        system, solver, mat, rhs, x = solve_in_process(open({path!r}).read(), options={{}})
        assert solver.choice == "condensed", solver.choice
        return solver

    if {raise_!r}:
        def frame():
            solver = held()
            raise RuntimeError("the end, the solver in this frame")
        frame()
    kept = held()   # (a module's global at exit)
    print("the end, the solver in a global", flush=True)
""")


@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("raise_", [True, False])
def test_a_condensed_solver_alive_at_exit_exits_cleanly(tmp_path, ranks, raise_):
    data = shipped("contact_ironing_3d.toml")
    data["mesh"]["file"] = str(ROOT / "configs" / data["mesh"]["file"])
    path = tmp_path / "ironing.toml"
    path.write_text(scene(data, steps={"times": [0.05]}, solver={"preset": "iterative"}))
    script = tmp_path / "held.py"
    script.write_text(SCRIPT.format(tests=str(ROOT / "tests"), path=str(path), raise_=raise_))
    cmd = [sys.executable, str(script)]
    if ranks > 1:
        cmd = ["bash", str(ROOT / "scripts" / "mpirun.sh"), "-n", str(ranks)] + cmd
    # (this pytest process is itself an MPI singleton: its MPI variables kept from the child)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    env["PETSC_OPTIONS"] = "-no_signal_handler"   # (a crash is the signal, not PETSc's abort)
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env, cwd=ROOT)
    if raise_:
        assert "RuntimeError: the end, the solver in this frame" in res.stderr
    else:
        assert res.stdout.count("the end, the solver in a global") == ranks
    assert res.returncode == int(raise_), res.stderr[-2000:]
