"""What every load kind shares: the scene's load entry (``LoadSpec``), the instant a load is
evaluated at (``Instant``: t, Δt, θ), named patterns of parts, and values given as numbers or
as expressions of (x, y, z, t) evaluated at quadrature points or nodes.

A part that does not depend on time is a vector assembled once and scaled by its evolution
(as cheap as a constant load can be); a part whose expression names ``t`` is assembled again
at each instant it is asked for (the last two instants are kept: a θ-step asks for t and t_n).
"""

from __future__ import annotations

import ast
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from parsolve.errors import InputError
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


@dataclass
class TimedPart:
    """A part assembled at each instant (``assemble(at)``: a full vector)."""

    assemble: Callable[[Instant], np.ndarray]
    cache: dict = field(default_factory=dict)

    def __call__(self, at: Instant) -> np.ndarray:
        if at not in self.cache:
            if len(self.cache) >= 2:
                self.cache.pop(next(iter(self.cache)))
            self.cache[at] = self.assemble(at)
        return self.cache[at]


@dataclass
class LoadPattern:
    name: str
    parts: list = field(default_factory=list)   # (vector or TimedPart, evolution)

    @property
    def timed(self) -> bool:
        return any(isinstance(v, TimedPart) for v, _ in self.parts)

    def vector(self) -> np.ndarray:
        """The pattern at unit intensity (evolutions ignored): a relation's dual direction
        (a pattern that varies in time is refused as one by the scene)."""
        return np.sum([v for v, _ in self.parts], axis=0)

    def at(self, t) -> np.ndarray:
        """The pattern at an instant (a time or an ``Instant``)."""
        now = instant(t)
        return np.sum([(v(now) if isinstance(v, TimedPart) else v) * evol(now.t)
                       for v, evol in self.parts], axis=0)


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
