"""The Pareto front of (cost, error) points and the cheapest point reaching a target error."""

from __future__ import annotations

import numpy as np


def pareto_front(cost, err) -> np.ndarray:
    """Indices of the non-dominated points (no other point is at least as cheap and at least as
    accurate, and strictly better in one), sorted by cost."""
    cost, err = np.asarray(cost, float), np.asarray(err, float)
    ok = np.flatnonzero(np.isfinite(cost) & np.isfinite(err))
    order = ok[np.lexsort((err[ok], cost[ok]))]                 # by cost, then by error
    best = np.minimum.accumulate(err[order])
    keep = np.r_[True, best[1:] < best[:-1]]                    # strictly improves the error
    return order[keep]


def cheapest(cost, err, target: float) -> int | None:
    """Index of the cheapest point with error ≤ target, or None."""
    cost, err = np.asarray(cost, float), np.asarray(err, float)
    ok = np.flatnonzero(np.isfinite(cost) & (err <= target))
    return int(ok[np.argmin(cost[ok])]) if ok.size else None
