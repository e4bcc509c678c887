"""The in-process Python API; ``parsolve run`` and ``parsolve check`` are a thin layer over it.

    import parsolve
    scene = parsolve.Scene.from_file("configs/controlled_bar.toml")   # or from_string, from_dict
    result = parsolve.run(scene, "bar.h5", on_step=lambda s: print(s.index, s.t))
    result.fields["displacement"]          # (nsteps, npoints, ncomp), input order

Every function is collective over ``comm`` (default ``MPI.COMM_WORLD``; a split, or a single
rank in a notebook). Invalid input raises :class:`parsolve.errors.InputError` (``source``: the
file, ``key``: the dotted key) on every rank alike, before any output is touched; a failed
solve raises :class:`SolverError`, a signal :class:`Interrupted`, a write failure
:class:`OutputError`, each with ``result`` set to the :class:`Result` of the finished steps.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
from mpi4py import MPI

from parsolve.errors import InputError, Interrupted, OutputError, SolverError
from parsolve.io.slabs import OwnedRows


# ------------------------------------------------------------------ scenes

@dataclass
class Scene:
    """A validated scene (everything but what needs the mesh: :func:`check` does that).
    ``spec``: the parsed :class:`parsolve.scene.Scene`; ``path``: its file, if any."""

    spec: Any
    path: Path | None = None

    @classmethod
    def from_file(cls, path: str | Path) -> "Scene":
        from parsolve.scene import load_scene

        return cls(load_scene(path), Path(path))

    @classmethod
    def from_string(cls, text: str, source: str = "<string>", base: str | Path = ".") -> "Scene":
        """A scene from TOML text; relative mesh files are read from ``base``."""
        import tomllib

        from parsolve.scene import parse_scene

        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"invalid TOML: {exc}", source) from None
        return cls(parse_scene(data, source, text, Path(base)))

    @classmethod
    def from_dict(cls, data: dict, source: str = "<dict>", base: str | Path = ".") -> "Scene":
        """A scene from Python dicts shaped as the TOML file (tables are dicts, arrays of
        tables lists of dicts); the result file stores it as TOML text."""
        from parsolve.batch.toml_write import dumps
        from parsolve.scene import parse_scene

        if not isinstance(data, dict):
            raise InputError(f"a scene is a dict, not {type(data).__name__}", source)
        scene = parse_scene(data, source, "", Path(base))   # (names a bad key first)
        try:
            scene.text = dumps(data)   # what the result file stores, as a file's text
        except (TypeError, ValueError) as exc:
            raise InputError(f"not representable in TOML: {exc}", source) from None
        return cls(scene)

    @property
    def source(self) -> str:
        return self.spec.source

    def default_output(self) -> str:
        """The scene's [output] file, else SCENE.h5 (a scene without a file: scene.h5)."""
        if self.spec.output:
            return self.spec.output
        return (self.path.stem if self.path is not None else "scene") + ".h5"


def load(source: "str | Path | dict | Scene") -> Scene:
    """A scene from a file path, a dict, or a Scene (returned as is). TOML text: use
    :meth:`Scene.from_string` (a string is taken as a path)."""
    if isinstance(source, Scene):
        return source
    if isinstance(source, dict):
        return Scene.from_dict(source)
    return Scene.from_file(source)


# ------------------------------------------------------------------ checks

def check(scene: "Scene | str | Path | dict", comm: MPI.Comm | None = None,
          options: "dict[str, str] | list[str] | None" = None):
    """Build and validate the model (mesh, regions, relations, PETSc options) without solving;
    returns the :class:`parsolve.model.Model`. Collective."""
    from parsolve.mesh import memory
    from parsolve.model import build_model

    scene = load(scene)
    comm = MPI.COMM_WORLD if comm is None else comm
    with memory.agreed_over(comm):
        model = build_model(scene.spec, comm)
    _check_all_regions(model)
    _validate_options(comm, model, petsc_options(options))
    return model


def petsc_options(options: "dict[str, str] | list[str] | None") -> dict[str, str]:
    """PETSc options as {name: value} (no leading dash), from a dict or command-line words."""
    from parsolve.solvers.options import parse_cli

    if options is None:
        return {}
    if isinstance(options, dict):
        return {str(k).lstrip("-"): "" if v is None else str(v) for k, v in options.items()}
    try:
        return parse_cli([str(w) for w in options])
    except ValueError as exc:
        raise InputError(str(exc), "options") from None


def _check_all_regions(model) -> None:
    """Regions no effect uses are evaluated too: their selectors must be valid and finite."""
    resolver = model.regions()
    for name, spec in model.scene.regions.items():
        resolver(name, spec.key)


def _validate_options(comm, model, cli_options: dict[str, str]) -> None:
    from parsolve.solvers import options as opt
    from parsolve.solvers.linear import preset_options

    scene = model.scene
    multiplied = [r for r in model.relations if not r.eliminable()]
    preset = preset_options(scene.solver.preset, all(r.associated for r in multiplied),
                            bool(multiplied))
    opt.validate(comm, scene.solver.prefix, preset, scene.solver.options, cli_options,
                 scene.source)


def check_output(path: str, source: str, key: str, inputs: list[Path],
                 export_dir: str | None = None) -> None:
    """The result file (and the XDMF beside it) must be a writable file that is no input."""
    def fail(message: str, src: str = source, k: str = key) -> InputError:
        return InputError(message, src, k)

    out = Path(path)
    targets = [out, out.with_suffix(".xdmf"), out.with_suffix(".xdmf.h5")]
    for target in targets:
        for inp in inputs:
            if _same(target, inp):
                raise fail(f"{target} would overwrite the input file {inp}")
    if out.is_dir():
        raise fail(f"{out} is a folder, not a result file")
    parent = out.parent if str(out.parent) else Path(".")
    if parent.exists() and not parent.is_dir():
        raise fail(f"cannot write {out}: {parent} is a file, not a folder")
    if not parent.exists():
        raise fail(f"cannot write {out}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise fail(f"cannot write {out}: folder {parent} is read-only")
    for target in targets:
        if target.exists() and (target.is_dir() or not os.access(target, os.W_OK)):
            raise fail(f"cannot write {target}: it is a folder or read-only")
    if export_dir is not None:
        d = Path(export_dir)
        if d.exists() and not d.is_dir():
            raise fail(f"--export-system {d} is a file, not a folder", "command line",
                       "--export-system")


def lock_output(comm, out: str, source: str, key: str):
    """Rank 0 locks the result (parsolve.io.lock) and every rank learns the verdict: a result
    another run is writing is an InputError, raised before any output is touched. Returns the
    lock on rank 0 (None elsewhere)."""
    from parsolve.io.lock import OutputLock

    lock, verdict = None, None
    if comm.rank == 0:
        lock = OutputLock(out)
        try:
            verdict = "ok" if lock.acquire() else "busy"
        except OSError as exc:
            verdict = f"cannot lock {lock.path}: {exc.strerror or exc}"
        if verdict == "ok" and not lock.reserve():
            lock.release()          # no room even for the reserve: no result is started
            verdict = "full"
    verdict = comm.bcast(verdict, root=0)
    if verdict == "full":
        from parsolve.io.lock import RESERVE_BYTES

        raise OutputError(f"{out}: No space left on device (disk full): the "
                          f"{RESERVE_BYTES >> 20} MiB kept beside the result to close it do not "
                          f"fit in {Path(out).parent}; nothing written")
    if verdict == "busy":
        raise InputError(f"{out} is being written by another run (lock held on "
                         f"{out}.lock)", source, key)
    if verdict != "ok":
        raise InputError(verdict, source, key)
    return lock


def _same(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and a.samefile(b))
    except OSError:
        return False


# ------------------------------------------------------------------ runs

@dataclass
class Step:
    """What a per-step callback receives. ``fields``, ``cell_fields``: this rank's rows (its
    owned nodes / cells in increasing input id; on one rank, every row in input order);
    ``relations``: name -> {multiplier, primal, resultant[, active]} (whole relations)."""

    index: int          # 0, 1, ... over the steps this run writes (after a restart's copies)
    t: float
    iterations: int
    residual: float
    fields: dict
    cell_fields: dict
    relations: dict


class _Watched:
    """The result writer with a callback after each written step (same calls otherwise)."""

    def __init__(self, writer, on_step: Callable[[Step], None]):
        # (after a restart's copied steps: the index of the first new one)
        self._writer, self._on_step, self._index = writer, on_step, len(writer.times)

    def __getattr__(self, name):
        return getattr(self._writer, name)

    def write_step(self, t, iterations, residual, fields, cell_fields, relations, timings,
                   extra=None) -> None:
        self._writer.write_step(t, iterations, residual, fields, cell_fields, relations, timings,
                                extra=extra)
        local = {k: v.values if isinstance(v, OwnedRows) else v for k, v in fields.items()}
        cells = {k: v.values if isinstance(v, OwnedRows) else v for k, v in cell_fields.items()}
        self._on_step(Step(self._index, float(t), int(iterations), float(residual), local,
                           cells, relations))
        self._index += 1


def run(scene: "Scene | str | Path | dict", output: str | Path | None = None,
        comm: MPI.Comm | None = None, options: "dict[str, str] | list[str] | None" = None,
        on_step: Callable[[Step], None] | None = None, restart: str | Path | None = None,
        output_mode: str | None = None, export_system: str | None = None,
        log: Callable[[str], None] | None = print, warn: Callable[[str], None] | None = None
        ) -> "Result":
    """Validate, solve every step, write the result file and return its :class:`Result`.
    ``output``: the result file (default: the scene's [output] file, else SCENE.h5);
    ``options``: PETSc options; ``on_step``: called on every rank after each written step;
    ``restart``: a result file of this scene to continue from (its last finished step);
    ``log``: progress lines (rank 0; None: silent); ``warn``: warnings (default: ``log``)."""
    scene = load(scene)
    comm = MPI.COMM_WORLD if comm is None else comm
    cli_options = petsc_options(options)
    out, source, key = (str(output), "command line", "-o") if output is not None else \
        (scene.default_output(), scene.source, "output.file")
    inputs = ([scene.path] if scene.path else []) + \
        ([Path(scene.spec.mesh.file)] if scene.spec.mesh.file else [])
    check_output(out, source, key, inputs, export_system)
    start = None
    if restart is not None:
        from parsolve.io.restart import read_restart

        check_output(out, source, key, [Path(restart)])
        start = read_restart(comm, str(restart), scene.spec)
    lock = lock_output(comm, out, source, key)
    try:
        return _run_locked(scene, out, comm, cli_options, on_step, start, output_mode,
                           export_system, log, warn or log)
    finally:
        if lock is not None:
            lock.release()


def _run_locked(scene, out, comm, cli_options, on_step, start, output_mode, export_system,
                log, warn) -> "Result":
    from parsolve import driver

    model = check(scene, comm, cli_options)
    if start is not None:
        driver.check_restart(model, start)
    say = _rank0(comm, log)
    for warning in model.mesh.warnings:
        _rank0(comm, warn)(f"parsolve: warning: {warning}")
    watch = (lambda writer: _Watched(writer, on_step)) if on_step is not None else None
    try:
        with _signals(comm):
            driver.run(comm, model, out, cli_options, export_system, log=say,
                       output=output_mode, watch=watch, restart=start)
    except (SolverError, Interrupted, OutputError) as exc:   # (raised on every rank alike)
        comm.Barrier()   # rank 0 has closed the file
        exc.result = _result_or_none(out)
        raise
    comm.Barrier()
    return Result(out)


def _signals(comm):
    """SIGINT / SIGTERM stop the run at a step's end (``parsolve.interrupts``); not from a
    thread other than the main one (no signal handlers there)."""
    from contextlib import nullcontext

    from parsolve.interrupts import interruptible

    if threading.current_thread() is not threading.main_thread():
        return nullcontext()
    return interruptible(comm)


def _rank0(comm, log):
    if log is None:
        return lambda message: None
    return (lambda message: log(message)) if comm.rank == 0 else (lambda message: None)


# ------------------------------------------------------------------ results

class Result:
    """A result file's contents as numpy arrays, in input order (the finished steps).

    ``times``, ``iterations``, ``residual``: per step; ``status``, ``attrs``: the root's;
    ``points``: the mesh's; ``fields[name]``: (nsteps, npoints, ncomp); ``cell_fields[name]``:
    (nsteps, ncells, ncomp); ``relations[name][key]`` with key multiplier, primal, resultant
    (and active): (nsteps, nrows). The per-step groups are read when first used."""

    def __init__(self, path: str | Path):
        from parsolve.io.restart import read_result

        self.path = str(path)
        summary = read_result(self.path, ())
        self.times, self.iterations = summary["times"], summary["iterations"]
        self.residual, self.status = summary["residual"], summary["status"]
        self.attrs, self.points = summary["attrs"], summary["points"]
        self._groups: dict = {}

    def _group(self, name: str) -> dict:
        from parsolve.io.restart import read_result

        if name not in self._groups:
            self._groups[name] = read_result(self.path, (name,))[name]
        return self._groups[name]

    @property
    def fields(self) -> dict[str, np.ndarray]:
        return self._group("fields")

    @property
    def cell_fields(self) -> dict[str, np.ndarray]:
        return self._group("cell_fields")

    @property
    def relations(self) -> dict[str, dict[str, np.ndarray]]:
        return self._group("relations")

    def __repr__(self) -> str:
        return f"Result({self.path!r}, {len(self.times)} steps, status {self.status!r})"


def _result_or_none(path: str) -> "Result | None":
    """The result of a run that stopped (None when it has no readable file)."""
    try:
        return Result(path)
    except (OSError, KeyError):
        return None
