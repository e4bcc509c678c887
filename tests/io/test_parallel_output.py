"""Output mode "parallel" (issue 8): every rank writes its own rows of every field into the result
file (MPI-IO, collectively), rank 0 the small per-step data. The file is the one the "swmr" mode
writes, dataset by dataset; XDMF, disk full, interruption and a crash between steps behave as
in that mode. Runs on 1, 2 and 3 ranks (subprocess tests: serial, they start their own ranks)."""

import errno
import os
import signal
import subprocess
import sys
import time
import tomllib

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from conftest import CONFIGS, ROOT
from helpers.scene import scene as build, shipped
from helpers.xdmf import SCENE_2D, SCENE_3D, meshio_reads_every_step, vtk_reads_every_step
from parsolve import driver
from parsolve.errors import Interrupted, OutputError
from parsolve.io.hdf5 import ResultWriter
from parsolve.io.parallel import ParallelResultWriter
from parsolve.io.slabs import OwnedRows, Rows, block_bounds, runs
from parsolve.mesh.generators import rectangle
from parsolve.model import build_model
from parsolve.scene import load_scene

SOLUBILITY = build(shipped("solubility_grow_shrink.toml"), steps={"count": 6})
CONTACT = (CONFIGS / "contact_block_friction.toml").read_text()
BASE_2D = tomllib.loads(SCENE_2D)
FIVE_STEPS_2D = build(BASE_2D, steps={"count": 5})   # SCENE_2D has 3


def datasets(path) -> dict:
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, o[()]) if isinstance(o, h5py.Dataset) else None)
        out["attrs"] = dict(f.attrs)
    return out


class Tee:
    """Both modes' writers fed the very same steps by one run."""

    def __init__(self, *writers):
        self.writers = writers

    def write_step(self, *args, **kw):
        for w in self.writers:
            w.write_step(*args, **kw)

    def note(self, text):
        for w in self.writers:
            w.note(text)

    def close(self, status):
        for w in self.writers:
            w.close(status)


@pytest.mark.parametrize("text", [SCENE_2D, SCENE_3D, SOLUBILITY, CONTACT],
                         ids=["2d", "3d", "solubility", "contact"])
def test_parallel_file_is_the_swmr_file(text, run, monkeypatch):
    """Every dataset (mesh, fields, cell fields, states, relations, balance, steps) and every
    attribute is the same in both modes; only the timings may differ."""
    def both(mode, comm, path, mesh, *args, owners=None, **kw):
        return Tee(ResultWriter(comm, path, mesh, *args, owners=owners, **kw),
                   ParallelResultWriter(comm, str(path).replace(".h5", "_par.h5"), mesh, *args,
                                        owners=owners, **kw))

    monkeypatch.setattr(driver, "result_writer", both)
    swmr = run(text)
    par = datasets(str(run.last).replace(".h5", "_par.h5"))
    assert par.keys() == swmr.keys()
    for name, expected in swmr.items():
        if name == "attrs":
            assert par[name].keys() == expected.keys()
            for key, value in expected.items():
                assert par[name][key] == value, key
        elif not name.startswith("timings/"):
            assert par[name].dtype == expected.dtype and par[name].shape == expected.shape, name
            np.testing.assert_allclose(par[name], expected, rtol=1e-15, atol=0, err_msg=name)
    assert swmr["attrs"]["status"] == "complete" and swmr["attrs"]["nprocs"] == MPI.COMM_WORLD.size
    assert len(swmr["steps/time"]) >= 2


@pytest.fixture
def run_mode(shared_tmp):
    """run_mode(text, mode, name) -> (path, datasets): a scene run through the driver."""
    comm = MPI.COMM_WORLD

    def _run(text: str, mode: str = "parallel", name: str = "result"):
        src, out = shared_tmp / f"{name}.toml", shared_tmp / f"{name}.h5"
        if comm.rank == 0:
            src.write_text(text)
        comm.Barrier()
        model = build_model(load_scene(src), comm)
        try:
            driver.run(comm, model, str(out), {}, log=lambda *a: None, output=mode)
        finally:
            comm.Barrier()  # every rank is done with the file
        return out, datasets(out)

    return _run


def test_parallel_mode_from_the_driver(run_mode):
    """Chosen by the driver's output argument: the file is in input order (the generator's
    points and cells exactly) and holds the linear solution (step k = k × step 1)."""
    _, data = run_mode(SCENE_2D)
    mesh = rectangle(2.0, 1.0, 8, 4, cell="triangle")
    np.testing.assert_array_equal(data["mesh/points"], mesh.points)
    np.testing.assert_array_equal(data["mesh/cells/triangle"], mesh.cells)
    assert data["attrs"]["status"] == "complete"
    assert data["attrs"]["nprocs"] == MPI.COMM_WORLD.size
    np.testing.assert_allclose(data["steps/time"], [1 / 3, 2 / 3, 1.0], rtol=1e-15)
    u = data["fields/displacement"]
    assert u.shape == (3, len(mesh.points), 2)
    np.testing.assert_allclose(u[1], 2 * u[0], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(u[2], 3 * u[0], rtol=1e-12, atol=1e-14)
    assert np.abs(u[0]).max() > 0


@pytest.mark.parametrize("mode", ["swmr", "parallel"])
def test_mesh_datasets_carry_a_checksum(run_mode, mode):
    """/mesh/points and /mesh/cells/<type> carry a Fletcher32 checksum in both modes, as the
    per-step field datasets do, and hold the generator's points and cells exactly; a bit
    changed in either is a read error, not numbers."""
    path, data = run_mode(SCENE_2D, mode, name=f"mesh_{mode}")
    mesh = rectangle(2.0, 1.0, 8, 4, cell="triangle")
    np.testing.assert_array_equal(data["mesh/points"], mesh.points)
    np.testing.assert_array_equal(data["mesh/cells/triangle"], mesh.cells)
    with h5py.File(path, "r") as f:
        assert [f[n].fletcher32 for n in ("mesh/points", "mesh/cells/triangle",
                                          "fields/displacement")] == [True] * 3
        offsets = {n: f[n].id.get_chunk_info(0).byte_offset
                   for n in ("mesh/points", "mesh/cells/triangle")}
    MPI.COMM_WORLD.Barrier()
    if MPI.COMM_WORLD.rank == 0:
        for name, offset in offsets.items():
            damaged = path.with_name(f"damaged_{mode}.h5")
            damaged.write_bytes(path.read_bytes())
            with open(damaged, "r+b") as fh:
                fh.seek(offset + 8)
                byte = fh.read(1)
                fh.seek(offset + 8)
                fh.write(bytes([byte[0] ^ 0x04]))
            with h5py.File(damaged, "r") as f, pytest.raises(OSError):
                f[name][()]
    MPI.COMM_WORLD.Barrier()


@pytest.mark.parametrize("text, dim", [(SCENE_2D, 2), (SCENE_3D, 3)], ids=["2d", "3d"])
def test_xdmf_of_a_parallel_result_reads_in_meshio_and_vtk(text, dim, run_mode):
    path, data = run_mode(text, name=f"xdmf{dim}")
    data = {k: v for k, v in data.items() if k != "attrs"}
    meshio_reads_every_step(path, data, dim)
    vtk_reads_every_step(path, data, dim)


def test_disk_full_exits_4_and_keeps_the_finished_steps(shared_tmp, monkeypatch):
    """The injected ENOSPC of the swmr tests, in the third step's stress: exit status 4 from the
    command line, two finished steps readable; the lock file's reserve (parsolve.io.lock) gave
    the room to write the failure as the status."""
    from parsolve.cli import main

    original = ParallelResultWriter._append

    def full(self, name, value):
        if name == "fields/stress" and len(self.times) == 2:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        original(self, name, value)

    monkeypatch.setattr(ParallelResultWriter, "_append", full)
    monkeypatch.setattr(sys, "excepthook", sys.excepthook)  # main sets its own under MPI
    scene, out = shared_tmp / "full.toml", shared_tmp / "full.h5"
    if MPI.COMM_WORLD.rank == 0:
        scene.write_text(FIVE_STEPS_2D)
    MPI.COMM_WORLD.Barrier()
    assert main(["run", str(scene), "-o", str(out), "--output-mode", "parallel"]) == 4
    MPI.COMM_WORLD.Barrier()
    _check_two_linear_steps(out, f"failed: writing step 3 to {out} failed: No space left on "
                            "device; the 2 finished step(s) stay readable", [0.2, 0.4])


def test_rank0_alone_failing_is_every_ranks_error(run_mode, shared_tmp, monkeypatch):
    """A small dataset (written by rank 0 only) fails: every rank raises the same OutputError
    instead of waiting for rank 0 in the next collective call."""
    original = ParallelResultWriter._append

    def full(self, name, value):
        if name == "steps/residual" and len(self.times) == 1:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        original(self, name, value)

    monkeypatch.setattr(ParallelResultWriter, "_append", full)
    with pytest.raises(OutputError, match="No space left on device; the 1 finished step"):
        run_mode(SCENE_2D, name="rank0")
    with h5py.File(shared_tmp / "rank0.h5", "r") as f:
        assert f.attrs["status"] == "running"
        np.testing.assert_allclose(f["steps/time"][()], [1 / 3], rtol=1e-15)


def test_interrupted_status(shared_tmp, monkeypatch):
    """SIGTERM's exception after the second step: exit 143 from the command line, status
    "interrupted: SIGTERM", two finished steps."""
    from parsolve.cli import main

    original = driver.progress

    def progress(log, comm, step, *args, **kw):
        original(log, comm, step, *args, **kw)
        if step == 2:
            raise Interrupted(signal.SIGTERM, "SIGTERM")

    monkeypatch.setattr(driver, "progress", progress)
    monkeypatch.setattr(sys, "excepthook", sys.excepthook)
    scene, out = shared_tmp / "stop.toml", shared_tmp / "stop.h5"
    if MPI.COMM_WORLD.rank == 0:
        scene.write_text(FIVE_STEPS_2D)
    MPI.COMM_WORLD.Barrier()
    assert main(["run", str(scene), "-o", str(out), "--output-mode", "parallel"]) == 143
    MPI.COMM_WORLD.Barrier()
    _check_two_linear_steps(out, "interrupted: SIGTERM", [0.2, 0.4])


def _check_two_linear_steps(out, status, times):
    with h5py.File(out, "r") as f:   # a plain reader: no SWMR in this mode
        assert f.attrs["status"] == status
        n = len(f["steps/time"])
        np.testing.assert_allclose(f["steps/time"][()], times, rtol=1e-15)
        u = f["fields/displacement"][:n]
        s = f["cell_fields/stress"][:n]
    np.testing.assert_allclose(u[1], 2 * u[0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(s[1], 2 * s[0], rtol=1e-12, atol=1e-12)
    assert np.abs(u[0]).max() > 0


# ---------------------------------------------------------------- runs in their own processes
ENV = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
MPIRUN = ["bash", str(ROOT / "scripts" / "mpirun.sh"), "-n"]

DYING = """
import os, sys
from parsolve.io.parallel import ParallelResultWriter
original = ParallelResultWriter.write_step
def dying(self, *args, **kw):
    original(self, *args, **kw)
    if len(self.times) == 2:
        os._exit(7)            # every rank, between steps 2 and 3: no close, no status
ParallelResultWriter.write_step = dying
from parsolve.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _launch(ranks, args, wait=True):
    """``python ARGS`` on ``ranks`` ranks under mpirun (0: one process without mpirun, which
    imports h5py's serial build: the POSIX driver path)."""
    cmd = ([] if ranks == 0 else MPIRUN + [str(ranks)]) + [sys.executable] + args
    if not wait:
        return subprocess.Popen(cmd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, start_new_session=True)
    return subprocess.run(cmd, env=ENV, capture_output=True, text=True, timeout=300)


@pytest.mark.serial
@pytest.mark.parametrize("ranks", [0, 1, 2, 3])
def test_killed_between_steps_leaves_a_plain_readable_file(ranks, tmp_path):
    """os._exit on every rank after the second step: no close, no status written; a plain
    h5py reader (no SWMR, no recover) opens the file and finds the two steps, and the XDMF
    describes them."""
    import meshio

    scene, out = tmp_path / "s.toml", tmp_path / "s.h5"
    scene.write_text(FIVE_STEPS_2D)
    proc = _launch(ranks, ["-c", DYING, "run", str(scene), "-o", str(out), "--output-mode", "parallel"])
    assert proc.returncode == 7, proc.stderr
    _check_two_linear_steps(out, "running", [0.2, 0.4])
    with h5py.File(out, "r") as f:
        assert f.attrs["nprocs"] == max(ranks, 1)
        lengths = {n: o.shape[0] for n, o in f["fields"].items()}
        assert set(lengths.values()) == {2}, lengths
    with meshio.xdmf.TimeSeriesReader(out.with_suffix(".xdmf")) as r:
        r.read_points_cells()
        assert r.num_steps == 2
        t, point_data, _ = r.read_data(1)
        assert t == 0.4
        with h5py.File(out, "r") as f:
            np.testing.assert_array_equal(point_data["displacement"][:, :2],
                                          f["fields/displacement"][1])


@pytest.mark.serial
@pytest.mark.parametrize("ranks", [0, 2])
def test_sigterm_stops_a_parallel_run(ranks, tmp_path):
    """SIGTERM to every rank in the middle of a long run: exit 143, status "interrupted: SIGTERM" written by rank 0, whole steps only."""
    scene, out = tmp_path / "long.toml", tmp_path / "long.h5"
    scene.write_text(build(shipped("solubility_grow_shrink.toml"), steps={"count": 4000, "end": 80.0}))
    proc = _launch(ranks, ["-m", "parsolve", "run", str(scene), "-o", str(out),
                           "--output-mode", "parallel"], wait=False)
    xdmf, deadline = out.with_suffix(".xdmf"), time.time() + 120
    while time.time() < deadline:   # no live HDF5 reading in this mode: the XDMF counts steps
        time.sleep(0.2)
        if xdmf.exists() and xdmf.read_text().count('<Grid Name="step') >= 3:
            break
    # every rank gets the signal, as from a batch scheduler (the signal to mpirun itself:
    # tests/test_signals.py); the ranks are the children of mpirun, scripts/mpirun.sh's child
    def children(pid):
        return [int(p) for p in subprocess.run(["pgrep", "-P", str(pid)], capture_output=True,
                                               text=True).stdout.split()]
    pids = [proc.pid] if ranks == 0 else children(children(proc.pid)[0])
    assert len(pids) == max(ranks, 1)
    for pid in pids:
        os.kill(pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 143, err
    assert "interrupted by SIGTERM" in err and "Traceback" not in err
    with h5py.File(out, "r") as f:
        assert f.attrs["status"] == "interrupted: SIGTERM"
        n = len(f["steps/time"])
        assert 3 <= n < 4000
        lengths = set()
        f.visititems(lambda name, o: lengths.add(o.shape[0]) if isinstance(o, h5py.Dataset)
                     and not name.startswith("mesh") else None)
        assert lengths == {n}
        c = f["fields/c_s"][()] + f["fields/c_g"][()]
        assert np.isfinite(c).all() and np.abs(c).max() > 0


def test_output_mode_choice():
    """swmr by default; auto picks parallel only from 1M DOFs with ranks on several nodes (here
    one node); an unknown mode is refused."""
    from parsolve.io.hdf5 import AUTO_PARALLEL_DOFS, nodes, output_mode

    comm = MPI.COMM_WORLD
    assert nodes(comm) == 1
    assert output_mode(None, comm, 10) == "swmr"
    assert output_mode("parallel", comm, 10) == "parallel"
    assert output_mode("auto", comm, AUTO_PARALLEL_DOFS) == "swmr"
    with pytest.raises(ValueError, match="not one of"):
        output_mode("fast", comm, 10)


def test_rows_exchanges_match_an_independent_placement():
    """The row bookkeeping of parsolve/io/slabs.py against plain indexing: runs of ids, the
    contiguous blocks made by Alltoallv, Scatterv from rank 0 and Gatherv back."""
    comm = MPI.COMM_WORLD
    starts, lengths = runs(np.array([0, 1, 2, 5, 7, 8]))
    assert starts.tolist() == [0, 5, 7] and lengths.tolist() == [3, 1, 2]
    n = 23
    owner = (np.arange(n) * 7 + 3) % comm.size   # scattered ownership, every rank some rows
    whole = np.arange(n * 2, dtype=float).reshape(n, 2) ** 1.5
    rows = Rows(comm, owner)
    mine = whole[owner == comm.rank]
    first, block = rows.to_block(mine)
    bounds = block_bounds(n, comm.size)
    assert first == bounds[comm.rank]
    np.testing.assert_array_equal(block, whole[bounds[comm.rank]:bounds[comm.rank + 1]])
    np.testing.assert_array_equal(rows.scatter(whole if comm.rank == 0 else None, (2,), float), mine)
    gathered = rows.gather(mine)
    if comm.rank == 0:
        np.testing.assert_array_equal(gathered, whole)
    else:
        assert gathered is None
    np.testing.assert_array_equal(rows.local(OwnedRows(mine)), mine)
    np.testing.assert_array_equal(rows.local(whole), mine)


@pytest.mark.parametrize("cls", [ResultWriter, ParallelResultWriter], ids=["swmr", "parallel"])
def test_owned_rows_make_the_same_file_as_whole_arrays(cls, shared_tmp):
    """Values given as OwnedRows (every rank only its rows, scattered ownership) land where the
    whole arrays do."""
    comm = MPI.COMM_WORLD
    mesh = rectangle(1.0, 1.0, 4, 3)
    owners = ((np.arange(mesh.num_points) * 5) % comm.size, (np.arange(mesh.num_cells) * 3) % comm.size)
    u = np.arange(mesh.num_points * 2, dtype=float).reshape(-1, 2) / 7
    s = np.arange(mesh.num_cells * 3, dtype=float).reshape(-1, 3) / 3
    mine = owners[0] == comm.rank, owners[1] == comm.rank
    paths = [shared_tmp / f"{cls.__name__}_{kind}.h5" for kind in ("owned", "whole")]
    for path, owned in zip(paths, (True, False)):
        w = cls(comm, path, mesh, "scene", "3.18", {"r": (1, False)}, owners=owners)
        for t in (1.0, 2.0):
            fields = {"displacement": OwnedRows(t * u[mine[0]]) if owned else t * u}
            cells = {"stress": OwnedRows(t * s[mine[1]]) if owned else t * s}
            w.write_step(t, 1, 0.0, fields, cells, {"r": {"multiplier": [t], "primal": [0.0]}},
                         {"total": 0.1})
        w.close("complete")
        comm.Barrier()
    owned, whole = datasets(paths[0]), datasets(paths[1])
    np.testing.assert_array_equal(owned["fields/displacement"], [u, 2 * u])
    np.testing.assert_array_equal(owned["cell_fields/stress"], [s, 2 * s])
    np.testing.assert_array_equal(whole["fields/displacement"], owned["fields/displacement"])
    assert owned["attrs"]["status"] == "complete"


def test_output_mode_from_the_scene():
    """[output] mode in the scene: read and checked (exit 2 naming output.mode on a bad one)."""
    from parsolve.errors import InputError
    from parsolve.scene import parse_scene

    text = build(BASE_2D, output={"mode": "parallel"})
    assert parse_scene(tomllib.loads(text), "s.toml", text).output_mode == "parallel"
    assert parse_scene(tomllib.loads(SCENE_2D), "s.toml", SCENE_2D).output_mode is None
    bad = build(BASE_2D, output={"mode": "parralel"})
    with pytest.raises(InputError) as err:
        parse_scene(tomllib.loads(bad), "s.toml", bad)
    assert err.value.key == "output.mode" and err.value.source == "s.toml"
