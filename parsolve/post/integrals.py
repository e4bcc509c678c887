"""Integrals over the mesh: L2 norm of a nodal field, strain energy of an elastic scene."""

from __future__ import annotations

import numpy as np

from parsolve.errors import InputError
from parsolve.fem import kernels
from parsolve.fem.elements import polynomial_order
from parsolve.post.result import Result


def l2_norm(points: np.ndarray, cells: np.ndarray, cell_type: str, values: np.ndarray) -> np.ndarray:
    """sqrt(∫ |f|² dΩ) per step for nodal values (nsteps, npoints, ncomp), exact for the
    element's polynomial (quadrature of degree 2 × order)."""
    geo = kernels.CellGeometry(points[cells], cell_type, degree=2 * polynomial_order(cell_type))
    fq = np.einsum("qa,scan->scqn", geo.N, values[:, cells, :])       # (nsteps, nc, nq, ncomp)
    return np.sqrt(np.einsum("scqn,cq->s", fq * fq, geo.wdet))


def strain_energy(res: Result, key: str) -> np.ndarray:
    """½ ∫ ε : C ε dΩ per step from /fields/displacement and the stored scene's materials
    (with the scene's thickness in 2D); linear elastic materials only."""
    from parsolve.post.scene_model import model_of

    model = model_of(res, key)
    if model.elasticity.nonlinear:
        raise InputError("energy needs linear elastic materials", res.path, key)
    u = res.dataset("fields/displacement", key)
    el = model.elasticity
    cells = np.arange(len(res.cells))
    geo = el.geometry(cells)
    B = geo.strain_operator()
    C = el.C[el.cell_model][:, None]                                   # (nc, 1, nv, nv)
    out = np.empty(len(u))
    for s, us in enumerate(u):                                         # steps, not cells
        eps = kernels.strains(B, us[res.cells].reshape(len(cells), -1))
        sig = np.matmul(C, eps[..., None])[..., 0]
        out[s] = 0.5 * np.einsum("cqv,cqv,cq->", eps, sig, geo.wdet)
    return out
