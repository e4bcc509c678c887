"""``parsolve post RESULT.h5 --summary``: what an engineer reads first."""

from __future__ import annotations

import numpy as np

from parsolve.post.result import COMPONENTS, Result


def _fmt(v: float) -> str:
    return f"{v:.6g}"


def _at(x: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in x) + ")"


def _extremes(res: Result, group: str) -> list[str]:
    """Per field and component, the largest |value| of the last step, where: the node's
    coordinates (a cell: its centroid's) and its number (0-based, in the file's order, which
    is the input mesh's; nodes an order elevation added come after the input's)."""
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
            if group == "fields":
                where = f"at {_at(res.points[i])}, node {i}"
            else:
                where = f"at {_at(res.points[res.cells[i]].mean(axis=0))}, cell {i}"
            parts.append(f"{comp} {_fmt(col[i])} {where}")
        lines.append(f"  {group}/{name}: max |value| " + "; ".join(parts))
    return lines


def _resultant(res: Result, values: np.ndarray) -> str:
    """``[fx -10000, fy 0, mz 500]`` (the labels the run wrote; moments about the origin)."""
    labels = res.attrs.get("resultant_components")
    labels = str(labels).split() if labels is not None else []
    if len(labels) != len(values):
        return "[" + ", ".join(_fmt(v) for v in values) + "]"
    names = [f"f{c}" if c in ("x", "y", "z") else c for c in labels]
    return "[" + ", ".join(f"{n} {_fmt(v)}" for n, v in zip(names, values)) + "]"


def _relations(res: Result) -> list[str]:
    lines = []
    for name in res.names("relations"):
        g = res.file[f"relations/{name}"]
        lam = g["multiplier"][-1] if len(g["multiplier"]) else np.zeros(0)
        rows = lam.size
        head = ", ".join(_fmt(v) for v in lam[:3]) + (", ..." if rows > 3 else "")
        line = f"  {name}: {rows} rows, multiplier [{head}] |λ|₂ {_fmt(np.linalg.norm(lam))}"
        if "resultant" in g and len(g["resultant"]):
            line += ", resultant " + _resultant(res, g["resultant"][-1])
        elif rows:
            line += f", Σλ {_fmt(lam.sum())} (no resultant dataset)"
        if "active" in g and len(g["active"]):
            line += f", active {int(g['active'][-1].sum())}/{rows}"
        lines.append(line)
    return lines


def contacts(res: Result) -> dict[str, dict[str, np.ndarray]]:
    """Per contact (a /fields/<name>_state beside /fields/<name>_normal_reaction), per step:
    ΣRn, ΣRt (tangent basis), |ΣRt|/ΣRn and the counts of open / stick / slip rows (state 0, 1,
    2; -1 marks the nodes that are not the contact's). ΣRn, ΣRt are the relations form's
    /relations/<name>_normal/normal_force and tangential_force where the file has them, else
    the sums of the nodal reactions."""
    out = {}
    for field in res.names("fields"):
        name = field[:-len("_state")]
        if not field.endswith("_state") or f"{name}_normal_reaction" not in res.names("fields"):
            continue
        state = res.file[f"fields/{field}"][()][..., 0]
        group = f"relations/{name}_normal"
        if f"{group}/normal_force" in res.file:
            rn = res.file[f"{group}/normal_force"][()].reshape(len(state), -1)[:, 0]
            rt = res.file[f"{group}/tangential_force"][()].reshape(len(state), -1)
        else:
            rn = np.nansum(res.file[f"fields/{name}_normal_reaction"][()][..., 0], axis=1)
            rt = np.nansum(res.file[f"fields/{name}_tangential_reaction"][()], axis=1)
        norm_t = np.linalg.norm(rt, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(rn > 0, norm_t / rn, np.nan)
        out[name] = {"normal": rn, "tangential": rt, "ratio": ratio,
                     **{s: (state == k).sum(axis=1) for k, s in enumerate(("open", "stick", "slip"))}}
    return out


def _contact_lines(res: Result) -> list[str]:
    lines = []
    for name, c in contacts(res).items():
        lines.append(f"contact {name} per step: ΣRn, ΣRt (tangent basis), |ΣRt|/ΣRn, rows open / "
                     "stick / slip")
        for k, t in enumerate(res.times):
            rt = " ".join(_fmt(v) for v in c["tangential"][k])
            lines.append(f"  {k + 1:4d}  t {_fmt(t):>10s}  ΣRn {_fmt(c['normal'][k]):>12s}  "
                         f"ΣRt {rt:>12s}  ratio {_fmt(c['ratio'][k]):>8s}  open {c['open'][k]} "
                         f"stick {c['stick'][k]} slip {c['slip'][k]}")
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
        lines.append("relations at the last step (resultants: forces, then moments about the "
                     "origin):")
        lines += _relations(res)
    lines += _contact_lines(res)
    if res.names("timings"):
        lines.append("timings (s, all steps): " + ", ".join(
            f"{n} {res.file['timings/' + n][()].sum():.3f}" for n in res.names("timings")))
    return "\n".join(lines)
