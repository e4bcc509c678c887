"""Curves y(x) from one or several result files: CSV and PNG (matplotlib, Agg)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np


def write_csv(path: str, xspec: str, yspec: str, curves: list[tuple[str, np.ndarray, np.ndarray]]) -> None:
    """One row per (file, step): file, step, x, y."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["file", "step", xspec, yspec])
        for label, x, y in curves:
            for k, (a, b) in enumerate(zip(x, y)):
                w.writerow([label, k + 1, repr(float(a)), repr(float(b))])


def write_png(path: str, xspec: str, yspec: str, curves: list[tuple[str, np.ndarray, np.ndarray]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for label, x, y in curves:
        ax.plot(x, y, marker="o", ms=3, label=label)
    ax.set_xlabel(xspec)
    ax.set_ylabel(yspec)
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(Path(path), dpi=120)
    plt.close(fig)
