"""Scene files (TOML) → a validated, typed scene. Every input error is raised here.

Errors name the file and the dotted key (``scene.toml: relations[2].component: ...``). The
scene is parsed identically on every rank, so an error is raised on all ranks together.
"""

from __future__ import annotations

import inspect
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from parsolve.errors import InputError
from parsolve.schema import (MAX_MAGNITUDE, MIN_MAGNITUDE, NAME_PATTERN, Declared,  # noqa: F401
                             Table, check_number, field_name, plain_name)
from parsolve.evolution import CONSTANT, RAMP, Evolution
from parsolve.fem.axisymmetric import Axisymmetric
from parsolve.loads.base import LoadSpec
from parsolve.loads.registry import parse as parse_load
from parsolve.relation_kinds.base import RelationSpec
from parsolve.relation_kinds.registry import RELATIONS

HYPOTHESES = ("plane_stress", "plane_strain", "3d", "axisymmetric")
PRESETS = ("direct", "iterative", "auto")
PARTITIONERS = ("scotch", "bisection")   # parsolve.mesh.partition.PARTITIONERS
DEFAULT_PARTITIONER = "scotch"
MAX_STEPS = 1_000_000


@dataclass
class MeshSpec:
    file: Path | None
    generator: str | None
    params: dict
    order: int


@dataclass
class RegionSpec:
    name: str
    kind: str          # "expr", "box", "point", "group"
    value: Any
    key: str


@dataclass
class NonlinearSpec:
    method: str            # "newton" or "arc_length"
    max_iterations: int
    rtol: float            # force residual relative to the forces in play
    stol: float            # increment relative to the displacement
    max_active_set_changes: int
    arc_pattern: str | None
    arc_length: float | None
    matrix: str = "tangent"   # "tangent" (consistent) or "secant" ((1 - D) C for damage)


@dataclass
class StepSpec:
    times: list[float]
    automatic: bool = False
    strain_increment: float = 0.0   # target largest strain increment per step
    max_steps: int = 0
    end: float = 0.0


@dataclass
class TimeSpec:
    """A transient run: the steps' t are times; θ-scheme (1: backward Euler) and the kind of
    capacity matrix (lumped keeps concentrations monotone when relations switch)."""

    theta: float = 1.0
    mass: str = "lumped"


@dataclass
class SolverSpec:
    preset: str
    prefix: str
    options: dict[str, str]
    eliminate: bool
    split: str = "primal"   # fieldsplit blocks: "primal" (q, lambda) or "fields" (one per field)
    partitioner: str = DEFAULT_PARTITIONER  # cells to ranks: "scotch" (PT-Scotch) or "bisection"
    chosen: str = ""   # why an "auto" preset became the one it is (build_model: solvers.choice)
    # ([solver] mesh is deprecated: every run holds its part of the mesh, 1 rank included; the
    # key is accepted whatever its value, ignored with a warning (``_deprecated_mesh``), and
    # will be refused in the next release)


@dataclass
class Scene:
    source: str
    text: str
    title: str
    mesh: MeshSpec
    hypothesis: str
    thickness: Any   # float, or fem.axisymmetric.Axisymmetric (2π r) for "axisymmetric"
    regions: dict[str, RegionSpec]
    evolutions: dict[str, Evolution]
    loads: list[LoadSpec]
    relations: list[RelationSpec]
    times: list[float]
    solver: SolverSpec
    output: str | None
    nonlinear: NonlinearSpec | None = None
    steps: StepSpec | None = None
    effects: list[str] = field(default_factory=list)
    effect_specs: dict[str, list] = field(default_factory=dict)   # registry name -> specs
    time: TimeSpec | None = None                                  # None: quasi-static
    dimension: int = 2                                            # without a hypothesis
    output_mode: str | None = None                                # [output] mode; None: swmr

    @property
    def dim(self) -> int:
        if self.hypothesis is None:
            return self.dimension
        return 3 if self.hypothesis == "3d" else 2

    @property
    def fields(self) -> dict[str, int]:
        """Field name -> number of components, as the effects will declare them."""
        return _declared_fields(self.effect_specs, self.dim)

    @property
    def primary(self) -> str | None:
        """The field loads and relations address without a ``field`` key: the displacement
        (None without elasticity)."""
        return _primary_field(self.effect_specs, self.dim)

    @property
    def materials(self) -> list:
        """The [[materials]] entries (the elasticity's specs; none without elasticity)."""
        specs = self.effect_specs
        return specs["elasticity"] if "elasticity" in specs else []


# ---------------------------------------------------------------- parsing


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file (everything but what needs the mesh: see ``model``)."""
    path = Path(path)
    data, text = read_toml(path)
    return parse_scene(data, str(path), text, path.parent)


def read_toml(path: Path, what: str = "scene") -> tuple[dict, str]:
    """(data, text) of a TOML file (a scene, a study, a job file), or an InputError."""
    source = str(path)
    text = read_text(path, source, what)
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"invalid TOML: {exc}", source) from None


def read_text(path: Path, source: str, what: str = "scene") -> str:
    """The file's text: a readable file of UTF-8 text, or an InputError saying what it is."""
    if path.is_dir():
        raise InputError(f"is a folder, not a {what} file", source)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read {what} file ({exc.strerror or exc})", source) from None
    if b"\0" in raw:
        raise InputError(f"is a binary file, not a TOML {what} (it contains NUL bytes)", source)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise InputError(f"is not UTF-8 text (byte 0x{raw[exc.start]:02x} on line {line}); "
                         "save it as UTF-8", source) from None


def parse_scene(data: dict, source: str, text: str = "", base: Path = Path(".")) -> Scene:
    top = Table(data, "", source)
    title = top.get("title", str, "")
    mesh = _mesh(top.table("mesh"), base)
    model = top.table("model")
    # the mechanics needs a hypothesis (its entries say so); other physics may go without
    needed = any(e.hypothesis and top.has(e.section) for e in _registry().values())
    hypothesis = model.get("hypothesis", str, ... if needed else None, choices=HYPOTHESES)
    dimension = model.get("dimension", int, 3 if hypothesis == "3d" else 2, choices=(2, 3))
    if hypothesis == "axisymmetric" and model.has("thickness"):
        raise model.error("thickness", "an axisymmetric model has no thickness (its measure "
                          "is 2π r: forces are for the whole ring)")
    thickness = model.get("thickness", float, 1.0)
    if thickness <= 0:
        raise model.error("thickness", "must be positive")
    if hypothesis == "axisymmetric":
        thickness = _axisymmetric_measure(mesh, source)
    model.done()
    regions = _regions(top.table("regions", {}))
    evolutions = _evolutions(top.table("evolutions", {}))
    dim = dimension if hypothesis is None else 3 if hypothesis == "3d" else 2
    effect_specs = _effect_specs(top, dim)
    if not effect_specs:
        raise InputError("nothing to simulate: give a physics section (" + ", ".join(
            f"[{e.section}] ({name})" for name, e in _registry().items()) + ")", source,
            "materials")
    fields = _declared_fields(effect_specs, dim)
    declared = Declared(dim, fields, _primary_field(effect_specs, dim))
    loads = [parse_load(t, declared) for t in top.tables("loads")]
    relations = [_relation(t, declared) for t in top.tables("relations")]
    time_spec = _time(top.table("time", None))
    if time_spec is not None and not top.has("steps"):
        raise InputError("a transient scene needs its time steps ([steps] times or count/end)",
                         source, "steps")
    steps = _steps(top.table("steps", {}))
    solver = _solver(top.table("solver", {}))
    nonlinear = _nonlinear(top.table("nonlinear", {}))
    out = top.table("output", {})
    output = out.get("file", str, None)
    output_mode = out.get("mode", str, None, choices=("swmr", "parallel", "auto"))
    out.done()
    top.done()
    scene = Scene(source, text, title, mesh, hypothesis, thickness, regions, evolutions, loads, relations, steps.times, solver, output, nonlinear, steps,
                  effect_specs=effect_specs, time=time_spec, dimension=dim,
                  output_mode=output_mode)
    _cross_check(scene)
    scene.effects = _effects(scene)
    return scene


def _mesh(t: Table, base: Path) -> MeshSpec:
    from parsolve.mesh.generators import GENERATORS

    order = t.get("order", int, 1, choices=(1, 2))
    if t.has("file") == t.has("generator"):
        raise t.error("file", "give exactly one of 'file' or 'generator'")
    if t.has("file"):
        file = base / t.get("file", str)
        t.done()
        return MeshSpec(file, None, {}, order)
    gen = t.get("generator", str, choices=tuple(GENERATORS))
    signature = inspect.signature(GENERATORS[gen])
    params = {}
    for name, par in signature.parameters.items():
        if par.default is inspect.Parameter.empty or t.has(name):
            value = t.get(name, (int, float, str, list))
            params[name] = t.floats(name) if isinstance(value, list) else value
    t.done()
    return MeshSpec(None, gen, params, order)


def _regions(t: Table) -> dict[str, RegionSpec]:
    regions = {}
    for name in list(t.data):
        value = t.get(name, (str, dict))
        key = t.key(name)
        if isinstance(value, str):
            regions[name] = RegionSpec(name, "expr", value, key)
            continue
        sub = Table(value, key, t.source)
        kinds = [k for k in ("expr", "box", "point", "group") if sub.has(k)]
        if len(kinds) != 1:
            raise InputError("give exactly one of expr, box, point, group", t.source, key)
        kind = kinds[0]
        if kind == "box":
            raw = sub.get("box", list)
            if len(raw) != 2 or not all(isinstance(v, list) for v in raw):
                raise sub.error("box", "expected [[xmin, ymin(, zmin)], [xmax, ymax(, zmax)]]")
            corners = Table({f"box[{i}]": c for i, c in enumerate(raw)}, key, t.source)
            regions[name] = RegionSpec(name, kind, [corners.floats("box[0]"), corners.floats("box[1]")], key)
        elif kind == "point":
            regions[name] = RegionSpec(name, kind, sub.floats("point"), key)
        else:
            regions[name] = RegionSpec(name, kind, sub.get(kind, str), key)
        sub.done()
    return regions


def _evolutions(t: Table) -> dict[str, Evolution]:
    evols = {"ramp": RAMP, "constant": CONSTANT}
    for name in list(t.data):
        sub = t.table(name)
        times, values = sub.floats("times"), sub.floats("values")
        if len(times) != len(values) or len(times) < 1:
            raise sub.error("values", "times and values must have the same, non-zero length")
        if any(b <= a for a, b in zip(times, times[1:])):
            raise sub.error("times", "must be strictly increasing")
        sub.done()
        evols[name] = Evolution(name, tuple(times), tuple(values))
    return evols


def _relation(t: Table, declared: Declared) -> RelationSpec:
    """A [[relations]] entry: the common keys, and its kind's own as its registry entry reads
    them (``relation_kinds.registry``)."""
    name = plain_name(t)
    kind = t.get("type", str, choices=tuple(RELATIONS))
    entry = RELATIONS[kind]
    spec = RelationSpec(name, kind, t.path, field_name(t, declared))
    entry.parse(t, spec, declared)
    if entry.value is None and t.has("value"):
        raise t.error("value", f"an {kind!r} relation has no value")
    spec.value = t.get("value", entry.value, 0.0) if entry.value is not None else 0.0
    spec.evolution = t.get("evolution", str, "ramp")
    spec.dual = t.get("dual", str, None)
    spec.sense = t.get("sense", str, "=", choices=("=", "<=", ">="))
    spec.eliminate = t.get("eliminate", bool, None)
    spec.maximum = t.get("maximum", bool, False)
    spec.report = t.get("report", bool, False)
    if spec.maximum and spec.sense == "=":
        raise t.error("maximum", "a maximum control needs a unilateral sense ('<=' or '>=')")
    if spec.maximum and not spec.per_cell:
        raise t.error("maximum", "a maximum control needs several rows (per_cell = true)")
    t.done()
    return spec


def _declared_fields(effect_specs: dict, dim: int) -> dict[str, int]:
    """Field name -> components, as each listed effect declares them (its registry entry
    says), in the registry's order."""
    out = {}
    for name, specs in effect_specs.items():
        for spec in _declaring(name, specs):
            out |= _registry()[name].fields(spec, dim)
    return out


def _declaring(name: str, specs: list) -> list:
    """The specs that declare fields: each entry's, or the first one's when one effect takes
    the whole section (every [[materials]] entry is the same displacement)."""
    return specs[:1] if _registry()[name].whole else specs


def _primary_field(effect_specs: dict, dim: int) -> str | None:
    """The field loads and relations address without a ``field`` key (the displacement)."""
    for name, specs in effect_specs.items():
        if _registry()[name].primary:
            return next(iter(_registry()[name].fields(specs[0], dim)))
    return None


def _registry() -> dict:
    from parsolve.effects.registry import EFFECTS

    return EFFECTS


def _effect_specs(top: Table, dim: int) -> dict[str, list]:
    """The physics sections the scene lists, each read by its effect's own schema."""
    specs = {}
    for name, entry in _registry().items():
        if not top.has(entry.section):
            continue
        tables = top.tables(entry.section) if entry.array else [top.table(entry.section)]
        specs[name] = [entry.parse(t, dim) for t in tables]
    seen = set()
    for name, entry_specs in specs.items():
        for spec in _declaring(name, entry_specs):
            for declared in _registry()[name].fields(spec, dim):
                if declared in seen:
                    raise InputError(f"field {declared!r} is declared twice", top.source,
                                     spec.key + ".field")
                seen.add(declared)
    return specs


def _time(t: Table | None) -> TimeSpec | None:
    if t is None:
        return None
    scheme = t.get("scheme", str, "backward_euler", choices=("backward_euler", "theta"))
    theta = t.get("theta", float, 1.0 if scheme == "backward_euler" else 0.5)
    if scheme == "backward_euler" and theta != 1.0:
        raise t.error("theta", "backward Euler is θ = 1; use scheme = \"theta\"")
    if not 0.5 <= theta <= 1.0:
        raise t.error("theta", "must lie in [0.5, 1] (unconditionally stable schemes)")
    mass = t.get("mass", str, "lumped", choices=("lumped", "consistent"))
    t.done()
    return TimeSpec(theta, mass)


def _steps(t: Table) -> StepSpec:
    if t.has("times"):
        times = t.floats("times")
        if len(times) > MAX_STEPS:
            raise t.error("times", f"{len(times)} steps is absurd (at most {MAX_STEPS})")
        if not times or any(b <= a for a, b in zip([0.0] + times, times)):
            raise t.error("times", "must be positive and strictly increasing")
        t.done()
        return StepSpec(times)
    count = t.get("count", int, 1)
    end = t.get("end", float, 1.0)
    if count < 1:
        raise t.error("count", "must be at least 1 (a non-positive step is not a step)")
    if count > MAX_STEPS:
        raise t.error("count", f"{count} steps is absurd (at most {MAX_STEPS})")
    if end <= 0:
        raise t.error("end", "must be positive")
    auto = t.table("automatic", None)
    spec = StepSpec([end * (i + 1) / count for i in range(count)])
    if auto is not None:
        spec.automatic = True
        spec.strain_increment = auto.get("strain_increment", float)
        if spec.strain_increment <= 0:
            raise auto.error("strain_increment", "must be positive")
        spec.max_steps = auto.get("max_steps", int, 10 * count)
        if not 1 <= spec.max_steps <= MAX_STEPS:
            raise auto.error("max_steps", f"must lie between 1 and {MAX_STEPS}")
        spec.end = end
        auto.done()
    t.done()
    return spec


def _nonlinear(t: Table) -> NonlinearSpec:
    method = t.get("method", str, "newton", choices=("newton", "arc_length"))
    spec = NonlinearSpec(method, t.get("max_iterations", int, 30), t.get("rtol", float, 1e-8),
                         t.get("stol", float, 1e-10), t.get("max_active_set_changes", int, 30),
                         None, None)
    spec.matrix = t.get("matrix", str, "tangent", choices=("tangent", "secant"))
    if not 1 <= spec.max_iterations <= 100_000:
        raise t.error("max_iterations", "must lie between 1 and 100000")
    for name in ("rtol", "stol"):
        if not 0 < getattr(spec, name) < 1:
            raise t.error(name, "must lie in (0, 1)")
    if not 0 <= spec.max_active_set_changes <= 100_000:
        raise t.error("max_active_set_changes", "must lie between 0 and 100000")
    if method == "arc_length":
        arc = t.table("arc_length")
        spec.arc_pattern = arc.get("pattern", str)
        spec.arc_length = arc.get("length", float)
        if spec.arc_length <= 0:
            raise arc.error("length", "must be positive")
        arc.done()
    t.done()
    return spec


def _flatten(t: Table, prefix: str = "") -> dict[str, str]:
    """Nested PETSc settings to option keys: {ksp: {type: "cg"}} → {"ksp_type": "cg"}."""
    flat = {}
    for name in list(t.data):
        value = t.get(name, (str, int, float, bool, dict))
        key = f"{prefix}{name}"
        if isinstance(value, dict):
            flat.update(_flatten(Table(value, t.key(name), t.source), key + "_"))
        elif isinstance(value, bool):
            flat[key] = "true" if value else "false"
        else:
            flat[key] = str(value)
    return flat


def _solver(t: Table) -> SolverSpec:
    preset = t.get("preset", str, "auto", choices=PRESETS)   # auto: solvers.choice
    prefix = t.get("prefix", str, "parsolve_")
    if not prefix or not prefix.endswith("_") or not prefix.replace("_", "").isalnum():
        raise t.error("prefix", "must be non-empty, alphanumeric and end with '_'")
    eliminate = t.get("eliminate", bool, True)
    split = t.get("split", str, "primal", choices=("primal", "fields"))
    partitioner = t.get("partitioner", str, DEFAULT_PARTITIONER, choices=PARTITIONERS)
    if "mesh" in t.data:
        t.used.add("mesh")   # whatever its value, but a number must be one (nan, inf refused)
        if isinstance(t.data["mesh"], float):
            check_number(t.data["mesh"], t.source, t.key("mesh"))
        _deprecated_mesh(t)
    options = _flatten(t.table("petsc", {}))
    t.done()
    return SolverSpec(preset, prefix, options, eliminate, split, partitioner)


_MESH_WARNED = False


def _deprecated_mesh(t: Table) -> None:
    """``[solver] mesh`` (any value): accepted and ignored for this release, said once per
    process on rank 0; the next release refuses it (exit 2)."""
    global _MESH_WARNED
    if _MESH_WARNED:
        return
    _MESH_WARNED = True
    from mpi4py import MPI

    if MPI.COMM_WORLD.rank == 0:
        print(f"parsolve: warning: {t.source}: {t.key('mesh')}: deprecated and ignored (every "
              "run distributes the mesh, 1 rank included); it will be refused in the next "
              "release: remove it", file=sys.stderr)


def _axisymmetric_measure(mesh: MeshSpec, source: str):
    """The 2π r measure; its mesh check names the mesh file (or the scene's [mesh])."""
    where = (str(mesh.file), "mesh.file") if mesh.file is not None else (source, "mesh")
    return Axisymmetric(mesh_source=where)


def _cross_check(scene: Scene) -> None:
    """References between sections: regions, evolutions, load patterns, relation names."""
    src = scene.source
    known = set(scene.regions) | {"all"}

    def region(name: str | None, key: str) -> None:
        # file groups are only known once the mesh is read: checked again in model building
        if name is not None and name not in known and scene.mesh.file is None:
            if not _generator_group(scene, name):
                raise InputError(f"unknown region {name!r}", src, key)

    for name, specs in scene.effect_specs.items():
        entry = _registry()[name]
        for spec in specs:
            for evolution, key in entry.evolutions(spec):
                if evolution not in scene.evolutions:
                    raise InputError(f"unknown evolution {evolution!r}", src, key)
            for region_name, key in entry.regions(spec):
                region(region_name, key)
    patterns = {l.pattern for l in scene.loads}
    if scene.nonlinear.method == "arc_length" and scene.nonlinear.arc_pattern not in patterns:
        raise InputError(f"names no load pattern: {scene.nonlinear.arc_pattern!r}", src,
                         "nonlinear.arc_length.pattern")
    for l in scene.loads:
        region(l.region, l.key + ".region")
        if l.evolution not in scene.evolutions:
            raise InputError(f"unknown evolution {l.evolution!r}", src, l.key + ".evolution")
    names = set()
    for r in scene.relations:
        if r.name in names:
            raise InputError(f"duplicate relation name {r.name!r}", src, r.key + ".name")
        names.add(r.name)
        for region_name, key in RELATIONS[r.type].regions(r):
            region(region_name, key)
        if r.evolution not in scene.evolutions:
            raise InputError(f"unknown evolution {r.evolution!r}", src, r.key + ".evolution")
        if r.dual is not None and r.dual not in patterns:
            raise InputError(f"dual names no load pattern: {r.dual!r} (patterns: "
                             f"{', '.join(sorted(patterns)) or 'none'})", src, r.key + ".dual")
    _fixed_directions(scene)


def _fixed_directions(scene: Scene) -> None:
    """A pattern that is a direction (a relation's dual, the arc-length's reference) is one
    vector: none of its loads may vary in time."""
    directions = {r.dual: r.key + ".dual" for r in scene.relations if r.dual is not None}
    if scene.nonlinear.method == "arc_length":
        directions[scene.nonlinear.arc_pattern] = "nonlinear.arc_length.pattern"
    for l in scene.loads:
        if l.pattern in directions and l.timed:
            raise InputError(f"pattern {l.pattern!r} is a direction ({directions[l.pattern]}): "
                             "its values cannot name t (use an evolution)", scene.source,
                             l.values_key)


def _generator_group(scene: Scene, name: str) -> bool:
    """Groups that generators always create (e.g. 'left', 'hole')."""
    from parsolve.mesh.generators import GENERATOR_GROUPS

    return name in GENERATOR_GROUPS.get(scene.mesh.generator, ())


def _effects(scene: Scene) -> list[str]:
    """The effects the scene calls for; only these are built and iterated."""
    effects = list(scene.effect_specs)
    if scene.time is not None:
        effects.append("transient")
    if scene.loads:
        effects.append("loads")
    if scene.relations:
        effects.append("relations")
    if any(r.dual for r in scene.relations):
        effects.append("control")
    if any(r.sense != "=" for r in scene.relations):
        effects.append("unilateral")
    for name, specs in scene.effect_specs.items():   # e.g. "nonlinear material"
        effects += _registry()[name].labels(specs)
    return effects
