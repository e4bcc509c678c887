"""What a maximum control costs as the mesh is refined: one control column for the whole group
(the enforced row's coefficients in one multiplier row) against the former layout, one copy of
the control vector per element row (O(N^1.5) entries).

The plate with a hole of configs/plate_hole_control.toml refined 1×, 2×, 4×, 8×, 16× per
direction (the per-row copies up to ``--old-up-to``), through its 30 steps past the peak.
Reports the operator's nonzeros, the relation block's, set-up + first assembly, and seconds
per global iteration (also per 1000 DOFs: flat when the cost grows no faster than the mesh).
Steps follow ``parsolve run``: a step that fails is cut in two and retried (the driver's
StepSchedule); ``--no-cuts`` takes the scene's steps as they are. Before the first tangent of
a step put the enforced cell on its loading branch (``RelationPolicies.loading_tangent``), the
plate refined 8× stopped at t = 0.182 after 4 cuts (null pivots) and the 2× plate needed cuts.

    .venv/bin/python scripts/bench_max_control.py [--steps 30] [--levels 1 2 4 8 16] [--no-cuts]
    .venv/bin/python scripts/bench_max_control.py --smoke   # level 1, 3 steps; temp folder
"""

from __future__ import annotations

import argparse
import os
import time
import tomllib
from pathlib import Path

from mpi4py import MPI

import bench_harness as bh

ROOT = bh.ROOT


def scene_text(level: int, steps: int) -> str:
    text = (ROOT / "configs" / "plate_hole_control.toml").read_text()
    text = text.replace("n_radial = 8", f"n_radial = {8 * level}")
    text = text.replace("n_angular = 12", f"n_angular = {12 * level}")
    return text.replace("count = 30", f"count = {steps}\nend = {steps / 30}")


def run(level: int, steps: int, per_row_copies: bool, cuts: bool = True) -> dict:
    from parsolve.driver import StepSchedule, make_solver
    from parsolve.errors import SolverError
    from parsolve.model import build_model
    from parsolve.scene import parse_scene
    from parsolve.solvers.newton import NewtonSolver
    from parsolve.solvers.problem import SaddleProblem
    from parsolve.solvers.system import SaddleSystem

    text = scene_text(level, steps)
    scene = parse_scene(tomllib.loads(text), "plate.toml", text)
    model = build_model(scene, MPI.COMM_WORLD)
    if per_row_copies:  # the former layout: every row its own copy of the control vector
        for r in model.relations:
            if r.collapsed:
                r.dual, r.shared_dual = r.dual_coo(), None
    t0 = time.perf_counter()
    system = SaddleSystem(MPI.COMM_WORLD, model)
    mat = system.assemble()
    setup = time.perf_counter() - t0
    info = mat.getInfo()
    problem = SaddleProblem(MPI.COMM_WORLD, system, make_solver(MPI.COMM_WORLD, system, {}),
                            scene.nonlinear)
    newton = NewtonSolver(problem, scene.nonlinear)
    schedule = StepSchedule(scene)
    its, steps, t1, status, reached = 0, 0, time.perf_counter(), "complete", 0.0
    while (t := schedule.next()) is not None:
        snap = problem.snapshot()
        try:
            its += newton.step(t).iterations
        except SolverError as exc:  # the driver's rule: cut and retry, then report
            its += max(len(newton.residual_history) - 1, 0)  # the failed attempt's solves
            problem.restore(snap)
            if cuts and schedule.cut(t):
                continue
            status = f"failed at t = {t:.4g}: {str(exc).split(' (')[0][:110]}"
            break
        steps, reached = steps + 1, t
        schedule.done(t, 0.0)
    seconds = time.perf_counter() - t1
    return {"level": level, "layout": "per-row copies" if per_row_copies else "one column",
            "dofs": model.mesh.num_points * 2, "cells": model.mesh.num_cells,
            "nnz": int(info["nz_used"]), "block": int(system.relation_set.d_vals.size + system.relation_set.a_vals.size),
            "setup": setup, "iterations": its, "per_iteration": seconds / max(its, 1),
            "steps": steps, "cuts": steps - len([x for x in scene.times if x <= reached + 1e-12]),
            "reached": reached, "status": status}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=30)
    p.add_argument("--levels", type=int, nargs="+", default=[1, 2, 4, 8, 16])
    p.add_argument("--old-up-to", type=int, default=4, help="largest level for the old layout")
    p.add_argument("--output", help="table file (default scripts/results/bench_max_control.md)")
    p.add_argument("--no-cuts", action="store_true", help="no step cuts (a failed step ends the run)")
    bh.add_smoke(p)
    args = p.parse_args(argv)
    if args.smoke:   # level 1, both layouts, 3 steps; the table into a temporary folder
        args.levels, args.steps = [1], 3
    rows = []
    for level in args.levels:
        for old in (False, True):
            if old and level > args.old_up_to:
                continue
            rows.append(run(level, args.steps, old, not args.no_cuts))
            print(rows[-1], flush=True)
    head = ("| level | layout | cells | DOFs | operator nnz | relation entries | set-up + assembly s "
            "| steps (cuts) | t reached | iterations (all attempts) | s / iteration "
            "| ms / iteration / 1k DOFs | status |\n"
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|\n")
    lines = [f"| {r['level']}× | {r['layout']} | {r['cells']} | {r['dofs']} | {r['nnz']} | {r['block']} "
             f"| {r['setup']:.2f} | {r['steps']} ({r['cuts']}) | {r['reached']:.4g} | {r['iterations']} "
             f"| {r['per_iteration']:.3f} | {1e6 * r['per_iteration'] / r['dofs']:.2f} "
             f"| {r['status']} |" for r in rows]
    load = os.getloadavg()[0]
    mode = "no step cuts" if args.no_cuts else "failed steps cut in two as by `parsolve run`"
    text = (f"# Maximum control at scale (`scripts/bench_max_control.py`, {args.steps} steps of "
            f"1/30, {mode}; load average {load:.1f} on {os.cpu_count()} cores)\n\n" + head
            + "\n".join(lines) + "\n")
    print(text)
    if args.output is not None:
        Path(args.output).write_text(text)
    else:
        bh.publish("bench_max_control.md", text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
