"""``dirichlet``: u_c(node) = value at every node of a region and listed component; the value
a number or an expression of x, y, z (per node). Built per rank: each rank the rows of the
nodes it owns, node-major as in the whole relation (nodes by input id, then components)."""

from __future__ import annotations

import numpy as np

from parsolve import relations as rel
from parsolve.collective import agree
from parsolve.mesh import selectors
from parsolve.relation_kinds.base import RelationSpec, Where, components


def parse(t, spec: RelationSpec, declared) -> None:
    spec.region = t.get("region", str)
    spec.components = components(t, declared, spec.field)


def build(spec: RelationSpec, where: Where, evolution) -> rel.Relation:
    nodes, points = where.owned_nodes(spec.region, spec.key + ".region")
    value = spec.value
    ncomps = len(spec.components)
    # a string: an expression of the coordinates, per node (its error raised on every rank)
    if isinstance(value, str):
        per_node = agree(where.comm, selectors.evaluate_value, value, points, where.source,
                         spec.key + ".value")
        value = np.broadcast_to(np.asarray(per_node, dtype=float).reshape(-1, 1)
                                if np.ndim(per_node) else per_node, (nodes.size, ncomps))
    comps = [where.fields.component(spec.field, c) for c in spec.components]
    r = rel.dirichlet(spec.name, nodes, comps, where.fields.ncomp, value, evolution)
    keys = (nodes[:, None] * ncomps + np.arange(ncomps)).ravel()
    return where.numbered(r, keys, where.num_nodes * ncomps)
