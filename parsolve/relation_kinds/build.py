"""The scene's relations on this rank's part of the mesh: each built by its kind's registry
entry, associated or with a load pattern as dual part, then checked as a set (a DOF fixed
twice, a tie held at both ends, a control that would drive nothing)."""

from __future__ import annotations

import numpy as np

from parsolve import relations as rel
from parsolve.errors import InputError
from parsolve.relation_kinds.base import Where
from parsolve.relation_kinds.registry import RELATIONS


def build_relations(specs: list, regions, evolutions: dict, patterns: dict, fields,
                    source: str, eliminate: bool, thickness=1.0) -> list[rel.Relation]:
    """Relations on the fields' DOFs (node · ncomp + offset of the field + component);
    ``thickness``: the model's out-of-plane measure (a strain's mean is over the volume: in
    axisymmetry weighted by 2π r)."""
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
        out.append(r)
    out = rel.drop_repeated_rows(out)
    _check_repeated_ties(out, fields, source)
    out = _drop_held_ties(out, source)
    _check_duals(out, specs, source)
    dups = rel.duplicate_rows(out)
    if dups:
        a, b, dof = dups[0]
        node, comp = divmod(dof, ncomp)
        field = next(f for f in fields if comp in fields.columns(f.name))
        label = f"{field.name}.{field.components[comp - fields.offset[field.name]]}".rstrip(".")
        what = f"relations {a!r} and {b!r} both fix" if a != b else f"relation {a!r} fixes twice"
        raise InputError(f"redundant relations: {what} {label} at node {node} "
                         f"({len(dups)} such DOFs); the system would be singular", source, "relations")
    return _per_rank(out, regions.mesh, ncomp)


def _per_rank(relations: list, mesh, ncomp: int) -> list:
    """The multiplied relations of kinds whose rows each constrain one DOF or node (a
    Dirichlet row, a tie's u_a): built per rank, each row held by the rank owning the DOF it
    constrains (``rel.lead_dofs``), numbered by its place in the whole relation. The checks
    above ran on the whole relations (the same answer on every rank); an eliminated relation
    stays whole (its values lift every rank's columns), and so do rows sharing a load pattern,
    a maximum or groups (decided together)."""
    owned = np.sort(mesh.global_nodes[:mesh.n_owned].astype(np.int64))
    out = []
    for r in relations:
        entry = RELATIONS.get(r.meta.get("type"))
        if entry is None or not entry.per_rank or r.eliminable() or r.shared_dual is not None \
                or r.maximum or r.groups is not None:
            out.append(r)
            continue
        node = rel.lead_dofs(r) // ncomp
        pos = np.minimum(np.searchsorted(owned, node), max(owned.size - 1, 0))
        mine = owned[pos] == node if owned.size else np.zeros(r.nrows, dtype=bool)
        out.append(rel.own_rows(r, mine & (node >= 0)))
    return out


def _kind(r: rel.Relation, flag: str) -> bool:
    """Whether a relation of the scene is of a kind with that flag (``RelationEntry``)."""
    entry = RELATIONS.get(r.meta.get("type"))
    return entry is not None and getattr(entry, flag)


def _check_duals(relations: list[rel.Relation], specs: list, source: str) -> None:
    """A control relation's multiplier drives its load pattern; a pattern acting only on DOFs
    that Dirichlet relations hold is taken by their reactions, leaves the multiplier nothing
    to drive, and the system is singular (MUMPS null pivot): refuse it before any solve."""
    held = [r.a_dofs for r in relations if _kind(r, "holds") and r.sense == "="]
    held = np.unique(np.concatenate(held)) if held else np.zeros(0, dtype=np.int64)
    keys = {spec.name: spec.key for spec in specs}
    for r in relations:
        if r.shared_dual is None:
            continue
        dofs, vals = r.shared_dual
        acting = dofs[vals != 0]
        if acting.size and np.isin(acting, held).all():
            holders = sorted({h.name for h in relations if _kind(h, "holds")
                              and np.isin(h.a_dofs, acting).any()})
            raise InputError(f"load pattern {r.meta['dual']!r} acts only on DOFs that "
                             f"{', '.join(map(repr, holders))} already hold: the control "
                             "multiplier would drive nothing (singular system)",
                             source, keys.get(r.name, "relations") + ".dual")


def _held_values(relations: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(DOF, value, evolution number) of every single-DOF associated equality row (sorted by
    DOF), the evolutions numbered by their first appearance."""
    evolutions, dof, value, evol = [], [], [], []
    for r in relations:
        if _kind(r, "ties") or r.sense != "=" or not r.associated:
            continue
        at = np.bincount(r.a_rows, minlength=r.nrows)[r.a_rows] == 1
        if r.evolution not in evolutions:
            evolutions.append(r.evolution)
        dof.append(r.a_dofs[at])
        value.append(r.values[r.a_rows[at]] / r.a_vals[at])
        evol.append(np.full(int(at.sum()), evolutions.index(r.evolution)))
    if not dof:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
    dof, value, evol = np.concatenate(dof), np.concatenate(value), np.concatenate(evol)
    order = np.argsort(dof, kind="stable")
    return dof[order], value[order], evol[order]


def _check_repeated_ties(relations: list, fields, source: str) -> None:
    """The same pair of DOFs tied twice (one periodic relation given twice, or both ways:
    region and target swapped) makes the system singular: refused, naming both relations.
    Relations here are the whole set on every rank: the same answer everywhere."""
    pairs, owner = [], []
    for k, r in enumerate(relations):
        if not _kind(r, "ties"):
            continue
        ends = np.empty((r.nrows, 2), dtype=np.int64)   # the row's two DOFs, either order
        ends[r.a_rows[r.a_vals > 0], 0] = r.a_dofs[r.a_vals > 0]
        ends[r.a_rows[r.a_vals < 0], 1] = r.a_dofs[r.a_vals < 0]
        pairs.append(np.sort(ends, axis=1))
        owner.append(np.full(r.nrows, k))
    if len(pairs) == 0:
        return
    pairs, owner = np.concatenate(pairs), np.concatenate(owner)
    order = np.lexsort((owner, pairs[:, 1], pairs[:, 0]))
    pairs, owner = pairs[order], owner[order]
    again = np.flatnonzero((pairs[1:] == pairs[:-1]).all(axis=1))
    if again.size == 0:
        return
    first, second = relations[owner[again[0]]], relations[owner[again[0] + 1]]
    node_a, comp = divmod(int(pairs[again[0], 0]), fields.ncomp)
    node_b = int(pairs[again[0], 1]) // fields.ncomp
    field = next(f for f in fields if comp in fields.columns(f.name))
    label = f"{field.name}.{field.components[comp - fields.offset[field.name]]}".rstrip(".")
    both = f"relations {first.name!r} and {second.name!r} both tie" if first is not second \
        else f"relation {first.name!r} ties twice"
    raise InputError(f"repeated periodic tie: {both} {label} of nodes {node_a} and {node_b} "
                     f"({again.size} such pairs; a tie given twice, or both ways); the system "
                     "would be singular: give each tie once", source, second.meta["key"])


def _drop_held_ties(relations: list, source: str) -> list:
    """A periodic row between two DOFs that Dirichlet rows both hold (the corners of a cell
    whose top and bottom are held) would constrain nothing and make the system singular: it
    is dropped when the two held values agree (same value and evolution: the tie holds by
    itself), an input error when they do not."""
    ties = [k for k, r in enumerate(relations) if _kind(r, "ties")]
    if not ties:
        return relations
    dof, value, evol = _held_values(relations)
    out = list(relations)
    for k in ties:   # a loop over relations, not rows
        r = out[k]
        ends = []
        for side in (r.a_vals > 0, r.a_vals < 0):   # u_a (+1) and u_b (-1) of each row
            d = np.empty(r.nrows, dtype=np.int64)
            d[r.a_rows[side]] = r.a_dofs[side]
            pos = np.minimum(np.searchsorted(dof, d), max(dof.size - 1, 0))
            held = dof[pos] == d if dof.size else np.zeros(r.nrows, dtype=bool)
            ends.append((d, held, value[pos] if dof.size else d * 0.0,
                         evol[pos] if dof.size else d * 0))
        (da, ha, va, ea), (_, hb, vb, eb) = ends
        both = ha & hb
        clash = both & ((va != vb) | (ea != eb))
        if clash.any():
            raise InputError(f"a tied pair is held by conditions of different values (DOF "
                             f"{int(da[np.argmax(clash)])} and its partner, {int(clash.sum())} "
                             "such rows): the tie contradicts them", source,
                             r.meta["key"] + ".region")
        if both.all():
            raise InputError("every tied DOF is held by other conditions: the tie constrains "
                             "nothing", source, r.meta["key"] + ".region")
        if both.any():
            out[k] = rel.keep_rows(r, ~both)
    return out
