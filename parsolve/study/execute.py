"""Run a study's grid through the batch API and measure every run: DOFs, quantities, time per
phase, peak memory.

Peak memory: every run gets PETSc's ``-memory_view``, which prints at exit the maximum
resident set size of each rank over the run (getrusage); it is read back from the run's
stdout, so it works the same on the local and the SLURM executor.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from parsolve.errors import InputError
from parsolve.study.config import Study
from parsolve.study.grid import Setting

RUN_ARGS = ("-memory_view",)   # added to every run's arguments (peak memory)
_MEMORY = re.compile(r"Maximum \(over computational time\) process memory:\s+total\s+(\S+)\s+max\s+(\S+)")


@dataclass
class Measured:
    setting: Setting
    status: str
    dofs: int | None = None
    values: dict[str, float] = field(default_factory=dict)
    phases: dict[str, float] = field(default_factory=dict)   # /timings/<phase> summed over steps
    wall: float | None = None                                 # seconds of the run's process
    peak_mb: float | None = None                              # largest rank
    peak_total_mb: float | None = None                        # sum over ranks
    result: Path | None = None

    @property
    def ok(self) -> bool:
        return self.status == "complete"

    def cost(self, kind: str) -> float | None:
        return self.wall if kind == "wall" else self.phases.get("total")


def peak_memory(stdout: Path) -> tuple[float | None, float | None]:
    """(max over ranks, total) peak RSS in MB from PETSc's -memory_view output."""
    try:
        found = _MEMORY.search(stdout.read_text(errors="replace"))
    except OSError:
        return None, None
    if not found:
        return None, None
    total, most = (float(v) / 2 ** 20 for v in found.groups())
    return most, total


def scene_model(text: str, scene_path):
    """The model of an effective scene, built as a run would build it (one rank)."""
    import tomllib

    from parsolve.model import build_model
    from parsolve.scene import parse_scene

    scene = parse_scene(tomllib.loads(text), str(scene_path), text, Path(scene_path).parent)
    return build_model(scene)


def check_quantities(study: Study, settings: list[Setting]) -> None:
    """Before anything runs: every spec parses, and on the coarsest scene of every family the
    relation, field or region it names exists and its point lies in the mesh. (A dataset an
    effect writes only in some runs, e.g. damage, and a point inside the coarsest mesh but
    outside a finer one are still found when the runs are read.)"""
    from parsolve.post.spec import parse

    specs = []
    for q in study.quantities:
        try:
            specs.append((q, parse(q.spec)))
        except InputError as exc:
            raise InputError(exc.message, study.source, q.key + ".spec") from None
    for s in settings:
        if s.level != 0:
            continue
        try:
            model = scene_model(s.scene_text, study.scene)
        except InputError as exc:   # (a family's value the model refuses: the family's key)
            raise InputError(f"the effective scene is invalid: {exc.oneline()}", study.source,
                             _family_key(study, s.family, exc.key)) from None
        _check_options(study, model, s.family)
        for q, spec in specs:
            problem = spec_problem(spec, model)
            if problem:
                raise InputError(f"{problem} in the scene of {s.family}", study.source,
                                 q.key + ".spec")


def _check_options(study: Study, model, family: str) -> None:
    """The study's ``args`` and the scene's PETSc options, as PETSc sees them, before any run."""
    from parsolve.batch.jobs import options_error

    exc = options_error(model, tuple(study.args) + RUN_ARGS)
    if exc is None:
        return
    if exc.source == "command line":
        raise InputError(f"{exc.key}: {exc.message}", study.source, "args")
    raise InputError(f"{exc.oneline()} (scene of {family})", study.source,
                     _family_key(study, family, exc.key))


def _family_key(study: Study, family: str, key: str | None) -> str:
    """The study's key to blame for an error at a scene's ``key``: the family's when it
    changes that key (or a table above it), else the scene's."""
    fam = next(f for f in study.families if f.name == family)
    varied = any(key == k or key.startswith(k + ".") for k in fam.changes) if key else False
    return fam.key if varied else "scene"


def _relation_problem(spec, model) -> str | None:
    """A row selector or a resultant component the relation cannot have (rows counted on the
    coarsest mesh: a multi-row relation stays multi-row when refined)."""
    from parsolve.outputs import resultant_labels

    relation = next(r for r in model.relations if r.name == spec.name)
    if spec.what == "resultant":
        labels = resultant_labels(model.fields, model.mesh.dim)
        return None if spec.sel in labels else \
            f"no resultant component {spec.sel!r} (known: {', '.join(labels)})"
    if spec.sel in ("sum", "mean") or (not spec.sel and relation.total == 1):
        return None
    if spec.sel.isdigit() and int(spec.sel) < relation.total:
        return None
    return (f"relation {spec.name!r} has {relation.total} rows: add :sum, :mean or a row number "
            f"0..{relation.total - 1}")


def spec_problem(spec, model) -> str | None:
    """Why a run of ``model`` cannot give ``spec`` (a parsed post spec), or None."""
    from parsolve.post.locate import locate

    names = {"relation": [r.name for r in model.relations],
             "field": [f.output for f in model.fields] + [n for e in model.effects for n in e.output_names()],
             "cell_field": [n for e in model.effects for n in e.output_names()]}
    group = "field" if spec.kind in ("max", "maxabs", "norm") else spec.kind
    if group in names and spec.name not in names[group]:
        what = "cell field" if group == "cell_field" else group
        return f"no {what} {spec.name!r} (known: {', '.join(map(str, names[group])) or 'none'})"
    if spec.kind == "relation":
        return _relation_problem(spec, model)
    mesh = model.mesh
    field = next((f for f in model.fields if f.output == spec.name), None)
    if field is not None and spec.kind in ("field", "max", "maxabs"):
        from parsolve.post.result import COMPONENTS

        comps = COMPONENTS.get((mesh.dim, field.ncomp), ())
        if spec.sel not in comps and not (spec.sel.isdigit() and int(spec.sel) < field.ncomp):
            return (f"no component {spec.sel!r} of {spec.name!r} (known: {', '.join(comps)}, "
                    f"or 0..{field.ncomp - 1})")
    if spec.at is not None:
        if len(spec.at) != mesh.dim:
            return f"the point needs {mesh.dim} coordinates"
        if locate(mesh.points, mesh.cells, mesh.cell_type, spec.at) is None:
            return f"point {spec.at} is outside the mesh"
    if spec.region is not None:
        try:
            model.regions()(spec.region, spec.text)
        except InputError as exc:
            return f"region {spec.region!r}: {exc.message}"
    return None


def measure(study: Study, setting: Setting, outcome) -> Measured:
    """Read one run's result; a quantity the result cannot give is an InputError naming the
    study file and the quantity's key."""
    from parsolve.post.result import Result
    from parsolve.post.spec import series

    m = Measured(setting, outcome.status, wall=outcome.seconds, result=outcome.result)
    from parsolve.batch.runner import STDOUT

    m.peak_mb, m.peak_total_mb = peak_memory(Path(outcome.folder) / STDOUT)
    if not m.ok:
        return m
    with Result(outcome.result) as res:
        if "dofs" in res.file.attrs:  # the unknowns of every field
            m.dofs = int(res.file.attrs["dofs"])
        else:
            u = res.file["fields/displacement"]
            m.dofs = int(u.shape[1] * u.shape[2])
        m.phases = {n: float(res.file[f"timings/{n}"][()].sum()) for n in res.names("timings")}
        for q in study.quantities:
            try:
                m.values[q.name] = float(series(res, q.spec)[-1])
            except InputError as exc:
                raise InputError(f"{exc.message} (in {outcome.result})", study.source,
                                 q.key + ".spec") from None
    return m


def run_grid(study: Study, settings: list[Setting], root: Path, executor: str, parallel: int,
             log: Callable[[str], None] = print) -> list[Measured]:
    """Run the coarsest setting first (a quantity naming a missing field stops the study
    there), then the rest. Runs already complete with the same scene, ranks and arguments are
    kept (the batch API's resume): a study interrupted or extended runs only what is new."""
    from parsolve.batch.api import Run, execute

    args = tuple(study.args) + RUN_ARGS
    runs = [Run(s.name, s.scene_text, study.ranks, args, params=s.changes) for s in settings]
    kw = dict(executor=executor, parallel=parallel, resources=study.resources, resume=True, log=log)
    first = execute(runs[:1], root, **kw)[0]
    if first.ok:
        measure(study, settings[0], first)
    outcomes = execute(runs, root, **kw)
    return [measure(study, s, o) for s, o in zip(settings, outcomes)]
