"""Scene + mesh → the effects the scene lists (their fields, materials), loads and relations.
All input errors that need the mesh are raised here, before any solve; ``parsolve check``
stops after this."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsolve import progress
from parsolve.collective import agree
from parsolve.effects.base import Effect
from parsolve.relation_kinds.build import build_relations
from parsolve.effects.elasticity import Elasticity
from parsolve.effects.registry import EFFECTS
from parsolve.errors import InputError
from parsolve.fields import FieldSet
from parsolve.loads.base import Instant, LoadPattern, load_patterns
from parsolve.loads.build import SceneLoads
from parsolve.mesh import blocks, gmsh, memory
from parsolve.mesh.checks import check_mesh
from parsolve.mesh.distribute import LocalMesh, distribute
from parsolve.mesh.generators import GENERATORS, SLICED, make_quadratic
from parsolve.mesh.gmshmesh import open_gmsh
from parsolve.mesh.midside import QuadraticSlices
from parsolve.mesh.h5mesh import is_mesh_h5, open_mesh, read_whole
from parsolve.mesh.mesh import CELL_INFO, SECOND_ORDER, Mesh
from parsolve.mesh.reader import read_mesh
from parsolve.mesh.regions import RegionResolver
from parsolve.mesh.slices import distribute_slices
from parsolve.mesh.xdmfmesh import is_xdmf, open_xdmf
from parsolve.relations import Relation
from parsolve.scene import Scene
from parsolve.solvers.choice import choose


@dataclass
class Model:
    scene: Scene
    mesh: LocalMesh       # this rank's part (``mesh.distribute``; on 1 rank the whole mesh)
    fields: FieldSet
    effects: list[Effect]
    patterns: dict[str, LoadPattern]
    relations: list[Relation]
    reference_patterns: tuple[str, ...] = ()  # applied by a solver (arc-length), not as loads
    comm: object = None   # the ranks sharing the mesh

    def regions(self) -> RegionResolver:
        """A fresh resolver of the scene's regions on this model's mesh."""
        return RegionResolver(self.mesh, self.scene.regions, self.scene.source, self.comm)

    @property
    def ncomp(self) -> int:
        """DOFs per node (all fields)."""
        return self.fields.ncomp

    @property
    def elasticity(self) -> Elasticity | None:
        return next((e for e in self.effects if isinstance(e, Elasticity)), None)

    @property
    def nonlinear(self) -> bool:
        """An effect, or a term one declares, is nonlinear: the Newton loop runs."""
        return any(not e.linear or any(not t.linear for t in e.terms()) for e in self.effects)

    @property
    def transient(self) -> bool:
        return self.scene.time is not None

    def symmetric(self, secant: bool = False) -> bool:
        """Every effect's tangent is symmetric (Mazars' only with the secant matrix), and so
        is every term the effects declare."""
        def holds(symmetric: bool, e) -> bool:
            return symmetric or secant and getattr(e, "symmetric_secant", False)
        return all(holds(e.symmetric, e) and all(holds(t.symmetric, e) for t in e.terms())
                   for e in self.effects)

    def initial_q(self) -> np.ndarray:
        """The primal vector at t = 0 (this rank's DOFs): the effects' initial values, else 0."""
        q = np.zeros((self.mesh.num_points, self.ncomp))
        for e in self.effects:
            for name, values in e.initial().items():
                q[:, self.fields.columns(name)] = values
        return q.ravel()

    def external_load(self, t: "float | Instant") -> np.ndarray:
        """Known loads at an instant (a time, or t with the step's Δt and θ; this rank's
        DOFs); patterns used as duals are not applied."""
        duals = {r.meta.get("dual") for r in self.relations} | set(self.reference_patterns)
        f = np.zeros(self.mesh.num_points * self.ncomp)
        for name, pattern in self.patterns.items():
            if name not in duals:
                f += pattern.at(t)
        return f


def mesh_source(scene: Scene) -> tuple[str, str]:
    """(file, key) that the mesh's errors name."""
    if scene.mesh.file is not None:
        return str(scene.mesh.file), "mesh.file"
    return scene.source, "mesh"


def build_mesh(scene: Scene) -> Mesh:
    """The scene's whole mesh, checked: its size against this machine's memory (a generator's
    before it runs, a file's once read; this process alone: rank 0 builds it), coordinates
    (the cells: by blocks, ``build_model``); ``mesh.warnings`` says the rest."""
    spec = scene.mesh
    source, key = mesh_source(scene)
    if spec.file is not None:
        mesh = read_whole(source) if is_mesh_h5(source) else read_mesh(source)
        memory.check_whole_mesh(_points_after_order(mesh, spec.order), mesh.dim, source, key,
                                f"a mesh of {mesh.num_cells} {mesh.cell_type} cells")
    else:
        counted = _generated_counts(scene)   # None: bad parameters, the generator says which
        if counted is not None:
            points, cells, dim = counted
            memory.check_whole_mesh(points, dim, scene.source, "mesh.generator",
                                    f"the {spec.generator} of {cells} cells and {points} nodes")
        try:
            with np.errstate(over="raise", divide="raise", invalid="raise"):
                mesh = GENERATORS[spec.generator](**spec.params)
        except (TypeError, ValueError, FloatingPointError, OverflowError, MemoryError) as exc:
            raise InputError(f"invalid generator parameters: {exc}", scene.source,
                             _generator_key(exc)) from None
    if spec.order == 2 and mesh.cell_type in ("triangle", "tetra"):
        mesh = make_quadratic(mesh)
    elif spec.order == 2 and mesh.cell_type not in SECOND_ORDER:
        raise InputError(f"order = 2 needs a simplex mesh, not {mesh.cell_type} (or one of "
                         f"second-order cells: {', '.join(SECOND_ORDER)})", scene.source,
                         "mesh.order")
    _refuse_contact_on(scene, mesh.cell_type)
    if mesh.dim != scene.dim:
        raise InputError(f"a {mesh.dim}D mesh ({mesh.cell_type}) cannot carry hypothesis "
                         f"{scene.hypothesis!r}", scene.source, "model.hypothesis")
    mesh.warnings = [f"{source}: {key}: {w}" for w in check_mesh(mesh, source, key)]
    return mesh


@dataclass
class BuildContext:
    scene: Scene
    mesh: Mesh
    regions: RegionResolver
    fields: FieldSet | None = None


def build_effects(scene: Scene, mesh: LocalMesh, regions: RegionResolver) -> tuple[list[Effect], FieldSet]:
    """The effects the scene lists, in registry order: the physics first (they declare the
    fields), then the couplings that need the fields (solubility)."""
    effects: list[Effect] = []
    ctx = BuildContext(scene, mesh, regions)
    for coupling in (False, True):
        if coupling:
            ctx.fields = FieldSet([f for e in effects for f in e.fields()])
        for name, entry in EFFECTS.items():
            specs = scene.effect_specs.get(name, [])
            if entry.coupling != coupling or not specs:
                continue
            effects += [entry.build(specs, ctx)] if entry.whole else \
                [entry.build(spec, ctx) for spec in specs]
    _check_output_names(effects, scene.source)
    return effects, ctx.fields


def _check_output_names(effects: list[Effect], source: str) -> None:
    """Every field and every effect output has its own name in the result file."""
    taken: dict[str, str] = {}
    for e in effects:
        names = [f.output for f in e.fields()] + e.output_names()
        spec = getattr(e, "spec", None)
        key = spec.key + ".field" if hasattr(spec, "field") else e.name
        for name in names:
            if name in taken:
                raise InputError(f"{name!r} would be written twice in the result file "
                                 f"(it is already the {taken[name]}'s): rename the field",
                                 source, key)
            taken[name] = f"{e.name} effect"


def _points_after_order(mesh: Mesh, order: int) -> int:
    """Nodes once ``order = 2`` adds the midside ones (about 1.5 per triangle, 1.2 per tetra)."""
    extra = {"triangle": 1.5, "tetra": 1.2}.get(mesh.cell_type, 0.0) if order == 2 else 0.0
    return mesh.num_points + int(extra * mesh.num_cells)


def _generator_key(exc: Exception) -> str:
    """``mesh.<parameter>`` when the generator's message starts with the parameter's name."""
    words = str(exc).split()
    name = {"unsupported": "cell"}.get(words[0], words[0]) if words else ""
    return f"mesh.{name}" if name.isidentifier() and name != "invalid" else "mesh"


def _distributed_mesh(scene: Scene, comm) -> LocalMesh:
    """Every rank's part of the scene's mesh: from slices (a parallel mesh file, a generator;
    their quadratic cells and ``order = 2`` included: no rank holds the whole,
    ``mesh.slices``, ``mesh.midside``; a Gmsh MSH 4.1 or 2.2 file: ``mesh.gmshmesh``; XDMF +
    HDF5: ``mesh.xdmfmesh``), else built whole on rank 0 (Gmsh 4.0 and other meshio files). The
    solve's share of every rank is checked against the memory before anything is built when
    the mesh's size is known from a generator's parameters, else once the mesh is read."""
    counted = _generated_counts(scene)
    if counted is not None:   # every rank the same counts: the collective verdict before the build
        points, cells, dim = counted
        memory.check_fits(points, dim, scene.solver.preset, scene.source, "mesh.generator",
                          f"the {scene.mesh.generator} of {cells} cells and {points} nodes")
    src = _slice_source(scene, comm)
    if src is None:
        part = _mesh_from_rank0(scene, comm)
    else:
        try:
            dim = CELL_INFO[src.cell_type][0]
            if dim != scene.dim:
                raise InputError(f"a {dim}D mesh ({src.cell_type}) cannot carry hypothesis "
                                 f"{scene.hypothesis!r}", scene.source, "model.hypothesis")
            source, key = mesh_source(scene)
            points = _points_after_order(src, scene.mesh.order) if counted is None else counted[0]
            memory.check_part(points, dim, source, "mesh.generator" if key == "mesh"
                              else key, f"a mesh of {src.num_cells} {src.cell_type} cells")
            src = _quadratic(scene, comm, src)
            part = distribute_slices(comm, src, scene.solver.partitioner, source, key)
        finally:
            getattr(src, "close", lambda: None)()
    if counted is None:   # the solve, each rank its share (every rank's machine: collective)
        source, key = mesh_source(scene)
        key = "mesh.generator" if key == "mesh" else key   # as build_mesh's memory check names it
        memory.check_fits(part.num_global_points, part.dim, scene.solver.preset, source, key,
                          f"a mesh of {part.num_global_cells} {part.cell_type} cells")
    return part


def _slice_source(scene: Scene, comm):
    """The mesh as slices every rank reads its own of (``mesh.slices.SliceSource``), or None
    for the rank-0 path. Collective (an input error is every rank's)."""
    spec = scene.mesh
    if spec.file is not None:
        path = mesh_source(scene)[0]
        if is_mesh_h5(spec.file):
            return agree(comm, open_mesh, path)
        if is_xdmf(spec.file):
            return open_xdmf(comm, path)
        return open_gmsh(comm, path) if agree(comm, gmsh.ours, path) else None
    slicer = SLICED.get(spec.generator)
    if slicer is None:
        return None
    try:
        with np.errstate(over="raise", divide="raise", invalid="raise"):
            return slicer(**spec.params)
    except (TypeError, ValueError, FloatingPointError, OverflowError) as exc:
        raise InputError(f"invalid generator parameters: {exc}", scene.source,
                         _generator_key(exc)) from None


# Q2 hexahedra's faces (quad9, quad8) have no contact rows: node-to-face pairs no such face,
# and the serendipity face's corners carry negative shares of a uniform pressure
NO_CONTACT = ("hexahedron27", "hexahedron20")


def _refuse_contact_on(scene: Scene, cell_type: str) -> None:
    specs = scene.effect_specs.get("contact") or []
    if cell_type in NO_CONTACT and specs:
        raise InputError(f"contact is not available on {cell_type} cells (their quad9/quad8 "
                         f"faces); mesh the bodies in contact with hexahedron, tetra or tetra10",
                         scene.source, getattr(specs[0], "key", "contact"))


def _quadratic(scene: Scene, comm, src):
    """``src`` with its midside nodes (``midside.QuadraticSlices``) for ``order = 2`` or a
    generator's quadratic cells, else ``src`` itself. Collective."""
    _refuse_contact_on(scene, src.cell_type)
    cell = getattr(src, "cell", src.cell_type)   # a generator's cell: triangle6, tetra10
    if src.cell_type in SECOND_ORDER or (cell == src.cell_type and scene.mesh.order == 1):
        return src
    if src.cell_type not in ("triangle", "tetra"):
        raise InputError(f"order = 2 needs a simplex mesh, not {src.cell_type} (or one of "
                         f"second-order cells: {', '.join(SECOND_ORDER)})", scene.source,
                         "mesh.order")
    return QuadraticSlices(comm, src, *mesh_source(scene), midside_groups=cell != src.cell_type)


def _mesh_from_rank0(scene: Scene, comm) -> LocalMesh:
    """Rank 0 builds and checks the whole mesh, then every rank gets its part (on 1 rank: the
    whole mesh itself, not a copy); an input error of rank 0's is raised on every rank."""
    whole, error = None, None
    if comm.rank == 0:
        try:
            # rank 0 alone: the whole on one rank
            whole = progress.timed("mesh read", build_mesh, scene)
        except InputError as exc:
            error = (exc.message, exc.source, exc.key)
    error = comm.bcast(error, root=0)
    if error is not None:
        raise InputError(*error)
    # the cells checked and the dual graph built by every rank on a block of cells
    block = blocks.scatter_blocks(comm, whole)
    progress.timed("checks", blocks.check_jacobians, comm, block, *mesh_source(scene))
    block.coords = None   # (the facets need the cells only: the coordinates go before them)
    graph = blocks.facet_groups(comm, block, *mesh_source(scene), graph=comm.size > 1)
    del block
    part = progress.timed("partition", distribute, comm, whole, scene.solver.partitioner, graph)
    del whole
    return part


def _generated_counts(scene: Scene) -> tuple[int, int, int] | None:
    """(points, cells, dim) of a generated mesh from its parameters (None: a file, or
    parameters the generator refuses: it says why when it runs)."""
    spec = scene.mesh
    if spec.file is not None:
        return None
    try:
        counts = memory.cell_counts(spec.generator, spec.params, spec.order)
    except (TypeError, ValueError):
        return None
    return counts if counts[0] > 0 else None


def build_model(scene: Scene, comm=None) -> Model:
    """The model of a scene on this rank's part of the mesh; collective over ``comm`` (None:
    this process alone, ``MPI.COMM_SELF``)."""
    comm = MPI.COMM_SELF if comm is None else comm
    mesh = _distributed_mesh(scene, comm)
    regions = RegionResolver(mesh, scene.regions, scene.source, comm)
    # a check of a rank's part (cells without a material) fails there alone: every rank
    # raises it (the checks that decide for the whole mesh are collective)
    effects, fields = progress.timed("effects", agree, comm, build_effects, scene, mesh, regions)
    # every load is a declared vector term: the scene's, then the effects' (their patterns
    # named by their scene keys), assembled on the composition's local cells
    cells = mesh.partition().local_cells(comm.rank, mesh.cells)
    ndof = mesh.num_points * fields.ncomp
    first = Instant(scene.times[0] if scene.times else 0.0)
    patterns = agree(comm, lambda: load_patterns([SceneLoads(mesh, scene, regions, fields)],
                                                 cells, fields, ndof, first))   # errors now
    relations = progress.timed("relations", agree, comm, build_relations, scene.relations,
                               regions, scene.evolutions, patterns, fields, scene.source,
                               scene.solver.eliminate, scene.thickness)
    for name, pattern in load_patterns(effects, cells, fields, ndof).items():
        patterns.setdefault(name, LoadPattern(name)).parts += pattern.parts
    names = {r.name for r in relations}
    for e in effects:
        for r in e.relations():
            if r.name in names:
                raise InputError(f"relation name {r.name!r} is taken by the {e.name} effect",
                                 scene.source, "relations")
            relations.append(r)
            names.add(r.name)
    reference = (scene.nonlinear.arc_pattern,) if scene.nonlinear.method == "arc_length" else ()
    model = Model(scene, mesh, fields, effects, patterns, relations, reference, comm)
    if scene.solver.preset == "auto":   # by size and kind, said once by the driver
        scene.solver.preset, scene.solver.chosen = choose(
            mesh.num_global_points * model.ncomp, mesh.dim)
    return model
