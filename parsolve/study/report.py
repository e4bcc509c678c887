"""The study's answer: errors and orders per family, the table (Markdown and CSV), the picture
(error against seconds, log-log, Pareto front marked) and the cheapest setting for a target."""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parsolve.study.config import Study
from parsolve.study.convergence import error, observed_orders, richardson
from parsolve.study.execute import Measured
from parsolve.study.pareto import cheapest, pareto_front


@dataclass
class Analysis:
    references: dict[str, float]              # quantity -> reference value
    reference_notes: dict[str, str]           # quantity -> how it was obtained
    errors: dict[str, list[float]]            # quantity -> error per row (nan if failed)
    orders: dict[str, list[float | None]]     # quantity -> observed order per row (within family)
    front: list[int]                          # rows on the Pareto front (first quantity)
    best: int | None                          # cheapest row reaching the target


def _family_rows(rows: list[Measured], family: str) -> list[int]:
    return [i for i, r in enumerate(rows) if r.setting.family == family and r.ok]


def analyse(study: Study, rows: list[Measured], dim: int, target: float | None) -> Analysis:
    refs, notes, errs, orders = {}, {}, {}, {}
    families = [f.name for f in study.families]
    for q in study.quantities:
        if q.reference == "richardson":
            fam = q.richardson_family or families[-1]
            idx = _family_rows(rows, fam)
            if len(idx) < 2:
                refs[q.name], notes[q.name] = math.nan, f"Richardson: too few complete runs of {fam}"
            else:
                value, p = richardson([rows[i].values[q.name] for i in idx],
                                      [rows[i].dofs for i in idx], dim)
                refs[q.name] = value
                notes[q.name] = (f"Richardson extrapolation of {fam} (its {min(3, len(idx))} finest levels"
                                 + (f", observed order {p:.2f} in h ∝ DOFs^(-1/{dim}))" if p else
                                    ", not asymptotic: finest value)"))
        else:
            refs[q.name], notes[q.name] = float(q.reference), "given"
        errs[q.name] = [error(r.values[q.name], refs[q.name], q.error) if r.ok else math.nan
                        for r in rows]
        orders[q.name] = [None] * len(rows)
        for fam in families:
            idx = _family_rows(rows, fam)
            for i, p in zip(idx, observed_orders([errs[q.name][i] for i in idx],
                                                 [rows[i].dofs for i in idx], dim)):
                orders[q.name][i] = p
    first = study.quantities[0].name
    cost = [r.cost(study.cost) if r.ok else math.nan for r in rows]
    cost = [math.nan if c is None else c for c in cost]
    front = [int(i) for i in pareto_front(cost, errs[first])]
    best = cheapest(cost, errs[first], target) if target is not None else None
    return Analysis(refs, notes, errs, orders, front, best)


def _g(v, fmt: str = ".4g") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    return format(v, fmt)


def table(study: Study, rows: list[Measured], a: Analysis) -> tuple[list[str], list[list[str]]]:
    phases = sorted({p for r in rows for p in r.phases if p != "total"})
    head = ["family", "level", "DOFs"]
    for q in study.quantities:
        head += [q.name, f"error({q.name})", f"order({q.name})"]
    head += [f"{p} s" for p in phases] + ["compute s", "wall s", "peak MB/rank", "status", "pareto"]
    body = []
    for i, r in enumerate(rows):
        line = [r.setting.family, r.setting.label, _g(r.dofs, "d")]
        for q in study.quantities:
            line += [_g(r.values.get(q.name), ".8g"), _g(a.errors[q.name][i], ".3e"),
                     _g(a.orders[q.name][i], ".2f")]
        line += [_g(r.phases.get(p), ".3f") for p in phases]
        line += [_g(r.phases.get("total"), ".3f"), _g(r.wall, ".2f"), _g(r.peak_mb, ".0f"),
                 r.status, "*" if i in a.front else ""]
        body.append(line)
    return head, body


def write_csv(path: Path, head: list[str], body: list[list[str]]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(head)
        w.writerows(body)


def markdown(study: Study, rows: list[Measured], a: Analysis, head, body, target: float | None) -> str:
    lines = [f"# Study: {study.title or Path(study.source).stem}", "",
             f"Base scene `{study.scene.name}`, {study.ranks} rank(s) per run; cost = "
             f"{'wall seconds of the run' if study.cost == 'wall' else 'sum of /timings/total'}.", ""]
    for q in study.quantities:
        lines.append(f"- `{q.name}` = `{q.spec}`, error {q.error}, reference "
                     f"{a.references[q.name]:.10g} ({a.reference_notes[q.name]})")
    lines += ["", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(b) + " |" for b in body]
    lines += ["", answer(study, rows, a, target), ""]
    return "\n".join(lines)


def answer(study: Study, rows: list[Measured], a: Analysis, target: float | None) -> str:
    if target is None:
        return "No target error given (--target or target = ...)."
    q = study.quantities[0].name
    if a.best is None:
        return f"No setting reaches error({q}) ≤ {target:g}."
    r = rows[a.best]
    changes = ", ".join(f"{k} = {v!r}" for k, v in r.setting.changes.items())
    return (f"Cheapest setting with error({q}) ≤ {target:g}: {r.setting.family}, level "
            f"{r.setting.label} ({changes}): error {a.errors[q][a.best]:.3e}, "
            f"{r.cost(study.cost):.3g} s, {r.dofs} DOFs.")


def picture(path: Path, study: Study, rows: list[Measured], a: Analysis, target: float | None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    q = study.quantities[0]
    err = np.array(a.errors[q.name], dtype=float)
    cost = np.array([r.cost(study.cost) if r.ok and r.cost(study.cost) is not None else np.nan
                     for r in rows])
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    markers = "osD^v<>p*h"
    for k, fam in enumerate(f.name for f in study.families):
        idx = [i for i, r in enumerate(rows) if r.setting.family == fam and np.isfinite(err[i]) and err[i] > 0]
        if idx:
            ax.loglog(cost[idx], err[idx], marker=markers[k % len(markers)], label=fam)
            for i in idx:
                ax.annotate(f"{rows[i].dofs}", (cost[i], err[i]), fontsize=6, alpha=0.7,
                            xytext=(3, 3), textcoords="offset points")
    front = [i for i in a.front if err[i] > 0]
    if front:
        ax.step(cost[front], err[front], where="post", color="k", lw=1, alpha=0.5)
        ax.scatter(cost[front], err[front], s=90, facecolors="none", edgecolors="k",
                   label="Pareto front")
    if target is not None:
        ax.axhline(target, color="r", ls="--", lw=1, label=f"target {target:g}")
    ax.set_xlabel("wall seconds per run" if study.cost == "wall" else "compute seconds per run")
    ax.set_ylabel(f"{q.error} error of {q.name}")
    ax.set_title(study.title or Path(study.source).stem, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
