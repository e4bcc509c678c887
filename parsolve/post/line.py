"""Profiles along a segment: ``parsolve post RESULT.h5 --line X0,Y0 X1,Y1 N --y SPEC ...``.

N points evenly spaced from P0 to P1 (both included). A nodal field is interpolated with the
mesh's own shape functions in the cell that contains the point (exact for a field the
elements represent: linear on P1/Q1 cells, quadratic on P2 ones); a cell field takes the
value of that cell. A point outside the mesh (a hole, past the boundary) gives NaN; a segment
with no point in the mesh is an error.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from parsolve.errors import InputError
from parsolve.fem.elements import element
from parsolve.post.locate import locate
from parsolve.post.result import Result

MAX_POINTS = 100000


def parse_line(words: list[str], source: str) -> tuple[np.ndarray, np.ndarray, int]:
    """(P0, P1, N) of ``--line X0,Y0[,Z0] X1,Y1[,Z1] N``."""
    def point(text: str) -> np.ndarray:
        try:
            x = np.array([float(v) for v in text.split(",")])
        except ValueError:
            raise InputError(f"point {text!r} is not numbers (x,y[,z])", source, "--line") from None
        if not 2 <= len(x) <= 3 or not np.isfinite(x).all():
            raise InputError(f"point {text!r} is not 2 or 3 finite numbers", source, "--line")
        return x

    p0, p1 = point(words[0]), point(words[1])
    if len(p0) != len(p1):
        raise InputError("P0 and P1 have different numbers of coordinates", source, "--line")
    if not words[2].isdigit() or not 2 <= int(words[2]) <= MAX_POINTS:
        raise InputError(f"N = {words[2]!r}: the number of points is an integer from 2 to "
                         f"{MAX_POINTS}", source, "--line")
    return p0, p1, int(words[2])


def parse_field(text: str, source: str) -> tuple[str, str, str]:
    """(group, name, component) of a --y of a line: field:<name>[:<comp>] or
    cell_field:<name>[:<comp>] (no point: the line gives them)."""
    parts = text.split(":")
    if parts[0] not in ("field", "cell_field") or len(parts) not in (2, 3) or "@" in text:
        raise InputError("invalid spec: with --line, --y is field:<name>[:<comp>] or "
                         "cell_field:<name>[:<comp>]", source, text)
    return parts[0] + "s", parts[1], parts[2] if len(parts) == 3 else "0"


def places(res: Result, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cell (n,), shape function values (n, nen)) of each point; cell -1 outside the mesh."""
    cells = np.full(len(xs), -1)
    N = np.zeros((len(xs), res.cells.shape[1]))
    ref = element(res.cell_type)
    # the cells whose boxes meet the segment's box, once: each point searches only those
    coords = res.points[res.cells]
    slack = 1e-9 * np.ptp(res.points, axis=0).max() + 1e-14
    near = np.flatnonzero((coords.min(axis=1) - slack <= xs.max(axis=0)).all(axis=1)
                          & (coords.max(axis=1) + slack >= xs.min(axis=0)).all(axis=1))
    for i, x in enumerate(xs):   # (sample points, not mesh entities: each search is vectorised)
        found = locate(res.points, res.cells[near], res.cell_type, x)
        if found is not None:
            cells[i], N[i] = near[found[0]], ref.shape(found[1][None, :])[0]
    return cells, N


def sample(res: Result, p0: np.ndarray, p1: np.ndarray, n: int, specs: list[str],
           steps: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """(s (n,), points (n, dim), per spec values (nsteps, n)) along P0→P1 at the steps."""
    if len(p0) != res.dim:
        raise InputError(f"the line's points need {res.dim} coordinates", res.path, "--line")
    s = np.linspace(0.0, 1.0, n)
    xs = p0[None, :] + s[:, None] * (p1 - p0)[None, :]
    cells, N = places(res, xs)
    inside = cells >= 0
    if not inside.any():
        raise InputError(f"the line from {tuple(p0)} to {tuple(p1)} is outside the mesh",
                         res.path, "--line")
    out = []
    for text in specs:
        group, name, comp = parse_field(text, res.path)
        if name not in res.names(group):
            known = ", ".join(res.names(group)) or "none"
            raise InputError(f"no {group[:-1].replace('_', ' ')} {name!r} (known: {known})",
                             res.path, text)
        data = res.file[f"{group}/{name}"]
        c = res.component(data.shape[2], comp, text)
        values = np.full((len(steps), n), np.nan)
        for k, step in enumerate(steps):
            col = data[step, :, c]
            if group == "fields":
                values[k, inside] = np.einsum("pa,pa->p", N[inside], col[res.cells[cells[inside]]])
            else:
                values[k, inside] = col[cells[inside]]
        out.append(values)
    return s * np.linalg.norm(p1 - p0), xs, out


def steps_of(res: Result, text: str | None) -> np.ndarray:
    """Step indices (0-based) of ``--step``: a number 1..n, "last" (default) or "all"."""
    n = len(res.times)
    if n == 0:
        raise InputError("the file has no finished step", res.path, "--step")
    if text in (None, "last"):
        return np.array([n - 1])
    if text == "all":
        return np.arange(n)
    if text.isdigit() and 1 <= int(text) <= n:
        return np.array([int(text) - 1])
    raise InputError(f"--step {text!r}: a step 1..{n}, last or all", res.path, "--step")


def write_csv(path: str, rows: list[dict]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def table(res: Result, s, xs, values, specs, steps) -> list[dict]:
    """One row per (step, point): file, step, time, s, x, y[, z], then each spec."""
    axes = "xyz"[:res.dim]
    rows = []
    for k, step in enumerate(steps):
        for i in range(len(s)):
            row = {"file": res.stem, "step": int(step) + 1, "time": repr(float(res.times[step])),
                   "s": repr(float(s[i]))}
            row.update({a: repr(float(xs[i, j])) for j, a in enumerate(axes)})
            row.update({spec: repr(float(v[k, i])) for spec, v in zip(specs, values)})
            rows.append(row)
    return rows


def write_png(path: str, profiles: list[tuple[str, np.ndarray, np.ndarray]], ylabel: str) -> None:
    """One line per (file, step, spec): value against the distance s from P0."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for label, s, v in profiles:
        ax.plot(s, v, marker="o", ms=2, label=label)
    ax.set_xlabel("distance from P0")
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(Path(path), dpi=120)
    plt.close(fig)
