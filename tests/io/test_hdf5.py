"""The result file survives a run that dies: every finished step is readable."""

import os
import subprocess
import sys
import textwrap

import h5py
import numpy as np
import pytest

pytestmark = pytest.mark.serial


def test_killed_run_keeps_finished_steps(tmp_path):
    """Write two steps, then die without closing (no exception handler runs)."""
    out = tmp_path / "r.h5"
    code = textwrap.dedent(f"""
        import os, numpy as np
        from mpi4py import MPI
        from parsolve.io.hdf5 import ResultWriter
        from parsolve.mesh.generators import rectangle
        mesh = rectangle(1.0, 1.0, 2, 2)
        w = ResultWriter(MPI.COMM_WORLD, r"{out}", mesh, "scene", "3.18", {{"r": (2, True)}})
        for t in (0.5, 1.0):
            w.write_step(t, 3, 1e-9, {{"displacement": np.full((9, 2), t)}},
                         {{"stress": np.zeros((4, 3))}},
                         {{"r": {{"multiplier": [t, 0], "primal": [0, t], "active": [1, 0]}}}},
                         {{"total": 0.1}})
        os._exit(1)
    """)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert proc.returncode == 1, proc.stderr
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "running"   # it never finished
        np.testing.assert_array_equal(f["steps/time"][()], [0.5, 1.0])
        np.testing.assert_array_equal(f["fields/displacement"][1], np.full((9, 2), 1.0))
        np.testing.assert_array_equal(f["relations/r/active"][()], [[1, 0], [1, 0]])
    assert out.with_suffix(".xdmf").exists()
