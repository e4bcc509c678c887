"""A term's products checked against its assembled operator (tests of cell and facet terms)."""

from __future__ import annotations

import numpy as np

from parsolve.effects.compose import Composition


def check_products(whole, effect, expected: np.ndarray, stiffness: float) -> None:
    """On a one-rank model ``whole`` with ``effect`` added, the effect's products (the
    composition's product of its linear values, and its default ``evaluate``) are
    ``expected @ q`` for a random q; ``stiffness``: the term's scale (for the tolerance)."""
    whole.effects.append(effect)
    comp = Composition(whole, np.arange(whole.mesh.num_cells))
    q = np.random.default_rng(5).normal(size=whole.mesh.num_points * 2)
    product = comp.product(effect.linear_values(comp.cells), q)
    np.testing.assert_allclose(product, expected @ q, rtol=1e-13,
                               atol=1e-13 * np.abs(q).max() * stiffness)
    forces = np.zeros_like(q)
    comp._scatter(effect.evaluate(comp.cells, comp.values(q), None, False, comp.now)[0], forces)
    np.testing.assert_allclose(forces, product, rtol=1e-14, atol=1e-14)
