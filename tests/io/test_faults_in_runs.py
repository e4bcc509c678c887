"""A full disk in the middle of a real run, on any number of ranks: every rank stops with the
same OutputError, and the finished steps stay readable."""

import errno
import os

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from helpers.xdmf import SCENE_2D
from parsolve.errors import OutputError
from parsolve.io.hdf5 import ResultWriter


def test_disk_full_stops_every_rank_and_keeps_the_finished_steps(run, monkeypatch):
    original = ResultWriter._append

    def full(self, name, value):   # rank 0 writes; the disk fills during the third step
        if name == "fields/stress" and len(self.times) == 2:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        original(self, name, value)

    monkeypatch.setattr(ResultWriter, "_append", full)
    text = SCENE_2D.replace("count = 3", "count = 5")
    with pytest.raises(OutputError, match="No space left on device; the 2 finished step"):
        run(text, name="full")
    MPI.COMM_WORLD.Barrier()
    with h5py.File(run.last, "r") as f:
        assert f.attrs["status"] == "running"
        n = len(f["steps/time"])
        assert n == 2
        np.testing.assert_allclose(f["steps/time"][()], [0.2, 0.4], rtol=1e-15)
        u = f["fields/displacement"][:n]
    # the finished steps are the linear solution: displacement proportional to the load
    np.testing.assert_allclose(u[1], 2 * u[0], rtol=1e-12, atol=1e-15)
    assert np.abs(u[0]).max() > 0
