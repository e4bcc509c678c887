"""Mazars (1984) isotropic scalar damage model for concrete.

    sigma = (1 - D) C eps,      D = alpha_t^beta D_t(kappa) + alpha_c^beta D_c(kappa)

* equivalent strain ``eps_eq = sqrt(sum_i <eps_i>_+^2)`` over the three principal strains of the
  3D strain tensor. In plane strain ``eps_zz = 0``. In plane stress
  ``eps_zz = -nu/(1-nu) (eps_xx + eps_yy)``: with a scalar (isotropic) damage
  ``sigma_zz = (1-D) (C eps)_zz`` vanishes for any D exactly when the elastic relation does, so
  this is the exact out-of-plane strain, not an approximation.
* history ``kappa = max(eps_d0, max over time of eps_eq)``;
* ``D_t = 1 - eps_d0 (1-At)/kappa - At exp(-Bt (kappa - eps_d0))`` (D_c likewise with Ac, Bc),
  evaluated in the algebraically identical form
  ``(1-At)(1 - eps_d0/kappa) + At (1 - exp(-Bt (kappa - eps_d0)))`` so that it is exactly 0 at
  ``kappa = eps_d0``;
* ``alpha_t = sum_i <eps_i>_+ eps_t,i / eps_eq^2`` and ``alpha_c = 1 - alpha_t`` (Mazars 1984,
  Pijaudier-Cabot & Mazars 2001), where ``eps_t = C^-1 <sigma~>_+`` is the strain of the positive
  part of the effective stress ``sigma~ = C eps`` (same principal axes as eps). ``alpha_t`` is
  set to exactly 1 when all principal strains are >= 0 or all principal effective stresses are
  >= 0 (then ``eps_t = eps``), and to exactly 0 when all principal effective stresses are <= 0.
  So uniaxial tension with ``nu = 0`` in plane stress gives exactly ``sigma = E eps (1 - D_t)``.

Choices (documented deviations from the bare formula):

* Irreversibility: ``D`` is a state variable and never decreases,
  ``D = min(1, max(D_old, D(alpha, kappa)))``. With alpha varying the bare formula could lower D
  at a fixed kappa (which would dissipate negative energy); with the max it cannot, and
  unloading is exactly secant. For proportional monotonic loading both agree.
* Damage only grows where some principal strain is positive (``eps_eq > 0``); at zero strain, or
  under all-negative principal strains, D is kept.
* ``D <= 1`` is enforced (with ``At > 1`` or ``Ac > 1`` the formula exceeds 1 at large kappa);
  there is NO residual stiffness: a fully damaged point has zero stress and zero tangent, so
  the global problem may become singular. No silent clipping below 1 is done.

Tangent ``dsigma/deps`` (consistent with ``update``), per point:

* no damage growth (elastic, unloading, reloading below the previous maximum, or D = 1):
  the secant ``(1 - D) C``;
* damage growth with alpha_t exactly 0 or 1 (pure tension/compression of the effective stress):
  analytic, ``(1-D) C - (C eps) (x) dD/dkappa d eps_eq/d eps`` (the last factor from the
  eigen-decomposition of the strain, zero when kappa does not grow);
* damage growth with mixed alpha: central finite differences of the loading branch (kappa
  following eps_eq if it grows at the point, D following the formula), vectorised over points,
  relative step ``fd_step`` (default 1e-6 of the strain magnitude): truncation and round-off
  errors are both ~1e-10 relative. Complex step is not used because ``numpy.linalg.eigvalsh``
  and the ``<.>_+`` brackets do not propagate it.
"""

from __future__ import annotations

import numpy as np

from .base import ELASTIC_PARAMETERS, REQUIRED, Material, check_parameters, lame


class Mazars(Material):
    """Mazars isotropic damage; state ``{"kappa": (nq,), "D": (nq,)}``."""

    PARAMETERS = {**ELASTIC_PARAMETERS, "eps_d0": (REQUIRED, "positive"), "At": (REQUIRED, "any"),
                  "Bt": (REQUIRED, "non_negative"), "Ac": (REQUIRED, "any"),
                  "Bc": (REQUIRED, "non_negative"), "beta": (1.06, "positive")}
    # its principal strains are written for the plane ones
    HYPOTHESES = ("plane_stress", "plane_strain", "3d")

    def __init__(
        self,
        E: float,
        nu: float,
        hypothesis: str,
        eps_d0: float,
        At: float,
        Bt: float,
        Ac: float,
        Bc: float,
        beta: float = 1.06,
        fd_step: float = 1e-6,
    ):
        super().__init__(E, nu, hypothesis)
        check_parameters(self.PARAMETERS, {"eps_d0": eps_d0, "Bt": Bt, "Bc": Bc, "beta": beta})
        if not 0.0 < fd_step < 1e-2:
            raise ValueError(f"fd_step must lie in (0, 1e-2), got {fd_step}")
        self.eps_d0 = float(eps_d0)
        self.At, self.Bt, self.Ac, self.Bc = float(At), float(Bt), float(Ac), float(Bc)
        self.beta = float(beta)
        self.fd_step = float(fd_step)
        self.lam, self.mu = lame(self.E, self.nu)
        # eps_zz = -kzz (eps_xx + eps_yy): the elastic plane-stress out-of-plane strain.
        self._kzz = self.nu / (1.0 - self.nu) if hypothesis == "plane_stress" else 0.0

    # ------------------------------------------------------------------ interface
    def init_state(self, nq: int) -> dict[str, np.ndarray]:
        """Virgin points: ``kappa = eps_d0``, ``D = 0``."""
        return {"kappa": np.full(nq, self.eps_d0), "D": np.zeros(nq)}

    def update(
        self, eps: np.ndarray, state: dict[str, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Stress, consistent tangent and trial state ``{"kappa", "D"}`` at total strain eps."""
        eps = self._as_strain(eps)
        kappa_old = np.asarray(state["kappa"], dtype=float)
        D_old = np.asarray(state["D"], dtype=float)

        eq, at, pure = self._split(eps)
        kappa_grows = eq > kappa_old
        kappa = np.maximum(kappa_old, eq)
        cand = self._candidate(kappa, at, eq)
        grows = cand > D_old
        D = np.where(grows, np.minimum(cand, 1.0), D_old)

        sig_eff = eps @ self.C  # C is symmetric
        sigma = (1.0 - D)[:, None] * sig_eff
        tangent = (1.0 - D)[:, None, None] * self.C

        # Points where D follows the formula (strictly below 1): add the damage derivative.
        active = grows & (cand < 1.0)
        sel = np.flatnonzero(active & pure & kappa_grows)
        if sel.size:
            a = at[sel]
            k = kappa[sel]
            dDdk = a**self.beta * self._dD(k, self.At, self.Bt) + (1.0 - a) ** self.beta * self._dD(
                k, self.Ac, self.Bc
            )
            g = self._grad_eq(eps[sel])
            tangent[sel] -= sig_eff[sel][:, :, None] * (dDdk[:, None] * g)[:, None, :]
        sel = np.flatnonzero(active & ~pure)
        if sel.size:
            tangent[sel] = self._fd_tangent(eps[sel], kappa_old[sel], kappa_grows[sel])
        return sigma, tangent, {"kappa": kappa, "D": D}

    def out_of_plane_stress(self, eps: np.ndarray, state: dict[str, np.ndarray]) -> np.ndarray:
        """sigma_zz ``(nq,)`` of a 2D hypothesis for ``state`` returned by ``update(eps, .)``."""
        eps = self._as_strain(eps)
        if self.hypothesis == "3d":
            raise ValueError("sigma_zz is part of the stress in 3d")
        if self.hypothesis == "plane_stress":
            return np.zeros(eps.shape[0])
        return (1.0 - np.asarray(state["D"])) * self.lam * (eps[:, 0] + eps[:, 1])

    # ------------------------------------------------------------------ kinematics
    def _tensor(self, eps: np.ndarray) -> np.ndarray:
        """3D strain tensors ``(m, 3, 3)`` (tensor shear = engineering / 2)."""
        m = eps.shape[0]
        T = np.zeros((m, 3, 3))
        if self.hypothesis == "3d":
            T[:, [0, 1, 2], [0, 1, 2]] = eps[:, :3]
            T[:, 1, 2] = T[:, 2, 1] = 0.5 * eps[:, 3]
            T[:, 0, 2] = T[:, 2, 0] = 0.5 * eps[:, 4]
            T[:, 0, 1] = T[:, 1, 0] = 0.5 * eps[:, 5]
        else:
            T[:, 0, 0] = eps[:, 0]
            T[:, 1, 1] = eps[:, 1]
            T[:, 0, 1] = T[:, 1, 0] = 0.5 * eps[:, 2]
            T[:, 2, 2] = -self._kzz * (eps[:, 0] + eps[:, 1])
        return T

    def _principal(self, eps: np.ndarray) -> np.ndarray:
        """Principal strains ``(m, 3)``; in 2D columns 0, 1 in-plane and column 2 = eps_zz."""
        if self.hypothesis == "3d":
            return np.linalg.eigvalsh(self._tensor(eps))
        # Closed form in 2D: exact for diagonal strains (uniaxial eps -> (eps, 0, eps_zz)).
        c = 0.5 * (eps[:, 0] + eps[:, 1])
        r = np.hypot(0.5 * (eps[:, 0] - eps[:, 1]), 0.5 * eps[:, 2])
        ezz = -self._kzz * (eps[:, 0] + eps[:, 1])
        return np.stack([c + r, c - r, ezz], axis=1)

    def _split(self, eps: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``eps_eq``, ``alpha_t`` and the mask of points where alpha_t is exactly 0 or 1."""
        e = self._principal(eps)
        ep = np.maximum(e, 0.0)
        eq2 = np.einsum("mi,mi->m", ep, ep)
        eq = np.sqrt(eq2)
        # Principal effective stresses; in plane stress sigma~_zz is identically 0, set it
        # exactly so that round-off cannot flip its sign.
        st = self.lam * e.sum(axis=1)[:, None] + 2.0 * self.mu * e
        if self.hypothesis == "plane_stress":
            st[:, 2] = 0.0
        sp = np.maximum(st, 0.0)
        eps_t = ((1.0 + self.nu) * sp - self.nu * sp.sum(axis=1, keepdims=True)) / self.E
        with np.errstate(divide="ignore", invalid="ignore"):
            at = np.einsum("mi,mi->m", ep, eps_t) / eq2
        # Clip guards round-off only (0 <= alpha_t <= 1 holds in exact arithmetic).
        at = np.clip(np.nan_to_num(at, nan=0.0), 0.0, 1.0)
        all_t = np.all(e >= 0.0, axis=1) | np.all(st >= 0.0, axis=1)
        all_c = ~all_t & np.all(st <= 0.0, axis=1)
        at = np.where(all_t, 1.0, np.where(all_c, 0.0, at))
        return eq, at, all_t | all_c

    def _grad_eq(self, eps: np.ndarray) -> np.ndarray:
        """``d eps_eq / d eps`` in Voigt ``(m, nvoigt)``: the tensor ``<eps>_+ / eps_eq``."""
        w, V = np.linalg.eigh(self._tensor(eps))
        wp = np.maximum(w, 0.0)
        eq = np.sqrt(np.einsum("mi,mi->m", wp, wp))
        G = np.einsum("mi,mji,mki->mjk", wp, V, V) / eq[:, None, None]
        # Engineering shear gamma = 2 eps_ij enters both (i,j) and (j,i): d/dgamma = G_ij.
        if self.hypothesis == "3d":
            return np.stack(
                [G[:, 0, 0], G[:, 1, 1], G[:, 2, 2], G[:, 1, 2], G[:, 0, 2], G[:, 0, 1]], axis=1
            )
        # eps_zz = -kzz (eps_xx + eps_yy) (0 in plane strain): chain rule.
        gz = -self._kzz * G[:, 2, 2]
        return np.stack([G[:, 0, 0] + gz, G[:, 1, 1] + gz, G[:, 0, 1]], axis=1)

    # ------------------------------------------------------------------ damage
    def _D(self, kappa: np.ndarray, A: float, B: float) -> np.ndarray:
        """``1 - eps_d0 (1-A)/kappa - A exp(-B (kappa-eps_d0))``, exactly 0 at eps_d0."""
        e0 = self.eps_d0
        return (1.0 - A) * (1.0 - e0 / kappa) - A * np.expm1(-B * (kappa - e0))

    def _dD(self, kappa: np.ndarray, A: float, B: float) -> np.ndarray:
        """Derivative of ``_D`` with respect to kappa."""
        e0 = self.eps_d0
        return (1.0 - A) * e0 / kappa**2 + A * B * np.exp(-B * (kappa - e0))

    def _candidate(self, kappa: np.ndarray, at: np.ndarray, eq: np.ndarray) -> np.ndarray:
        """Unbounded ``alpha_t^beta D_t + alpha_c^beta D_c``; 0 where eps_eq = 0."""
        D = at**self.beta * self._D(kappa, self.At, self.Bt) + (1.0 - at) ** self.beta * self._D(
            kappa, self.Ac, self.Bc
        )
        return np.where(eq > 0.0, D, 0.0)

    def _fd_tangent(
        self, eps: np.ndarray, kappa_old: np.ndarray, kappa_grows: np.ndarray
    ) -> np.ndarray:
        """Central differences of the loading branch, all points and components at once."""
        m, nv = eps.shape
        h = self.fd_step * np.maximum(np.abs(eps).max(axis=1), self.eps_d0)
        P = h[:, None, None] * np.eye(nv)  # row j: perturbation of component j
        X = np.concatenate([eps[:, None, :] + P, eps[:, None, :] - P], axis=1)
        X = X.reshape(-1, nv)
        k_old = np.repeat(kappa_old, 2 * nv)
        grows = np.repeat(kappa_grows, 2 * nv)
        # The branch is frozen at the centre point: kappa follows eps_eq where it grows there
        # (one-sided-consistent even if a perturbation falls below kappa_old), D = formula.
        eq, at, _ = self._split(X)
        kappa = np.where(grows, eq, k_old)
        D = self._candidate(kappa, at, eq)
        S = ((1.0 - D)[:, None] * (X @ self.C)).reshape(m, 2 * nv, nv)
        dS = (S[:, :nv, :] - S[:, nv:, :]) / (2.0 * h)[:, None, None]  # [m, j, i] = dsig_i/deps_j
        return np.transpose(dS, (0, 2, 1))
