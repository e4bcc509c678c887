"""What every relation kind shares: the scene's relation entry (``RelationSpec``) and its
terms, the components it reads, and what a kind builds its rows on (``Where``)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from parsolve import relations as rel
from parsolve.relation_kinds.spread import places
from parsolve.schema import Declared, Table, component, field_component


@dataclass
class TermSpec:
    region: str
    component: int
    coefficient: float
    mean: bool
    field: str
    key: str = ""        # the dotted key its region is given by


@dataclass
class RelationSpec:
    name: str
    type: str                              # its registry entry
    key: str
    field: str                             # the field the relation constrains
    region: str | None = None
    components: list[int] = field(default_factory=list)
    value: float | str = 0.0               # a string is an expression of x, y, z
    evolution: str = "ramp"
    terms: list[TermSpec] = field(default_factory=list)
    dual: str | None = None
    sense: str = "="
    eliminate: bool | None = None
    direction: list[float] | None = None   # strain: unit vector n of n·ε·n
    per_cell: bool = False                 # strain: one row per cell of the region
    maximum: bool = False                  # unilateral rows of which the largest is enforced
    report: bool = False                   # print its resultant with each step's progress line
    target: str | None = None              # periodic: the region tied to ``region``
    translation: list[float] | None = None  # periodic: target node = region node + this


@dataclass
class Where:
    """What a kind builds its rows on: the region resolver (this rank's part, whole-mesh
    answers), the fields, the scene file its errors name and the model's out-of-plane
    measure (a strain's mean is over the volume: in axisymmetry weighted by 2π r)."""

    regions: object
    fields: object
    source: str
    thickness: object = 1.0

    @property
    def comm(self):
        return self.regions.comm

    @property
    def num_nodes(self) -> int:
        """Nodes of the whole mesh."""
        return int(self.regions.mesh.num_global_points)

    def owned_nodes(self, region: str, key: str) -> tuple[np.ndarray, np.ndarray]:
        """The region's nodes this rank owns, as input ids (sorted), with their coordinates:
        what a kind builds its rows (one per node) or its part of a spread row on."""
        mesh = self.regions.mesh
        nodes = self.regions(region, key).nodes
        own = nodes[nodes < mesh.n_owned]
        ids = mesh.global_nodes[own].astype(np.int64)
        order = np.argsort(ids, kind="stable")
        return ids[order], mesh.points[own[order]]

    def numbered(self, relation: rel.Relation, keys: np.ndarray, space: int) -> rel.Relation:
        """Rows built on this rank, held here (not eliminated), numbered by the place of their
        key (of ``[0, space)``, increasing, in the whole relation's row order) among every
        rank's: the same numbers at every rank count. Collective."""
        return rel.rows_here(relation, places(self.comm, keys, space),
                             self.comm.allreduce(relation.nrows))


def components(t: Table, declared: Declared, field: str, every: bool = False) -> list[int]:
    """'component' or 'components' of the field (``every``: all of them when neither is
    given)."""
    raw = t.get("components", list, None)
    if every and raw is None and not t.has("component"):
        return list(range(declared.fields[field]))
    if declared.fields[field] == 1 and raw is None:
        return [field_component(t, "component", declared, field)]
    if raw is None:
        return [component(t, "component", declared.dim)]
    sub = Table({f"components[{i}]": c for i, c in enumerate(raw)}, t.path, t.source)
    comps = [field_component(sub, k, declared, field) for k in sub.data]
    if len(set(comps)) != len(comps):
        raise t.error("components", "a component is listed twice")
    return comps


def own_regions(spec: RelationSpec) -> list[tuple[str, str]]:
    """The regions a relation names with their keys (checked before the mesh is read)."""
    out = [(spec.region, spec.key + ".region")] if spec.region is not None else []
    out += [(spec.target, spec.key + ".target")] if spec.target is not None else []
    return out + [(term.region, term.key) for term in spec.terms if term.key not in dict(out).values()]
