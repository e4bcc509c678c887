"""``strain``: the strain n·ε·n of the displacement over a region, its mean (one row) or one
row per cell (``per_cell``), n a unit direction or a named normal component."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve import relations as rel
from parsolve.errors import InputError
from parsolve.fem import kernels
from parsolve.relation_kinds.base import RelationSpec, Where
from parsolve.relation_kinds.spread import places, to_owners

STRAIN_COMPONENTS = {"xx": (0, 0), "yy": (1, 1), "zz": (2, 2), "xy": (0, 1), "yz": (1, 2),
                     "xz": (0, 2)}


def parse(t, spec: RelationSpec, declared) -> None:
    if spec.field != declared.primary:
        raise t.error("type", "a strain relation constrains the displacement field")
    spec.region = t.get("region", str)
    spec.direction = _direction(t, declared.dim)
    spec.per_cell = t.get("per_cell", bool, False)


def _direction(t, dim: int) -> list[float]:
    """n of the strain n·ε·n: from 'direction' (normalised) or a component name ('xx', ...)."""
    if t.has("direction") == t.has("component"):
        raise t.error("direction", "give exactly one of 'direction' or 'component'")
    if t.has("direction"):
        n = t.floats("direction", dim)
        norm = sum(v * v for v in n) ** 0.5
        if norm == 0:
            raise t.error("direction", "must not be zero")
        return [v / norm for v in n]
    comp = t.get("component", str)
    pair = STRAIN_COMPONENTS.get(comp)
    if pair is None or max(pair) >= dim:
        known = [c for c, p in STRAIN_COMPONENTS.items() if max(p) < dim]
        raise t.error("component", f"unknown strain component {comp!r} (use {', '.join(known)})")
    n = [0.0] * dim
    if pair[0] == pair[1]:
        n[pair[0]] = 1.0
        return n
    # shear: n·ε·n with n at 45° in the (i, j) plane is ε_ij + (ε_ii + ε_jj)/2; plain ε_ij is
    # asked through a pair direction instead: keep it simple and refuse
    raise t.error("component", "shear components are controlled through 'direction'")


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


def build(spec: RelationSpec, where: Where, evolution) -> rel.Relation:
    """The rows of the cells this rank counts (``owned_cells``). One row per cell: each
    cell's row built and held by the rank counting it (``Relation.ids``: row j the region's
    j-th cell by input id; its entries on other ranks' nodes reach them in the stacking, as
    a tie's), under a maximum too (the group spans the ranks: the active set decides it by
    reductions). A mean: a spread relation (``Relation.spread``), its one row whole, the
    entries sent to the ranks owning their DOFs (``spread.to_owners``). No rank holds the
    region's entries or cells (each the cells it counts: ``row_cell``)."""
    regions, fields, comm = where.regions, where.fields, where.comm
    mesh = regions.mesh
    region = regions(spec.region, spec.key + ".region")
    if regions.cell_count(region.cells) == 0:
        raise InputError(f"region {spec.region!r} contains no cell (a strain needs cells)",
                         where.source, spec.key + ".region")
    cells = regions.owned_cells(region.cells)
    per_rank = spec.per_cell
    if per_rank:   # (its rows held in increasing number: the cells by input id)
        cells = cells[np.argsort(mesh.global_cells[cells], kind="stable")]
    dofs, coefs, vol = strain_rows(mesh, cells, spec.direction, where.thickness,
                                   fields=fields, field=spec.field)
    ids = mesh.global_cells[cells].astype(np.int64)
    if spec.per_cell:   # (row j: the region's j-th cell by input id)
        rows, nrows = places(comm, ids, int(mesh.num_global_cells)), comm.allreduce(ids.size)
    else:
        coefs = coefs * (vol / comm.allreduce(float(vol.sum())))[:, None]
        rows, nrows = np.zeros(ids.size, dtype=np.int64), 1
    node, comp = np.divmod(dofs, fields.ncomp)   # local DOFs → input DOFs, their owners
    inputs = mesh.global_nodes[node].astype(np.int64) * fields.ncomp + comp
    a_rows, a_dofs, a_vals = _cell_entries(rows, inputs, coefs) if per_rank else \
        to_owners(comm, np.repeat(rows, dofs.shape[1]), inputs.ravel(), coefs.ravel(),
                  mesh.owner_of(node).ravel())
    here = ids.size if per_rank else nrows
    r = rel.Relation(spec.name, here, a_rows, a_dofs, a_vals, np.full(here, spec.value),
                     evolution, spec.sense)
    # the cells this rank counts (input ids) and, one row per cell, their rows
    r.meta["cells"], r.meta["cell_rows"] = ids, (rows if spec.per_cell else None)
    return rel.rows_here(r, rows, nrows) if per_rank else rel.spread_rows(r)


def _cell_entries(rows: np.ndarray, inputs: np.ndarray, coefs: np.ndarray) -> tuple:
    """A per-rank relation's entries of its cells' rows (local rows, input DOFs,
    coefficients), by row then DOF, the zero coefficients left out (as ``to_owners``
    does): one row per cell, its DOFs each once."""
    local = np.repeat(np.arange(rows.size), inputs.shape[1])
    dofs, vals = inputs.ravel(), coefs.ravel()
    keep = vals != 0.0
    order = np.lexsort((dofs[keep], local[keep]))
    return local[keep][order], dofs[keep][order], vals[keep][order]


def row_cell(comm, r: rel.Relation, row: int) -> int | None:
    """The input id of the cell of a per-cell strain row (its number in the whole relation;
    None for another relation), from the rank counting it. Collective."""
    rows = r.meta.get("cell_rows")
    if rows is None:
        return None
    mine = r.meta["cells"][rows == row]
    return comm.allreduce(int(mine[0]) if mine.size else -1, op=MPI.MAX)
