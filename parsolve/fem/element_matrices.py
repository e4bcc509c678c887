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
    tensors: np.ndarray | None = None         # factored: M (nmat, d², d²)
    cell_material: np.ndarray | None = None   # factored: (nc,) index into tensors

    def reduce(self, pair_slot: np.ndarray, npairs: int) -> np.ndarray:
        """Sum over cells into node-pair blocks: (d², npairs)."""
        slots = pair_slot.ravel()
        if self.values is not None:
            return _bincount_rows(slots, self.values.reshape(len(self.values), -1), npairs)
        P = self.geometric.reshape(len(self.geometric), -1)
        nmat = len(self.tensors)
        if nmat == 1:
            return self.tensors[0].T @ _bincount_rows(slots, P, npairs)
        out = np.zeros((P.shape[0], npairs))
        nen2 = P.shape[1] // len(self.cell_material)
        for m in range(nmat):  # weights zero outside the material keep one pass per material
            mask = np.tile(self.cell_material == m, nen2).astype(float)
            out += self.tensors[m].T @ _bincount_rows(slots, P * mask, npairs)
        return out


def _bincount_rows(slots: np.ndarray, values: np.ndarray, npairs: int) -> np.ndarray:
    """Row-wise bincount, dropping the dump slot ``npairs`` (rows owned by another rank)."""
    return np.stack([np.bincount(slots, weights=v, minlength=npairs + 1)[:npairs] for v in values])
