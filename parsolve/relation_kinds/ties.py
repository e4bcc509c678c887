"""Relations of means and sums over regions: ``equal`` (a component equal over a region),
``mean`` (its mean over a region, minus another's: an opening) and ``linear`` (Σ coefficient ×
the sum or mean of a component over a region)."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve import relations as rel
from parsolve.errors import InputError
from parsolve.relation_kinds.base import RelationSpec, TermSpec, Where
from parsolve.schema import field_component, field_name


def parse_equal(t, spec: RelationSpec, declared) -> None:
    _region_term(t, spec, declared)
    if t.table("minus", None) is not None:
        raise t.error("minus", "only a 'mean' relation takes 'minus'")


def parse_mean(t, spec: RelationSpec, declared) -> None:
    _region_term(t, spec, declared)
    minus = t.table("minus", None)
    if minus is not None:
        spec.terms.append(_term(minus, spec, declared, -1.0, True))
        minus.done()


def parse_linear(t, spec: RelationSpec, declared) -> None:
    for sub in t.tables("terms"):
        spec.terms.append(_term(sub, spec, declared, sub.get("coefficient", float, 1.0),
                                sub.get("mean", bool, False)))
        sub.done()
    if not spec.terms:
        raise t.error("terms", "a linear relation needs at least one term")


def _region_term(t, spec: RelationSpec, declared) -> None:
    """The relation's own region and component, its first term (a mean over the region)."""
    spec.region = t.get("region", str)
    spec.components = [field_component(t, "component", declared, spec.field)]
    spec.terms = [TermSpec(spec.region, spec.components[0], 1.0, True, spec.field,
                           spec.key + ".region")]


def _term(sub, spec: RelationSpec, declared, coefficient: float, mean: bool) -> TermSpec:
    field = field_name(sub, declared) if sub.has("field") else spec.field
    return TermSpec(sub.get("region", str), field_component(sub, "component", declared, field),
                    coefficient, mean, field, sub.key("region"))


def build_equal(spec: RelationSpec, where: Where, evolution) -> rel.Relation:
    """u_c(n) − u_c(n_0) = 0 for each node n of the region but its lowest n_0 (by input id):
    built per rank, the rows of the nodes this rank owns (a row's u_c(n_0) may be another
    rank's DOF), in the order of their nodes."""
    nodes, _ = where.owned_nodes(spec.region, spec.key + ".region")
    comm = where.comm
    if comm.allreduce(nodes.size) < 2:
        raise InputError(f"region {spec.region!r} has fewer than 2 nodes", where.source,
                         spec.key + ".region")
    first = comm.allreduce(int(nodes[0]) if nodes.size else where.num_nodes, op=MPI.MIN)
    rest = nodes[nodes != first]
    comp = where.fields.component(spec.field, spec.components[0])
    r = rel.equal(spec.name, np.concatenate([[first], rest]), comp, where.fields.ncomp)
    return where.numbered(r, rest, where.num_nodes)


def build_combination(spec: RelationSpec, where: Where, evolution) -> rel.Relation:
    """One row: Σ coefficient × (mean or sum of a component over the term's nodes) = value,
    spread (``Relation.spread``): each rank the entries of the nodes it owns, a mean over the
    whole term's count."""
    comm, terms = where.comm, []
    for term in spec.terms:
        nodes, _ = where.owned_nodes(term.region, term.key)
        terms.append((nodes, where.fields.component(term.field, term.component),
                      term.coefficient, term.mean, comm.allreduce(nodes.size)))
    r = rel.combination(spec.name, terms, where.fields.ncomp, spec.value, evolution)
    if comm.allreduce(r.a_dofs.size) == 0:
        raise InputError("the relation's terms cancel out: it constrains nothing", where.source,
                         spec.key)
    return rel.spread_rows(r)
