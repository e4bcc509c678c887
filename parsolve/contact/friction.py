"""Coulomb friction logic as pure functions on per-node arrays.

Sign conventions (parsolve's relations, ``K q = F + D lambda``, associated ``D = -A^T``):

* normal row ``Dn . q >= -g0`` with dual ``D = -(Dn - mu Dt.s)``: the force on the slave node is
  ``-lambda_n (n - mu s_vec) = Rn n - mu Rn s_vec`` with the contact pressure (force)
  ``Rn = -lambda_n >= 0`` (a ">=" row's multiplier is <= 0 when active). The paper writes the
  same thing as ``lambda_n Dn`` and ``-mu lambda_n Dt`` with its lambda_n = Rn.
* tangential rows ``Dt_j . q = (value)``, associated: force on the slave ``-lambda_t_j t_j``.
* so the friction force on the slave in the tangent basis is
  ``Rt = -lambda_t - mu Rn s`` (the term ``-mu Rn s`` only when the normal dual carries the
  friction); the paper's "(lambda_t - mu lambda_n) Dt" with its signs.
* ``s`` is the slip direction of the slave relative to the master, in the tangent basis
  (2D: +-1; 3D: a unit 2-vector); friction opposes it: in slip ``Rt = -mu Rn s``.
* Coulomb cone: ``mu Rn - |Rt| >= 0``.

States (int8, the values saved per node): OPEN = 0 (lift-off), STICK = 1, SLIP = 2.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve.errors import InputError

OPEN, STICK, SLIP = 0, 1, 2
STATE_NAMES = {OPEN: "open", STICK: "stick", SLIP: "slip"}
DIRECTION_MODES = ("displacement", "reaction")
#: A sliding direction has settled when it turns by less than this (radians) in an update.
TOL_ANGLE = 1e-10


#: The largest friction coefficient accepted. Measured dry coefficients stay below about 2
#: (rubber on dry rock, clean metals in vacuum reach 1–2); far above, the frictional dual
#: Dn − μ Dt·s is dominated by μ and the saddle system's conditioning goes with it (1e30
#: gives garbage, not stick).
MU_MAX = 10.0


def check_mu(mu: float, source: str | None = None, key: str | None = None) -> float:
    """The friction coefficient as a float; InputError unless finite and >= 0."""
    try:
        value = float(mu)
    except (TypeError, ValueError):
        raise InputError(f"friction coefficient must be a number, got {mu!r}", source, key) from None
    if not np.isfinite(value) or value < 0.0:
        raise InputError(f"friction coefficient must be >= 0, got {mu!r}", source, key)
    if value > MU_MAX:
        raise InputError(f"friction coefficient {value:.3g} is beyond any measured one (at most "
                         f"{MU_MAX:g}): a surface that must not slip is a tie relation", source,
                         key)
    return value


def _vec(a: np.ndarray, n: int) -> np.ndarray:
    """Tangential quantities as (n, dim-1): a 2D scalar per node becomes a column."""
    a = np.asarray(a, dtype=float)
    return a.reshape(n, 1) if a.ndim <= 1 else a


def reactions(lam_n: np.ndarray, lam_t: np.ndarray | None, mu: float | np.ndarray,
              direction: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Normal force Rn (n,) and friction force Rt (n, dim-1) on the slave nodes from multipliers.

    lam_n (n,): multipliers of the normal rows; lam_t (n, dim-1) or None: multipliers of the
    tangential rows expressed in the tangent basis (for one row along s, pass ``lam * s``);
    direction (n, dim-1) or None: the slip direction carried by the normal dual (None: the
    normal rows are frictionless/associated).
    """
    lam_n = np.asarray(lam_n, dtype=float)
    n = lam_n.size
    rn = -lam_n
    rt = np.zeros((n, 1)) if lam_t is None else -_vec(lam_t, n)
    if direction is not None:
        mu = np.broadcast_to(np.asarray(mu, dtype=float), (n,))
        rt = rt - (mu * rn)[:, None] * _vec(direction, n)
    return rn, rt


def cone_margin(rn: np.ndarray, rt: np.ndarray, mu: float | np.ndarray) -> np.ndarray:
    """mu Rn - |Rt| (n,): >= 0 inside the Coulomb cone."""
    rn = np.asarray(rn, dtype=float)
    return np.asarray(mu, dtype=float) * rn - np.linalg.norm(_vec(rt, rn.size), axis=1)


def contact_states(gap: np.ndarray, rn: np.ndarray, slip_increment: np.ndarray,
                   tol_gap: float = 0.0, tol_slip: float = 0.0) -> np.ndarray:
    """OPEN where the gap is open (> tol_gap) or the node carries no compression (Rn <= 0),
    else SLIP where the tangential slip increment exceeds tol_slip, else STICK. int8 (n,)."""
    gap = np.asarray(gap, dtype=float)
    n = gap.size
    closed = (gap <= tol_gap) & (np.asarray(rn) > 0.0)
    moving = np.linalg.norm(_vec(slip_increment, n), axis=1) > tol_slip
    return np.where(closed, np.where(moving, SLIP, STICK), OPEN).astype(np.int8)


def _unit(v: np.ndarray, previous: np.ndarray, tol: float) -> np.ndarray:
    norm = np.linalg.norm(v, axis=1)
    ok = norm > tol
    out = previous.copy()
    out[ok] = v[ok] / norm[ok, None]
    return out


def slip_direction(previous: np.ndarray, mode: str, slip_increment: np.ndarray | None = None,
                   rt: np.ndarray | None = None, tol: float = 0.0) -> np.ndarray:
    """Updated unit slip direction (n, dim-1) in the tangent basis.

    mode "displacement": along the tangential displacement increment (slave minus master);
    mode "reaction": opposite to the friction force, -Rt/|Rt| (friction opposes the slip).
    Where the chosen vector is not above tol, the previous direction is kept. In 2D the
    direction is the sense +-1 (a (n, 1) column).
    """
    if mode not in DIRECTION_MODES:
        raise ValueError(f"slip direction mode must be one of {DIRECTION_MODES}, got {mode!r}")
    previous = np.asarray(previous, dtype=float)
    n = previous.shape[0]
    previous = _vec(previous, n)
    if mode == "displacement":
        return _unit(_vec(slip_increment, n), previous, tol)
    return _unit(-_vec(rt, n), previous, tol)


def friction_update(
    state: np.ndarray,
    direction: np.ndarray,
    closed: np.ndarray,
    rn: np.ndarray,
    rt: np.ndarray,
    slip_increment: np.ndarray,
    mu: float | np.ndarray,
    mode: str = "displacement",
    tol_force: float = 1e-12,
    tol_slip: float = 1e-14,
    tol_angle: float = TOL_ANGLE,
    rn_max: float | None = None,
) -> tuple[np.ndarray, np.ndarray, bool]:
    """One friction active-set update between global iterations.

    state (n,) int8 and direction (n, dim-1) of the iteration just solved; closed (n,) bool:
    the normal row is active; rn, rt: forces (see :func:`reactions`); slip_increment
    (n, dim-1): tangential displacement since the start of the step (slave minus master).

    * open -> OPEN; newly closed -> STICK.
    * STICK with |Rt| > mu Rn (1 + tol): SLIP, direction -Rt/|Rt| (the stick reaction is the
      only information in stick, whatever the mode).
    * SLIP moving against its direction (slip_increment . s < -tol_slip): STICK (2D: the sense
      was wrong; the next stick solve gives the right one).
    * SLIP otherwise: the direction is updated (``mode``, see :func:`slip_direction`); in 2D
      it cannot change this way (the slip is along +-s).

    tol_force scales with max(Rn) (``rn_max``: the whole surface's, when these are a part of
    it). Returns (state, direction, changed): changed when a state
    changed or a direction turned by more than tol_angle (radians).
    """
    state = np.asarray(state, dtype=np.int8)
    n = state.size
    direction = _vec(direction, n)
    rn = np.asarray(rn, dtype=float)
    rt = _vec(rt, n)
    du = _vec(slip_increment, n)
    closed = np.asarray(closed, dtype=bool)
    mu = np.broadcast_to(np.asarray(mu, dtype=float), (n,))
    if rn_max is None:
        rn_max = float(np.max(np.abs(rn))) if n else 0.0
    scale = max(rn_max, 1e-300)

    new_state = np.where(closed, state, OPEN).astype(np.int8)
    new_state[closed & (state == OPEN)] = STICK
    new_dir = direction.copy()

    stick = closed & (state == STICK)
    over = stick & (np.linalg.norm(rt, axis=1) - mu * rn > tol_force * scale)
    new_state[over] = SLIP
    new_dir[over] = slip_direction(direction[over], "reaction", rt=rt[over])

    slip = closed & (state == SLIP)
    back = slip & (np.einsum("mj,mj->m", du, direction) < -tol_slip)
    new_state[back] = STICK
    keep = slip & ~back
    if direction.shape[1] > 1 and np.any(keep):
        new_dir[keep] = slip_direction(direction[keep], mode, du[keep], rt[keep], tol_slip)

    # directions matter only where the node slides before and after
    both = (state == SLIP) & (new_state == SLIP)
    # chord length of unit vectors = 2 sin(angle/2): well conditioned for small angles
    angle = np.linalg.norm(new_dir[both] - direction[both], axis=1)
    changed = bool(np.any(new_state != state) or np.any(angle > tol_angle))
    return new_state, new_dir, changed


def signed_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (n,) turning the unit 2-vectors a (n, 2) to b (n, 2), in (-pi, pi]."""
    return np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], np.einsum("mj,mj->m", a, b))


#: A free sliding node's cross stiffness stays within this factor of the surface's tangential
#: stiffness (a node that barely slides, whose κ = mu Rn / γ would be far above it, is held:
#: the limit κ → ∞, without the ill-conditioning).
KAPPA_MAX = 1e4


class SlipNewton:
    """The 3D slip direction by a generalised Newton step inside the paper's relations.

    A sliding node carries the friction ``-mu Rn s`` through its normal row's dual, with ``s``
    the direction of its slip in the step, ``s = Δu_t/γ``, ``γ = |Δu_t|``. Linearised in the
    displacement (the dual's dependence on s; Alart–Curnier, the semi-smooth Newton of
    Hüeber–Stadler–Wohlmuth), the force is

        d(-mu Rn s) = -mu s dRn - (mu Rn / γ) (I - s sᵀ) dΔu_t

    the first term is the dual's own (Rn is a multiplier, an unknown of the solve), the second
    a tangential stiffness ``κ = mu Rn / γ`` across s, which the effect adds to the Newton
    matrix only: the forces, the residual and hence the converged answer are the relations'.
    With it, ``s ← Δu_t/|Δu_t|`` after each solve is Newton's update of s (the *free* node:
    both tangential rows released), quadratic near the answer, whatever the node's ξ =
    kγ/(mu Rn) and the coupling through the structure. A node that starts sliding (γ = 0,
    κ infinite) is *held* first: its row across s blocked (the limit κ → ∞), so that it
    slides along s and gets a γ; it is then free. A node whose slip stays at or below ``tol``
    (no direction to take from it) stays held and turns s towards −Rt (the plain update,
    whose error factor ξ is then negligible). Deterministic arithmetic: every rank takes the
    same decisions on the nodes it holds (``turn``'s ``comm``: the surface's nodes split over
    the ranks, whose one surface number k is then taken over all).
    """

    def __init__(self):
        self.committed = np.zeros(0)
        self.k: float | None = None    # the surface's tangential stiffness, once measured
        self.start(np.zeros(0, dtype=np.int8))

    def start(self, state: np.ndarray) -> None:
        """A new step from the committed node states: a node that slid at the end of the last
        converged step starts free, with the cross stiffness it had there (its slip of the
        last step for that of this one: equal steps of a steady slide); the others are held
        and get no stiffness."""
        n = len(state)
        kappa = self.committed if self.committed.size == n else np.zeros(n)
        free = (np.asarray(state) == SLIP) & (kappa > 0.0)
        self.held = ~free
        self.kappa = np.where(free, kappa, 0.0)
        self.excess = np.zeros(n)

    def commit(self) -> None:
        """The step converged: keep its cross stiffnesses for the next step's start."""
        self.committed = self.kappa.copy()

    def turn(self, sliding: np.ndarray, s: np.ndarray, du: np.ndarray, rt: np.ndarray,
             murn: np.ndarray, tol: float, comm=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(new directions (n, 2), residual angles (n,), mode switched (n,)) of the nodes that
        slide before and after the iteration just solved (``sliding``; the others keep s),
        from its slip increments du (n, 2), friction forces rt (n, 2) and mu Rn (n,).
        Afterwards ``held`` and ``kappa`` (the cross stiffness of the free nodes, 0 on the
        others) are those of the next solve. The residual is the angle between s and the
        slip (free) or −Rt (held): the direction's error."""
        sliding = np.asarray(sliding, dtype=bool)
        gamma = np.linalg.norm(du, axis=1)
        free = sliding & (gamma > tol)
        if self.k is not None:   # a cross stiffness far above the structure's: held instead
            free &= murn <= KAPPA_MAX * self.k * gamma
        out = s.copy()
        out[free] = du[free] / gamma[free, None]
        held = sliding & ~free
        out[held] = _unit(-rt[held], s[held], 0.0)
        residual = np.where(sliding, np.abs(signed_angle(s, out)), 0.0)
        switched = free & self.held
        measured = switched & (self.excess > 0.0)
        if self.k is None:
            # the held solve slid them by γ under the force their stick reaction had beyond
            # the cone: k ≈ excess / γ (a median: one number for the surface, robust; over
            # the ranks sharing the surface, by reductions)
            self.k = median(comm, self.excess[measured] / gamma[measured])
        self.held = ~free
        self.kappa = np.where(free, murn / np.where(free, gamma, 1.0), 0.0)
        self.excess[:] = 0.0
        return out, residual, switched

    def begin_slip(self, starting: np.ndarray, excess: np.ndarray, murn: np.ndarray) -> None:
        """Nodes that start sliding (``starting``, from stick, their reaction ``excess`` =
        |Rt| − mu Rn beyond the cone): held while the surface's tangential stiffness k is
        not known; once it is, free at once with the cross stiffness of the slip that excess
        will make, γ ≈ excess / k: κ = mu Rn k / excess (a held node spends a solve getting
        its γ). Call after :meth:`turn`, which holds every node that is not free."""
        self.excess[starting] = excess[starting]
        if self.k is None:
            self.held |= starting
            return
        free = starting & (murn <= KAPPA_MAX * excess)
        self.held[starting] = ~free[starting]
        self.kappa[free] = murn[free] * self.k / excess[free]


def median(comm, values: np.ndarray) -> float | None:
    """``np.median`` of every rank's values together (None when there are none; NaN when
    one is NaN), by reductions alone: each middle value found by bisection on the order of
    the floats' bits (64 reductions of a count), no rank holding another's values.
    Collective (``comm`` None: this rank's alone)."""
    values = np.asarray(values, dtype=float)
    if comm is None or comm.size == 1:
        return float(np.median(values)) if values.size else None
    n = comm.allreduce(int(values.size))
    if n == 0:
        return None
    if comm.allreduce(bool(np.isnan(values).any()), op=MPI.LOR):
        return float("nan")   # (as np.median: NaN has no place in the order)
    bits = values.view(np.int64)
    keys = np.where(bits >= 0, bits, -(bits & np.int64(0x7FFFFFFFFFFFFFFF)))   # (float order)
    middle = [_kth(comm, keys, values, k) for k in sorted({(n - 1) // 2, n // 2})]
    return float(np.mean(middle))


def _kth(comm, keys: np.ndarray, values: np.ndarray, k: int) -> float:
    """The k-th smallest (from 0) of every rank's values, ``keys`` their order: the least key
    with more than k keys at or below it, by bisection. Collective."""
    lo, hi = -(2 ** 63) + 1, 2 ** 63 - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if comm.allreduce(int(np.count_nonzero(keys <= mid))) > k:
            hi = mid
        else:
            lo = mid + 1
    here = values[keys == lo]
    return comm.allreduce(float(here[0]) if here.size else -np.inf, op=MPI.MAX)
