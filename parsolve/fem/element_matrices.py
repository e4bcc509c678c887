"""Element matrices as the assembly receives them, cell-last.

Either *factored*: ``K_e[ij] = Σ_kl M[material][kl, ij] P[kl]`` with a geometric part
``P`` (d², nen, nen, nc) and constant material tensors ``M`` (nmat, d², d²) -- then the
material contraction can be done after summing over cells, on far fewer numbers -- or *full*:
the values (d², nen, nen, nc) themselves (a tangent that varies from point to point).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ElementMatrices:
    values: np.ndarray | None = None          # full: (d², nen, nen, nc)
    geometric: np.ndarray | None = None       # factored: P (d², nen, nen, nc)
    tensors: np.ndarray | None = None         # factored: M (nmat, d², ncomp²)
    cell_material: np.ndarray | None = None   # factored: (nc,) index into tensors

    def reduce(self, pair_slot: np.ndarray, npairs: int) -> np.ndarray:
        """Sum over cells into node-pair blocks: (d², npairs)."""
        slots = _slots(pair_slot)
        if self.values is not None:
            return _bincount_rows(slots, self.values.reshape(len(self.values), -1), npairs)
        P = self.geometric.reshape(len(self.geometric), -1)
        nmat = len(self.tensors)
        if nmat == 1:
            return self.tensors[0].T @ _bincount_rows(slots, P, npairs)
        out = np.zeros((self.tensors.shape[2], npairs))
        nen2 = P.shape[1] // len(self.cell_material)
        for m in range(nmat):  # weights zero outside the material keep one pass per material
            mask = np.tile(self.cell_material == m, nen2).astype(float)
            out += self.tensors[m].T @ _bincount_rows(slots, P * mask, npairs)
        return out


def _slots(pair_slot: np.ndarray) -> np.ndarray:
    """The pair slots flat, as np.bincount takes them (intp): the pattern keeps them int32 to
    halve their memory, so they are widened once per reduction, not once per row."""
    return pair_slot.astype(np.intp, copy=False).ravel()


def _bincount_rows(slots: np.ndarray, values: np.ndarray, npairs: int) -> np.ndarray:
    """Row-wise bincount, dropping the dump slot ``npairs`` (rows owned by another rank)."""
    out = np.empty((len(values), npairs))
    for k, v in enumerate(values):  # one row's counts alive at a time, not all of them
        out[k] = np.bincount(slots, weights=v, minlength=npairs + 1)[:npairs]
    return out


def full_values(m: ElementMatrices) -> np.ndarray:
    """The element matrices (d², nen, nen, nc) whatever their form."""
    if m.values is not None:
        return m.values
    M = m.tensors[m.cell_material]                      # (nc, d², d²)
    return np.einsum("ckm,kabc->mabc", M, m.geometric)


def apply(m: ElementMatrices, ue: np.ndarray) -> np.ndarray:
    """Element products K_e u_e: ue (nc, nen, dj) → (nc, nen, di), d² = di·dj."""
    V = full_values(m)
    nc, nen, dj = ue.shape
    di = V.shape[0] // dj
    return np.einsum("ijabc,cbj->cai", V.reshape(di, dj, nen, nen, nc), ue)


@dataclass
class BlockMatrices:
    """Element matrices of several effects, each on its own (row, column) components of the
    node DOFs, scaled: reduced into the full (ncomp², npairs) node-pair blocks."""

    ncomp: int
    parts: list  # (row components, column components, ElementMatrices, factor)

    def reduce(self, pair_slot: np.ndarray, npairs: int) -> np.ndarray:
        nc = self.ncomp
        pair_slot = pair_slot.astype(np.intp, copy=False)   # widened once for every part
        if len(self.parts) == 1:
            ci, cj, m, fac = self.parts[0]
            if len(ci) == len(cj) == nc and np.all(ci == np.arange(nc)) \
                    and np.all(cj == np.arange(nc)) and fac == 1.0:
                return m.reduce(pair_slot, npairs)
        out = np.zeros((nc * nc, npairs))
        for ci, cj, m, fac in self.parts:
            idx = (np.asarray(ci)[:, None] * nc + np.asarray(cj)[None, :]).ravel()
            out[idx] += fac * m.reduce(pair_slot, npairs)
        return out
