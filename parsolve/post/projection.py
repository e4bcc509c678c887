"""Nodal fields from cell fields by lumped L² projection: smooth pictures and nodal maxima of
von Mises, principal stresses, stress components, damage, ...

The cell field σ_h (one value per cell: the stored cell means) is projected onto the mesh's
nodal shape functions with a lumped (diagonal) mass matrix, M_L u = ∫ N σ_h dΩ:

    u_a = Σ_c m_ca σ_c / Σ_c m_ca

with m_ca the lumped mass of node a in cell c. The lumping is HRZ's (each cell's diagonal of
its consistent mass ∫ N_a N_a, scaled to the cell's measure), whose weights are positive for
every element, quadratic triangles and tetrahedra included (whose row sums ∫ N_a are zero or
negative at the corners). A constant field is reproduced exactly; so is a linear field's
value at a node whose cells are symmetric about it (the cell means of a linear field average
back to its nodal value). The measure is the plane one (no thickness, no 2π r: both cancel
in u_a for a uniform thickness; an axisymmetric model's r weighting is not applied).
"""

from __future__ import annotations

import numpy as np

from parsolve.fem import kernels
from parsolve.fem.elements import polynomial_order

CELL_BLOCK = 20000   # cells per block of geometry (bounded memory on large meshes)


def lumped_weights(points: np.ndarray, cells: np.ndarray, cell_type: str) -> np.ndarray:
    """HRZ lumped mass m_ca of each cell's nodes (ncells, nen): the diagonal of ∫ N_a N_b,
    scaled so that each cell's weights sum to its measure."""
    out = np.empty(cells.shape)
    degree = 2 * polynomial_order(cell_type)
    for lo in range(0, len(cells), CELL_BLOCK):
        block = cells[lo:lo + CELL_BLOCK]
        geo = kernels.CellGeometry(points[block], cell_type, degree=degree)
        diag = np.einsum("qa,cq->ca", geo.N ** 2, geo.wdet)          # ∫ N_a² per cell
        measure = geo.wdet.sum(axis=1)
        out[lo:lo + CELL_BLOCK] = diag * (measure / diag.sum(axis=1))[:, None]
    return out


def project(points: np.ndarray, cells: np.ndarray, cell_type: str,
            values: np.ndarray) -> np.ndarray:
    """Nodal values (nsteps, npoints, ncomp) of cell values (nsteps, ncells, ncomp) by lumped
    L² projection. A node no cell holds (an unused point) gets NaN."""
    m = lumped_weights(points, cells, cell_type)                     # (nc, nen)
    npoints = len(points)
    mass = np.bincount(cells.ravel(), weights=m.ravel(), minlength=npoints)
    flat = cells.ravel()
    out = np.empty((values.shape[0], npoints, values.shape[2]))
    # Σ_c m_ca σ_c by bincount, one step and component at a time: no loop over cells
    for s in range(values.shape[0]):
        for c in range(values.shape[2]):
            out[s, :, c] = np.bincount(flat, weights=(m * values[s, :, c, None]).ravel(),
                                       minlength=npoints)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(mass[None, :, None] > 0, out / mass[None, :, None], np.nan)


def nodal_names(cell_fields: list[str], fields: list[str]) -> dict[str, str]:
    """{cell field: its projection's name under /fields}: the same name, or
    ``<name>_projected`` where /fields has it already (/fields/stress, the nodal average of
    the stress evaluated at the nodes, stays as the run wrote it)."""
    return {n: n if n not in fields else f"{n}_projected" for n in cell_fields}
