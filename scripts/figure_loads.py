"""The guide's figure of section 10 (Loads): the shipped thick cylinder under internal pressure
(curved six-node triangles) and the shipped fin cooled by convection, each against its closed
form. Runs both scenes on one rank and writes docs/img/loads.png:

    .venv/bin/python scripts/figure_loads.py [OUT.png]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def run(name: str, out: Path) -> Path:
    from parsolve.cli import main

    result = out / f"{Path(name).stem}.h5"
    if main(["run", str(ROOT / "configs" / name), "-o", str(result)]) != 0:
        raise SystemExit(f"{name} failed")
    return result


def main(path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8))
    with tempfile.TemporaryDirectory() as tmp:
        with h5py.File(run("thick_cylinder_pressure.toml", Path(tmp))) as f:
            pts, u = f["mesh/points"][:], f["fields/displacement"][-1]
        with h5py.File(run("fin_convection.toml", Path(tmp))) as f:
            x, temp = f["mesh/points"][:, 0], f["fields/T"][-1][:, 0]
    r = np.hypot(pts[:, 0], pts[:, 1])
    ur = np.einsum("ni,ni->n", u, pts / r[:, None])
    c = 10.0 / 3.0
    rr = np.linspace(1.0, 2.0, 200)
    left.plot(rr, 1.3 / 210e3 * (0.4 * c * rr + 4 * c / rr), "k-", label="Lamé")
    left.plot(r, ur, "o", ms=3, label="parsolve (pressure, curved P2)")
    left.set(xlabel="r", ylabel="u_r", title="thick cylinder, p = 10 on the bore")
    m = np.sqrt(2.0)
    xx = np.linspace(0.0, 1.0, 200)
    right.plot(xx, 20 + 80 * np.cosh(m * (1 - xx)) / np.cosh(m), "k-", label="cosh closed form")
    right.plot(x, temp, "o", ms=3, label="parsolve ([[exchange]])")
    right.set(xlabel="x", ylabel="T", title="fin cooled by convection, T∞ = 20")
    for ax in (left, right):
        ax.legend()
        ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    print(path)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "img" / "loads.png")
