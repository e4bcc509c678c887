"""Scene + mesh → the effects the scene lists (materials, loads, relations). All input errors
that need the mesh are raised here, before any solve; ``parsolve check`` stops after this."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.effects.constraints import build_relations
from parsolve.effects.elasticity import Elasticity
from parsolve.effects.loads import LoadPattern, load_patterns
from parsolve.errors import InputError
from parsolve.mesh import memory
from parsolve.mesh.checks import check_mesh
from parsolve.mesh.generators import GENERATORS, make_quadratic
from parsolve.mesh.mesh import Mesh
from parsolve.mesh.reader import read_mesh
from parsolve.mesh.regions import RegionResolver
from parsolve.relations import Relation
from parsolve.scene import Scene


@dataclass
class Model:
    scene: Scene
    mesh: Mesh
    elasticity: Elasticity
    patterns: dict[str, LoadPattern]
    relations: list[Relation]
    reference_patterns: tuple[str, ...] = ()  # applied by a solver (arc-length), not as loads

    @property
    def ncomp(self) -> int:
        return self.mesh.dim

    def external_load(self, t: float) -> np.ndarray:
        """Known loads at t (input DOF numbering); patterns used as duals are not applied."""
        duals = {r.meta.get("dual") for r in self.relations} | set(self.reference_patterns)
        f = np.zeros(self.mesh.num_points * self.ncomp)
        for name, pattern in self.patterns.items():
            if name not in duals:
                f += pattern.at(t)
        return f


def build_mesh(scene: Scene) -> Mesh:
    """The scene's mesh, checked: size against the machine's memory (a generator's before it
    runs, a file's once read), coordinates, cell shapes; ``mesh.warnings`` says the rest."""
    spec = scene.mesh
    preset = scene.solver.preset
    if spec.file is not None:
        source, key = str(spec.file), "mesh.file"
        mesh = read_mesh(source)
        memory.check_fits(_points_after_order(mesh, spec.order), mesh.dim, preset, source, key,
                          f"a mesh of {mesh.num_cells} {mesh.cell_type} cells")
    else:
        source, key = scene.source, "mesh"
        try:
            points, cells, dim = memory.cell_counts(spec.generator, spec.params, spec.order)
        except (TypeError, ValueError):  # bad parameters: the generator says which below
            points = None
        if points is not None and points > 0:
            memory.check_fits(points, dim, preset, scene.source, "mesh.generator",
                              f"the {spec.generator} of {cells} cells and {points} nodes")
        try:
            with np.errstate(over="raise", divide="raise", invalid="raise"):
                mesh = GENERATORS[spec.generator](**spec.params)
        except (TypeError, ValueError, FloatingPointError, OverflowError, MemoryError) as exc:
            raise InputError(f"invalid generator parameters: {exc}", scene.source,
                             _generator_key(exc)) from None
    if spec.order == 2 and mesh.cell_type in ("triangle", "tetra"):
        mesh = make_quadratic(mesh)
    elif spec.order == 2 and mesh.cell_type not in ("triangle6", "tetra10"):
        raise InputError(f"order = 2 needs a simplex mesh, not {mesh.cell_type}", scene.source, "mesh.order")
    if mesh.dim != scene.dim:
        raise InputError(f"a {mesh.dim}D mesh ({mesh.cell_type}) cannot carry hypothesis "
                         f"{scene.hypothesis!r}", scene.source, "model.hypothesis")
    mesh.warnings = [f"{source}: {key}: {w}" for w in check_mesh(mesh, source, key)]
    return mesh


def _points_after_order(mesh: Mesh, order: int) -> int:
    """Nodes once ``order = 2`` adds the midside ones (about 1.5 per triangle, 1.2 per tetra)."""
    extra = {"triangle": 1.5, "tetra": 1.2}.get(mesh.cell_type, 0.0) if order == 2 else 0.0
    return mesh.num_points + int(extra * mesh.num_cells)


def _generator_key(exc: Exception) -> str:
    """``mesh.<parameter>`` when the generator's message starts with the parameter's name."""
    words = str(exc).split()
    name = {"unsupported": "cell"}.get(words[0], words[0]) if words else ""
    return f"mesh.{name}" if name.isidentifier() and name != "invalid" else "mesh"


def build_model(scene: Scene) -> Model:
    mesh = build_mesh(scene)
    regions = RegionResolver(mesh, scene.regions, scene.source)
    elasticity = Elasticity(mesh, scene.hypothesis, scene.thickness, scene.materials, regions,
                            scene.source)
    patterns = load_patterns(mesh, scene.loads, regions, scene.evolutions, scene.thickness,
                             scene.source)
    relations = build_relations(scene.relations, regions, scene.evolutions, patterns, mesh.dim,
                                scene.source, scene.solver.eliminate)
    reference = (scene.nonlinear.arc_pattern,) if scene.nonlinear.method == "arc_length" else ()
    return Model(scene, mesh, elasticity, patterns, relations, reference)
