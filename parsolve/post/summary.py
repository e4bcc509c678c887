"""``parsolve post RESULT.h5 --summary``: what an engineer reads first."""

from __future__ import annotations

import numpy as np

from parsolve.post.result import COMPONENTS, Result


def _fmt(v: float) -> str:
    return f"{v:.6g}"


def _extremes(res: Result, group: str) -> list[str]:
    lines = []
    for name in res.names(group):
        values = res.file[f"{group}/{name}"][-1]                    # last step (nrows, ncomp)
        names = COMPONENTS.get((res.dim, values.shape[1]), ())
        if name == "principal_stress" or not names:
            names = tuple(str(k + 1) for k in range(values.shape[1]))
        parts = []
        for c, comp in enumerate(names):
            col = values[:, c].astype(float)
            if not np.isfinite(col).any():
                continue
            i = int(np.nanargmax(np.abs(col)))
            where = "node" if group == "fields" else "cell"
            parts.append(f"{comp} {_fmt(col[i])} ({where} {i})")
        lines.append(f"  {group}/{name}: max |value| " + ", ".join(parts))
    return lines


def _relations(res: Result) -> list[str]:
    lines = []
    for name in res.names("relations"):
        g = res.file[f"relations/{name}"]
        lam = g["multiplier"][-1] if len(g["multiplier"]) else np.zeros(0)
        rows = lam.size
        head = ", ".join(_fmt(v) for v in lam[:3]) + (", ..." if rows > 3 else "")
        line = f"  {name}: {rows} rows, multiplier [{head}] |λ|₂ {_fmt(np.linalg.norm(lam))}"
        if "resultant" in g and len(g["resultant"]):
            line += ", resultant [" + ", ".join(_fmt(v) for v in g["resultant"][-1]) + "]"
        elif rows:
            line += f", Σλ {_fmt(lam.sum())} (no resultant dataset)"
        if "active" in g and len(g["active"]):
            line += f", active {int(g['active'][-1].sum())}/{rows}"
        lines.append(line)
    return lines


def summary(res: Result) -> str:
    a = res.attrs
    t = res.times
    lines = [f"{res.path}: status {a.get('status', '?')!s}, {len(t)} steps"
             + (f" (t = {_fmt(t[0])} … {_fmt(t[-1])})" if len(t) else ""),
             f"  parsolve {a.get('parsolve_version', '?')}, PETSc {a.get('petsc_version', '?')}, "
             f"{a.get('nprocs', '?')} ranks; mesh {len(res.points)} nodes, {len(res.cells)} "
             f"{res.cell_type} cells"]
    if "steps/iterations" in res.file and len(t):
        lines.append(f"  iterations: {int(res.file['steps/iterations'][()].sum())} in total, "
                     f"last residual {_fmt(res.file['steps/residual'][-1])}")
    if not len(t):
        return "\n".join(lines)
    lines.append("fields at the last step:")
    lines += _extremes(res, "fields") + _extremes(res, "cell_fields")
    if res.names("relations"):
        lines.append("relations at the last step:")
        lines += _relations(res)
    if res.names("timings"):
        lines.append("timings (s, all steps): " + ", ".join(
            f"{n} {res.file['timings/' + n][()].sum():.3f}" for n in res.names("timings")))
    return "\n".join(lines)
