"""``body`` (``source`` on a scalar field): a force per unit volume of a region's cells,
numbers or expressions of (x, y, z, t), integrated at the cells' quadrature points."""

from __future__ import annotations

from typing import Iterator

from parsolve.fem.element_matrices import NodeForces
from parsolve.fem.integrals import cell_rule, integrate
from parsolve.loads.base import Instant, LoadSpec, Where, blocks, need_cells, values_at


def cell_forces(where: Where, value) -> Iterator[NodeForces]:
    """∫ N_a v dV on the region's cells, cell block after cell block (a generator: one
    block's arrays at a time); ``value(rule, cells)`` gives the force per unit volume
    (nc, nq, ncomp) at the rule's points."""
    cells = where.region.cells
    for sl in blocks(cells.size):
        nodes = where.mesh.cells[cells[sl]]
        rule = cell_rule(where.mesh.points[nodes], where.mesh.cell_type, where.thickness)
        yield NodeForces(nodes, integrate(rule, value(rule, cells[sl])))


def forces(spec: LoadSpec, where: Where, at: Instant) -> Iterator[NodeForces]:
    need_cells(spec, where)
    return cell_forces(where, lambda rule, cells: values_at(spec, rule.points, at,
                                                                  where.source))
