"""Curves y(x) from one or several result files: CSV and PNG (matplotlib, Agg)."""

from __future__ import annotations

import csv
import os
from collections.abc import Callable
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


def write_whole(path: str, key: str, write: Callable[[str], None]) -> None:
    """``write(name)`` whole or not at all (parsolve.io.whole): a failure (a full disk) leaves
    nothing, and is an InputError naming the output and its option."""
    from parsolve.errors import InputError
    from parsolve.io import whole

    try:
        whole.write_whole(path, write)
    except OSError as exc:
        raise InputError(f"cannot write ({exc.strerror}): nothing written", path, key) from None


Curve = tuple[str, np.ndarray, list[np.ndarray], np.ndarray]   # label, x, ys, step numbers


def with_rest(res, x: np.ndarray, ys: list[np.ndarray]) -> Curve:
    """The file's curve (label, x, [y per spec], step numbers), led by the unloaded state
    (step 0: every spec is 0 there, time and step included) when the scene starts from rest
    (``scene_model.starts_from_rest``) and its first saved step is after t = 0."""
    from parsolve.post.scene_model import starts_from_rest

    steps = np.arange(1, len(x) + 1)
    if len(res.times) and res.times[0] > 0 and starts_from_rest(res):
        x = np.concatenate([[0.0], x])
        ys = [np.concatenate([[0.0], y]) for y in ys]
        steps = np.concatenate([[0], steps])
    return res.stem, x, ys, steps


def write_csv(path: str, xspec: str, yspecs: list[str], curves: list[Curve]) -> None:
    """One row per (file, step): file, step (0: the unloaded state), x, then each y."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["file", "step", xspec] + list(yspecs))
        for label, x, ys, steps in curves:
            for k in range(len(x)):
                w.writerow([label, int(steps[k]), repr(float(x[k]))] + [repr(float(y[k])) for y in ys])


def write_png(path: str, xspec: str, yspecs: list[str], curves: list[Curve]) -> None:
    """One line per (file, y); the y axis is named by the spec when there is one."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for label, x, ys, _ in curves:
        for spec, y in zip(yspecs, ys):
            ax.plot(x, y, marker="o", ms=3, label=label if len(yspecs) == 1 else f"{label}: {spec}")
    ax.set_xlabel(xspec)
    ax.set_ylabel(yspecs[0] if len(yspecs) == 1 else "value")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(Path(path), dpi=120)
    plt.close(fig)
