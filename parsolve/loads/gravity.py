"""``gravity``: an acceleration g on a region's cells (default all), the body force ρ g with
the density ρ of each cell's material (``density`` of its ``[[materials]]`` entry; later
entries override earlier ones on shared cells, as for the other parameters)."""

from __future__ import annotations

from typing import Iterable

import numpy as np

from parsolve.errors import InputError
from parsolve.fem.element_matrices import NodeForces
from parsolve.loads.base import Instant, LoadSpec, Where, need_cells
from parsolve.loads.body import cell_forces


def densities(spec: LoadSpec, where: Where) -> np.ndarray:
    """ρ of every local cell (NaN where no material gives one)."""
    rho = np.full(where.mesh.num_cells, np.nan)
    for material in where.scene.materials:
        region = where.regions(material.region, material.key + ".region")
        rho[region.cells] = np.nan if material.density is None else material.density
    return rho


def forces(spec: LoadSpec, where: Where, at: Instant) -> Iterable[NodeForces]:
    need_cells(spec, where)
    rho = densities(spec, where)
    missing = where.regions.cell_count(where.region.cells[np.isnan(rho[where.region.cells])])
    if missing:
        raise InputError(f"{missing} cells of region {spec.region!r} have no density (give "
                         "'density' in their [[materials]] entry)", where.source,
                         spec.key + ".gravity")
    g = np.asarray(spec.vector, dtype=float)
    return cell_forces(where, lambda rule, cells: rho[cells][:, None, None] * g)
