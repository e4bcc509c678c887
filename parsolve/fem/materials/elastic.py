"""Linear isotropic elasticity in the Material interface."""

from __future__ import annotations

import numpy as np

from parsolve.fem.materials.base import ELASTIC_PARAMETERS, HYPOTHESES, elastic_matrix


class Elastic:
    """σ = C ε; no state."""

    PARAMETERS = ELASTIC_PARAMETERS
    HYPOTHESES = tuple(HYPOTHESES)

    def __init__(self, E: float, nu: float, hypothesis: str):
        self.E, self.nu, self.hypothesis = E, nu, hypothesis
        self.C = elastic_matrix(E, nu, hypothesis)
        self.nvoigt = self.C.shape[0]

    def init_state(self, nq: int) -> dict[str, np.ndarray]:
        return {}

    def update(self, eps: np.ndarray, state: dict) -> tuple[np.ndarray, np.ndarray, dict]:
        tangent = np.broadcast_to(self.C, (len(eps),) + self.C.shape)
        return eps @ self.C.T, tangent, state
