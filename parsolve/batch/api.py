"""The batch API: a list of runs → one folder each under a root, executed locally or on SLURM,
resumable, with a manifest. ``parsolve study`` and ``parsolve batch`` both call ``execute``.

    runs = [Run("nx10", effective_scene("bar.toml", {"mesh.nx": 10}), params={"mesh.nx": 10})]
    outcomes = execute(runs, Path("out"), executor="local", parallel=2)
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from parsolve.batch import manifest, runner
from parsolve.batch.scene_edit import effective_scene  # noqa: F401 -- part of the API

EXECUTORS = ("local", "slurm")


@dataclass
class Run:
    name: str                 # unique folder name under the batch root
    scene_text: str           # the effective scene (TOML text), written as RUN/scene.toml
    ranks: int = 1            # mpirun -n
    args: tuple[str, ...] = ()  # extra command-line arguments (PETSc options)
    params: dict = field(default_factory=dict)  # what was varied, for the manifest


@dataclass
class Outcome:
    name: str
    folder: Path
    result: Path
    status: str               # "complete", "failed: ...", "interrupted: ...", "missing", ...
    exit_code: int | None
    seconds: float | None

    @property
    def ok(self) -> bool:
        return self.status == "complete"


def execute(runs: list[Run], root: Path, executor: str = "local", parallel: int = 1,
            resources: dict | None = None, resume: bool = True, log: Callable[[str], None] = print,
            wait: bool = True) -> list[Outcome]:
    """Run every run that is not already complete (with ``resume``; otherwise all of them) and
    return one outcome per run, in order. ``resources``: the SLURM settings (partition, time,
    cpus_per_task, mem, throttle, extra, poll). With ``executor="slurm"`` and ``wait=False``
    the outcomes of submitted runs are "submitted"."""
    if executor not in EXECUTORS:
        raise ValueError(f"unknown executor {executor!r} (expected one of {', '.join(EXECUTORS)})")
    _check_names(runs)
    root = Path(root).resolve()
    root.mkdir(parents=True, exist_ok=True)
    specs = [{"name": r.name, "ranks": r.ranks, "args": list(map(str, r.args)), "params": r.params}
             for r in runs]
    manifest.save_runs(root, specs)
    busy = {r.name for r in runs if runner.active(root / r.name)}
    todo = [r for r in runs if r.name not in busy and not (resume and is_done(root / r.name, r))]
    log(f"batch: {len(runs)} runs in {root}, {len(runs) - len(todo) - len(busy)} already complete, "
        f"{len(todo)} to run ({executor})" + (f", {len(busy)} still running elsewhere (left alone)"
                                              if busy else ""))
    for r in todo:
        runner.prepare(root / r.name, r.scene_text, r.ranks, r.args, r.params)
    submitted: set[str] = set()
    try:
        if todo and executor == "local":
            from parsolve.batch import local

            local.execute([root / r.name for r in todo], parallel, log)
        elif todo:
            from parsolve.batch import slurm

            slurm.execute(root, [r.name for r in todo], resources or {}, log, wait)
            submitted = set() if wait else {r.name for r in todo}
    finally:
        manifest.write(root, specs)
    return [_outcome(root, r.name, "submitted" if r.name in submitted else
                     "running elsewhere" if r.name in busy else None) for r in runs]


def folder_problem(path: Path) -> str | None:
    """Why ``path`` cannot be (or become) a folder of runs, or None: it is a file, or the
    nearest existing ancestor is a file, is read-only or refuses a new entry (mkdir would fail
    half way)."""
    path = Path(path).resolve()
    if path.exists():
        if not path.is_dir():
            return f"{path} is a file, not a folder"
        return _unwritable(path, f"folder {path}")
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                return f"cannot create {path}: {parent} is a file, not a folder"
            problem = _unwritable(parent, f"folder {parent}")
            return f"cannot create {path}: {problem}" if problem else None
    return None


def _unwritable(folder: Path, name: str) -> str | None:
    """Why nothing can be created in ``folder``, or None. Tried with a probe folder made and
    removed at once: the permission bits do not tell (root passes them; /proc, /sys and
    read-only mounts refuse anyway)."""
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"{name} is read-only"
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".parsolve-probe-", dir=folder))
    except OSError as exc:
        return f"{name} is not writable ({exc.strerror or exc})"
    return None


def is_done(folder: Path, run: Run) -> bool:
    """Complete, and with the same scene, ranks and arguments as asked now (otherwise the old
    result answers another question)."""
    spec = runner.read_json(folder / runner.SPEC)
    try:
        same = ((folder / runner.SCENE).read_text() == run.scene_text and spec is not None
                and spec.get("ranks") == run.ranks and spec.get("args") == list(map(str, run.args)))
    except OSError:
        return False
    return same and runner.status_of(folder)[0] == "complete"


def outcomes(root: Path) -> list[Outcome]:
    """The outcome of every run recorded under ``root`` (its ``runs.json``)."""
    root = Path(root).resolve()
    return [_outcome(root, spec["name"]) for spec in manifest.load_runs(root)]


def _outcome(root: Path, name: str, status: str | None = None) -> Outcome:
    folder = root / name
    found, code, seconds = runner.status_of(folder)
    return Outcome(name, folder, folder / runner.RESULT, status or found, code, seconds)


def _check_names(runs: list[Run]) -> None:
    seen = set()
    for r in runs:
        if not r.name or "/" in r.name or r.name in (".", "..") or r.name.startswith("."):
            raise ValueError(f"invalid run name {r.name!r}")
        if r.name in seen:
            raise ValueError(f"duplicate run name {r.name!r}")
        if r.ranks < 1:
            raise ValueError(f"run {r.name!r}: ranks must be at least 1")
        seen.add(r.name)
