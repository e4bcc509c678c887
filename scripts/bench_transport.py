#!/usr/bin/env python3
"""Benchmark: steady Poisson / Darcy with parsolve's diffusion effect against DOLFINx 0.5 on
the same mesh in the same run, and transient solubility under refinement.

Problem: −∇·∇h = 1 on the unit square, h = 0 on the four sides; parsolve's rectangle
generator, n × n quads (Q1) or 2n² triangles (P1), (n+1)² DOFs. The same point and cell
arrays go to DOLFINx (given on rank 0, distributed by DOLFINx).

parsolve (a ``[[diffusion]]`` scene, in a worker process under scripts/mpirun.sh):
  * set-up = build_model + SaddleSystem (partition, numbering, pattern); asm = its first
    assemble(); re-asm = a second assemble() (best of 2);
  * one run of the driver per preset (``direct``: MUMPS; ``iterative``: CG + GAMG, rtol 1e-10
    on the true residual): its /timings (factorization = PCSetUp, solve) and the Krylov
    iterations from its log.
DOLFINx 0.5 (Debian's /usr/bin/python3, same mpirun): form = JIT (excluded), first =
create_matrix + assemble_matrix with the BCs, re = zeroEntries + assemble_matrix (best of 3);
MUMPS LU and CG + GAMG with the same options; max |h_parsolve − h_DOLFINx| is checked through
the solution's maximum and L2-like norm (‖h‖₂ / √DOFs), which do not depend on numbering.
Times are the slowest rank's (barrier, then max over ranks).

Transient solubility: read from scripts/results/bench_solubility.json (run
scripts/bench_solubility.py first): time per step and active-set iterations per step on the
refined strip.

    .venv/bin/python scripts/bench_transport.py [--sizes 125 250]   → table on stdout,
        scripts/results/bench_transport.md and .json; scratch in bench_results/transport/
    .venv/bin/python scripts/bench_transport.py --smoke   (n = 8, 1 rank; files in a temp folder)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import bench_harness as bh
from bench_harness import child_env

ROOT = bh.ROOT
OUT = bh.SCRATCH / "transport"
RESULTS = bh.PUBLISHED                # scripts/results/ (a temporary folder in smoke mode)
VENV_PY, DEBIAN_PY = bh.VENV_PY, bh.DEBIAN_PY
SIZES = (125, 250, 500, 1000)      # (n+1)² DOFs: 16k, 63k, 251k, 1.0M
CELLS = ("triangle", "quad")
RANKS = (1, 2)
PRESETS = ("direct", "iterative")
CG_RTOL = 1e-10

SCENE = """title = "Poisson on the unit square, h = 0 on the boundary, unit source"
[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = {n}
ny = {n}
cell = "{cell}"

[model]
dimension = 2

[regions]
walls = "x == 0 or x == 1 or y == 0 or y == 1"

[[diffusion]]
field = "h"
[[diffusion.materials]]
conductivity = 1.0

[[loads]]
name = "source"
field = "h"
source = 1.0

[[relations]]
name = "walls"
type = "dirichlet"
field = "h"
region = "walls"
value = 0.0

[solver]
preset = "{preset}"
"""
def scene_text(n: int, cell: str, preset: str) -> str:
    return SCENE.format(n=n, cell=cell, preset=preset)


class Clock:
    """Wall time of a phase on the slowest rank (barrier before, max after)."""

    def __init__(self, comm):
        self.comm = comm

    def __call__(self, fn, *args, **kwargs):
        self.comm.Barrier()
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        dt = time.perf_counter() - t0
        return out, self.comm.allreduce(dt, op=_max_op())


def _max_op():
    from mpi4py import MPI
    return MPI.MAX


# ---------------------------------------------------------------------------------------------
# parsolve worker

def parsolve_worker(n: int, cell: str, json_out: str) -> None:
    import h5py
    from mpi4py import MPI

    from parsolve.driver import run
    from parsolve.model import build_model
    from parsolve.scene import load_scene
    from parsolve.solvers.system import SaddleSystem

    comm = MPI.COMM_WORLD
    clock = Clock(comm)
    tag = f"{cell}_{n}_np{comm.size}"
    out = dict(code="parsolve", cell=cell, n=n, nranks=comm.size, dofs=(n + 1) ** 2)
    scene_file = OUT / f"{tag}_direct.toml"
    for preset in PRESETS:
        if comm.rank == 0:
            (OUT / f"{tag}_{preset}.toml").write_text(scene_text(n, cell, preset))
    comm.Barrier()
    model, t_model = clock(lambda: build_model(load_scene(scene_file), comm))
    system, t_system = clock(SaddleSystem, comm, model)
    _, t_asm = clock(system.assemble)
    out.update(t_setup=t_model + t_system, t_model=t_model, t_system=t_system, t_asm=t_asm,
               t_re=min(clock(system.assemble)[1] for _ in range(2)))
    del system, model
    for preset in PRESETS:
        lines = []
        model = build_model(load_scene(OUT / f"{tag}_{preset}.toml"), comm)
        h5 = str(OUT / f"{tag}_{preset}.h5")
        _, t_run = clock(run, comm, model, h5, {}, log=lines.append)
        its = [int(m.group(1)) for m in (re.search(r"linear its (\d+)", s) for s in lines) if m]
        if comm.rank == 0:
            with h5py.File(h5) as f:
                t = {k: float(f[f"timings/{k}"][()].sum()) for k in f["timings"]}
                h = f["fields/h"][-1, :, 0]
            out[preset] = dict(t_run=t_run, its=its[0] if its else None, hmax=float(h.max()),
                               hnorm=float(np.linalg.norm(h) / np.sqrt(len(h))), **t)
        del model
    if comm.rank == 0:
        Path(json_out).write_text(json.dumps(out, indent=1))


# ---------------------------------------------------------------------------------------------
# DOLFINx worker (Debian's python; imports nothing from parsolve)

def dolfinx_worker(n: int, cell: str, json_out: str) -> None:
    import logging

    import ufl
    from dolfinx import fem, mesh as dmesh
    import dolfinx.fem.petsc as fpetsc
    from dolfinx.cpp.io import perm_vtk
    from mpi4py import MPI
    from petsc4py import PETSc

    logging.getLogger().setLevel(logging.WARNING)
    comm = MPI.COMM_WORLD
    clock = Clock(comm)
    ufl_cell, ctype, k = {"triangle": ("triangle", dmesh.CellType.triangle, 3),
                          "quad": ("quadrilateral", dmesh.CellType.quadrilateral, 4)}[cell]
    if comm.rank == 0:
        arrays = np.load(OUT / f"mesh_{cell}_{n}.npz")
        points = np.ascontiguousarray(arrays["points"][:, :2])
        cells = np.ascontiguousarray(arrays["cells"][:, perm_vtk(ctype, k)].astype(np.int64))
    else:
        points, cells = np.zeros((0, 2)), np.zeros((0, k), dtype=np.int64)
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl_cell, 1))
    msh, t_mesh = clock(dmesh.create_mesh, comm, cells, points, domain)
    V = fem.FunctionSpace(msh, ("Lagrange", 1))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    jit = {"cache_dir": str(OUT / "jit")}
    (a, L), t_form = clock(lambda: (fem.form(ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx, jit_params=jit),
                                    fem.form(fem.Constant(msh, PETSc.ScalarType(1.0)) * v * ufl.dx,
                                             jit_params=jit)))
    fdim = msh.topology.dim - 1
    msh.topology.create_connectivity(fdim, fdim + 1)
    bdofs = fem.locate_dofs_topological(V, fdim, dmesh.exterior_facet_indices(msh.topology))
    bc = fem.dirichletbc(PETSc.ScalarType(0.0), bdofs, V)

    def first():
        A = fpetsc.create_matrix(a)
        fpetsc.assemble_matrix(A, a, bcs=[bc])
        A.assemble()
        return A

    def again(A):
        A.zeroEntries()
        fpetsc.assemble_matrix(A, a, bcs=[bc])
        A.assemble()

    def rhs():
        b = fpetsc.assemble_vector(L)
        fpetsc.apply_lifting(b, [a], bcs=[[bc]])
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fpetsc.set_bc(b, [bc])
        return b

    A, t_first = clock(first)
    t_re = min(clock(again, A)[1] for _ in range(3))
    b, t_rhs = clock(rhs)
    out = dict(code="dolfinx", cell=cell, n=n, nranks=comm.size, dofs=V.dofmap.index_map.size_global,
               t_mesh=t_mesh, t_form=t_form, t_first=t_first, t_re=t_re, t_rhs=t_rhs)
    methods = {"direct": {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"},
               "iterative": {"ksp_type": "cg", "pc_type": "gamg", "ksp_rtol": CG_RTOL,
                             "ksp_norm_type": "unpreconditioned"}}
    opts = PETSc.Options()
    for name, popts in methods.items():
        prefix = f"b_{name}_"
        for key, val in popts.items():
            opts[prefix + key] = val
        ksp = PETSc.KSP().create(comm)
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(A)
        ksp.setFromOptions()
        x = A.createVecRight()
        _, t_setup = clock(ksp.setUp)
        _, t_solve = clock(ksp.solve, b, x)
        hmax = comm.allreduce(float(x.array.max()) if x.getLocalSize() else -np.inf, op=_max_op())
        out[name] = dict(factorization=t_setup, solve=t_solve, its=ksp.getIterationNumber(),
                         reason=int(ksp.getConvergedReason()), hmax=hmax,
                         hnorm=float(x.norm() / np.sqrt(out["dofs"])))
        ksp.destroy()
    if comm.rank == 0:
        Path(json_out).write_text(json.dumps(out, indent=1))


# ---------------------------------------------------------------------------------------------
# driver

def launch(code: str, n: int, cell: str, nranks: int) -> dict:
    py = DEBIAN_PY if code == "dolfinx" else VENV_PY
    js = OUT / f"{code}_{cell}_{n}_np{nranks}.json"
    js.unlink(missing_ok=True)
    cmd = bh.mpirun(nranks, [__file__, code, "--n", str(n), "--cell", cell, "--json", str(js)], py)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, env=child_env(), capture_output=True, text=True,
                          timeout=900)
    if proc.returncode != 0 or not js.exists():
        tail = (proc.stdout + proc.stderr).strip().splitlines()[-3:]
        return dict(code=code, cell=cell, n=n, nranks=nranks, failed=" / ".join(tail))
    out = json.loads(js.read_text())
    out["wall"] = time.perf_counter() - t0
    return out


def write_meshes(sizes: tuple[int, ...]) -> None:
    from parsolve.mesh.generators import rectangle

    for cell in CELLS:
        for n in sizes:
            mesh = rectangle(1.0, 1.0, n, n, cell=cell)
            np.savez(OUT / f"mesh_{cell}_{n}.npz", points=mesh.points, cells=mesh.cells)


def _f(x, fmt=".3f") -> str:
    return "–" if x is None else format(x, fmt)


STEADY_HEAD = (
    "| cell | np | n | DOFs | parsolve model s | system + asm s | re-asm s | DOLFINx first s "
    "| DOLFINx re s | ×DOLFINx first | ×DOLFINx re | direct: fact + solve s | DOLFINx s "
    "| iterative: setup + solve s | its | DOLFINx s | DOLFINx its | max h (parsolve / DOLFINx) |\n"
    "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|")


def steady_line(p: dict, d: dict | None) -> str:
    """×DOLFINx: parsolve's rate over DOLFINx's (DOLFINx time / parsolve time; ≥ 1: as fast)."""
    if "failed" in p:
        return f"| {p['cell']} | {p['nranks']} | {p['n']} | | parsolve FAILED: {p['failed']} |"
    dok = d is not None and "failed" not in d
    di, it = p["direct"], p["iterative"]
    first = p["t_system"] + p["t_asm"]
    dd = d if dok else {}
    get = lambda *keys: _dig(dd, keys)  # noqa: E731
    return (f"| {p['cell']} | {p['nranks']} | {p['n']} | {p['dofs']} | {p['t_model']:.3f} | "
            f"{first:.3f} | {p['t_re']:.3f} | {_f(get('t_first'))} | {_f(get('t_re'))} | "
            f"{_f(get('t_first') and get('t_first') / first, '.2f')} | "
            f"{_f(get('t_re') and get('t_re') / p['t_re'], '.2f')} | "
            f"{di['factorization'] + di['solve']:.3f} | "
            f"{_f(get('direct', 'factorization') and get('direct', 'factorization') + get('direct', 'solve'))} | "
            f"{it['factorization'] + it['solve']:.3f} | {it['its']} | "
            f"{_f(get('iterative', 'factorization') and get('iterative', 'factorization') + get('iterative', 'solve'))} | "
            f"{_f(get('iterative', 'its'), 'd')} | {di['hmax']:.6f} / {_f(get('direct', 'hmax'), '.6f')} |")


def _dig(d: dict, keys) -> float | None:
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d


def solubility_table() -> str:
    path = RESULTS / "bench_solubility.json"
    if not path.exists():
        return "(scripts/results/bench_solubility.json missing: run scripts/bench_solubility.py)\n"
    data = json.loads(path.read_text())
    head = ("| nx | nodes | method | s / step | iterations / step (mean) | max | compute s | steps s |\n"
            "|---:|---:|---|---:|---:|---:|---:|---:|\n")
    lines = []
    for r in data["rows"]:
        if r["family"] != "strip" or "failed" in r:
            continue
        its = np.asarray(r["iterations"])
        lines.append(f"| {r['size']} | {r['nodes']} | {r['method']} | {r['per_step'] * 1e3:.1f} ms | "
                     f"{its.mean():.2f} | {its.max()} | {r['compute']:.2f} | {r['steps_time']:.2f} |")
    return f"From bench_solubility ({data['machine']}):\n\n" + head + "\n".join(lines) + "\n"


def findings(rows: list[tuple[dict, dict | None]]) -> str:
    """Plain statements computed from the rows."""
    ok = [(p, d) for p, d in rows if "failed" not in p]
    both = [(p, d) for p, d in ok if d is not None and "failed" not in d]
    out = []
    if both:
        re_r = [(d["t_re"] / p["t_re"], p) for p, d in both]
        first_r = [(d["t_first"] / (p["t_system"] + p["t_asm"]), p) for p, d in both]
        big = [(r, p) for r, p in re_r if p["dofs"] >= 250_000]
        worst = min(re_r, key=lambda rp: rp[0])
        out.append(
            f"- **Re-assembly vs DOLFINx** (target: at least DOLFINx's rate, ×DOLFINx re ≥ 1): "
            f"{sum(r >= 1 for r, _ in re_r)} of {len(re_r)} rows meet it; range "
            f"{min(r for r, _ in re_r):.2f}–{max(r for r, _ in re_r):.2f}, worst {worst[0]:.2f} "
            f"({worst[1]['cell']}, np={worst[1]['nranks']}, n={worst[1]['n']})"
            + (f"; at ≥ 250k DOFs {min(r for r, _ in big):.2f}–{max(r for r, _ in big):.2f}." if big else "."))
        out.append(f"- **First assembly** (parsolve SaddleSystem + assemble vs DOLFINx create_matrix + "
                   f"assemble_matrix; parsolve's scene/mesh/model building and DOLFINx's mesh "
                   f"distribution and JIT excluded): ×DOLFINx {min(r for r, _ in first_r):.2f}–"
                   f"{max(r for r, _ in first_r):.2f}.")
        dr = [(d["direct"]["factorization"] + d["direct"]["solve"])
              / (p["direct"]["factorization"] + p["direct"]["solve"]) for p, d in both]
        ir = [(d["iterative"]["factorization"] + d["iterative"]["solve"])
              / (p["iterative"]["factorization"] + p["iterative"]["solve"]) for p, d in both]
        out.append(f"- **Solves vs DOLFINx** (same PETSc underneath; DOLFINx time / parsolve time): "
                   f"MUMPS {min(dr):.2f}–{max(dr):.2f}, CG + GAMG {min(ir):.2f}–{max(ir):.2f}.")
        dh = max(abs(p["direct"]["hmax"] - d["direct"]["hmax"]) for p, d in both)
        out.append(f"- **Same answer**: max h differs from DOLFINx's by at most {dh:.1e} "
                   f"(max h ≈ {both[-1][0]['direct']['hmax']:.4f}).")
    for cell in CELLS:
        for nr in RANKS:
            seq = sorted((p for p, _ in ok if p["cell"] == cell and p["nranks"] == nr), key=lambda p: p["n"])
            if seq:
                out.append(f"- **CG + GAMG iterations**, {cell}, {nr} rank{'s' * (nr > 1)}: "
                           + ", ".join(f"{p['iterative']['its']} (n={p['n']})" for p in seq)
                           + (f"; DOLFINx " + ", ".join(str(d["iterative"]["its"]) for p, d in both
                                                        if p["cell"] == cell and p["nranks"] == nr)
                              if both else "") + ".")
    two = {(p["cell"], p["n"]): p for p, _ in ok if p["nranks"] == 2}
    sp = [(p, two[(p["cell"], p["n"])]) for p, _ in ok if p["nranks"] == 1 and (p["cell"], p["n"]) in two]
    if sp:
        big = max(sp, key=lambda ab: ab[0]["n"])
        a, b = big
        out.append(f"- **2 ranks vs 1** at n={a['n']} ({a['cell']}): re-assembly "
                   f"{a['t_re'] / b['t_re']:.2f}×, MUMPS {(a['direct']['factorization'] + a['direct']['solve']) / (b['direct']['factorization'] + b['direct']['solve']):.2f}×, "
                   f"CG + GAMG {(a['iterative']['factorization'] + a['iterative']['solve']) / (b['iterative']['factorization'] + b['iterative']['solve']):.2f}× "
                   "faster (speed-up; the machine is shared, see the load).")
    return "\n".join(out) + "\n"


INTRO = """# Transport benchmark: steady Poisson / Darcy against DOLFINx 0.5, transient solubility

−∇·∇h = 1 on the unit square, h = 0 on its sides, P1 triangles and Q1 quads from parsolve's
rectangle generator; the same point and cell arrays go to DOLFINx 0.5 (Debian), run in the same
script, one size after the other, each code in its own process under `scripts/mpirun.sh`.
parsolve: *model* = scene → model (mesh generation, regions, effects); *system + asm* =
`SaddleSystem` (partition, numbering, pattern) + first `assemble()`; *re-asm* = a second
`assemble()` (best of 2); solves from the driver's /timings (preset `direct`: MUMPS LU;
`iterative`: CG + GAMG, rtol 1e-10 on the true residual) and the Krylov iterations from its log.
DOLFINx: *first* = `create_matrix` + `assemble_matrix` with the BC (JIT excluded), *re* =
`zeroEntries` + `assemble_matrix` (best of 3); the same two solvers on its matrix. Times: the
slowest rank's. ×DOLFINx = DOLFINx time / parsolve time (≥ 1: parsolve at least as fast).
Direct solves are not the same factorization: parsolve's preset factors the symmetric operator
by MUMPS Cholesky (LDLᵀ, QAMD ordering), DOLFINx here by MUMPS LU (default ordering), so about
half the work; CG + GAMG has the same options on both sides (parsolve's iterative preset).
The machine is shared: a single row can be hit by other jobs (see the load); compare ratios
along a column rather than one row.
"""


def report(rows, machine: str) -> str:
    table = STEADY_HEAD + "\n" + "\n".join(steady_line(p, d) for p, d in rows) + "\n"
    return (f"{INTRO}\nMachine: {machine}\n\n## Steady Poisson\n\n{table}\n### Findings\n\n"
            f"{findings(rows)}\n## Transient solubility under refinement (grow-shrink strip)\n\n"
            f"{solubility_table()}")


def main(sizes: tuple[int, ...] = SIZES, ranks: tuple[int, ...] = RANKS) -> None:
    if "--report" in sys.argv[1:]:  # rewrite the markdown from the saved rows
        if "--partial" in sys.argv[1:]:  # a run cut short: the rows saved so far
            data = dict(rows=json.loads((OUT / "partial.json").read_text()),
                        machine=sys.argv[sys.argv.index("--partial") + 1])
        else:
            data = json.loads((RESULTS / "bench_transport.json").read_text())
        rows = sorted(((r["parsolve"], r["dolfinx"]) for r in data["rows"]),
                      key=lambda pd: (pd[0]["cell"], pd[0]["nranks"], pd[0]["n"]))
        (RESULTS / "bench_transport.md").write_text(report(rows, data["machine"]))
        return
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "jit").mkdir(exist_ok=True)
    RESULTS.mkdir(exist_ok=True)
    load0, t0 = os.getloadavg(), time.perf_counter()
    write_meshes(sizes)
    peer = bh.peer_available("dolfinx")
    print(STEADY_HEAD, flush=True)
    rows = []
    for n in sizes:  # smallest sizes first everywhere: a cut-short run still has a trend
        for cell in CELLS:
            for nr in ranks:
                p = launch("parsolve", n, cell, nr)
                d = launch("dolfinx", n, cell, nr) if peer else None
                rows.append((p, d))
                print(steady_line(p, d), flush=True)
                (OUT / "partial.json").write_text(json.dumps([dict(parsolve=a, dolfinx=b) for a, b in rows]))
    rows.sort(key=lambda pd: (pd[0]["cell"], pd[0]["nranks"], pd[0]["n"]))
    load1, seconds = os.getloadavg(), time.perf_counter() - t0
    machine = (f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
               f"{bh.load_line(load0, load1)}; run {bh.utc_now()} UTC, {seconds:.0f} s; "
               f"DOLFINx {'0.5 (Debian)' if peer else 'not installed'}")
    print(f"\n{machine}\n\n{findings(rows)}\n{solubility_table()}")
    bh.write_json(RESULTS / "bench_transport.json",
                  dict(machine=machine, rows=[dict(parsolve=p, dolfinx=d) for p, d in rows]))
    (RESULTS / "bench_transport.md").write_text(report(rows, machine))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", nargs="?", default="main", choices=("main", "parsolve", "dolfinx"))
    ap.add_argument("--n", type=int)
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SIZES),
                    help="n of the n × n meshes (default: %(default)s; ~19 min at load ~7)")
    ap.add_argument("--cell")
    ap.add_argument("--json")
    ap.add_argument("--report", action="store_true", help="rewrite the markdown from the saved JSON")
    ap.add_argument("--partial", help="with --report: from the partial rows; the machine line")
    bh.add_smoke(ap)
    a = ap.parse_args()
    if a.smoke and a.mode == "main":   # n = 8, 1 rank, both cells; DOLFINx if installed
        a.sizes, ranks = [8], (1,)
    else:
        ranks = RANKS
    if a.mode == "parsolve":
        parsolve_worker(a.n, a.cell, a.json)
    elif a.mode == "dolfinx":
        dolfinx_worker(a.n, a.cell, a.json)
    else:
        sys.exit(main(tuple(a.sizes), ranks))
