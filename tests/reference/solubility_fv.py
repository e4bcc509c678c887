"""Independent reference for gas solubility: a 1D finite-volume enthalpy-type solver (numpy only).

One unknown per control volume, the total concentration m = c_s + c_g, with the equilibrium

    c_s = min(m, c_sat),   c_g = max(0, m − c_sat),

and the balance of the total over each control volume V_i, implicit Euler:

    V_i (m_i − m_i⁰) + Δt Σ_faces (two-point fluxes of c_s with D_s, of c_g with D_g)
        = Δt (V_i S_i + boundary inflow),

solved by a semi-smooth Newton iteration on m (the generalised Jacobian of min/max is 0 or 1
per node) with a vectorised tridiagonal solve (parallel cyclic reduction). The Jacobian
V + Δt (A_s D + A_g (I − D)) is a column diagonally dominant Z-matrix, so the solve needs no
pivoting and the iteration stops when the saturated set repeats and the residual is at
round-off (finite termination of a piecewise-linear monotone system).

Two grids on [0, L]:
* ``"cell"``: N cells of width h, unknowns at the centres; Dirichlet data at a wall through a
  half-cell distance.
* ``"vertex"``: N + 1 nodes x_i = i h, control volumes of width h (h/2 at the ends); a
  Dirichlet node is fixed (c_s = c_b, c_g = 0, needs c_b < c_sat). On a uniform grid this is
  exactly the P1/Q1 finite-element scheme with lumped mass on a 1-cell-thick strip, with a
  source constant per element (evaluated at the element midpoints).

Boundary conditions act on the dissolved phase: ``("flux", q)`` an inflow per unit area
(q may be a function of t; 0 is a closed wall), or ``("dirichlet", c_b)``. The source S(t, x)
is a volume source of the total (which phase receives it does not matter at equilibrium).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

Boundary = tuple[str, float | Callable[[float], float]]


@dataclass
class Problem1D:
    length: float
    n: int                                     # cells (cell grid) or intervals (vertex grid)
    D_s: float
    c_sat: float | Callable[[np.ndarray], np.ndarray]
    source: Callable[[float, np.ndarray], np.ndarray] = lambda t, x: np.zeros_like(x)
    left: Boundary = ("flux", 0.0)
    right: Boundary = ("flux", 0.0)
    D_g: float = 0.0
    m0: float | Callable[[np.ndarray], np.ndarray] = 0.0
    grid: str = "cell"
    tol: float = 1e-13
    max_iter: int = 100


def tridiag_solve(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Solve a_i x_{i−1} + b_i x_i + c_i x_{i+1} = d_i by parallel cyclic reduction
    (log2 n vectorised sweeps; a_0 and c_{n−1} are ignored). Stable for diagonally
    dominant systems."""
    a, b, c, d = (np.asarray(v, dtype=float).copy() for v in (a, b, c, d))
    n = len(b)
    a[0], c[-1] = 0.0, 0.0
    s = 1
    while s < n:
        def shift(v, k, fill):  # v[i + k], with fill outside
            out = np.full(n, fill)
            if k > 0:
                out[:n - k] = v[k:]
            else:
                out[-k:] = v[:n + k]
            return out
        bm, bp = shift(b, -s, 1.0), shift(b, s, 1.0)
        alpha, gamma = -a / bm, -c / bp
        a_new = alpha * shift(a, -s, 0.0)
        c_new = gamma * shift(c, s, 0.0)
        b = b + alpha * shift(c, -s, 0.0) + gamma * shift(a, s, 0.0)
        d = d + alpha * shift(d, -s, 0.0) + gamma * shift(d, s, 0.0)
        a, c = a_new, c_new
        s *= 2
    return d / b


class Grid:
    """Control volumes, face transmissibilities and boundary couplings of a 1D grid."""

    def __init__(self, p: Problem1D):
        h = p.length / p.n
        self.h = h
        if p.grid == "cell":
            self.x = (np.arange(p.n) + 0.5) * h
            self.V = np.full(p.n, h)
            self.wall = h / 2                 # distance centre → wall for Dirichlet data
        elif p.grid == "vertex":
            self.x = np.arange(p.n + 1) * h
            self.V = np.full(p.n + 1, h)
            self.V[[0, -1]] = h / 2
        else:
            raise ValueError(f"grid must be 'cell' or 'vertex', got {p.grid!r}")
        self.grid = p.grid
        self.mid = (np.arange(p.n) + 0.5) * h  # element / cell midpoints (where S is sampled)

    def source(self, p: Problem1D, t: float) -> np.ndarray:
        """∫ S over each control volume, S constant on each element [x_j, x_j+1]."""
        s = np.asarray(p.source(t, self.mid), dtype=float) * np.ones(len(self.mid))
        if self.grid == "cell":
            return s * self.h
        out = np.zeros(len(self.V))
        out[:-1] += s * self.h / 2
        out[1:] += s * self.h / 2
        return out


def _value(v, t: float) -> float:
    return float(v(t)) if callable(v) else float(v)


def _operator(n: int, T: float, grid: Grid, bcs: list, D: float):
    """Tridiagonal −div operator (lower, diag, upper) for one phase with transmissibility T,
    plus the Dirichlet wall couplings of the cell grid (diag += 2D/h, rhs += 2D/h c_b)."""
    lower, upper = np.full(n, -T), np.full(n, -T)
    diag = np.full(n, 2 * T)
    diag[0] -= T
    diag[-1] -= T
    wall = np.zeros(n)
    if grid.grid == "cell":
        for i, (kind, _) in zip((0, -1), bcs):
            if kind == "dirichlet":
                wall[i] = D / grid.wall
    return lower, diag + wall, upper, wall


def _apply(lower, diag, upper, v):
    out = diag * v
    out[1:] += lower[1:] * v[:-1]
    out[:-1] += upper[:-1] * v[1:]
    return out


def run(p: Problem1D, times: np.ndarray) -> dict:
    """March through ``times`` (times[0] is the initial time). Returns per step (rows):
    ``c_s``, ``c_g``, ``mass`` (Σ V m), ``source_in`` and ``boundary_in`` (this step's
    Δt × rates), ``balance_error`` (relative), ``iterations``, ``saturated`` (count), and ``x``."""
    g = Grid(p)
    n = len(g.V)
    csat = np.asarray(p.c_sat(g.x) if callable(p.c_sat) else np.full(n, float(p.c_sat)))
    m = np.asarray(p.m0(g.x) if callable(p.m0) else np.full(n, float(p.m0)), dtype=float)
    bcs = [p.left, p.right]
    fixed = np.zeros(n, bool)
    if g.grid == "vertex":
        for i, (kind, val) in zip((0, -1), bcs):
            if kind == "dirichlet":
                fixed[i] = True
    As = _operator(n, p.D_s / g.h, g, bcs, p.D_s)
    Ag = _operator(n, p.D_g / g.h, g, [("flux", 0.0), ("flux", 0.0)], p.D_g)
    out = {k: [] for k in ("c_s", "c_g", "mass", "source_in", "boundary_in", "iterations",
                           "saturated")}

    def record(m, src, bnd, its):
        cs = np.minimum(m, csat)
        out["c_s"].append(cs)
        out["c_g"].append(m - cs)
        out["mass"].append(float(g.V @ m))
        out["source_in"].append(src)
        out["boundary_in"].append(bnd)
        out["iterations"].append(its)
        out["saturated"].append(int((m > csat).sum()))

    record(m, 0.0, 0.0, 0)
    for t_old, t in zip(times[:-1], times[1:]):
        dt = t - t_old
        S = g.source(p, t)
        rhs = g.V * m + dt * S
        for i, (kind, val) in zip((0, -1), bcs):
            if kind == "flux":
                rhs[i] += dt * _value(val, t)
            elif g.grid == "cell":
                rhs[i] += dt * As[3][i] * _value(val, t)
        m_new = m.copy()
        for i, (kind, val) in zip((0, -1), bcs):
            if fixed[i]:
                m_new[i] = _value(val, t)
        m_new, its = _newton(p, g, As, Ag, csat, rhs, m_new, fixed, dt)
        # boundary inflow this step: Dirichlet reactions (vertex) or wall fluxes (cell), + fluxes
        residual = g.V * m_new + dt * (_apply(*As[:3], np.minimum(m_new, csat))
                                       + _apply(*Ag[:3], np.maximum(m_new - csat, 0.0))) - rhs
        bnd = 0.0
        for i, (kind, val) in zip((0, -1), bcs):
            if kind == "flux":
                bnd += dt * _value(val, t)
            elif g.grid == "cell":
                bnd += dt * As[3][i] * (_value(val, t) - min(m_new[i], csat[i]))
            else:
                bnd += residual[i]
        m = m_new
        record(m, dt * S.sum(), bnd, its)
    res = {k: np.array(v) for k, v in out.items()}
    change = np.diff(res["mass"])
    scale = max(np.abs(res["mass"]).max(), 1e-300)
    res["balance_error"] = np.concatenate(
        [[0.0], np.abs(change - res["source_in"][1:] - res["boundary_in"][1:]) / scale])
    res["x"], res["V"], res["c_sat"] = g.x, g.V, csat
    return res


def _newton(p, g, As, Ag, csat, rhs, m, fixed, dt) -> tuple[np.ndarray, int]:
    """Semi-smooth Newton on F(m) = V m + Δt (A_s min(m, c_sat) + A_g max(m − c_sat, 0)) − rhs
    over the free nodes (fixed nodes keep their value)."""
    previous = None
    for it in range(p.max_iter + 1):
        below = m <= csat                                   # φ_s' = 1, φ_g' = 0
        cs, cg = np.minimum(m, csat), np.maximum(m - csat, 0.0)
        F = g.V * m + dt * (_apply(*As[:3], cs) + _apply(*Ag[:3], cg)) - rhs
        F[fixed] = 0.0
        # F is piecewise linear: once the phases of the new iterate are those its linear solve
        # assumed, it solves the system exactly (up to round-off, checked)
        scale = np.abs(g.V * m).max() + np.abs(rhs).max() \
            + dt * (np.abs(As[1]).max() * np.abs(cs).max() + np.abs(Ag[1]).max() * np.abs(cg).max())
        if np.abs(F).max() <= 0.1 * p.tol * scale:   # also ends a tie m ≈ c_sat flipping
            return m, it
        if previous is not None and np.array_equal(below, previous):
            if np.abs(F).max() > p.tol * scale:
                raise RuntimeError(f"residual {np.abs(F).max():.3e} above round-off")
            return m, it
        previous = below
        ds, dg = below.astype(float), (~below).astype(float)
        # J_ij = V_i δ_ij + Δt (A_s,ij ds_j + A_g,ij dg_j): column j scaled by the phase of node j
        lower = dt * (As[0] * np.roll(ds, 1) + Ag[0] * np.roll(dg, 1))
        upper = dt * (As[2] * np.roll(ds, -1) + Ag[2] * np.roll(dg, -1))
        diag = g.V + dt * (As[1] * ds + Ag[1] * dg)
        # fixed nodes: identity rows, and no coupling from them (their update is zero)
        lower[fixed], upper[fixed], diag[fixed] = 0.0, 0.0, 1.0
        lower[1:][fixed[:-1]] = 0.0
        upper[:-1][fixed[1:]] = 0.0
        m = m - tridiag_solve(lower, diag, upper, F)
    raise RuntimeError(f"semi-smooth Newton did not converge in {p.max_iter} iterations")


def well_mixed(m0: float, c_sat: float, times: np.ndarray, rate: Callable[[float], float]) -> dict:
    """Exact implicit-Euler history of a uniform domain under a uniform source (no flux out):
    m_{n+1} = m_n + Δt S(t_{n+1}), c_s = min(m, c_sat), c_g = max(0, m − c_sat)."""
    m = m0 + np.concatenate([[0.0], np.cumsum(np.diff(times) * np.array([rate(t) for t in times[1:]]))])
    return {"m": m, "c_s": np.minimum(m, c_sat), "c_g": np.maximum(m - c_sat, 0.0)}


# The shipped 1D scene "a saturated zone grows, then shrinks": [0, 1], closed at x = 0, drained
# at x = 1 (c_s = 0), source 4 per unit volume and time on x < 1/4 while t <= 1/2, then none.
# The zone appears at t ≈ 0.3, reaches x ≈ 0.16 at t = 1/2 and is gone by t ≈ 1.3.
GROW_SHRINK = {"length": 1.0, "D_s": 0.1, "c_sat": 1.0, "source": 4.0, "source_until": 0.5,
               "source_region": 0.25, "t_end": 2.0, "steps": 100}


def grow_shrink_source(t: float, x: np.ndarray) -> np.ndarray:
    """The scene's source at time t (step end) and abscissae x (element midpoints)."""
    p = GROW_SHRINK
    on = t <= p["source_until"] + 1e-12
    return np.where((np.asarray(x) < p["source_region"]) & on, p["source"], 0.0)


def grow_shrink_problem(n: int, grid: str = "cell", D_g: float = 0.0) -> Problem1D:
    """The shipped scene on n cells / intervals (n a multiple of 4 aligns the source edge)."""
    p = GROW_SHRINK
    return Problem1D(length=p["length"], n=n, D_s=p["D_s"], D_g=D_g, c_sat=p["c_sat"],
                     source=grow_shrink_source, left=("flux", 0.0), right=("dirichlet", 0.0),
                     grid=grid)


def grow_shrink_times() -> np.ndarray:
    return np.linspace(0.0, GROW_SHRINK["t_end"], GROW_SHRINK["steps"] + 1)


@lru_cache(maxsize=1)
def fine_grow_shrink() -> dict:
    """The scene on 1280 cells (cell grid): the converged answer tests compare with (~2 s,
    computed once per process)."""
    return run(grow_shrink_problem(1280, "cell"), grow_shrink_times())
