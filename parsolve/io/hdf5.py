"""The result file (DESIGN §5), written step by step by rank 0 (output mode "swmr", the default).

Two output modes write the same file (same datasets and values; :func:`result_writer`):

* ``swmr`` (this module): rank 0 gathers and writes everything, in SWMR mode, so that a reader
  can follow the run live;
* ``parallel`` (:mod:`parsolve.io.parallel`): every rank writes its own rows of every field
  through MPI-IO, rank 0 only the small per-step data; no SWMR (MPI-IO and SWMR exclude each
  other), so the file is read after the run (or between steps), with a plain reader.
* ``auto``: parallel on 2 ranks or more from AUTO_PARALLEL_DOFS DOFs, else swmr.

Rules of the swmr mode:

Guarantees, and the rules a reader follows:

* **Replacing a result never destroys it in place.** The old names (``.h5``, ``.xdmf``,
  ``.xdmf.h5``) are unlinked before the new file is created: a reader holding the old file open
  keeps a valid copy, and the new file has its final name from the start.
* **Readable during the run** with plain h5py, in HDF5's single-writer/multiple-reader mode
  (SWMR): ``/mesh``, ``/steps`` and ``/relations`` are created with the file, the other
  datasets at the first step, then the file switches to SWMR (a reader can open it from the
  end of the first step on). A reader opens it with ``h5py.File(path, "r", swmr=True)`` and
  calls ``refresh()`` on each dataset it reads to see new steps, ``/steps/time`` first. (A plain ``h5py.File(path, "r")`` works once the run has closed the file; after a
  hard kill, -9 or a node failure, only ``swmr=True`` opens it — or run
  ``parsolve post RESULT.h5 --recover``.)
* **A step counts only once all its datasets are written.** ``/steps/time`` is the commit
  marker: each step resizes and writes every other per-step dataset, flushes them to the file,
  and only then extends ``/steps/time`` and flushes again (one flush for all would write the
  metadata in HDF5's order, the marker's maybe first). ``n = len(/steps/time)`` is the number
  of finished steps; a reader takes ``[:n]`` of the other per-step datasets (after a crash in
  the middle of a step they may hold one unfinished row more; a normal close and
  ``post --recover`` trim it). A hard kill at any point of a step's write is tested
  (:mod:`parsolve.io.faults`).
* **Disk full.** Any OSError while writing raises :class:`parsolve.errors.OutputError` (on every
  rank) naming the path; nothing more is written to the file and the finished steps stay
  readable. The status attribute is *not* rewritten then (on a full disk that needs new space
  and HDF5 could no longer close the file): it stays "running"; the exit status 4 and the
  message say what happened. The file has no chunk cache, so a step's data reaches the disk
  inside ``write_step``, where the error is caught, and not later when a dataset is closed.
* ``status`` is "running" during the run; ``close(status)`` writes the caller's status, except
  that a result with no finished step is never "complete".
* Chunks hold one step of a field (fields are written and read a step at a time), so a file is
  its data plus a few kilobytes of metadata.
"""

from __future__ import annotations

import time
from pathlib import Path

import h5py
import numpy as np

from parsolve import __version__
from parsolve.errors import OutputError
from parsolve.io import faults
from parsolve.io.lock import free_reserve
from parsolve.io.slabs import OwnedRows, Rows, split_owners
from parsolve.io.xdmf import XdmfWriter, sidecar_path

COMMIT = "steps/time"  # the commit marker: a step counts once this dataset has its row
STEP_CHUNK = 64  # rows per chunk of the one-number-per-step datasets (/steps/*, /timings/*)
MODES = ("swmr", "parallel", "auto")
AUTO_PARALLEL_DOFS = 1_000_000  # "auto": parallel output from this many DOFs on several nodes


def output_mode(mode: str | None, comm, dofs: int) -> str:
    """The mode a run writes with: "swmr" (rank 0 writes, readers follow the run live) unless
    "parallel" is asked for, or "auto" with ranks on several nodes and a large problem (on one
    node the parallel mode was slower: scripts/results/bench_output.md). Collective."""
    mode = mode or "swmr"
    if mode not in MODES:
        raise ValueError(f"output mode {mode!r} is not one of {MODES}")
    if mode == "auto":
        return "parallel" if dofs >= AUTO_PARALLEL_DOFS and nodes(comm) > 1 else "swmr"
    return mode


def nodes(comm) -> int:
    """How many machines (shared-memory nodes) the ranks run on."""
    from mpi4py import MPI

    if comm.size == 1:
        return 1
    local = comm.Split_type(MPI.COMM_TYPE_SHARED)
    count = comm.allreduce(int(local.rank == 0))
    local.Free()
    return count


def result_writer(mode: str, comm, path, mesh, scene_text: str, petsc_version: str,
                  relations: dict, xdmf: bool = True, attrs: dict | None = None,
                  owners: tuple | None = None) -> "ResultWriter":
    """The writer of output mode ``mode`` ("swmr" or "parallel"; see :func:`output_mode`).
    ``owners``: (rank of each node, rank of each cell), the rows each rank reports."""
    if mode == "parallel":
        from parsolve.io.parallel import ParallelResultWriter

        return ParallelResultWriter(comm, path, mesh, scene_text, petsc_version, relations,
                                    xdmf=xdmf, attrs=attrs, owners=owners)
    return ResultWriter(comm, path, mesh, scene_text, petsc_version, relations, xdmf=xdmf,
                        attrs=attrs, owners=owners)


def _create(f: h5py.File, name: str, row_shape: tuple, dtype, checksum: bool = True) -> None:
    """An empty per-step dataset (0, *row_shape), growable along the steps; ``checksum``: with
    a Fletcher32 checksum per chunk (a damaged chunk is a read error, not numbers)."""
    rows = STEP_CHUNK if not row_shape else 1
    chunks = (rows,) + tuple(max(int(s), 1) for s in row_shape)
    maxshape = (None,) + tuple(max(int(s), 1) for s in row_shape)
    f.create_dataset(name, (0,) + tuple(row_shape), maxshape=maxshape, chunks=chunks, dtype=dtype,
                     fletcher32=checksum)



def create_mesh_dataset(f: h5py.File, name: str, shape: tuple, dtype, data=None) -> h5py.Dataset:
    """A /mesh dataset: one chunk (the whole array, as a field's step is one) with a Fletcher32
    checksum, so that a damaged mesh is a read error, as damaged step data is."""
    chunks = tuple(max(int(s), 1) for s in shape)
    return f.create_dataset(name, tuple(shape), dtype=dtype, data=data, chunks=chunks,
                            fletcher32=True)


def known_datasets(relations: dict) -> dict:
    """{name: (row shape, dtype)} of the per-step datasets known before any step: they exist
    even if no step finishes (a failure before the first step)."""
    known = {"steps/time": ((), np.float64), "steps/iterations": ((), np.int64),
             "steps/residual": ((), np.float64)}
    for name, (nrows, unilateral) in relations.items():
        known[f"relations/{name}/multiplier"] = ((nrows,), np.float64)
        known[f"relations/{name}/primal"] = ((nrows,), np.float64)
        if unilateral:
            known[f"relations/{name}/active"] = ((nrows,), np.int8)
    return known

class ResultWriter:
    """Appends one saved step at a time; only rank 0 touches the file, but ``write_step`` and
    the constructor are collective (every rank raises the same OutputError).

    ``output_seconds``: the time the last ``write_step`` took (for ``/timings/output``).
    ``status``: after ``close``, the status recorded (or that would have been, after a failure).
    """

    def __init__(self, comm, path: str | Path, mesh, scene_text: str, petsc_version: str,
                 relations: dict[str, tuple[int, bool]], xdmf: bool = True,
                 attrs: dict | None = None, owners: tuple | None = None):
        """``attrs``: more root attributes (e.g. the unknown fields and their DOFs);
        ``owners``: (rank of each node, rank of each cell), needed only for values given as
        :class:`parsolve.io.slabs.OwnedRows` (gathered to rank 0)."""
        self.comm, self.path, self.mesh = comm, Path(path), mesh
        self.owners = owners
        self.relations = relations  # name -> (nrows, unilateral)
        self.times: list[float] = []
        self.fields: dict[str, int] = {}
        self.cell_fields: dict[str, int] = {}
        self.file = None
        self.error: str | None = None      # set once writing failed: nothing more is written
        self.output_seconds = 0.0          # time spent in the last write_step
        self._layout: dict[str, tuple] = {}  # per-step dataset -> (row shape, dtype)
        self._known: dict[str, tuple] = {}   # those created with the file
        self._xdmf = XdmfWriter(self.path, mesh) if xdmf else None
        self.attrs = attrs or {}
        # the mesh as rank 0 writes it (gathered when every rank holds only its part)
        self._points = self._whole({"p": mesh.points})["p"]
        self._cells = self._whole({"c": mesh.cells}, cells=True)["c"]
        if comm.rank == 0:
            try:
                self._open(scene_text, petsc_version)
            except OSError as exc:
                self._fail(exc, "creating")
        self._raise_if_failed()

    def _open(self, scene_text: str, petsc_version: str) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # Unlink, never truncate: a reader of the previous result keeps its copy.
        for old in (self.path, self.path.with_suffix(".xdmf"), sidecar_path(self.path)):
            old.unlink(missing_ok=True)
        # No chunk cache: a step's data reaches the file inside write_step (where a full disk is
        # an OSError we handle), never later when HDF5 evicts or closes a dataset.
        f = self.file = h5py.File(self.path, "w", libver="latest", rdcc_nbytes=0)
        f.attrs.update(parsolve_version=__version__, petsc_version=petsc_version,
                       nprocs=self.comm.size, status="running", scene=scene_text, **self.attrs)
        for name, data in (("mesh/points", self._points),
                           (f"mesh/cells/{self.mesh.cell_type}", self._cells)):
            create_mesh_dataset(f, name, data.shape, data.dtype, data)
        self._points = self._cells = None
        # What is known now exists even if no step finishes (a failure before the first step)
        for name, (shape, dtype) in known_datasets(self.relations).items():
            _create(f, name, shape, dtype)
            self._known[name] = (shape, dtype)
        f.flush()

    # ------------------------------------------------------------------ steps
    def write_step(self, t: float, iterations: int, residual: float, fields: dict, cell_fields: dict,
                   relations: dict, timings: dict, extra: dict | None = None) -> None:
        """fields: name -> (npoints, ncomp); relations: name -> dict(multiplier, primal[, active]);
        extra: other per-step values by dataset path (/balance/..., /steps/cuts).

        Raises OutputError (rank 0) if the file cannot be written; the finished steps stay."""
        fields, cell_fields = self._whole(fields), self._whole(cell_fields, cells=True)
        if self.comm.rank == 0 and self.error is None:
            self._write_step(t, iterations, residual, fields, cell_fields, relations, timings,
                             extra or {})
        elif self.comm.rank != 0:
            self.times.append(t)
        self._raise_if_failed()

    def _whole(self, values: dict, cells: bool = False) -> dict:
        """Values given as OwnedRows (every rank its own rows) gathered whole on rank 0."""
        owned = [name for name, v in values.items() if isinstance(v, OwnedRows)]
        if not owned:
            return values
        if self.owners is None:
            owner = split_owners(self.mesh.num_cells if cells else self.mesh.num_points,
                                 self.comm.size)
        else:
            owner = self.owners[1 if cells else 0]
        rows = owner if isinstance(owner, Rows) else Rows(self.comm, owner)
        return {**values, **{name: rows.gather(values[name].values) for name in owned}}

    def _raise_if_failed(self) -> None:
        """Collective: every rank raises the same OutputError once rank 0 failed."""
        self.error = self.comm.bcast(self.error, root=0)
        if self.error is not None:
            raise OutputError(self.error)

    def _write_step(self, t, iterations, residual, fields, cell_fields, relations, timings,
                    extra) -> None:
        start = time.perf_counter()
        rows = self._rows(t, iterations, residual, fields, cell_fields, relations, timings, extra)
        step = len(self.times) + 1
        faults.step_begins(step)
        try:
            if not self._layout:
                self._create_all(rows)
            for name, value in rows.items():
                if name != COMMIT:
                    self._append(name, value)
                    faults.passed(step)
            self.file.flush()   # every other row on disk before the marker (one flush, in
            faults.passed(step)  # any order of the metadata, would not guarantee that)
            self._append(COMMIT, rows[COMMIT])  # last: the step now counts
            faults.passed(step)
            self.file.flush()
            faults.passed(step)
            faults.step_ends(step)
        except (OSError, RuntimeError) as exc:  # h5py reports some write errors as RuntimeError
            return self._fail(exc, f"writing step {len(self.times) + 1} to")
        self.times.append(t)
        if self._xdmf is not None:
            try:
                self._xdmf.append(len(self.times) - 1, t, self.fields, self.cell_fields)
            except (OSError, RuntimeError) as exc:
                return self._fail(exc, "writing", self._xdmf.path)
        self.output_seconds = time.perf_counter() - start

    def _rows(self, t, iterations, residual, fields, cell_fields, relations, timings,
              extra=None) -> dict:
        """Every per-step dataset's row for this step, by dataset name."""
        rows = {"steps/iterations": np.int64(iterations), "steps/residual": np.float64(residual)}
        rows.update({name: np.asarray(value) for name, value in (extra or {}).items()})
        for group, data, registry in (("fields", fields, self.fields),
                                      ("cell_fields", cell_fields, self.cell_fields)):
            for name, value in data.items():
                value = np.asarray(value)
                if value.dtype.kind not in "iu":  # states (int8) keep their type
                    value = value.astype(float)
                value = value[:, None] if value.ndim == 1 else value
                registry[name] = value.shape[1]
                rows[f"{group}/{name}"] = value
        for name, data in relations.items():
            for key, value in data.items():
                rows[f"relations/{name}/{key}"] = np.asarray(value)
        for name, value in timings.items():
            rows[f"timings/{name}"] = np.float64(value)
        expected = self._layout or self._known
        missing = set(expected) - set(rows) - {"steps/time"}
        if any(not name.startswith("timings/") for name in missing):
            raise ValueError(f"datasets {sorted(missing)} are missing from step {len(self.times) + 1}")
        for name in missing:
            rows[name] = np.float64(0.0)  # a phase that did not run this step took no time
        if self._layout and set(rows) - set(self._layout):
            # SWMR cannot add datasets once the first step is written
            raise ValueError(f"datasets {sorted(set(rows) - set(self._layout))} were not in the "
                             "first step")
        rows["steps/time"] = np.float64(t)
        return rows

    def _create_all(self, rows: dict) -> None:
        """Every other per-step dataset (empty), then SWMR: from here on readers may open it."""
        f = self.file
        self._layout.update(self._known)
        for name, value in rows.items():
            if name not in self._known:
                value = np.asarray(value)
                _create(f, name, value.shape, value.dtype)
                self._layout[name] = (value.shape, value.dtype)
        f.swmr_mode = True

    def _append(self, name: str, value) -> None:
        ds = self.file[name]
        n = ds.shape[0]
        ds.resize(n + 1, axis=0)
        ds[n] = value

    # ------------------------------------------------------------------ faults
    def _fail(self, exc: OSError, doing: str, path: Path | None = None) -> None:
        """Stop writing for good (OutputError follows); the finished steps stay readable."""
        path = path or self.path
        reason = getattr(exc, "strerror", None) or str(exc)
        if "errno = 28" in reason or "No space left" in reason:
            reason = "No space left on device"
        self.error = (f"{doing} {path} failed: {reason}; the {len(self.times)} finished step(s) "
                      f"stay readable")

    def note(self, text: str) -> None:
        """A warning kept in the file (root attribute ``warnings``, one line each, written at
        close: attributes do not change under SWMR)."""
        self.notes = getattr(self, "notes", []) + [text]

    def close(self, status: str) -> None:
        """Record ``status`` and close. A failed write wins over the caller's status, and a result
        with no finished step is never "complete"."""
        if self.error is not None:
            status = f"failed: {self.error}"
        elif status == "complete" and not self.times:
            status = "failed: no step finished"
        self.status = status
        if self._xdmf is not None:
            try:
                self._xdmf.close()
            except (OSError, RuntimeError):
                pass  # the views already flushed stay; the XDMF names no other
        if self.file is None:
            return
        f, self.file = self.file, None
        if self.error is not None:
            # After a failed write nothing more goes in: writing the status would need new space
            # and, on a full disk, leaves HDF5 unable to close the file (tested: it stays
            # "running"; the exit status and the message say what happened) — unless the lock
            # file's reserve (parsolve.io.lock, runs started by `parsolve run`) gives it room.
            room = free_reserve(self.path)
            try:
                f.close()
            except (OSError, RuntimeError):
                return
            if room:
                try:
                    with h5py.File(self.path, "r+", locking=False) as f:
                        self._trim(f)
                        f.attrs["status"] = status
                except (OSError, RuntimeError):
                    pass
            return
        self._trim(f)
        f.attrs["status"] = status
        if getattr(self, "notes", None):
            f.attrs["warnings"] = "\n".join(self.notes)
        f.close()

    def _trim(self, f: h5py.File) -> None:
        """Cut rows of an unfinished step (an exception between datasets)."""
        n = len(self.times)
        for name in self._layout:
            if f[name].shape[0] > n:
                f[name].resize(n, axis=0)


def open_result(path: str | Path) -> h5py.File:
    """Open a result for reading, during the run, after it, or after a hard kill."""
    return h5py.File(path, "r", swmr=True)
