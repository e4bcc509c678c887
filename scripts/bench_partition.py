#!/usr/bin/env python3
"""Partition benchmark: coordinate bisection (RCB) against PT-Scotch, and what the partition
decides of MUMPS's cost.

Problems:
  plate : configs/kirsch.toml (quarter plate with a hole, P2 triangles, plane stress, symmetry
          conditions eliminated) refined k× per direction (k = 2, 4: 100k, 400k DOFs; 6: 900k);
  box   : 3D elasticity on a unit cube of N³ Q1 hexahedra (x = 0 clamped, traction on x = 1),
          3 (N+1)³ DOFs (N = 20: 28k DOFs; N = 33: 118k DOFs, whose factorization takes
          minutes per run: `--box 33 --orderings` measures its partitions alone);
  square: bench_solve's problem, where bench_solve measured QAMD's 2.2× (unit square, N × N quads
          split into P1 triangles, N = 707: 1M DOFs).
One fresh process per (problem, ranks) under `scripts/mpirun.sh -n RANKS` (2, 3 and 4 ranks,
4 oversubscribed on 2 cores; 1 rank = the input numbering, no partition, for reference), both
partitioners in that process (order alternating between processes, so that neither always
runs first):
  * partition: the run's (for PT-Scotch: the cell checks and dual graph by blocks, the MPIAdj
    rows, PT-Scotch, the gather), seconds = slowest rank's; edge cut = shared facets between parts; interface
    nodes = nodes whose cells lie in more than one part; DOF balance = largest rank's owned
    DOFs / mean;
  * the system (`SaddleSystem` + `assemble`), then the `direct` preset (MUMPS LDLᵀ) with the
    ordering QAMD (`-mat_mumps_icntl_7 6`, parsolve's default) and METIS (`5`): analysis
    estimates INFOG(3) (factor entries; negative = millions) and RINFOG(1) (flops), the
    flops of the factorization RINFOG(3), the analysis and numeric factorization seconds
    (PETSc events MatCholFctrSym / MatCholFctrNum, slowest rank), the solve seconds.
Times on this 2-core shared machine are noisy: compare the two partitioners within a row
group (same process), and trust flops and counts, which do not depend on the load.

Usage (from the repository root):
    .venv/bin/python scripts/bench_partition.py                       # everything
    .venv/bin/python scripts/bench_partition.py --plate 2 --box --ranks 2   # a quick look
Writes bench_results/partition.json and scripts/results/bench_partition.md (the latter only for
a full run).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import sys
import time
from pathlib import Path

import bench_harness as bh
from bench_assembly import COMMITTED, CONTENTION, RESULTS, ROOT, Phase, machine_line, run_worker
from bench_assembly import scene_text as square
from bench_harness import cpu_idle, git_status, machine_info, md_table, text_table

PLATE_K = [2, 4]
BOX_N = [20]
SQUARE_N = [707]
RANKS = [1, 2, 3, 4]
ORDERINGS = {"QAMD": "6", "METIS": "5"}
# INFOG(7): the ordering MUMPS actually ran (Debian's MUMPS has no METIS: asked for 5, it runs PORD)
ORDERING_NAMES = {0: "AMD", 1: "given", 2: "AMF", 3: "SCOTCH", 4: "PORD", 5: "METIS", 6: "QAMD"}


def label(results: list[dict], asked: str) -> str:
    """The requested ordering's name, with the one MUMPS ran when they differ."""
    used = {ORDERING_NAMES.get(run["orderings"][asked]["ordering_used"], "?")
            for r in results if "error" not in r for run in r["runs"].values()
            if asked in run["orderings"]}
    ran = "/".join(sorted(used))
    return asked if not used or used == {asked} else f"{asked}→{ran}"
METHODS = ("bisection", "scotch")


# ------------------------------------------------------------------------------------------------
# scenes


def plate_text(k: int) -> str:
    text = (ROOT / "configs" / "kirsch.toml").read_text()
    text = text.replace("n_radial = 48", f"n_radial = {48 * k}")
    text = text.replace("n_angular = 64", f"n_angular = {64 * k}")
    return text.replace('file = "kirsch.h5"', "")


def box_text(n: int) -> str:
    return f"""
[mesh]
generator = "box"
lx = 1.0
ly = 1.0
lz = 1.0
nx = {n}
ny = {n}
nz = {n}
cell = "hexahedron"

[model]
hypothesis = "3d"

[[materials]]
E = 1.0
nu = 0.3

[[loads]]
region = "xmax"
traction = [0.0, 0.0, -1.0]

[[relations]]
name = "clamp"
type = "dirichlet"
region = "xmin"
components = ["x", "y", "z"]
"""


def square_text(n: int) -> str:
    """bench_solve's problem (where the issue measured QAMD's 2.2×): unit square, N × N quads
    split into P1 triangles, plane strain, left edge clamped, traction on the right."""
    return square(n, "triangle", "direct").split("[solver]")[0]   # ours is appended


def scene_text(problem: str, size: int, method: str) -> str:
    text = {"plate": plate_text, "box": box_text, "square": square_text}[problem](size)
    return text + f'\n[solver]\npreset = "direct"\npartitioner = "{method}"\n'


# ------------------------------------------------------------------------------------------------
# worker (under mpirun)


class Clock(Phase):
    """Phase plus .cpu_s: the largest rank's CPU seconds (on a loaded machine the wall time
    counts other processes' work too; the CPU time does not)."""

    def __exit__(self, *exc):
        cpu = time.process_time() - self.c0
        super().__exit__(*exc)
        if exc[0] is None:
            from mpi4py import MPI

            self.cpu_s = self.comm.allreduce(cpu, op=MPI.MAX)
        return False


def _events() -> dict:
    from petsc4py import PETSc

    names = ("MatCholFctrSym", "MatCholFctrNum", "MatLUFactorSym", "MatLUFactorNum", "MatSolve")
    return {e: PETSc.Log.Event(e).getPerfInfo()["time"] for e in names}


def _slowest(comm, before: dict) -> dict:
    from mpi4py import MPI

    after = _events()
    return {e: comm.allreduce(after[e] - before[e], op=MPI.MAX) for e in after}


def _entries(v: int) -> float:
    return float(v) if v >= 0 else float(-v) * 1e6   # MUMPS: negative = millions


def partition_stats(comm, mesh, method: str) -> dict:
    """Time the run's partition alone (``distribute``'s: for PT-Scotch the cell checks and dual
    graph by blocks, the MPIAdj rows, PT-Scotch, the gather), then the counts it gives."""
    import numpy as np
    from mpi4py import MPI

    from parsolve.mesh import blocks
    from parsolve.mesh.distribute import _cell_parts
    from parsolve.mesh.partition import edge_cut, from_cell_parts

    def cell_parts():
        parts, used = _cell_parts(comm, mesh, method)
        return comm.bcast(parts, root=0), used

    cell_parts()     # warm-up: imports, PETSc registration
    with Clock(comm) as p:
        parts, used = cell_parts()
    graph = blocks.check_cells(MPI.COMM_SELF, mesh, None, None)   # the whole graph, one block
    lo = np.full(mesh.num_points, comm.size)
    hi = np.full(mesh.num_points, -1)
    np.minimum.at(lo, mesh.cells, parts[:, None])
    np.maximum.at(hi, mesh.cells, parts[:, None])
    part = from_cell_parts(mesh, parts, comm.size, used)
    owned = np.diff(part.node_ranges)
    return dict(method=used, t_partition=p.t, cpu_partition=p.cpu_s, edge_cut=edge_cut(*graph, parts),
                interface_nodes=int(np.count_nonzero((hi >= 0) & (lo != hi))),
                dof_balance=float(owned.max() / owned.mean()),
                cell_balance=float(np.bincount(parts).max() * comm.size / mesh.num_cells))


def solve_stats(comm, system, mat, ordering: str) -> dict:
    from parsolve.solvers.setup import make_solver

    x, rhs = mat.createVecs()
    rhs.array[:] = system.rhs(1.0)[0]
    solver = make_solver(comm, system, {"mat_mumps_icntl_7": ordering})
    gc.collect()
    ev0 = _events()
    with Clock(comm) as p_set:
        solver.set_operator(mat)
    with Clock(comm) as p_solve:
        solver.solve(rhs, x)
    ev = _slowest(comm, ev0)
    F = solver.ksp.getPC().getFactorMatrix()
    out = dict(ordering_used=int(F.getMumpsInfog(7)), analysis_kind=int(F.getMumpsInfog(32)),
               est_entries=_entries(F.getMumpsInfog(3)),
               est_flops=float(F.getMumpsRinfog(1)), flops=float(F.getMumpsRinfog(3)),
               entries=_entries(F.getMumpsInfog(29)),
               t_analysis=ev["MatCholFctrSym"] + ev["MatLUFactorSym"],
               t_numeric=ev["MatCholFctrNum"] + ev["MatLUFactorNum"],
               t_backsub=ev["MatSolve"], t_total=p_set.t + p_solve.t,
               cpu_total=p_set.cpu_s + p_solve.cpu_s, unorm=float(x.norm()),
               cpu_share=min(p_set.cpu, p_solve.cpu), pc=solver.ksp.getPC().getType())
    solver.ksp.destroy()
    return out


def run_method(comm, problem: str, size: int, method: str, orderings: list[str]) -> dict:
    import tomllib

    from parsolve.model import build_model
    from parsolve.scene import parse_scene
    from parsolve.solvers.system import SaddleSystem

    text = scene_text(problem, size, method)
    scene = parse_scene(tomllib.loads(text), "bench.toml", text)
    # the partitioner's statistics on the whole mesh (every rank its own copy, COMM_SELF);
    # the system on the ranks' parts, as a run builds it
    whole = build_model(scene)
    out = dict(dofs=whole.mesh.num_points * whole.ncomp, cells=whole.mesh.num_cells)
    out.update(partition_stats(comm, whole.mesh, method))
    del whole
    out["orderings"] = {}
    if not orderings:   # the partition alone
        return out
    model = build_model(scene, comm)
    with Phase(comm) as p_sys:
        system = SaddleSystem(comm, model)
        mat = system.assemble()
    out["t_system"] = p_sys.t
    out["orderings"] = {o: solve_stats(comm, system, mat, ORDERINGS[o]) for o in orderings}
    mat.destroy()
    return out


def worker(args) -> None:
    from mpi4py import MPI
    from petsc4py import PETSc

    comm = MPI.COMM_WORLD
    PETSc.Log.begin()
    PETSc.KSP().create(comm).destroy()   # register the events before reading them
    methods = list(METHODS) if comm.size > 1 else ["bisection"]   # 1 rank: no partition
    if args.flip:
        methods.reverse()
    out = dict(problem=args.problem, size=args.size, nranks=comm.size, runs={})
    for m in methods:
        out["runs"][m] = run_method(comm, args.problem, args.size, m, args.orderings)
        gc.collect()
    out["cpu_share"] = min([o["cpu_share"] for r in out["runs"].values()
                            for o in r["orderings"].values()] or [1.0])
    if comm.rank == 0:
        Path(args.json).write_text(json.dumps(out, indent=1))


# ------------------------------------------------------------------------------------------------
# driver


def g(x: float) -> str:
    return f"{x:.3g}"


def table(results: list[dict], orderings: list[str]) -> tuple[list[str], list[list[str]]]:
    head = ["problem", "DOFs", "np", "partitioner", "edge cut", "interface nodes", "DOF bal.",
            "partition s (cpu)"]
    for o in orderings:
        n = label(results, o)
        head += [f"{n} INFOG(3)", f"{n} RINFOG(1)", f"{n} flops vs np=1", f"{n} analysis s",
                 f"{n} factor s", f"{n} solve s", f"{n} total s (cpu)"]
    rows = []
    base = {}
    for r in results:
        if "error" in r:   # listed under the table (see report)
            continue
        for m, run in r["runs"].items():
            key = (r["problem"], r["size"])
            if r["nranks"] == 1:
                base[key] = {o: run["orderings"][o]["est_flops"] for o in orderings
                             if o in run["orderings"]}
            row = [r["problem"], str(run["dofs"]), str(r["nranks"]),
                   run["method"], str(run["edge_cut"]), str(run["interface_nodes"]),
                   f"{run['dof_balance']:.3f}",
                   f"{run['t_partition']:.2f} ({run['cpu_partition']:.2f})"]
            for o in orderings:
                if o not in run["orderings"]:   # partition only
                    row += ["-"] * 7
                    continue
                s = run["orderings"][o]
                ref = base.get(key, {}).get(o)
                row += [g(s["est_entries"]), g(s["est_flops"]),
                        f"{s['est_flops'] / ref:.2f}×" if ref else "-",
                        f"{s['t_analysis']:.2f}", f"{s['t_numeric']:.2f}",
                        f"{s['t_backsub']:.2f}", f"{s['t_total']:.2f} ({s['cpu_total']:.2f})"]
            rows.append(row)
    return head, rows


def findings(results: list[dict], orderings: list[str]) -> list[str]:
    """Ratios scotch / bisection per (problem, np), and flops against 1 rank."""
    lines = []
    base = {}
    for r in results:
        if "error" in r:
            continue
        runs = r["runs"]
        key = (r["problem"], r["size"])
        if r["nranks"] == 1:
            base[key] = runs["bisection"]
            continue
        b, s = runs.get("bisection"), runs.get("scotch")
        if not (b and s):
            continue
        parts = [f"{r['problem']} {b['dofs']} DOFs, np={r['nranks']}: edge cut "
                 f"{s['edge_cut']}/{b['edge_cut']} = {s['edge_cut'] / max(b['edge_cut'], 1):.2f}, "
                 f"interface nodes {s['interface_nodes'] / max(b['interface_nodes'], 1):.2f}, "
                 f"partition CPU {s['cpu_partition']:.2f} s vs {b['cpu_partition']:.2f} s"]
        for o in orderings:
            if o not in s["orderings"] or o not in b["orderings"]:
                continue
            so, bo = s["orderings"][o], b["orderings"][o]
            one = base.get(key, {}).get("orderings", {}).get(o)
            vs1 = (f" (np=1: {g(one['est_flops'])}; RCB {bo['est_flops'] / one['est_flops']:.2f}×, "
                   f"Scotch {so['est_flops'] / one['est_flops']:.2f}×)") if one else ""
            parts.append(f"{label(results, o)} flops Scotch/RCB {so['est_flops'] / bo['est_flops']:.2f}{vs1}, "
                         f"set-up + solve CPU "
                         f"{so['cpu_total'] / max(bo['cpu_total'], 1e-9):.2f}×")
        lines.append("- " + "; ".join(parts))
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--problem", help=argparse.SUPPRESS)
    p.add_argument("--size", type=int, help=argparse.SUPPRESS)
    p.add_argument("--flip", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--json", help=argparse.SUPPRESS)
    p.add_argument("--plate", type=int, nargs="*", default=PLATE_K,
                   help="Kirsch refinement factors (default 2 4)")
    p.add_argument("--box", type=int, nargs="*", default=BOX_N, help="box cells per side")
    p.add_argument("--square", type=int, nargs="*", default=SQUARE_N,
                   help="unit square quads per side (bench_solve's problem)")
    p.add_argument("--ranks", type=int, nargs="+", default=RANKS)
    p.add_argument("--orderings", nargs="*", default=list(ORDERINGS), choices=list(ORDERINGS),
                   help="none: the partition alone (no factorization)")
    p.add_argument("--timeout", type=float, default=1800.0)
    p.add_argument("--out", default="partition", help="bench_results/OUT.json")
    p.add_argument("--render", type=Path, nargs="+", default=None, metavar="JSON",
                   help="only write the tables from earlier runs' JSON files (merged)")
    p.add_argument("--wait", type=float, default=5.0,
                   help="before each process wait up to this many seconds for idle CPUs")
    bh.add_smoke(p)
    args = p.parse_args(argv)
    if args.worker:
        worker(args)
        return 0
    if args.smoke:   # the smallest Kirsch plate, small box and square, 2 ranks, no waiting
        args.plate, args.box, args.square, args.ranks, args.wait = [1], [4], [8], [2], 0.0
    RESULTS.mkdir(exist_ok=True)
    if args.render:
        return render(args.render)
    CONTENTION.update(wait=args.wait, retries=0, budget=10 * args.wait)
    info = machine_info()
    info["idle_at_start"] = cpu_idle(1.0)
    info["git_status"] = git_status()
    t0 = time.perf_counter()
    results = []
    jobs = [("plate", k) for k in args.plate] + [("box", n) for n in args.box] + \
        [("square", n) for n in args.square]
    for i, (problem, size) in enumerate(jobs):
        for j, nr in enumerate(args.ranks):
            wargs = ["--problem", problem, "--size", str(size), "--orderings", *args.orderings]
            if (i + j) % 2:
                wargs.append("--flip")
            r = run_worker("bench_partition.py", nr, wargs, timeout=args.timeout,
                           retry_import=False)
            r.setdefault("problem", problem)
            r.setdefault("size", size)
            r.setdefault("nranks", nr)
            results.append(r)
            print(f"[bench] {problem} {size} np={nr}: "
                  + (r["error"][-300:] if "error" in r else
                     ", ".join(f"{m} cut {v['edge_cut']}" for m, v in r["runs"].items())),
                  flush=True)
    elapsed = time.perf_counter() - t0
    info["loadavg_end"] = os.getloadavg()[0]
    out = dict(machine=info, elapsed_s=elapsed, results=results, orderings=args.orderings)
    (RESULTS / f"{args.out}.json").write_text(json.dumps(out, indent=1))
    return report(out, full=(args.plate == PLATE_K and args.box == BOX_N and args.ranks == RANKS
                             and args.square == SQUARE_N
                             and args.orderings == list(ORDERINGS)))


def render(paths: list[Path]) -> int:
    """One report from several runs (e.g. problems measured in separate invocations)."""
    runs = [json.loads(p.read_text()) for p in paths]
    out = dict(runs[0])
    out["results"] = [r for run in runs for r in run["results"]]
    out["elapsed_s"] = sum(run["elapsed_s"] for run in runs)
    out["machine"]["loadavg_end"] = max(run["machine"].get("loadavg_end", 0) for run in runs)
    return report(out, full=True)


def report(out: dict, full: bool) -> int:
    head, rows = table(out["results"], out["orderings"])
    summary = findings(out["results"], out["orderings"])
    print("\n" + text_table(head, rows) + "\n\n" + "\n".join(summary))
    md = "\n".join([
        "# Partition benchmark: coordinate bisection (RCB) vs PT-Scotch",
        "",
        "Kirsch plate (`configs/kirsch.toml`, P2 triangles, refined k× per direction), "
        "bench_solve's unit square (P1 triangles, where bench_solve measured QAMD's 2.2×) and a 3D "
        "box of Q1 hexahedra (box 33: partitions only, `--orderings` empty); one fresh process per (problem, ranks), both partitioners in it; "
        "4 ranks are oversubscribed on 2 cores; np=1 is the input numbering (no partition). "
        "Partition = the run's (PT-Scotch: cell checks and dual graph by blocks + MPIAdj rows + "
        "PT-Scotch + gather). "
        "MUMPS LDLᵀ of the `direct` preset with the ordering QAMD (parsolve's default, "
        "icntl_7 6) and METIS (5; Debian's MUMPS has no METIS: INFOG(7) says it ran PORD, "
        "shown as METIS→PORD): INFOG(3) = estimated factor entries, RINFOG(1) = estimated "
        "flops (analysis), 'flops vs np=1' = RINFOG(1) against the same problem on 1 rank; "
        "analysis / factor / solve = PETSc events MatCholFctrSym / MatCholFctrNum / MatSolve "
        "(slowest rank, wall), total = `set_operator` + `solve` (the preset's whole "
        "factorization and solve), wall (the largest rank's CPU seconds). Wall times are noisy (shared 2-core machine, "
        "often loaded: see the load average below); CPU times much less so, counts and flops "
        "not at all.",
        "",
        machine_line(out["machine"], out["elapsed_s"]),
        "",
        md_table(head, rows),
        "",
        "## Scotch against RCB, per problem and rank count",
        "",
        *summary,
        "",
        *[f"- not measured: {r['problem']} size {r['size']} np={r['nranks']} (the worker was "
          f"stopped or failed: {r['error'][:60].strip() or '?'}; stopped ones were ended for the "
          "time budget on a machine at load average ~20)"
          for r in out["results"] if "error" in r],
        "",
        "Rerun: `.venv/bin/python scripts/bench_partition.py`",
        "",
    ])
    (RESULTS / "partition.md").write_text(md)
    if full:
        COMMITTED.mkdir(exist_ok=True)
        (COMMITTED / "bench_partition.md").write_text(md)
        print("[bench] wrote scripts/results/bench_partition.md")
    else:
        print("[bench] partial run: bench_results/partition.md only")
    return 0


if __name__ == "__main__":
    sys.exit(main())
