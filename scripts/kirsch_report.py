"""Stress concentration of a Kirsch result file, against Kirsch's 3 (infinite plate)."""

import sys

import h5py
import numpy as np


def concentration(path: str) -> float:
    with h5py.File(path, "r") as f:
        pts = f["mesh/points"][()]
        sxx = f["fields/stress"][-1][:, 0]
    top = np.argmin(np.hypot(pts[:, 0], pts[:, 1] - 1.0))  # the node at (0, a)
    return float(sxx[top])


if __name__ == "__main__":
    k = concentration(sys.argv[1])
    print(f"Kirsch: stress concentration sigma_xx(0, a) / sigma = {k:.4f} "
          f"(Kirsch, infinite plate: 3; this finite 40 x 40 plate, converged: about 3.02)")
