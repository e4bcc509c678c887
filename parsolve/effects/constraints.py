"""Relations from the scene: Dirichlet, equal, mean (and opening), general linear combinations,
associated or with a load pattern as dual part."""

from __future__ import annotations

import numpy as np

from parsolve import relations as rel
from parsolve.errors import InputError
from parsolve.fem import kernels
from parsolve.mesh import selectors


def build_relations(specs: list, regions, evolutions: dict, patterns: dict, fields,
                    source: str, eliminate: bool) -> list[rel.Relation]:
    """Relations on the fields' DOFs (node · ncomp + offset of the field + component)."""
    ncomp = fields.ncomp
    out = []
    for spec in specs:
        r = _one(spec, regions, evolutions, fields, source)
        r.sense, r.maximum = spec.sense, spec.maximum
        if spec.dual is not None:
            r.shared_dual = regions.relation_vector(patterns[spec.dual].vector(), ncomp)
        r.eliminate = spec.eliminate if spec.eliminate is not None else (eliminate and None)
        r.meta = {"type": spec.type, "key": spec.key, "dual": spec.dual}
        out.append(r)
    out = rel.drop_repeated_rows(out)
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


def _one(spec, regions, evolutions, fields, source: str) -> rel.Relation:
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
        return _strain(spec, regions, evol, source, fields)
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
                fields=None):
    """Per cell: DOFs (nc, nen·d) and coefficients of the mean of n·ε·n over the cell, and the
    cell volumes."""
    geo = kernels.CellGeometry(mesh.points[mesh.cells[cells]], mesh.cell_type, thickness=thickness)
    B = geo.strain_operator()                                   # (nc, nq, nv, ndof)
    n = np.asarray(direction, dtype=float)
    if mesh.dim == 2:
        nv = np.array([n[0] ** 2, n[1] ** 2, n[0] * n[1]])
    else:
        nv = np.array([n[0] ** 2, n[1] ** 2, n[2] ** 2, n[1] * n[2], n[0] * n[2], n[0] * n[1]])
    vol = geo.wdet.sum(axis=1)
    coefs = np.einsum("cqvd,v,cq->cd", B, nv, geo.wdet) / vol[:, None]
    if fields is None:
        return kernels.cell_dofs(mesh.cells[cells], mesh.dim), coefs, vol
    nodes = mesh.cells[cells]
    return fields.dofs("u", nodes.ravel()).reshape(len(cells), -1), coefs, vol


def _strain(spec, regions, evol, source: str, fields) -> rel.Relation:
    """Strain n·ε·n of a region: its mean (one row), or one row per cell (per_cell)."""
    region = regions(spec.region, spec.key + ".region")
    if regions.cell_count(region.cells) == 0:
        raise InputError(f"region {spec.region!r} contains no cell (a strain needs cells)",
                         source, spec.key + ".region")
    dofs, coefs, vol = strain_rows(regions.mesh, region.cells, spec.direction, fields=fields)
    # (the owned cells' rows of every rank, in input ids)
    cells, dofs, coefs, vol = regions.owned_cell_rows(region.cells, fields.ncomp, dofs, coefs,
                                                        vol)
    if not spec.per_cell:
        coefs = (coefs * (vol / vol.sum())[:, None]).reshape(1, -1)
        dofs = dofs.reshape(1, -1)
    r = rel.rows(spec.name, dofs, coefs, spec.value, evol, spec.sense)
    r.meta["cells"] = cells
    return r
