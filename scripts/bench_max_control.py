"""What a maximum control costs as the mesh is refined: one control column for the whole group
(the enforced row's coefficients in one multiplier row) against the former layout, one copy of
the control vector per element row (O(N^1.5) entries).

The plate with a hole of configs/plate_hole_control.toml refined 1×, 2×, 4× (and 8× for the
collapsed layout) per direction; a few steps past the elastic range. Reports the operator's
nonzeros, the relation block's, set-up + first assembly, and seconds per global iteration.

    .venv/bin/python scripts/bench_max_control.py [--steps 4] [--levels 1 2 4 8]
"""

from __future__ import annotations

import argparse
import os
import time
import tomllib
from pathlib import Path

import numpy as np
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]


def scene_text(level: int, steps: int) -> str:
    text = (ROOT / "configs" / "plate_hole_control.toml").read_text()
    text = text.replace("n_radial = 8", f"n_radial = {8 * level}")
    text = text.replace("n_angular = 12", f"n_angular = {12 * level}")
    return text.replace("count = 30", f"count = {steps}\nend = {steps / 30}")


def run(level: int, steps: int, per_row_copies: bool) -> dict:
    from parsolve.driver import make_solver
    from parsolve.model import build_model
    from parsolve.scene import parse_scene
    from parsolve.solvers.newton import NewtonSolver
    from parsolve.solvers.system import SaddleSystem

    text = scene_text(level, steps)
    scene = parse_scene(tomllib.loads(text), "plate.toml", text)
    model = build_model(scene)
    if per_row_copies:  # the former layout: every row its own copy of the control vector
        for r in model.relations:
            if r.collapsed:
                r.dual, r.shared_dual = r.dual_coo(), None
    t0 = time.perf_counter()
    system = SaddleSystem(MPI.COMM_WORLD, model)
    mat = system.assemble()
    setup = time.perf_counter() - t0
    info = mat.getInfo()
    newton = NewtonSolver(MPI.COMM_WORLD, system, make_solver(MPI.COMM_WORLD, system, {}),
                          scene.nonlinear)
    its, t1, status = 0, time.perf_counter(), "complete"
    try:
        for t in scene.times:
            its += newton.step(t).iterations
    except Exception as exc:  # report, do not stop the table
        status = f"failed: {str(exc)[:60]}"
    seconds = time.perf_counter() - t1
    return {"level": level, "layout": "per-row copies" if per_row_copies else "one column",
            "dofs": model.mesh.num_points * 2, "cells": model.mesh.num_cells,
            "nnz": int(info["nz_used"]), "block": int(system.block.d_vals.size + system.block.a_vals.size),
            "setup": setup, "iterations": its, "per_iteration": seconds / max(its, 1),
            "status": status}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--steps", type=int, default=4)
    p.add_argument("--levels", type=int, nargs="+", default=[1, 2, 4, 8])
    p.add_argument("--old-up-to", type=int, default=4, help="largest level for the old layout")
    args = p.parse_args()
    rows = []
    for level in args.levels:
        for old in (False, True):
            if old and level > args.old_up_to:
                continue
            rows.append(run(level, args.steps, old))
            print(rows[-1], flush=True)
    head = ("| level | layout | cells | DOFs | operator nnz | relation entries | set-up + assembly s "
            "| iterations | s / iteration | status |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---|\n")
    lines = [f"| {r['level']}× | {r['layout']} | {r['cells']} | {r['dofs']} | {r['nnz']} | {r['block']} "
             f"| {r['setup']:.2f} | {r['iterations']} | {r['per_iteration']:.3f} | {r['status']} |"
             for r in rows]
    load = os.getloadavg()[0]
    text = (f"# Maximum control at scale (`scripts/bench_max_control.py`, {args.steps} steps, "
            f"load average {load:.1f} on {os.cpu_count()} cores)\n\n" + head + "\n".join(lines) + "\n")
    print(text)
    out = ROOT / "scripts" / "results" / "bench_max_control.md"
    out.write_text(text)


if __name__ == "__main__":
    main()
