"""The study file.

    title = "Kirsch: stress concentration"
    scene = "../kirsch.toml"          # base scene, relative to the study file
    ranks = 1                         # mpirun -n per run
    executor = "local"                # or "slurm" (command line --executor wins)
    parallel = 1                      # runs at a time (local); --parallel wins
    cost = "wall"                     # seconds of a run: "wall" (the process) or "compute"
                                      # (the sum of its /timings/total)
    target = 1e-3                     # optional: the cheapest setting reaching this error
    args = ["-mat_mumps_icntl_14", "80"]   # optional extra arguments of every run

    [refine]                          # the levels: multiply base values of generator keys ...
    keys = ["mesh.n_radial", "mesh.n_angular"]
    levels = [1, 2, 4]
    # files = ["coarse.msh", "fine.msh"]   # ... or a list of mesh files (mesh.file)

    [vary]                            # every combination is one family (one series)
    "mesh.cell" = ["triangle", "triangle6"]
    "solver.preset" = ["direct"]
    # or explicit families:  [[families]]  name = "P2"  set = { "mesh.cell" = "triangle6" }

    [[quantities]]                    # the first one is the error measure of the picture
    name = "scf"
    spec = "field:stress:xx@0,1"      # the SPEC language of parsolve post (last step)
    reference = 3.0                   # a number, an expression ("1e9 * 0.1 * 1e-4"), or
                                      # "richardson" (from the finest runs of a family)
    error = "relative"                # "relative" | "absolute" | "energy_norm"
    # richardson_family = "triangle6" # the family extrapolated (default: the last one)

    [reduced]                         # --reduced: these dotted keys replace the above (CI)
    "refine.levels" = [1, 2]

Refused (exit 2, naming this file and the key), before any run: ranks or parallel below 1, a
target that is not a positive finite number, more than MAX_LEVELS levels or MAX_RUNS runs, a
missing mesh file, a reference that is not finite or whose expression overflows, divides by
zero or is too long or deeply nested (see expression.py); and, checked on the coarsest scene of
every family (execute.check_quantities), a spec naming a relation, field, component, row or
region the scene lacks, or a point outside its mesh, and PETSc options PETSc refuses.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

from parsolve.errors import InputError
from parsolve.scene import Table, read_toml
from parsolve.study.expression import evaluate_expression

ERRORS = ("relative", "absolute", "energy_norm")
MAX_LEVELS = 12     # refinement levels (or mesh files) of a study
MAX_RUNS = 200      # families × levels


@dataclass
class Quantity:
    name: str
    spec: str
    reference: float | str          # a value or "richardson"
    error: str
    key: str                        # quantities[i] in the study file
    richardson_family: str | None = None


@dataclass
class Family:
    name: str
    changes: dict
    key: str


@dataclass
class Study:
    source: str
    title: str
    scene: Path
    ranks: int
    executor: str
    parallel: int
    cost: str
    target: float | None
    args: tuple[str, ...]
    refine_keys: list[str]
    levels: list                    # multipliers (int) or mesh files (str)
    families: list[Family]
    quantities: list[Quantity]
    resources: dict = field(default_factory=dict)


def load_study(path: str | Path, reduced: bool = False) -> Study:
    path = Path(path)
    source = str(path)
    data = read_toml(path, "study")[0]
    top = Table(data, "", source)
    changes = top.get("reduced", dict, {})
    if reduced:
        for dotted, value in changes.items():
            _replace(data, dotted, value, source)
    return _parse(top, path.parent)


def _replace(data: dict, dotted: str, value, source: str) -> None:
    *parents, last = dotted.split(".")
    node = data
    for i, part in enumerate(parents):
        if not isinstance(node.get(part), dict):
            raise InputError("no such table in the study", source, f"reduced.{dotted}")
        node = node[part]
    if last not in node:
        raise InputError("no such key in the study", source, f"reduced.{dotted}")
    node[last] = value


def _parse(top: Table, folder: Path) -> Study:
    source = top.source
    title = top.get("title", str, "")
    scene = folder / top.get("scene", str)
    if not scene.is_file():
        raise top.error("scene", f"no scene file {str(scene)!r}")
    ranks = _at_least_one(top, "ranks")
    executor = top.get("executor", str, "local", choices=("local", "slurm"))
    parallel = _at_least_one(top, "parallel")
    cost = top.get("cost", str, "wall", choices=("wall", "compute"))
    target = top.get("target", float, None)
    if target is not None and not positive_number(target):
        raise top.error("target", f"expected a positive finite number, got {target!r}")
    args = tuple(str(a) for a in top.get("args", list, []))
    resources = top.get("slurm", dict, {})
    top.get("reduced", dict, {})
    keys, levels = _refine(top.table("refine"), folder)
    families = _families(top)
    if len(families) * len(levels) > MAX_RUNS:
        raise top.error("vary" if top.has("vary") else "families",
                        f"{len(families)} families × {len(levels)} levels = "
                        f"{len(families) * len(levels)} runs, more than {MAX_RUNS}")
    quantities = [_quantity(t) for t in top.tables("quantities")]
    if not quantities:
        raise InputError("at least one [[quantities]] entry is required", source, "quantities")
    names = [f.name for f in families]
    for q in quantities:
        if q.richardson_family is not None and q.richardson_family not in names:
            raise InputError(f"no family {q.richardson_family!r} (known: {', '.join(names)})",
                             source, q.key + ".richardson_family")
    top.done()
    return Study(source, title, scene, ranks, executor, parallel, cost, target, args, keys, levels,
                 families, quantities, resources)


def positive_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) \
        and value > 0


def _at_least_one(top: Table, name: str) -> int:
    value = top.get(name, int, 1)
    if value < 1:
        raise top.error(name, f"must be at least 1, got {value}")
    return value


def _refine(t: Table, folder: Path) -> tuple[list[str], list]:
    if t.has("files"):
        files = t.get("files", list)
        if not files or not all(isinstance(f, str) for f in files):
            raise t.error("files", "expected a list of mesh file names")
        if len(files) > MAX_LEVELS:
            raise t.error("files", f"{len(files)} mesh files, more than {MAX_LEVELS} levels")
        for i, f in enumerate(files):
            if not (folder / f).is_file():
                raise InputError(f"no mesh file {str(folder / f)!r}", t.source, f"{t.key('files')}[{i}]")
        t.done()
        return ["mesh.file"], [str((folder / f).resolve()) for f in files]
    keys = t.get("keys", list)
    levels = t.get("levels", list)
    if not keys or not all(isinstance(k, str) for k in keys):
        raise t.error("keys", "expected a list of dotted scene keys, e.g. [\"mesh.nx\", \"mesh.ny\"]")
    if len(levels) < 2 or not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in levels):
        raise t.error("levels", "expected at least two positive integers, e.g. [1, 2, 4]")
    if len(levels) > MAX_LEVELS:
        raise t.error("levels", f"{len(levels)} levels, more than {MAX_LEVELS}")
    t.done()
    return keys, levels


def _families(top: Table) -> list[Family]:
    if top.has("vary") and top.has("families"):
        raise top.error("families", "give [vary] or [[families]], not both")
    if top.has("families"):
        out = []
        for t in top.tables("families"):
            out.append(Family(t.get("name", str), dict(t.get("set", dict, {})), t.path))
            t.done()
        if len({f.name for f in out}) != len(out):
            raise top.error("families", "family names must differ")
        return out
    vary = top.table("vary", {})
    if vary is None or not vary.data:
        return [Family("base", {}, "vary")]
    axes = []
    for k, values in vary.data.items():
        vary.get(k, list)
        if not values:
            raise vary.error(k, "expected a non-empty list of values")
        axes.append([(k, v) for v in values])
    fams = []
    for combo in itertools.product(*axes):
        varied = [(k, v) for k, v in combo if len(vary.data[k]) > 1] or list(combo)
        name = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in varied)
        fams.append(Family(name, dict(combo), "vary"))
    return fams


def _quantity(t: Table) -> Quantity:
    name = t.get("name", str)
    spec = t.get("spec", str)
    ref = t.get("reference", (float, str))
    if isinstance(ref, str) and ref != "richardson":
        try:
            ref = evaluate_expression(ref)
        except ValueError as exc:
            raise t.error("reference", f"expected a number, an expression or \"richardson\": {exc}") from None
    if isinstance(ref, float) and not math.isfinite(ref):
        raise t.error("reference", f"expected a finite number, got {ref}")
    error = t.get("error", str, "relative", choices=ERRORS)
    fam = t.get("richardson_family", str, None)
    t.done()
    return Quantity(name, spec, ref, error, t.path, fam)
