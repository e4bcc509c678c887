"""J2 (von Mises) plasticity with linear isotropic hardening, radial return.

Yield function ``f = q(sigma) - (sigma_y + H p)`` with ``q = sqrt(3/2 s:s)`` and ``p`` the
cumulated equivalent plastic strain (``dp = sqrt(2/3 deps_p:deps_p)``), associated flow
``deps_p = dp 3/2 s/q``. The return mapping is exact for linear hardening (one step, no
iteration): ``dp = f_trial / (3 mu + H)``, and the returned stress lies on the yield surface.
The tangent is the consistent (algorithmic) one (Simo & Taylor 1985):

    C_alg = K 1(x)1 + 2 mu theta I_dev - 2 mu theta_bar n(x)n,
    theta = 1 - 3 mu dp / q_trial,  theta_bar = 3 mu / (3 mu + H) - 3 mu dp / q_trial,

with ``n = s_trial / |s_trial|``. Under uniaxial stress the slope after yield is E H/(E + H).

Hypotheses ``"3d"``, ``"plane_strain"`` and ``"axisymmetric"`` (the 3D algorithm on
(rr, zz, θθ, 0, 0, γ_rz), every component of the plastic strain kept); plane stress would need a different (constrained)
return mapping and is refused. Plane strain is computed with the 3D algorithm on the strain
``(eps_xx, eps_yy, 0, 0, 0, gamma_xy)`` and condensed by keeping the in-plane rows and columns
(eps_zz is prescribed, so no static condensation is involved).

State: ``"eps_p"`` plastic strain in Voigt with engineering shear, ``(nq, 6)`` in 3D and
``(nq, 4)`` = (xx, yy, zz, xy) in plane strain (eps_p_zz is not zero there); ``"p"`` ``(nq,)``.
"""

from __future__ import annotations

import numpy as np

from .base import (AXISYMMETRIC_COLS, ELASTIC_PARAMETERS, REQUIRED, Material, check_parameters,
                   elastic_matrix, lame)

_SQRT32 = np.sqrt(1.5)
#: Relative yield tolerance: plastic only when q exceeds the radius by more than round-off.
YIELD_TOL = 1e-10
# Deviatoric projector in Voigt, mapping engineering strains to (plain) stresses / (2 mu).
_IDEV = np.zeros((6, 6))
_IDEV[:3, :3] = -1.0 / 3.0
_IDEV[[0, 1, 2], [0, 1, 2]] = 2.0 / 3.0
_IDEV[[3, 4, 5], [3, 4, 5]] = 0.5
_ONES = np.zeros((6, 6))
_ONES[:3, :3] = 1.0


class VonMises(Material):
    """J2 plasticity with linear isotropic hardening; state ``{"eps_p", "p"}``."""

    PARAMETERS = {**ELASTIC_PARAMETERS, "sigma_y": (REQUIRED, "positive"),
                  "H": (REQUIRED, "non_negative")}
    HYPOTHESES = ("plane_strain", "axisymmetric", "3d")   # plane stress: not written

    def __init__(self, E: float, nu: float, hypothesis: str, sigma_y: float, H: float):
        super().__init__(E, nu, hypothesis)
        check_parameters(self.PARAMETERS, {"sigma_y": sigma_y, "H": H})
        self.sigma_y = float(sigma_y)
        self.H = float(H)
        self.lam, self.mu = lame(self.E, self.nu)
        self.K = self.lam + 2.0 * self.mu / 3.0
        self._C6 = elastic_matrix(self.E, self.nu, "3d")
        # Voigt-6 columns of the in-plane strain and of the stored plastic strain.
        self._strain_cols = {"plane_strain": [0, 1, 5],
                             "axisymmetric": AXISYMMETRIC_COLS}.get(hypothesis, list(range(6)))
        self._state_cols = {"plane_strain": [0, 1, 2, 5],
                            "axisymmetric": AXISYMMETRIC_COLS}.get(hypothesis, list(range(6)))

    def init_state(self, nq: int) -> dict[str, np.ndarray]:
        """Virgin points: zero plastic strain and zero cumulated plastic strain."""
        return {"eps_p": np.zeros((nq, len(self._state_cols))), "p": np.zeros(nq)}

    def _to6(self, a: np.ndarray, cols: list[int]) -> np.ndarray:
        """Embed rows of ``a`` into Voigt-6 columns ``cols`` (the others are zero)."""
        out = np.zeros((a.shape[0], 6))
        out[:, cols] = a
        return out

    def update(
        self, eps: np.ndarray, state: dict[str, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Radial return from the converged ``state``: stress, consistent tangent, trial state."""
        eps = self._as_strain(eps)
        nq = eps.shape[0]
        mu, H = self.mu, self.H
        ep_old = self._to6(np.asarray(state["eps_p"], dtype=float), self._state_cols)
        p_old = np.asarray(state["p"], dtype=float)

        ee = self._to6(eps, self._strain_cols) - ep_old  # trial elastic strain (engineering)
        tr = ee[:, :3].sum(axis=1)
        s = np.empty((nq, 6))  # trial deviatoric stress, tensor components
        s[:, :3] = 2.0 * mu * (ee[:, :3] - tr[:, None] / 3.0)
        s[:, 3:] = mu * ee[:, 3:]
        # |s| with tensor components: each off-diagonal term counts twice
        norm = np.sqrt((s[:, :3] ** 2).sum(axis=1) + 2.0 * (s[:, 3:] ** 2).sum(axis=1))
        q = _SQRT32 * norm
        radius = self.sigma_y + H * p_old
        f = q - radius
        # A point returned onto the surface at the last step sits at f = 0 up to round-off;
        # the tolerance keeps it elastic whatever that round-off (and so the partition) is.
        plastic = f > YIELD_TOL * radius

        dp = np.where(plastic, f, 0.0) / (3.0 * mu + H)
        n = np.zeros((nq, 6))
        n[plastic] = s[plastic] / norm[plastic, None]
        sig = s - (2.0 * mu * _SQRT32 * dp)[:, None] * n
        sig[:, :3] += (self.K * tr)[:, None]
        dep = (_SQRT32 * dp)[:, None] * n
        dep[:, 3:] *= 2.0  # engineering shear
        new_state = {"eps_p": (ep_old + dep)[:, self._state_cols], "p": p_old + dp}

        T = np.repeat(self._C6[None], nq, axis=0)
        idx = np.flatnonzero(plastic)
        if idx.size:
            r = 3.0 * mu * dp[idx] / q[idx]
            theta = 1.0 - r
            theta_bar = 3.0 * mu / (3.0 * mu + H) - r
            ni = n[idx]
            T[idx] = (
                self.K * _ONES
                + (2.0 * mu * theta)[:, None, None] * _IDEV
                - (2.0 * mu * theta_bar)[:, None, None] * ni[:, :, None] * ni[:, None, :]
            )
        c = self._strain_cols
        return sig[:, c], T[:, c][:, :, c], new_state

    def out_of_plane_stress(self, eps: np.ndarray, state: dict[str, np.ndarray]) -> np.ndarray:
        """Plane strain sigma_zz ``(nq,)`` for ``state`` returned by ``update(eps, .)``."""
        eps = self._as_strain(eps)
        if self.hypothesis != "plane_strain":
            raise ValueError("sigma_zz is part of the stress in 3d")
        ee = self._to6(eps, self._strain_cols) - self._to6(state["eps_p"], self._state_cols)
        return ee @ self._C6[2]
