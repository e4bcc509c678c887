#!/usr/bin/env python3
"""Benchmark: writing the result file, output mode "swmr" (rank 0 writes) against "parallel"
(every rank writes its rows through MPI-IO), at 1 and 2 ranks.

Problem: 2D, parsolve's rectangle generator, n × n quads ((n+1)² nodes, 2 (n+1)² DOFs; n = 707:
1.0M DOFs), the rank partition of a real run (parsolve.mesh.partition), 20 steps. Each step
writes what an elasticity run writes: ``/fields/displacement`` (N, 2), the averaged nodal
``/fields/stress`` (N, 3), ``/cell_fields/stress`` (C, 3), a 2-row relation and the per-step
scalars; the XDMF beside it. Values are synthetic (the solve is not what is measured).

Inputs, as the writer receives them:
  * ``today``: what ``parsolve.outputs.step_outputs`` hands over now: the displacement whole on
    every rank, the nodal and cell stress whole on rank 0 only (None elsewhere: the parallel
    writer scatters them);
  * ``owned``: every value as ``OwnedRows`` (each rank only its own rows; what step_outputs
    could hand over once it stops reducing and gathering to rank 0).
Selections of the parallel mode (parsolve/io/slabs.py): ``blocks`` (one Alltoallv, one
contiguous hyperslab per rank) and ``runs`` (no exchange, one hyperslab per run of owned ids).

Each configuration runs in its own process group (scripts/mpirun.sh) so that peak memory is its
own: rank 0's peak RSS (ru_maxrss) and its growth from just before the first step (the data
already built), the write time per step (slowest rank; median of steps 2-20, and step 1, which
creates the datasets), the file size.

    .venv/bin/python scripts/bench_output.py [--n 707] [--steps 20]
        → table on stdout and in scripts/results/bench_output.md; scratch in bench_results/output/
    .venv/bin/python scripts/bench_output.py --smoke   (n = 8, 3 steps; files in a temp folder)
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import bench_harness as bh

ROOT = bh.ROOT
PY = bh.VENV_PY

CONFIGS = [  # (ranks, mode, inputs, selection)
    (1, "swmr", "today", "-"),
    (1, "parallel", "today", "blocks"),
    (2, "swmr", "today", "-"),
    (2, "parallel", "today", "blocks"),
    (2, "parallel", "today", "runs"),
    (2, "swmr", "owned", "-"),
    (2, "parallel", "owned", "blocks"),
]


def rss_mib() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def child(n: int, steps: int, mode: str, inputs: str, selection: str, out: Path) -> None:
    import numpy as np
    from mpi4py import MPI

    from parsolve.io.hdf5 import ResultWriter
    from parsolve.io.parallel import ParallelResultWriter
    from parsolve.io.slabs import OwnedRows
    from parsolve.mesh.generators import rectangle
    from parsolve.mesh.partition import bisect, from_cell_parts

    comm = MPI.COMM_WORLD
    mesh = rectangle(1.0, 1.0, n, n, cell="quad")
    part = from_cell_parts(mesh, bisect(mesh.points[mesh.cells].mean(axis=1), comm.size),
                           comm.size, "bisection")
    owners = (part.node_part, part.node_part[mesh.cells].min(axis=1))
    nodes = np.flatnonzero(owners[0] == comm.rank)
    cells = np.flatnonzero(owners[1] == comm.rank)
    npts, ncells = mesh.num_points, mesh.num_cells

    def step_values(t: float):
        """The step's values in the form ``inputs`` says (independent of the rank count)."""
        x, y = mesh.points[:, 0], mesh.points[:, 1]
        if inputs == "owned":
            xo, yo = x[nodes], y[nodes]
            c = mesh.points[mesh.cells[cells]].mean(axis=1)
            return ({"displacement": OwnedRows(t * np.stack([xo, yo], 1)),
                     "stress": OwnedRows(t * np.stack([xo, yo, xo * yo], 1))},
                    {"stress": OwnedRows(t * np.stack([c[:, 0], c[:, 1], c[:, 0] * c[:, 1]], 1))})
        fields = {"displacement": t * np.stack([x, y], 1), "stress": None}
        cell_fields = {"stress": None}
        if comm.rank == 0:
            c = mesh.points[mesh.cells].mean(axis=1)
            fields["stress"] = t * np.stack([x, y, x * y], 1)
            cell_fields["stress"] = t * np.stack([c[:, 0], c[:, 1], c[:, 0] * c[:, 1]], 1)
        return fields, cell_fields

    cls = ParallelResultWriter if mode == "parallel" else ResultWriter
    kw = {"selection": selection} if mode == "parallel" else {}
    writer = cls(comm, out, mesh, "bench", "3.18", {"clamp": (2, False)}, owners=owners, **kw)
    base = rss_mib()
    seconds = []
    for k in range(steps):
        t = (k + 1) / steps
        fields, cell_fields = step_values(t)
        comm.Barrier()
        t0 = time.perf_counter()
        writer.write_step(t, 1, 1e-12, fields, cell_fields,
                          {"clamp": {"multiplier": [t, -t], "primal": [0.0, 0.0]}},
                          {"total": 0.0})
        seconds.append(comm.allreduce(time.perf_counter() - t0, op=MPI.MAX))
        del fields, cell_fields
    writer.close("complete")
    comm.Barrier()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    if comm.rank == 0:
        import h5py

        with h5py.File(out, "r") as f:  # the values arrived where they belong
            u = f["fields/displacement"][steps - 1]
            s = f["cell_fields/stress"][steps - 1]
            ok = bool(np.array_equal(u, mesh.points) and f.attrs["status"] == "complete"
                      and np.array_equal(s[:, 0], mesh.points[mesh.cells].mean(axis=1)[:, 0]))
        print(json.dumps({"first": seconds[0], "median": float(np.median(seconds[1:])),
                          "base_mib": base, "peak_mib": peak, "ok": ok,
                          "file_mib": out.stat().st_size / 2**20, "dofs": 2 * npts,
                          "cells": ncells}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=707)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--child", nargs=3, metavar=("MODE", "INPUTS", "SELECTION"))
    ap.add_argument("--out")
    bh.add_smoke(ap)
    args = ap.parse_args()
    if args.smoke and not args.child:   # every configuration on 8 × 8 quads, 3 steps
        args.n, args.steps = 8, 3
    if args.child:
        mode, inputs, selection = args.child
        return child(args.n, args.steps, mode, inputs, selection, Path(args.out))
    scratch = bh.scratch("output")
    env = bh.child_env()
    rows = []
    for ranks, mode, inputs, selection in CONFIGS:
        out = scratch / f"r{ranks}_{mode}_{inputs}_{selection}.h5"
        cmd = bh.mpirun(ranks, [__file__, "--n", str(args.n), "--steps", str(args.steps), "--child", mode, inputs,
               selection if selection != "-" else "blocks", "--out", str(out)], PY)
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            sys.exit(f"{cmd} failed:\n{proc.stderr}")
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        rows.append((ranks, mode, inputs, selection, r))
        print(ranks, mode, inputs, selection, r, flush=True)
        for p in (out, out.with_suffix(".xdmf"), out.with_suffix(".xdmf.h5")):
            p.unlink(missing_ok=True)
    dofs, cells = rows[0][4]["dofs"], rows[0][4]["cells"]
    ref = {ranks: r["median"] for ranks, mode, inputs, _, r in rows
           if mode == "swmr" and inputs == "today"}
    lines = [f"# Output modes: write time per step and rank 0's memory\n",
             f"2D, {dofs:,} DOFs ({cells:,} quads), {args.steps} steps of displacement (N×2), "
             f"nodal stress (N×3), cell stress (C×3): {rows[0][4]['file_mib']:.0f} MiB per file. "
             f"`scripts/bench_output.py`, 2 cores shared with other jobs: compare ratios "
             "within one run. Time: slowest rank; memory: rank 0's peak RSS and its growth "
             "during the 20 steps (the step's data already built).\n",
             "| ranks | mode | inputs | selection | step 1 (s) | per step, median (s) | vs swmr | "
             "rank 0 peak RSS (MiB) | growth while writing (MiB) | file ok |",
             "|---:|---|---|---|---:|---:|---:|---:|---:|---|"]
    for ranks, mode, inputs, selection, r in rows:
        lines.append(f"| {ranks} | {mode} | {inputs} | {selection} | {r['first']:.3f} | "
                     f"{r['median']:.3f} | {r['median'] / ref[ranks]:.2f} | {r['peak_mib']:.0f} | "
                     f"{r['peak_mib'] - r['base_mib']:.0f} | {'yes' if r['ok'] else 'NO'} |")
    text = "\n".join(lines) + "\n"
    print(text)
    bh.publish("bench_output.md", text)


if __name__ == "__main__":
    main()
