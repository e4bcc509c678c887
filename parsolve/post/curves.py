"""Curves y(x) from one or several result files: CSV and PNG (matplotlib, Agg)."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np


def check_output(path: str | None, key: str, inputs: list[str]) -> None:
    """An output file (--csv, --png, --derive and the XDMF beside it) can be written: no
    input, not a folder, in an existing writable folder. Checked before anything is computed
    or written."""
    from parsolve.errors import InputError

    if path is None:
        return
    out = Path(path)
    targets = [out, out.with_suffix(".xdmf")] if key == "--derive" else [out]
    for target in targets:
        if any(target.resolve() == Path(i).resolve() for i in inputs):
            what = "writes a copy" if key == "--derive" else f"would overwrite {target}"
            raise InputError(f"{key} {what}: the input is never overwritten", path, key)
        if target.is_dir():
            raise InputError(f"{target} is a folder, not a file", path, key)
    parent = out.parent if str(out.parent) else Path(".")
    if parent.exists() and not parent.is_dir():
        raise InputError(f"{parent} is a file, not a folder", path, key)
    if not parent.exists():
        raise InputError(f"folder {parent} does not exist", path, key)
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"folder {parent} is read-only", path, key)


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
