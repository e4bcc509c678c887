"""The result file (DESIGN §5), written step by step by rank 0 so that a run that stops early
leaves every finished step readable."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from parsolve import __version__
from parsolve.io.xdmf import write_xdmf


class ResultWriter:
    """Appends one saved step at a time; only rank 0 touches the file."""

    def __init__(self, comm, path: str | Path, mesh, scene_text: str, petsc_version: str,
                 relations: dict[str, tuple[int, bool]]):
        self.comm, self.path, self.mesh = comm, Path(path), mesh
        self.relations = relations  # name -> (nrows, unilateral)
        self.times: list[float] = []
        self.fields: dict[str, int] = {}
        self.cell_fields: dict[str, int] = {}
        self.file = None
        if comm.rank != 0:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        f = self.file = h5py.File(self.path, "w", driver=None)
        f.attrs.update(parsolve_version=__version__, petsc_version=petsc_version,
                       nprocs=comm.size, status="running", scene=scene_text)
        f["mesh/points"] = mesh.points
        f[f"mesh/cells/{mesh.cell_type}"] = mesh.cells
        for name in ("time", "iterations", "residual"):
            dtype = np.int64 if name == "iterations" else float
            f.create_dataset(f"steps/{name}", (0,), maxshape=(None,), dtype=dtype)
        for name, (nrows, unilateral) in relations.items():
            f.create_dataset(f"relations/{name}/multiplier", (0, nrows), maxshape=(None, nrows), dtype=float)
            f.create_dataset(f"relations/{name}/primal", (0, nrows), maxshape=(None, nrows), dtype=float)
            if unilateral:
                f.create_dataset(f"relations/{name}/active", (0, nrows), maxshape=(None, nrows),
                                 dtype=np.int8)
        f.flush()

    def _append(self, path: str, value) -> None:
        f = self.file
        value = np.asarray(value)
        if path not in f:
            f.create_dataset(path, (0,) + value.shape, maxshape=(None,) + value.shape, dtype=value.dtype)
        ds = f[path]
        ds.resize(ds.shape[0] + 1, axis=0)
        ds[-1] = value

    def write_step(self, t: float, iterations: int, residual: float, fields: dict, cell_fields: dict,
                   relations: dict, timings: dict, extra: dict | None = None) -> None:
        """fields: name -> (npoints, ncomp); relations: name -> dict(multiplier, primal[, active])."""
        self.times.append(t)
        if self.comm.rank != 0:
            return
        for name, value in (("time", t), ("iterations", iterations), ("residual", residual)):
            self._append(f"steps/{name}", value)
        for group, data, registry in (("fields", fields, self.fields),
                                      ("cell_fields", cell_fields, self.cell_fields)):
            for name, value in data.items():
                value = np.asarray(value, dtype=float)
                value = value[:, None] if value.ndim == 1 else value
                registry[name] = value.shape[1]
                self._append(f"{group}/{name}", value)
        for name, data in relations.items():
            for key, value in data.items():
                self._append(f"relations/{name}/{key}", value)
        for name, value in timings.items():
            self._append(f"timings/{name}", float(value))
        for path, value in (extra or {}).items():  # per-step scalars: /balance, /steps/cuts
            self._append(path, value)
        self.file.flush()
        write_xdmf(self.path.with_suffix(".xdmf"), self.path.name, self.mesh.cell_type,
                   self.mesh.num_points, self.mesh.num_cells, self.mesh.cells.shape[1], self.mesh.dim,
                   self.times, self.fields, self.cell_fields)

    def note(self, text: str) -> None:
        """A warning kept in the file (root attribute ``warnings``, one line each)."""
        if self.file is not None:
            previous = self.file.attrs.get("warnings", "")
            self.file.attrs["warnings"] = (previous + "\n" if previous else "") + text

    def close(self, status: str) -> None:
        if self.file is not None:
            self.file.attrs["status"] = status
            self.file.close()
            self.file = None
