"""Relations from the scene: Dirichlet, equal, mean (and opening), general linear combinations,
associated or with a load pattern as dual part."""

from __future__ import annotations

import numpy as np

from parsolve import relations as rel
from parsolve.errors import InputError
from parsolve.fem import kernels
from parsolve.mesh import selectors


def build_relations(specs: list, regions, evolutions: dict, patterns: dict, fields,
                    source: str, eliminate: bool, thickness=1.0) -> list[rel.Relation]:
    """Relations on the fields' DOFs (node · ncomp + offset of the field + component);
    ``thickness``: the model's out-of-plane measure (a strain's mean is over the volume: in
    axisymmetry weighted by 2π r)."""
    ncomp = fields.ncomp
    out = []
    for spec in specs:
        r = _one(spec, regions, evolutions, fields, source, thickness)
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
    return out


def _check_duals(relations: list[rel.Relation], specs: list, source: str) -> None:
    """A control relation's multiplier drives its load pattern; a pattern acting only on DOFs
    that Dirichlet relations hold is taken by their reactions, leaves the multiplier nothing
    to drive, and the system is singular (MUMPS null pivot): refuse it before any solve."""
    held = [r.a_dofs for r in relations if r.meta.get("type") == "dirichlet" and r.sense == "="]
    held = np.unique(np.concatenate(held)) if held else np.zeros(0, dtype=np.int64)
    keys = {spec.name: spec.key for spec in specs}
    for r in relations:
        if r.shared_dual is None:
            continue
        dofs, vals = r.shared_dual
        acting = dofs[vals != 0]
        if acting.size and np.isin(acting, held).all():
            holders = sorted({h.name for h in relations if h.meta.get("type") == "dirichlet"
                              and np.isin(h.a_dofs, acting).any()})
            raise InputError(f"load pattern {r.meta['dual']!r} acts only on DOFs that "
                             f"{', '.join(map(repr, holders))} already hold: the control "
                             "multiplier would drive nothing (singular system)",
                             source, keys.get(r.name, "relations") + ".dual")


def _one(spec, regions, evolutions, fields, source: str, thickness=1.0) -> rel.Relation:
    evol = evolutions[spec.evolution]
    ncomp = fields.ncomp
    comps = [fields.component(spec.field, c) for c in spec.components]
    if spec.type == "dirichlet":
        nodes = regions.relation_nodes(spec.region, spec.key + ".region")
        value = spec.value
        if isinstance(value, str):  # an expression of the coordinates, per node
            per_node = selectors.evaluate_value(value, regions.points_of(nodes), source,
                                                spec.key + ".value")
            value = np.repeat(per_node[:, None], len(spec.components), axis=1)
        return rel.dirichlet(spec.name, nodes, comps, ncomp, value, evol)
    if spec.type == "equal":
        nodes = regions.relation_nodes(spec.region, spec.key + ".region")
        if len(nodes) < 2:
            raise InputError(f"region {spec.region!r} has fewer than 2 nodes", source, spec.key + ".region")
        return rel.equal(spec.name, nodes, comps[0], ncomp)
    if spec.type == "strain":
        return _strain(spec, regions, evol, source, fields, thickness)
    if spec.type == "periodic":
        return _periodic(spec, regions, comps, ncomp, evol, source)
    terms = []
    for i, term in enumerate(spec.terms):
        key = f"{spec.key}.terms[{i}].region" if spec.type == "linear" else spec.key + ".region"
        nodes = regions.relation_nodes(term.region, key)
        terms.append((nodes, fields.component(term.field, term.component), term.coefficient,
                      term.mean))
    r = rel.combination(spec.name, terms, ncomp, spec.value, evol)
    if r.a_dofs.size == 0:
        raise InputError("the relation's terms cancel out: it constrains nothing", source, spec.key)
    return r


def strain_rows(mesh, cells: np.ndarray, direction: np.ndarray, thickness: float = 1.0,
                fields=None, field: str | None = None):
    """Per cell: DOFs (nc, nen·d) and coefficients of the mean of n·ε·n over the cell, and the
    cell volumes."""
    geo = kernels.CellGeometry(mesh.points[mesh.cells[cells]], mesh.cell_type, thickness=thickness)
    B = geo.strain_operator()                                   # (nc, nq, nv, ndof)
    n = np.asarray(direction, dtype=float)
    if geo.axisymmetric:   # (rr, zz, rz, θθ): n lies in the (r, z) plane
        nv = np.array([n[0] ** 2, n[1] ** 2, n[0] * n[1], 0.0])
    elif mesh.dim == 2:
        nv = np.array([n[0] ** 2, n[1] ** 2, n[0] * n[1]])
    else:
        nv = np.array([n[0] ** 2, n[1] ** 2, n[2] ** 2, n[1] * n[2], n[0] * n[2], n[0] * n[1]])
    vol = geo.wdet.sum(axis=1)
    coefs = np.einsum("cqvd,v,cq->cd", B, nv, geo.wdet) / vol[:, None]
    if fields is None:
        return kernels.cell_dofs(mesh.cells[cells], mesh.dim), coefs, vol
    nodes = mesh.cells[cells]   # (none on a rank's part that holds none of the region)
    width = nodes.shape[1] * fields[field].ncomp
    return fields.dofs(field, nodes.ravel()).reshape(len(cells), width), coefs, vol


def _strain(spec, regions, evol, source: str, fields, thickness=1.0) -> rel.Relation:
    """Strain n·ε·n of a region: its mean (one row), or one row per cell (per_cell)."""
    region = regions(spec.region, spec.key + ".region")
    if regions.cell_count(region.cells) == 0:
        raise InputError(f"region {spec.region!r} contains no cell (a strain needs cells)",
                         source, spec.key + ".region")
    dofs, coefs, vol = strain_rows(regions.mesh, region.cells, spec.direction, thickness,
                                   fields=fields, field=spec.field)
    # (the owned cells' rows of every rank, in input ids)
    cells, dofs, coefs, vol = regions.owned_cell_rows(region.cells, fields.ncomp, dofs, coefs,
                                                        vol)
    if not spec.per_cell:
        coefs = (coefs * (vol / vol.sum())[:, None]).reshape(1, -1)
        dofs = dofs.reshape(1, -1)
    r = rel.rows(spec.name, dofs, coefs, spec.value, evol, spec.sense)
    r.meta["cells"] = cells
    return r


def _periodic(spec, regions, comps: list[int], ncomp: int, evol, source: str) -> rel.Relation:
    """u(a) - u(b) = 0 per listed component, for each node a of the region and its partner b,
    the node of the target at x_a + translation (associated rows, node-major)."""
    a = regions.relation_nodes(spec.region, spec.key + ".region")
    b_all = regions.relation_nodes(spec.target, spec.key + ".target")
    b = partners(regions.points_of(a), b_all, regions.points_of(b_all), spec.translation,
                 regions.tol)
    lost = np.flatnonzero(b < 0)
    if lost.size:
        x = ", ".join(f"{v:g}" for v in regions.points_of(a[lost[:1]])[0])
        raise InputError(f"node {a[lost[0]]} of region {spec.region!r} (at {x}) has no node of "
                         f"region {spec.target!r} at its position + translation (within "
                         f"{regions.tol:.3g}; {lost.size} such nodes)", source,
                         spec.key + ".target")
    if np.any(a == b):
        raise InputError("the translation pairs a node with itself", source,
                         spec.key + ".translation")
    c = np.asarray(comps, dtype=np.int64)
    dofs = np.stack([(a[:, None] * ncomp + c).ravel(), (b[:, None] * ncomp + c).ravel()], axis=1)
    r = rel.rows(spec.name, dofs, np.tile([1.0, -1.0], (dofs.shape[0], 1)), 0.0, evol,
                 spec.sense)
    return r


# a generic direction: points of a mesh rarely share their projection on it, so the window
# of candidates around each image is a point or two, whatever the region's shape
_PROBE = np.array([1.0, np.sqrt(2.0), np.sqrt(3.0)]) / np.sqrt(6.0)


def partners(points: np.ndarray, ids: np.ndarray, candidates: np.ndarray, translation,
             tol: float) -> np.ndarray:
    """For each point, the id (of ``ids``, coordinates ``candidates``) of the candidate at
    point + translation within ``tol`` (the nearest; a tie to the lowest id), or -1."""
    images = np.asarray(points, float) + np.asarray(translation, float)
    ids = np.asarray(ids, dtype=np.int64)
    out = np.full(len(images), -1, dtype=np.int64)
    if len(images) == 0 or len(ids) == 0:
        return out
    probe = _PROBE[:images.shape[1]]
    key = candidates @ probe
    order = np.lexsort((ids, key))
    key, ids, candidates = key[order], ids[order], candidates[order]
    s = images @ probe
    lo = np.searchsorted(key, s - 2.0 * tol, side="left")
    hi = np.searchsorted(key, s + 2.0 * tol, side="right")
    best = np.full(len(images), np.inf)
    for k in range(int((hi - lo).max(initial=0))):   # a loop over the window, not the nodes
        at = lo + k < hi
        j = np.minimum(lo + k, len(ids) - 1)
        d = np.linalg.norm(candidates[j] - images, axis=1)
        better = at & (d <= tol) & ((d < best) | (d == best) & (ids[j] < out))
        out[better], best[better] = ids[j][better], d[better]
    return out


def _held_values(relations: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(DOF, value, evolution number) of every single-DOF associated equality row (sorted by
    DOF), the evolutions numbered by their first appearance."""
    evolutions, dof, value, evol = [], [], [], []
    for r in relations:
        if r.meta.get("type") == "periodic" or r.sense != "=" or not r.associated:
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
        if r.meta.get("type") != "periodic":
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
    ties = [k for k, r in enumerate(relations) if r.meta.get("type") == "periodic"]
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
