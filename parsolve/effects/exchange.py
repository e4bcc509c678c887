"""An exchange (Robin, convection) condition on a scalar field: the flux leaving a boundary
region is h (T − T∞), with h a constant coefficient and T∞ (the ambient value) a number or an
expression of (x, y, z, t). It declares two facet terms on the region: h ∫ N Nᵀ on the field's
operator and the vector term h ∫ N T∞ (its load pattern named by its scene key, assembled again
at each instant when T∞ names t); with the θ-scheme both are weighted as the field's other
terms, and a steady run solves with them alike.

Scene schema (one table per condition)::

    [[exchange]]
    field = "T"                      # a scalar field (a [[diffusion]] one)
    region = "right"                 # a boundary region
    coefficient = 10.0               # h, per unit area
    ambient = "20 + 5 * t"           # T∞: a number (constant) or an expression of x, y, z, t
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import numpy as np

from parsolve.effects.base import Effect
from parsolve.errors import InputError
from parsolve.fem.element_matrices import ElementMatrices, NodeForces, Term
from parsolve.fem.integrals import facet_matrices, weighted_mass
from parsolve.loads.base import Instant, LoadSpec, Where, need_facets, values_at
from parsolve.loads.traction import facet_forces


@dataclass
class ExchangeSpec:
    field: str
    region: str
    coefficient: float
    ambient: float | str
    key: str


def parse(t, dim: int) -> ExchangeSpec:
    """An ``[[exchange]]`` table (a scene Table) → spec."""
    spec = ExchangeSpec(t.get("field", str), t.get("region", str), t.get("coefficient", float),
                        t.get("ambient", (float, str), 0.0), t.path)
    if spec.coefficient <= 0:
        raise t.error("coefficient", "must be positive")
    t.done()
    return spec


def regions(spec: ExchangeSpec) -> list[tuple[str, str]]:
    return [(spec.region, spec.key + ".region")]


def build(spec: ExchangeSpec, ctx) -> "Exchange":
    return Exchange(spec, ctx.mesh, ctx.regions, ctx.fields, ctx.scene)


class Exchange(Effect):
    name = "exchange"

    def __init__(self, spec: ExchangeSpec, mesh, regions, fields, scene):
        self.spec, self.mesh = spec, mesh
        if spec.field not in fields or fields[spec.field].ncomp != 1:
            raise InputError(f"{spec.field!r} is not a scalar field of the scene", scene.source,
                             spec.key + ".field")
        self.thickness = scene.thickness if mesh.dim == 2 else 1.0
        region = regions(spec.region, spec.key + ".region")
        self.load = LoadSpec(spec.key, spec.region, "traction", [spec.ambient], "constant",
                             spec.key, spec.field, "ambient")
        self.where = Where(mesh, region, fields, self.thickness, regions, scene)
        need_facets(self.load, self.where)
        self.term = Term(spec.field, spec.field, facets=region.facets)   # h ∫ N Nᵀ ds
        self.ambient = Term(spec.field, None, facets=region.facets,      # h ∫ N T∞ ds
                            timed=self.load.timed)
        first = Instant(scene.times[0] if scene.times else 0.0)
        for _ in self.vector_values(self.ambient, None, first):   # the ambient's errors now
            pass

    def terms(self) -> list[Term]:
        return [self.term, self.ambient]

    def term_values(self, term: Term, cells: np.ndarray) -> ElementMatrices:
        h = self.spec.coefficient
        return facet_matrices(self.mesh.points, term.facets, self.mesh.facet_type,
                              self.thickness, lambda rule, _: weighted_mass(rule, h))

    def vector_values(self, term: Term, cells, at: Instant) -> Iterable[NodeForces]:
        """h ∫ N T∞ ds at an instant, facet block after facet block (input errors at the
        first: the ambient's expression)."""
        h = self.spec.coefficient
        return facet_forces(self.where, lambda rule: h * values_at(self.load, rule.points, at,
                                                                   self.where.source))
