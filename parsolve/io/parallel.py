"""The result file written by every rank at once (output mode "parallel").

Same file as :class:`parsolve.io.hdf5.ResultWriter` writes (DESIGN §5: same datasets, same
values, input order), but each rank writes the rows of its own nodes and cells of every field,
cell field and of ``/mesh``, collectively through HDF5's MPI-IO driver (h5py's MPI build);
rank 0 alone writes the small per-step data (``/steps``, ``/relations``, ``/timings``,
``/balance``) and, at the end, the status.

Design decisions (MPI-IO and SWMR cannot be used on the same file at once):

* **No SWMR: a reader cannot follow the run live.** Read the file once the run is over, or
  between steps at your own risk (a read that overlaps a step's write may fail; it never
  harms the run, which takes no file lock).
* **The file is opened and closed around every step** (collectively). Between steps it is a
  closed, consistent HDF5 file: a run that dies between steps (os._exit, SIGKILL, a node
  failure) leaves every finished step readable by a plain ``h5py.File(path, "r")``, with no
  SWMR flag to clear and no ``recover`` needed. The format is HDF5 1.8's (superblock v2), which
  has no "file open for writing" flag that a crash would leave set. A crash *while* a step is
  being closed can still leave the file damaged (HDF5 without SWMR gives no guarantee there);
  that window is the few metadata writes at the step's close.
* **Checksums**: ``/mesh`` and the field and cell-field datasets carry a Fletcher32 checksum
  per chunk, as in the swmr mode (all written collectively); the small per-step datasets
  (written by rank 0 alone) do not (``_checked``).
* **A step counts only once** ``/steps/time`` **has it** (the commit marker): every other
  dataset of the step is written and flushed (collectively) before ``/steps/time`` is
  extended; after a crash the other datasets may hold one unfinished row more, which
  ``post --recover`` cuts (a hard kill at any point of a step's write is tested:
  :mod:`parsolve.io.faults`).
* **SIGINT / SIGTERM are held while a step is written** (they act right after it), so every
  rank leaves a step's collective calls together; the status is then written by rank 0 alone,
  on the closed file (POSIX driver): closing needs no other rank.
* **Disk full**: rank 0 allocates each step's space (``posix_fallocate``) before any rank
  writes it, so a full disk shows outside HDF5; an error inside a collective HDF5 call is
  agreed on by every rank after that call (``_together``), so no rank is left waiting in the
  next one. Every rank raises the same OutputError (exit 4) and nothing more of the step is
  written; the lock file's reserve (parsolve.io.lock) is given back so that the close and the
  status ("failed: … No space left on device …") find room: the finished steps stay readable
  by a plain reader. (Without that reserve, a run not started by ``parsolve run``, the status
  stays "running".)

Without h5py's MPI build (a run outside ``mpirun`` on Debian picks ``h5py._debian_h5py_serial``)
a one-rank run writes the same file with the POSIX driver; more ranks need the MPI build.
"""

from __future__ import annotations

import os
import shutil
import signal
import time
from contextlib import contextmanager
from pathlib import Path

import h5py
import numpy as np
from mpi4py import MPI

from parsolve import __version__
from parsolve.errors import OutputError
from parsolve.io import faults
from parsolve.io.hdf5 import COMMIT, ResultWriter, _create, create_mesh_dataset, known_datasets
from parsolve.interrupts import SIGNALS
from parsolve.io.lock import free_reserve
from parsolve.io.slabs import OwnedRows, Rows, split_owners
from parsolve.io.xdmf import XdmfWriter, sidecar_path

SELECTIONS = ("blocks", "runs")
CLOSE_WAIT = 30.0  # seconds the other ranks wait at close for rank 0's status
ROOM_BYTES, ROOM_PER_DATASET = 64 << 10, 8 << 10  # metadata room allocated with each step
LIBVER = ("v108", "v108")  # superblock v2: no consistency flags left set by a crash


def _row_form(value: np.ndarray) -> np.ndarray:
    """(rows, ncomp) float64, or the integer type of states (int8 stays int8)."""
    if value.dtype.kind not in "iu":
        value = value.astype(float)
    return value[:, None] if value.ndim == 1 else value


def _checked(name: str) -> bool:
    """Whether a per-step dataset carries a Fletcher32 checksum: the field slabs do (written
    collectively); the small rows rank 0 writes alone do not — HDF5 (1.10) writes filtered
    datasets collectively only, and a collective write would make a failure on rank 0 alone
    a hang of the others."""
    return name.startswith(("fields/", "cell_fields/"))


@contextmanager
def signals_held():
    """SIGINT / SIGTERM (and SIGUSR1 / SIGUSR2: parsolve.interrupts) wait until the block is
    over (then their handlers run as usual)."""
    held = set(SIGNALS)
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def mpi_h5py() -> bool:
    """True when the h5py imported is an MPI build (Debian: under mpirun, or
    H5PY_ALWAYS_USE_MPI set)."""
    return bool(h5py.get_config().mpi)


class ParallelResultWriter(ResultWriter):
    """Collective: every rank calls the constructor, ``write_step`` and ``close`` (the last
    touches the file on rank 0 only). ``owners``: (rank of each node, rank of each cell); by
    default near-equal contiguous blocks. ``selection``: "blocks" or "runs" (module
    :mod:`parsolve.io.slabs`)."""

    def __init__(self, comm, path: str | Path, mesh, scene_text: str, petsc_version: str,
                 relations: dict[str, tuple[int, bool]], xdmf: bool = True,
                 attrs: dict | None = None, owners: tuple | None = None,
                 selection: str = "blocks"):
        if selection not in SELECTIONS:
            raise ValueError(f"selection {selection!r} is not one of {SELECTIONS}")
        # its own communicator: the wait at close never meets another collective call
        self.comm, self.path, self.mesh = comm.Dup(), Path(path), mesh
        self.relations = relations
        self.times: list[float] = []
        self.fields: dict[str, int] = {}
        self.cell_fields: dict[str, int] = {}
        self.file = None
        self.error: str | None = None
        self.output_seconds = 0.0
        self._layout: dict[str, tuple] = {}
        self._known: dict[str, tuple] = {}
        self._xdmf = XdmfWriter(self.path, mesh) if xdmf else None
        self.attrs = attrs or {}
        self.selection = selection
        node_owner, cell_owner = owners if owners is not None else (
            split_owners(mesh.num_points, comm.size), split_owners(mesh.num_cells, comm.size))
        self.rows = {kind: owner if isinstance(owner, Rows) else Rows(self.comm, owner)
                     for kind, owner in (("fields", node_owner), ("cell_fields", cell_owner))}
        self.mpio = mpi_h5py()
        if comm.size > 1 and not self.mpio:
            raise OutputError(f"writing {self.path} in parallel needs h5py's MPI build "
                              "(Debian: python3-h5py-mpi, run under mpirun)")
        self._dxpl = None
        if self.mpio:
            self._dxpl = h5py.h5p.create(h5py.h5p.DATASET_XFER)
            self._dxpl.set_dxpl_mpio(h5py.h5fd.MPIO_COLLECTIVE)
        with signals_held():
            if comm.rank == 0:
                try:  # unlink, never truncate: a reader of the previous result keeps its copy
                    self.path.parent.mkdir(parents=True, exist_ok=True)
                    for old in (self.path, self.path.with_suffix(".xdmf"), sidecar_path(self.path)):
                        old.unlink(missing_ok=True)
                except OSError as exc:
                    self._fail(exc, "creating")
            self._raise_if_failed()
            try:
                self._open(scene_text, petsc_version)
            except (OSError, RuntimeError) as exc:
                self._fail(exc, "creating")
            self._raise_if_failed()

    # ------------------------------------------------------------------ the file
    def _h5(self, mode: str) -> h5py.File:
        """The result, opened by every rank (MPI-IO) or, without MPI, by this one."""
        extra = {"driver": "mpio", "comm": self.comm} if self.mpio else {}
        return h5py.File(self.path, mode, libver=LIBVER, rdcc_nbytes=0, **extra)

    def _open(self, scene_text: str, petsc_version: str) -> None:
        """Create the file: attributes, /mesh, the datasets known before any step. Every
        collective call is agreed on (``_together``) as in ``_write``."""
        mesh, doing, box = self.mesh, "creating", {}

        def create():
            f = box["f"] = self._h5("w")
            # attributes are metadata: every rank sets the same values
            f.attrs.update(parsolve_version=__version__, petsc_version=petsc_version,
                           nprocs=self.comm.size, status="running", scene=scene_text, **self.attrs)

        ok = self._together(doing, self._room_for_mesh)
        ok = ok and self._together(doing, create)
        f = box.get("f")
        for name, data, kind in (("mesh/points", mesh.points, "fields"),
                                 (f"mesh/cells/{mesh.cell_type}", mesh.cells, "cell_fields")):
            rows = self.rows[kind].local(data)
            if ok:
                ok = self._together(doing, lambda: self._write_rows(
                    create_mesh_dataset(f, name, (self.rows[kind].n,) + rows.shape[1:],
                                        rows.dtype), None, kind, rows))
        if ok:
            known = known_datasets(self.relations).items()
            ok = self._together(doing, lambda: [_create(f, name, shape, dtype, _checked(name))
                                                for name, (shape, dtype) in known])
        for name, (shape, dtype) in known_datasets(self.relations).items():
            self._known[name] = (shape, np.dtype(dtype))
        self._close_step(f, ok, doing)

    def _together(self, doing: str, action) -> bool:
        """Run ``action`` (collective on the file, or a no-op on some ranks), then agree: True
        when no rank has failed so far. Every rank makes the same calls up to the first failure
        any rank sees, and none after it, so none waits for a rank that left (disk full on one
        rank only would otherwise hang the run, or crash it inside MPI-IO)."""
        if self.error is None:
            try:
                action()
            except (OSError, RuntimeError) as exc:   # h5py reports some as RuntimeError
                self._fail(exc, doing)
        return not self.comm.allreduce(self.error is not None, op=MPI.LOR)

    def _close_step(self, f, ok: bool, doing: str) -> None:
        """Close the file collectively. After a failure rank 0 first frees the lock file's
        reserve (parsolve.io.lock), so that the metadata the close writes finds room."""
        self.file = None
        if not ok:
            if self.comm.rank == 0:
                self._room = free_reserve(self.path)
            self._room = self.comm.bcast(getattr(self, "_room", False), root=0)
        if f is not None and ok:
            self._together(doing, f.close)
        elif f is not None:
            self._close_quietly(f)

    def _fail(self, exc: OSError, doing: str, path: Path | None = None) -> None:
        # MPI-IO reports a full disk as "file write failed", without the errno
        super()._fail(exc, doing, path)
        try:
            full = shutil.disk_usage(self.path.parent).free < ROOM_BYTES
        except OSError:
            full = False
        if full and "No space left" not in self.error:
            self.error = self.error.replace(" failed: ", " failed: No space left on device (", 1) \
                .replace("; the ", "); the ", 1)

    def _close_quietly(self, f) -> None:
        try:
            f.close()
        except (OSError, RuntimeError):
            pass
        self.comm.Barrier()

    def _raise_if_failed(self) -> None:
        """Collective: any rank's failure becomes every rank's OutputError."""
        errors = [e for e in self.comm.allgather(self.error) if e is not None]
        if errors:
            self.error = errors[0]
            raise OutputError(self.error)

    # ------------------------------------------------------------------ steps
    def write_step(self, t: float, iterations: int, residual: float, fields: dict, cell_fields: dict,
                   relations: dict, timings: dict, extra: dict | None = None) -> None:
        """As ResultWriter.write_step; every rank passes its values (module slabs: the whole
        array, None on ranks other than 0, or OwnedRows)."""
        if self.error is not None:
            raise OutputError(self.error)
        start = time.perf_counter()
        small, slabs = self._split(t, iterations, residual, fields, cell_fields, relations,
                                   timings, extra or {})
        with signals_held():
            if not self._layout:
                self._make_layout(small, slabs)
            slabs = self._scatter_missing(slabs)
            self._write(small, slabs)
            self.times.append(t)
            if self._xdmf is not None and self.comm.rank == 0:
                try:
                    self._xdmf.append(len(self.times) - 1, t, self.fields, self.cell_fields)
                except (OSError, RuntimeError) as exc:
                    self._fail(exc, "writing", self._xdmf.path)
            self._raise_if_failed()
        self._full_values = {}
        self.output_seconds = time.perf_counter() - start

    def _split(self, t, iterations, residual, fields, cell_fields, relations, timings,
               extra) -> tuple[dict, dict]:
        """(rank 0's small rows by dataset, this rank's slab rows by dataset: None when rank 0
        must send them). The same dataset names on every rank."""
        small = {"steps/iterations": np.int64(iterations), "steps/residual": np.float64(residual)}
        small.update({name: np.asarray(value) for name, value in extra.items()})
        for name, data in relations.items():
            for key, value in data.items():
                small[f"relations/{name}/{key}"] = np.asarray(value)
        for name, value in timings.items():
            small[f"timings/{name}"] = np.float64(value)
        slabs, self._full_values = {}, {}
        for group, data in (("fields", fields), ("cell_fields", cell_fields)):
            for name, value in data.items():
                local = self.rows[group].local(value)
                if local is not None:
                    local = _row_form(local)
                    if value is not None and not isinstance(value, OwnedRows):
                        self._full_values[f"{group}/{name}"] = value  # rank 0 may have to scatter it
                slabs[f"{group}/{name}"] = local
        expected = self._layout or self._known
        missing = set(expected) - set(small) - set(slabs) - {"steps/time"}
        if any(not name.startswith("timings/") for name in missing):
            raise ValueError(f"datasets {sorted(missing)} are missing from step {len(self.times) + 1}")
        for name in missing:
            small[name] = np.float64(0.0)  # a phase that did not run this step took no time
        if self._layout and (set(small) | set(slabs)) - set(self._layout):
            raise ValueError(f"datasets {sorted((set(small) | set(slabs)) - set(self._layout))} "
                             "were not in the first step")
        small["steps/time"] = np.float64(t)
        return small, slabs

    def _make_layout(self, small: dict, slabs: dict) -> None:
        """Rank 0's shapes and types of every per-step dataset, known to every rank (the
        datasets are created collectively, with the same calls everywhere)."""
        layout = None
        if self.comm.rank == 0:
            layout = dict(self._known)
            for name, value in small.items():
                if name not in layout:
                    layout[name] = (value.shape, value.dtype)
            for name, local in slabs.items():
                n = self.rows[name.split("/")[0]].n
                layout[name] = ((n, local.shape[1]), local.dtype)
        self._layout = self.comm.bcast(layout, root=0)
        for name, (shape, _) in self._layout.items():
            group, _, short = name.partition("/")
            if group in ("fields", "cell_fields"):
                getattr(self, group)[short] = shape[1]

    def _scatter_missing(self, slabs: dict) -> dict:
        """Rows that only rank 0 has (averaged nodal outputs, gathered cell values today):
        scattered to their owners, one Scatterv per dataset."""
        names = sorted(slabs)
        flags = np.array([slabs[n] is None for n in names], dtype=np.uint8)
        self.comm.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
        out = dict(slabs)
        for name, missing in zip(names, flags):
            if missing:
                shape, dtype = self._layout[name]
                full = None
                if self.comm.rank == 0:
                    full = np.asarray(self._full_values[name], dtype=dtype).reshape(shape)
                out[name] = self.rows[name.split("/")[0]].scatter(full, shape[1:], dtype)
        return out

    def _write(self, small: dict, slabs: dict) -> None:
        """One step: open, extend, slabs (collective), small rows (rank 0), flush, then
        /steps/time, close; every rank agrees after each of these (``_together``)."""
        step = len(self.times)
        doing, box = f"writing step {step + 1} to", {}

        def open_and_extend():
            f = box["f"] = self.file = self._h5("r+")
            if step == 0:
                for name, (shape, dtype) in self._layout.items():
                    if name not in self._known:
                        _create(f, name, shape, dtype, _checked(name))
            for name in self._layout:
                if name != COMMIT:
                    f[name].resize(step + 1, axis=0)

        def small_rows():               # independent writes: no other rank waits
            if self.comm.rank == 0:
                for name, value in small.items():
                    if name != COMMIT:
                        self._append(name, value)

        def step_time():                # last: the step now counts
            ds = box["f"][COMMIT]
            ds.resize(step + 1, axis=0)
            if self.comm.rank == 0:
                ds[step] = small[COMMIT]

        def act(action) -> bool:
            ok = self._together(doing, action)
            faults.passed(step + 1)
            return ok

        faults.step_begins(step + 1)
        ok = act(self._make_room)
        ok = ok and act(open_and_extend)
        for name in sorted(slabs):      # the same order on every rank
            ok = ok and act(lambda: self._append(name, slabs[name]))
        for action in (small_rows, lambda: box["f"].flush(), step_time):
            ok = ok and act(action)
        self._close_step(box.get("f"), ok, doing)
        faults.passed(step + 1)
        faults.step_ends(step + 1)
        self._raise_if_failed()

    def _room_for_mesh(self) -> None:
        """Rank 0: a disk without room for /mesh fails before the file is created."""
        if self.comm.rank != 0:
            return
        widths = {kind: np.shape(getattr(data, "values", data))[1] for kind, data in
                  (("fields", self.mesh.points), ("cell_fields", self.mesh.cells))}
        need = ROOM_BYTES + 8 * sum(self.rows[kind].n * w for kind, w in widths.items())
        if shutil.disk_usage(self.path.parent).free < need:
            raise OSError(28, "No space left on device")

    def _make_room(self) -> None:
        """Rank 0 allocates the disk space of the coming step (its rows plus room for the
        metadata) at the end of the file before any rank writes: a full disk shows here, as one
        rank's OSError outside HDF5. Inside HDF5's collective calls a write error on one rank
        leaves the others waiting in the call (tested: a hang at 2 ranks, a crash at 3), and
        the half-written metadata a file no reader opens. HDF5 places new data at its own end
        of the file, inside this space, and cuts the rest off when the file is closed."""
        if self.comm.rank != 0:
            return
        need = ROOM_BYTES + sum(ROOM_PER_DATASET + int(np.prod(shape, dtype=np.int64)) *
                                np.dtype(dtype).itemsize for shape, dtype in self._layout.values())
        fd = os.open(self.path, os.O_WRONLY)
        try:
            os.posix_fallocate(fd, os.fstat(fd).st_size, need)
        finally:
            os.close(fd)

    def _append(self, name: str, value) -> None:
        """Row ``len(self.times)`` of one dataset (already extended): a slab written by every
        rank, or a small row written by rank 0."""
        ds = self.file[name]
        step = len(self.times)
        group = name.split("/")[0]
        if group in ("fields", "cell_fields"):
            self._write_rows(ds, step, group, value)
        else:
            ds[step] = value

    def _write_rows(self, ds, step: int | None, kind: str, local: np.ndarray) -> None:
        """This rank's rows (owned ids, increasing) of a (n, w) dataset or of row ``step`` of a
        (nsteps, n, w) one, in one collective write."""
        rows = self.rows[kind]
        local = np.ascontiguousarray(local, dtype=ds.dtype)
        width = local.shape[1:]
        prefix = () if step is None else (step,)
        one = () if step is None else (1,)
        fspace = ds.id.get_space()
        if self.selection == "blocks":
            first, local = rows.to_block(local)
            starts, lengths = np.array([first]), np.array([local.shape[0]])
        else:
            starts, lengths = rows.starts, rows.lengths
        starts, lengths = starts[lengths > 0], lengths[lengths > 0]
        if starts.size == 0:
            fspace.select_none()
            mspace = h5py.h5s.create_simple((1,))
            mspace.select_none()
            local = np.zeros(1, dtype=ds.dtype)
        else:
            op = h5py.h5s.SELECT_SET
            for s, n in zip(starts.tolist(), lengths.tolist()):  # runs of rows, not rows
                fspace.select_hyperslab(prefix + (s,) + (0,) * len(width),
                                        one + (n,) + tuple(width), op=op)
                op = h5py.h5s.SELECT_OR
            mspace = h5py.h5s.create_simple(local.shape)
        ds.id.write(mspace, fspace, local, dxpl=self._dxpl)

    # ------------------------------------------------------------------ the end
    def close(self, status: str) -> None:
        """Record ``status`` (rank 0, on the closed file: no other rank needed). A failed write
        wins over the caller's status; no finished step is never "complete"."""
        if getattr(self, "closed", False):
            return
        self.closed = True
        if self.error is not None:
            status = f"failed: {self.error}"
        elif status == "complete" and not self.times:
            status = "failed: no step finished"
        self.status = status
        if self.file is not None:  # an exception inside a step (every rank gets here)
            f, self.file = self.file, None
            try:
                f.close()
            except (OSError, RuntimeError):
                pass
        if self._xdmf is not None:
            try:
                self._xdmf.close()
            except (OSError, RuntimeError):
                pass
        # after a failed write nothing more goes in, unless the reserve made room for the status
        if self.comm.rank == 0 and (self.error is None or getattr(self, "_room", False)):
            with signals_held():
                try:
                    with h5py.File(self.path, "r+", locking=False) as f:
                        self._trim(f)
                        f.attrs["status"] = status
                        if getattr(self, "notes", None):
                            f.attrs["warnings"] = "\n".join(self.notes)
                except (OSError, RuntimeError):
                    pass  # the file was never created (its OutputError was raised then)
        self._wait_for_rank0()

    def _wait_for_rank0(self, seconds: float = CLOSE_WAIT) -> None:
        """The other ranks wait (a bounded time) until rank 0 has written the status: under
        mpirun the first rank to exit with a non-zero status (3, 130, 143) gets the others
        killed, rank 0 included, maybe before the status is in the file. Bounded, because
        after a signal rank 0 may be stuck in a collective call of the solver."""
        request = self.comm.Ibarrier()
        deadline = time.monotonic() + seconds
        while not request.Test():
            if time.monotonic() > deadline:
                return  # (the communicator is left as it is: a rank never came)
            time.sleep(0.005)
        self.comm.Free()

    def _trim(self, f: h5py.File) -> None:
        n = len(self.times)
        for name in self._layout or self._known:
            if name in f and f[name].shape[0] > n:
                f[name].resize(n, axis=0)
