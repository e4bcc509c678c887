"""``dirichlet``: u_c(node) = value at every node of a region and listed component; the value
a number or an expression of x, y, z (per node)."""

from __future__ import annotations

import numpy as np

from parsolve import relations as rel
from parsolve.mesh import selectors
from parsolve.relation_kinds.base import RelationSpec, Where, components


def parse(t, spec: RelationSpec, declared) -> None:
    spec.region = t.get("region", str)
    spec.components = components(t, declared, spec.field)


def build(spec: RelationSpec, where: Where, evolution) -> rel.Relation:
    nodes = where.nodes(spec.region, spec.key + ".region")
    value = spec.value
    if isinstance(value, str):  # an expression of the coordinates, per node
        per_node = selectors.evaluate_value(value, where.regions.points_of(nodes), where.source,
                                            spec.key + ".value")
        value = np.repeat(per_node[:, None], len(spec.components), axis=1)
    comps = [where.fields.component(spec.field, c) for c in spec.components]
    return rel.dirichlet(spec.name, nodes, comps, where.fields.ncomp, value, evolution)
