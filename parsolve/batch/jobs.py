"""Job files (``parsolve batch JOBS.toml``) → validated runs.

    scene = "../controlled_bar.toml"   # the base scene, relative to this file
    output = "bar_runs"                # the batch root (default: this file's name, beside it)
    ranks = 1                          # mpirun -n for every run (a grid or a run may vary it)
    args = ["-ksp_rtol", "1e-10"]      # command-line (PETSc) options for every run
    executor = "local"                 # or "slurm"; the command line wins
    parallel = 2                       # local executor: runs at a time

    [grid]                             # cartesian product of these values
    "mesh.nx" = [10, 20]
    "materials[0].E" = [1e9, 2e9]

    [[runs]]                           # and/or a list: each entry × every grid point
    "steps.count" = 4
    ranks = 2
    name = "four_steps"                # optional folder name (entries only)

    [slurm]                            # sbatch settings (see parsolve.batch.slurm.RESOURCES)
    partition = "debug"
    time = "00:10:00"
    throttle = 4

Every error names this file and the key: ``jobs.toml: grid."mesh.nxx": ...``. Each effective
scene is validated as ``parsolve check`` would (scene, mesh, regions, relations, and the PETSc
options of its runs: an unknown ``-ksp_type`` / ``-pc_type``, a bad number) before anything
runs; ``parsolve batch`` also refuses an output folder that is a file or lies under one.
"""

from __future__ import annotations

import itertools
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from parsolve.batch.api import Run
from parsolve.batch.scene_edit import effective_scene, read_scene, split_path
from parsolve.batch.slurm import RESOURCES
from parsolve.errors import InputError
from parsolve.scene import Table, read_toml

SPECIAL = ("ranks", "args", "name")  # keys of a run that are not scene paths
EXECUTORS = ("local", "slurm")


@dataclass
class Jobs:
    source: Path
    scene: Path
    root: Path
    runs: list[Run]
    executor: str = "local"
    parallel: int = 1
    slurm: dict = field(default_factory=dict)


def load_jobs(path: str | Path, validate: bool = True) -> Jobs:
    path = Path(path)
    source = str(path)
    data = read_toml(path, "job")[0]
    top = Table(data, "", source)
    scene = path.parent / top.get("scene", str)
    root = path.parent / top.get("output", str, path.stem)
    ranks = top.get("ranks", int, 1)
    if ranks < 1:
        raise top.error("ranks", "must be at least 1")
    args = _args(top, "args")
    executor = top.get("executor", str, "local", choices=EXECUTORS)
    parallel = top.get("parallel", int, 1)
    if parallel < 1:
        raise top.error("parallel", "must be at least 1")
    slurm = _slurm(top.table("slurm", {}))
    grid = _grid(top.table("grid", {}))
    entries = [_entry(t) for t in top.tables("runs")]
    top.done()
    base = read_scene(scene)
    points = _points(grid, entries, source)
    runs = _runs(points, base, scene, path.parent, ranks, args, source)
    if validate:
        check(runs, points, scene, source)
    return Jobs(path, scene, root.resolve(), runs, executor, parallel, slurm)


def _args(t: Table, name: str) -> tuple[str, ...]:
    value = t.get(name, list, [])
    if not all(isinstance(a, (str, int, float)) and not isinstance(a, bool) for a in value):
        raise t.error(name, "expected a list of strings (command-line options)")
    args = tuple(map(str, value))
    from parsolve.solvers.options import parse_cli

    try:
        parse_cli(list(args))
    except ValueError as exc:
        raise t.error(name, str(exc)) from None
    return args


def _slurm(t: Table) -> dict:
    out = {}
    for name, kind in RESOURCES.items():
        if t.has(name):
            out[name] = t.get(name, kind)
    if "extra" in out and not all(isinstance(x, str) for x in out["extra"]):
        raise t.error("extra", "expected a list of strings (sbatch options)")
    for name in ("throttle", "cpus_per_task"):
        if name in out and out[name] < 1:
            raise t.error(name, "must be at least 1")
    t.done()
    return out


def _quoted(t: Table, name: str) -> str:
    return f'{t.path}."{name}"' if t.path else f'"{name}"'


def _grid(t: Table) -> dict[str, tuple[list, str]]:
    """path → (values, key in the job file)."""
    out = {}
    for name in list(t.data):
        values = t.get(name, list)
        key = _quoted(t, name)
        if not values:
            raise InputError("expected a non-empty list of values", t.source, key)
        if name in ("args", "name"):
            raise InputError(f"{name!r} cannot be varied in the grid (set it per [[runs]] entry)",
                             t.source, key)
        _check_path(name, t.source, key)
        out[name] = (values, key)
    return out


def _entry(t: Table) -> dict[str, tuple[object, str]]:
    out = {}
    for name in list(t.data):
        key = _quoted(t, name)
        if name == "args":
            out[name] = (_args(t, name), key)
        elif name == "name":
            out[name] = (t.get(name, str), key)
        else:
            out[name] = (t.get(name, (int, float, str, bool, list, dict)), key)
            _check_path(name, t.source, key)
    return out


def _check_path(name: str, source: str, key: str) -> None:
    if name in SPECIAL:
        return
    try:
        split_path(name)
    except ValueError as exc:
        raise InputError(str(exc), source, key) from None


def _points(grid: dict, entries: list[dict], source: str) -> list[dict[str, tuple[object, str]]]:
    """Every run's settings: each [[runs]] entry (or none) × every grid point."""
    combos = [dict(zip(grid, values)) for values in itertools.product(*(v for v, _ in grid.values()))]
    points = []
    for entry in entries or [{}]:
        for combo in combos:
            point = dict(entry)
            for name, value in combo.items():
                if name in entry:
                    raise InputError("set both in [grid] and in this [[runs]] entry", source,
                                     entry[name][1])
                point[name] = (value, grid[name][1])
            points.append(point)
    return points


def _runs(points: list[dict], base: dict, scene: Path, folder: Path, ranks: int,
          args: tuple[str, ...], source: str) -> list[Run]:
    runs, names = [], set()
    labels = _labels(_varied(points))
    order = list(dict.fromkeys(k for p in points for k in p if k not in SPECIAL)) + ["ranks"]
    for point in points:
        changes = {k: v for k, (v, _) in point.items() if k not in SPECIAL}
        params = {k: v for k, (v, _) in point.items() if k not in ("args", "name")}
        r = point.get("ranks", (ranks, ""))
        if "ranks" in labels:  # varied somewhere: name and list it for every run
            params["ranks"] = r[0]
        params = {k: params[k] for k in order if k in params}
        if not isinstance(r[0], int) or isinstance(r[0], bool) or r[0] < 1:
            raise InputError(f"ranks must be a positive integer, got {r[0]!r}", source, r[1])
        try:
            text = effective_scene(base, changes, scene.parent, folder,
                                   header=f"parsolve batch: {scene} with {params}")
        except (KeyError, IndexError) as exc:
            key = next(k for p, (_, k) in point.items() if p in changes and _fails(base, p))
            raise InputError(str(exc.args[0]) + f" ({scene})", source, key) from None
        name = point["name"][0] if "name" in point else \
            _name({k: v for k, v in params.items() if k in labels}, labels)
        name = _unique(name, names, point.get("name", (None, None))[1], source)
        runs.append(Run(name, text, r[0], args + tuple(point.get("args", ((), ""))[0]), params))
    return runs


def _varied(points: list[dict]) -> set[str]:
    """The paths whose value differs between runs (they name the folders)."""
    keys = {k for p in points for k in p if k not in ("args", "name")}
    return {k for k in keys if len({repr(p.get(k, (None,))[0]) for p in points}) > 1}


def _fails(base: dict, path: str) -> bool:
    try:
        effective_scene(base, {path: 0})
        return False
    except (KeyError, IndexError):
        return True


def _labels(paths: set[str]) -> dict[str, str]:
    """A short label per varied path for folder names: its last key, or the whole path when
    two paths end alike (``relations[0].value`` and ``relations[1].value``)."""
    last = {p: str(split_path(p)[-1]) if p not in SPECIAL else p for p in paths}
    return {p: (last[p] if list(last.values()).count(last[p]) == 1 else p) for p in paths}


def _name(params: dict, labels: dict) -> str:
    if not params:
        return "run"
    parts = [f"{labels[k]}={_text(v)}" for k, v in params.items()]
    return re.sub(r"[^A-Za-z0-9._=+-]", "-", "_".join(parts))[:120]


def _text(v) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, list):
        return "x".join(_text(x) for x in v)
    return str(v)


def _unique(name: str, names: set, key: str | None, source: str) -> str:
    if name in names:
        if key:  # a name the user gave
            raise InputError(f"duplicate run name {name!r}", source, key)
        i = 2
        while f"{name}-{i}" in names:
            i += 1
        name = f"{name}-{i}"
    if not re.fullmatch(r"[A-Za-z0-9._=+-]+", name) or name.startswith("."):
        raise InputError(f"invalid run name {name!r} (letters, digits, . _ = + -)", source, key)
    names.add(name)
    return name


def check(runs: list[Run], points: list[dict], scene: Path, source: str) -> None:
    """``parsolve check`` on every distinct effective scene, with the PETSc options of its
    runs; an error caused by a varied value names the job file and that value's key."""
    from parsolve.model import build_model
    from parsolve.scene import parse_scene

    solvers: dict[str, tuple] = {}   # scene text -> (prefix, preset, scene options, source)
    seen = set()
    for run, point in zip(runs, points):
        if run.scene_text not in solvers:
            try:
                model = build_model(parse_scene(tomllib.loads(run.scene_text), str(scene),
                                                run.scene_text, scene.parent))
            except InputError as exc:
                key = _culprit(exc.key, point)
                if key is None:
                    raise InputError(f"{exc.message} (run {run.name})", exc.source, exc.key) from None
                raise InputError(f"{exc.message} (run {run.name}, scene {scene})", source, key) from None
            solvers[run.scene_text] = _solver_options(model)
        layers = solvers[run.scene_text] + (petsc_options(run.args),)
        frozen = tuple(v if isinstance(v, str) else tuple(v.items()) for v in layers)
        if frozen in seen:
            continue
        seen.add(frozen)
        exc = _validate(*layers)
        if exc is None:
            continue
        if exc.source != "command line":
            key = _culprit(exc.key, point)
            if key is None:
                raise InputError(f"{exc.message} (run {run.name})", exc.source, exc.key)
            raise InputError(f"{exc.message} (run {run.name}, scene {scene})", source, key)
        entry = point.get("args")
        key = entry[1] if entry and exc.key in entry[0] else "args"
        raise InputError(f"{exc.key}: {exc.message} (run {run.name})", source, key)


def options_error(model, args: tuple[str, ...]) -> InputError | None:
    """PETSc's verdict on a run of ``model`` with ``args`` (unknown types, bad numbers), as
    ``parsolve run`` layers the options; a culprit among ``args`` has source "command line"
    and the option as its key."""
    return _validate(*_solver_options(model), petsc_options(args))


def petsc_options(args: tuple[str, ...]) -> dict[str, str]:
    """The PETSc options among a run's arguments (not ``-o FILE`` nor ``--long`` flags of
    ``parsolve run`` and their values)."""
    from parsolve.solvers.options import parse_cli

    words, i = [], 0
    while i < len(args):
        word = args[i]
        i += 1
        if word == "-o" or word.startswith("--"):
            if i < len(args) and not args[i].startswith("-") and "=" not in word:
                i += 1
            continue
        words.append(word)
    return parse_cli(words)


def _solver_options(model) -> tuple[str, dict, dict, str]:
    """(prefix, preset options, scene options, scene file) as ``parsolve run`` layers them."""
    from parsolve.solvers.linear import preset_options

    solver = model.scene.solver
    multiplied = [r for r in model.relations if not r.eliminable()]
    preset = preset_options(solver.preset, all(r.associated for r in multiplied), bool(multiplied))
    return solver.prefix, preset, dict(solver.options), model.scene.source


def _validate(prefix: str, preset: dict, options: dict, source: str, petsc: dict) -> InputError | None:
    from mpi4py import MPI

    from parsolve.solvers.options import validate

    try:
        validate(MPI.COMM_SELF, prefix, preset, options, petsc, source)
    except InputError as exc:
        return exc
    return None


def _culprit(key: str | None, point: dict) -> str | None:
    if not key:
        return None
    for path, (_, job_key) in point.items():
        if path in SPECIAL:
            continue
        if key == path or key.startswith((path + ".", path + "[")) or path.startswith((key + ".", key + "[")):
            return job_key
    return None
