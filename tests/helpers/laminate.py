"""The two-layer laminate cell of configs/periodic_shear_laminate.toml in simple shear:
its exact field (tests/test_configs.py, tests/effects/test_periodic.py)."""

import numpy as np

U, H1, G1, G2 = 0.01, 0.5, 1000.0 / 2.5, 250.0 / 2.5   # G = E / (2 (1 + ν)), ν = 0.25


TAU = U / (H1 / G1 + (1.0 - H1) / G2)


def laminate_ux(y: np.ndarray) -> np.ndarray:
    return np.where(y <= H1, TAU * y / G1, TAU * H1 / G1 + TAU * (y - H1) / G2)


def check_laminate(res: dict) -> None:
    """Exact laminate field; the tie carries the shear force of each side node (τ h, h =
    1/8 its tributary length) and nothing along x; its resultant is the couple of the pairs' forces."""
    y = res["mesh/points"][:, 1]
    u = res["fields/displacement"][-1]
    np.testing.assert_allclose(u[:, 0], laminate_ux(y), rtol=0, atol=1e-14)
    np.testing.assert_allclose(u[:, 1], 0.0, atol=1e-14)
    lam = res["relations/cell/multiplier"][-1].reshape(-1, 2)   # node-major: (x, y) per pair
    assert lam.shape == (7, 2)
    np.testing.assert_allclose(lam[:, 1], TAU / 8, rtol=1e-12)
    np.testing.assert_allclose(lam[:, 0], 0.0, atol=1e-12 * TAU)
    # equal and opposite forces: no resultant force, the couple of 7 pairs one unit apart
    resultant = res["relations/cell/resultant"][-1]
    np.testing.assert_allclose(resultant[:2], 0.0, atol=1e-12 * TAU)
    np.testing.assert_allclose(resultant[2], 7 * TAU / 8 * 1.0, rtol=1e-12)
