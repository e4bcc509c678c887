"""``body`` (``source`` on a scalar field): a force per unit volume of a region's cells,
numbers or expressions of (x, y, z, t), integrated at the cells' quadrature points."""

from __future__ import annotations

import numpy as np

from parsolve.fem.integrals import cell_rule, integrate
from parsolve.loads.base import (Instant, LoadSpec, Where, blocks, field_dofs, need_cells,
                                 scatter, values_at)


def cell_forces(spec: LoadSpec, where: Where, value) -> np.ndarray:
    """Σ ∫ N_a v dV over the region's cells as a full vector; ``value(rule, cells)`` gives
    the force per unit volume (nc, nq, ncomp) at the rule's points."""
    cells = where.region.cells
    out = np.zeros(where.ndof)
    for sl in blocks(cells.size):
        nodes = where.mesh.cells[cells[sl]]
        rule = cell_rule(where.mesh.points[nodes], where.mesh.cell_type, where.thickness)
        fe = integrate(rule, value(rule, cells[sl]))
        out += scatter(where.ndof, field_dofs(where.fields, spec.field, nodes),
                       fe.reshape(fe.shape[0], -1))
    return out


def assemble(spec: LoadSpec, where: Where, at: Instant) -> np.ndarray:
    need_cells(spec, where)
    return cell_forces(spec, where, lambda rule, cells: values_at(spec, rule.points, at,
                                                                  where.source))
