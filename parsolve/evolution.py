"""Evolutions: how a load or a relation value follows the load parameter t."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Evolution:
    """Piecewise-linear factor f(t) through the points (times, values); constant beyond them."""

    name: str
    times: tuple[float, ...]
    values: tuple[float, ...]

    def __call__(self, t: float) -> float:
        return float(np.interp(t, self.times, self.values))

    def constant_over(self, a: float, b: float) -> bool:
        """Whether f is the same at every t in [a, b]: piecewise linear, it is when f(a),
        f(b) and f at every point of the evolution between them are equal."""
        inside = [t for t in self.times if a < t < b]
        return all(self(t) == self(a) for t in [b, *inside])


RAMP = Evolution("ramp", (0.0, 1.0), (0.0, 1.0))
CONSTANT = Evolution("constant", (0.0, 1.0), (1.0, 1.0))


def ramp_through(t_end: float) -> Evolution:
    """f(t) = t for any t >= 0 (the ramp extended to the last load step)."""
    t_end = max(float(t_end), 1.0)
    return Evolution("ramp", (0.0, t_end), (0.0, t_end))
