"""What every load shares: the scene's load entry (``LoadSpec``), the instant a load is
evaluated at (``Instant``: t, Δt, θ), values given as numbers or as expressions of (x, y, z, t)
evaluated at quadrature points or nodes, and named patterns of vector terms.

Every load is a vector term (``Term`` without a trial field, on cells, facets or nodes)
declared by its declarer -- an effect (an exchange's h ∫ N T∞, thermal expansion's reference
state) or the scene's ``[[loads]]`` (``loads.build.SceneLoads``) -- with its pattern and
evolution; its forces come from the declarer's ``vector_values(term, cells, at)`` at the step's
instant. Patterns (the known loads, a control's dual, the arc-length's reference) are built
from those declarations alone (``load_patterns``).
"""

from __future__ import annotations

import ast
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from parsolve.errors import InputError
from parsolve.evolution import CONSTANT
from parsolve.fem.element_matrices import NodeForces, Term
from parsolve.fem.integrals import FACET_BLOCK
from parsolve.mesh import selectors


@dataclass
class LoadSpec:
    pattern: str
    region: str
    kind: str                 # the registry entry: "traction", "pressure", ...
    vector: list              # numbers or expressions of (x, y, z, t), one per component
    evolution: str
    key: str
    field: str                # the field it loads
    given: str = ""           # the scene key it was given by ("flux" for a scalar traction)

    @property
    def values_key(self) -> str:
        return f"{self.key}.{self.given or self.kind}"

    @property
    def expression(self) -> bool:
        return any(isinstance(v, str) for v in self.vector)

    @property
    def timed(self) -> bool:
        """Whether a value names the time ``t`` (assembled again at every instant)."""
        return any(isinstance(v, str) and uses_time(v) for v in self.vector)


@dataclass(frozen=True)
class Instant:
    """Where a step evaluates its loads: the time t, the step Δt and the θ of a transient
    scheme (1 in a quasi-static run)."""

    t: float
    dt: float = 0.0
    theta: float = 1.0


def instant(t) -> Instant:
    return t if isinstance(t, Instant) else Instant(float(t))


def uses_time(expr: str) -> bool:
    """Whether an expression names ``t`` (a syntax error is the evaluator's to report)."""
    try:
        tree = ast.parse(expr.strip(), mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return False
    return any(isinstance(n, ast.Name) and n.id == "t" for n in ast.walk(tree))


def scatter_forces(fields, ndof: int, name: str, forces: Iterable[NodeForces]) -> np.ndarray:
    """Forces at node tuples on the field ``name`` as a full vector (this mesh's DOFs), block
    after block (an iterable: a generator holds one block at a time)."""
    out = np.zeros(ndof)
    for f in forces:
        if len(f.nodes) == 0:   # (a rank holding none of the domain)
            continue
        out += scatter(ndof, field_dofs(fields, name, f.nodes), f.values.reshape(len(f.nodes), -1))
    return out


@dataclass(eq=False)
class VectorPart:
    """A declared vector term (``Term`` without a trial field) of a declarer (an effect, the
    scene's loads: anything with ``vector_values(term, cells, at)``) as a full vector at an
    instant: assembled once when its values do not depend on time (``Term.timed`` False: as
    cheap as a constant load can be), else at each instant it is asked for (the last two kept:
    a θ-step asks for t and t_n). ``cells``: the composition's local cells (a cell term's
    domain when it names no region)."""

    owner: object
    term: Term
    cells: np.ndarray
    fields: object
    ndof: int
    cache: dict = field(default_factory=dict)

    def __call__(self, at: Instant) -> np.ndarray:
        key = at if self.term.timed else None
        if key not in self.cache:
            if len(self.cache) >= 2:
                self.cache.pop(next(iter(self.cache)))
            self.cache[key] = scatter_forces(self.fields, self.ndof, self.term.test,
                                             self.owner.vector_values(self.term, self.cells, at))
        return self.cache[key]


@dataclass
class LoadPattern:
    """A named set of vector terms, each with its evolution: applied as known loads, or used
    as a relation's dual direction or the arc-length's reference load."""

    name: str
    parts: list = field(default_factory=list)   # (VectorPart, evolution)

    @property
    def timed(self) -> bool:
        return any(p.term.timed for p, _ in self.parts)

    def vector(self) -> np.ndarray:
        """The pattern at unit intensity (evolutions ignored): a relation's dual direction
        (a pattern that varies in time is refused as one by the scene)."""
        return np.sum([p(Instant(0.0)) for p, _ in self.parts], axis=0)

    def at(self, t) -> np.ndarray:
        """The pattern at an instant (a time or an ``Instant``)."""
        now = instant(t)
        return np.sum([p(now) * evol(now.t) for p, evol in self.parts], axis=0)


def pattern_name(owner, term: Term) -> str:
    """The pattern a vector term belongs to: its own, else its declarer's scene key (an
    effect's loads: ``exchange[0]``), else the declarer's name."""
    spec = getattr(owner, "spec", None)
    return term.pattern or getattr(spec, "key", "") or owner.name


def load_patterns(declarers, cells: np.ndarray, fields, ndof: int,
                  first: Instant | None = None) -> dict[str, LoadPattern]:
    """{pattern name: LoadPattern} of the vector terms the declarers declare (``terms()``),
    in declaration order; ``first``: every part assembled at that instant now (its input
    errors raised now, a constant part's vector kept)."""
    patterns: dict[str, LoadPattern] = {}
    for owner in declarers:
        for term in owner.terms():
            if not term.vector:
                continue
            part = VectorPart(owner, term, cells, fields, ndof)
            if first is not None:
                part(first)
            evolution = CONSTANT if term.evolution is None else term.evolution
            name = pattern_name(owner, term)
            patterns.setdefault(name, LoadPattern(name)).parts.append((part, evolution))
    return patterns


@dataclass
class Where:
    """What a load kind assembles on: this rank's mesh, the load's region, the fields, the
    out-of-plane measure (thickness, 2π r, or 1 in 3D), the region resolver (whole-mesh counts
    and sums) and the scene (gravity reads the materials' densities)."""

    mesh: object
    region: object
    fields: object
    thickness: object
    regions: object
    scene: object

    @property
    def source(self) -> str:
        return self.scene.source

    @property
    def ndof(self) -> int:
        return self.mesh.num_points * self.fields.ncomp


def scatter(ndof: int, dofs: np.ndarray, values: np.ndarray) -> np.ndarray:
    return np.bincount(dofs.ravel(), weights=values.ravel(), minlength=ndof).astype(float, copy=False)


def field_dofs(fields, name: str, nodes: np.ndarray) -> np.ndarray:
    """(n, nen·ncomp) DOFs of a field at (n, nen) nodes, node-major (n may be 0: a rank's
    part that holds none of the region, so the width is given, not inferred)."""
    nodes = np.asarray(nodes)
    width = nodes.shape[1] * fields[name].ncomp
    return fields.dofs(name, nodes.ravel()).reshape(nodes.shape[0], width)


def values_at(spec: LoadSpec, points: np.ndarray, at: Instant, source: str) -> np.ndarray:
    """The load's values (..., ncomp) at ``points`` (..., gdim): numbers broadcast,
    expressions evaluated at the points and the instant's time."""
    flat = points.reshape(-1, points.shape[-1])
    cols = [np.full(flat.shape[0], v) if not isinstance(v, str) else
            selectors.evaluate_value(v, flat, source, f"{spec.values_key}[{i}]"
                                     if len(spec.vector) > 1 else spec.values_key, at.t)
            for i, v in enumerate(spec.vector)]
    return np.stack(cols, axis=-1).reshape(points.shape[:-1] + (len(cols),))


def need_facets(spec: LoadSpec, where: Where) -> None:
    """A facet load's region must hold boundary facets somewhere (counted over the ranks)."""
    if where.regions.facet_count(where.region.facets) == 0:
        raise InputError(f"region {spec.region!r} contains no boundary facet", where.source,
                         spec.key + ".region")


def need_cells(spec: LoadSpec, where: Where) -> None:
    if where.regions.cell_count(where.region.cells) == 0:
        raise InputError(f"region {spec.region!r} contains no cell", where.source,
                         spec.key + ".region")


def blocks(n: int):
    """Consecutive slices of at most ``FACET_BLOCK`` rows."""
    for start in range(0, n, FACET_BLOCK):
        yield slice(start, min(start + FACET_BLOCK, n))
