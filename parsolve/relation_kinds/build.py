"""The scene's relations on this rank's part of the mesh: each built by its kind's registry
entry, associated or with a load pattern as dual part, then checked as a set (``checks``: a
DOF fixed twice, a tie held at both ends, a control that would drive nothing).

A kind whose rows each constrain one DOF or node (``RelationEntry.per_rank``: Dirichlet,
equal, periodic) builds only the rows this rank holds, those of the nodes it owns, numbered by
their place in the whole relation (``Relation.ids``), eliminated or multiplied alike (an
eliminated row lifts its owner's columns; the others read its value from there:
``SaddleSystem``). A kind of rows over regions (mean,
linear, strain) builds every row, each rank the entries of the nodes and cells it owns
(``Relation.spread``). A load pattern as a relation's dual (a control: its multiplier the
pattern's intensity) is each rank's part of it, on its owned DOFs
(``RegionResolver.relation_vector``), and moves one load: the relation has one row (a mean, a
point's value: a per-rank one is made spread, its entries sent to their DOFs' owners), or
several under a maximum (one column, its rows per rank: ``Relation.collapsed``); several rows
sharing one load otherwise would leave all but their multipliers' sum undetermined (a
singular system), and are refused before any solve."""

from __future__ import annotations

import dataclasses

import numpy as np
from mpi4py import MPI

from parsolve import relations as rel
from parsolve.errors import InputError
from parsolve.relation_kinds.base import Where
from parsolve.relation_kinds.checks import check_set
from parsolve.relation_kinds.registry import RELATIONS
from parsolve.relation_kinds.spread import node_owners, to_owners


def build_relations(specs: list, regions, evolutions: dict, patterns: dict, fields,
                    source: str, eliminate: bool, thickness=1.0) -> list[rel.Relation]:
    """Relations on the fields' DOFs (node · ncomp + offset of the field + component);
    ``thickness``: the model's out-of-plane measure (a strain's mean is over the volume: in
    axisymmetry weighted by 2π r). Collective."""
    ncomp = fields.ncomp
    where = Where(regions, fields, source, thickness)
    out = []
    for spec in specs:
        r = RELATIONS[spec.type].build(spec, where, evolutions[spec.evolution])
        r.sense, r.maximum = spec.sense, spec.maximum
        if spec.dual is not None:
            r.shared_dual = regions.relation_vector(patterns[spec.dual].vector(), ncomp)
        r.eliminate = spec.eliminate if spec.eliminate is not None else (eliminate and None)
        r.meta = {**r.meta, "type": spec.type, "key": spec.key, "dual": spec.dual}
        r.comm = regions.comm
        if r.shared_dual is not None and not r.maximum and r.total > 1:
            raise InputError(f"relation {spec.name!r} has {r.total} rows sharing the load "
                             f"pattern {spec.dual!r}: a load pattern as dual moves one load, "
                             "set by one row (a mean over the region: type = \"mean\"), or "
                             "by the extreme of several rows (per_cell = true, maximum = true)",
                             source, spec.key + ".dual")
        if not r.whole and r.shared_dual is not None and not r.maximum:
            r = _spread(where, r)
        elif not r.whole and not regions.comm.allreduce(r.eliminable(), op=MPI.LAND):
            r = _held(r)
        out.append(r)
    return check_set(out, specs, fields, source, regions.comm, where.num_nodes * ncomp)


def _spread(where: Where, r: rel.Relation) -> rel.Relation:
    """A one-row relation built per rank with a load pattern as dual (a point's value), as a
    spread relation: its row on every rank (its value from its holder), each entry on the rank
    owning its DOF (a tie's other end sent there): the control's one global multiplier row."""
    comm, ncomp = where.comm, where.fields.ncomp
    values = np.zeros(1)
    values[r.ids] = r.values
    comm.Allreduce(MPI.IN_PLACE, values, op=MPI.SUM)
    mesh = where.regions.mesh
    owned = np.sort(mesh.global_nodes[:mesh.n_owned].astype(np.int64))
    owners = node_owners(comm, r.a_dofs // ncomp, owned, where.num_nodes)
    rows, dofs, coefs = to_owners(comm, r.ids[r.a_rows], r.a_dofs, r.a_vals, owners)
    return dataclasses.replace(r, nrows=1, a_rows=rows, a_dofs=dofs, a_vals=coefs,
                               values=values, ids=None, size=None, spread=True)


def _held(r: rel.Relation) -> rel.Relation:
    """A relation built per rank that some rank cannot eliminate: multiplied on every rank,
    whatever rows it holds here (the ranks split the relations alike)."""
    r.eliminate = False
    return r
