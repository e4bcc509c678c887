"""Errors against a reference, observed orders, Richardson extrapolation.

The mesh size of a run is measured by its DOFs: h ∝ DOFs^(-1/d) (d the space dimension), so
that orders are comparable across refinement keys, element types and mesh files. The observed
order between two runs is p = log(e1/e2) / log(h1/h2).
"""

from __future__ import annotations

import math

import numpy as np


def error(value: float, reference: float, kind: str) -> float:
    """relative |q - q*| / |q*|; absolute |q - q*|; energy_norm sqrt(|q - q*| / |q*|), the
    relative energy-norm error when q is the strain energy of a load-driven linear problem
    (Π(u) - Π(u_h) = ½ ‖u - u_h‖²_E), which converges like h^p for P_p elements."""
    diff = abs(value - reference)
    if kind == "absolute":
        return diff
    rel = diff / abs(reference) if reference != 0 else math.inf
    return math.sqrt(rel) if kind == "energy_norm" else rel


def mesh_size(dofs, dim: int) -> np.ndarray:
    return np.asarray(dofs, dtype=float) ** (-1.0 / dim)


def observed_orders(errors, dofs, dim: int) -> list[float | None]:
    """Order between each run and the previous (coarser) one; None for the first run and where
    an error is zero or not finite."""
    h = mesh_size(dofs, dim)
    out: list[float | None] = [None]
    for k in range(1, len(errors)):
        e0, e1 = errors[k - 1], errors[k]
        ok = all(np.isfinite(v) and v > 0 for v in (e0, e1)) and h[k - 1] != h[k]
        out.append(math.log(e0 / e1) / math.log(h[k - 1] / h[k]) if ok else None)
    return out


def richardson(values, dofs, dim: int, order: float | None = None) -> tuple[float, float | None]:
    """Extrapolated value and the observed order from the three finest runs (q1, q2, q3, coarse
    to fine; for equal ratios r = h1/h2 = h2/h3: p = log((q1 - q2)/(q2 - q3)) / log r). With two
    runs, or when the differences change sign (not yet asymptotic), ``order`` must be given
    (else the finest value is returned with order None)."""
    q = np.asarray(values, dtype=float)
    h = mesh_size(dofs, dim)
    if len(q) >= 3:
        q1, q2, q3 = q[-3:]
        h1, h2, h3 = h[-3:]
        d1, d2 = q1 - q2, q2 - q3
        if d1 * d2 > 0 and abs(d2) < abs(d1):
            p = _order_unequal(d1, d2, h1 / h2, h2 / h3)
            return float(q3 - d2 / ((h2 / h3) ** p - 1.0)), float(p)
    if order is not None and len(q) >= 2:
        r = h[-2] / h[-1]
        return float(q[-1] + (q[-1] - q[-2]) / (r ** order - 1.0)), None
    return float(q[-1]), None


def _order_unequal(d1: float, d2: float, r1: float, r2: float) -> float:
    """Solve d1/d2 = r2^p (r1^p - 1)/(r2^p - 1) for p (equal ratios: log(d1/d2)/log r) by a
    fixed-point iteration that starts from the equal-ratio value."""
    p = math.log(d1 / d2) / math.log(math.sqrt(r1 * r2))
    for _ in range(50):
        new = math.log(d1 / d2 * (r2 ** p - 1.0) / (r1 ** p - 1.0)) / math.log(r2)
        if abs(new - p) < 1e-12:
            break
        p = new
    return p
