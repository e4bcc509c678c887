"""Relations from the scene: Dirichlet, equal, mean (and opening), general linear combinations,
associated or with a load pattern as dual part."""

from __future__ import annotations

import numpy as np

from parsolve import relations as rel
from parsolve.errors import InputError
from parsolve.mesh import selectors


def build_relations(specs: list, regions, evolutions: dict, patterns: dict, ncomp: int,
                    source: str, eliminate: bool) -> list[rel.Relation]:
    out = []
    for spec in specs:
        r = _one(spec, regions, evolutions, ncomp, source)
        if spec.dual is not None:
            rel.with_dual(r, patterns[spec.dual].vector())
        r.eliminate = spec.eliminate if spec.eliminate is not None else (eliminate and None)
        r.meta = {"type": spec.type, "key": spec.key, "dual": spec.dual}
        out.append(r)
    dups = rel.duplicate_rows(out)
    if dups:
        a, b, dof = dups[0]
        node, comp = divmod(dof, ncomp)
        what = f"relations {a!r} and {b!r} both fix" if a != b else f"relation {a!r} fixes twice"
        raise InputError(f"redundant relations: {what} component {'xyz'[comp]} of node {node} "
                         f"({len(dups)} such DOFs); the system would be singular", source, "relations")
    return out


def _one(spec, regions, evolutions, ncomp: int, source: str) -> rel.Relation:
    evol = evolutions[spec.evolution]
    if spec.type == "dirichlet":
        nodes = regions(spec.region, spec.key + ".region").nodes
        value = spec.value
        if isinstance(value, str):  # an expression of the coordinates, per node
            per_node = selectors.evaluate_value(value, regions.mesh.points[nodes], source,
                                                spec.key + ".value")
            value = np.repeat(per_node[:, None], len(spec.components), axis=1)
        return rel.dirichlet(spec.name, nodes, spec.components, ncomp, value, evol)
    if spec.type == "equal":
        nodes = regions(spec.region, spec.key + ".region").nodes
        if len(nodes) < 2:
            raise InputError(f"region {spec.region!r} has fewer than 2 nodes", source, spec.key + ".region")
        return rel.equal(spec.name, nodes, spec.components[0], ncomp)
    terms = []
    for i, term in enumerate(spec.terms):
        key = f"{spec.key}.terms[{i}].region" if spec.type == "linear" else spec.key + ".region"
        nodes = regions(term.region, key).nodes
        terms.append((nodes, term.component, term.coefficient, term.mean))
    r = rel.combination(spec.name, terms, ncomp, spec.value, evol)
    if r.a_dofs.size == 0:
        raise InputError("the relation's terms cancel out: it constrains nothing", source, spec.key)
    return r
