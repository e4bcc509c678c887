#!/usr/bin/env python3
"""Scale benchmark: memory per rank and time per phase against DOLFINx 0.5 at 1 and 2
ranks, weak scaling at 1, 2 and 4 ranks, and a model of 64 ranks × 50M DOFs fitted on them.

Problems: a clamped block under an end traction (E = 1, ν = 0.3; u = 0 on x = 0, traction −1
along the last axis on x = 1), one linear step:
  2d-direct     unit square, N × N quads split into 2N² P1 triangles, plane strain, MUMPS
                (parsolve's direct preset: LDLᵀ, QAMD, null-pivot detection), 2(N+1)² DOFs;
  3d-iterative  unit cube, N³ Q1 hexahedra, CG + GAMG with the rigid-body modes (parsolve's
                iterative preset, rtol 1e-10 on the true residual), 3(N+1)³ DOFs;
  (2d-iterative and 3d-direct on request: --cases).
The same points and cells (parsolve's generator, saved as npz) go to DOLFINx, given on rank 0 and
distributed by it, with the same PETSc solver options as parsolve's preset (Debian's
/usr/bin/python3 runs scripts/bench_peers.py's `dolfinx_phases`). Every run is a fresh process
under scripts/mpirun.sh, one thread per rank.

Phases (CPU seconds, max over ranks: the machine is shared, so wall seconds also count other
processes; wall seconds are in the JSON and the last columns):
  set-up          parsolve: load_scene + build_model (mesh generation, regions, effects) +
                  SaddleSystem (partition, numbering, pattern, operator) + make_solver;
                  DOLFINx: create_mesh + function spaces + BC + meshtags (the forms' JIT apart);
  assembly        parsolve: SaddleSystem.assemble (first); DOLFINx: create_matrix +
                  assemble_matrix + the right-hand side;
  factorization   PCSetUp: MUMPS analysis + factorization, or GAMG's hierarchy;
  solve           KSPSolve (parsolve: + its true-residual check);
  post            the stresses: parsolve: gather + unpack + step_outputs (cell means, nodal
                  averages, relation outputs); DOLFINx: DG0 interpolation + lumped projection;
  output          parsolve: ResultWriter (HDF5 + XDMF: create, write_step, close); DOLFINx:
                  XDMFFile of the mesh, u and both stresses.
parsolve's phases are timed by wrapping the driver's own calls (SaddleSystem, make_solver,
the solver's factorization, step_outputs, ResultWriter) from this script; the package is not
changed. Its /timings group (assembly, factorization, solve) is kept in the JSON beside them.

Memory per rank: VmHWM (peak resident, /proc/self/status) after every phase, the max over ranks;
the numpy arrays parsolve holds, by what holds them (mesh; operator = node pattern + saddle
operator + relation block; element = the effects and their composition; vectors = the step's
solution, multipliers and output fields; other = partition, numbering, relations), found by
walking the objects after assembly and after the post-processing; the PETSc matrix (MatGetInfo:
allocated nonzeros × 12 B + row offsets) and MUMPS's own factor memory (INFOG(21): used, max
over ranks; INFOG(16): estimated). --trace adds tracemalloc's peak of Python + numpy memory per
phase (slower: not for timings).

Fits (least squares on the relative error, coefficients ≥ 0): memory per rank = a + b·N + c·N/P
and CPU time per phase likewise, on every (N, P) measured (4-rank runs count for memory, not for
time: 2 cores), then the model at 64 ranks × 50M DOFs.

Mesh: parsolve has one mode, the distributed mesh (rank 0 builds the whole mesh and partitions
it, each rank keeps its owned cells + one ghost layer; at 1 rank the whole mesh itself).

Usage (repository root):
    .venv/bin/python scripts/bench_scale.py                  # ≈ 35-40 min on 2 loaded cores
    .venv/bin/python scripts/bench_scale.py --quick          # small sizes, a smoke test
    .venv/bin/python scripts/bench_scale.py --smoke          # CI: one tiny size, files in a temp folder
    .venv/bin/python scripts/bench_scale.py --sizes 2d-direct=1000,1414,2000 3d-iterative=60,79,100
    .venv/bin/python scripts/bench_scale.py --report         # tables again from the JSON
    .venv/bin/python scripts/bench_scale.py --phases post --baseline /tmp/main  # post only
Writes scripts/results/bench_scale.md and .json; scratch in bench_results/scale/. With
--phases post: set-up, one solve and the post-processing only (no output phase, no weak
scaling, sizes 2d-direct 432, 611 and 3d-iterative 37, 47), with a second assembly timed, and
--baseline DIR runs parsolve's package from DIR too (e.g. main before a change) in the same
run: scripts/results/bench_post.md and .json.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import bench_harness as bh
from bench_harness import (DEBIAN_PY, MiB, ROOT, SCRIPTS, VENV_PY, cpu_seconds,  # noqa: F401
                           machine_info, proc_memory)
from bench_harness import mat_bytes as _mat_bytes

RESULTS = bh.PUBLISHED                # scripts/results/ (a temporary folder in smoke mode)
SCRATCH = bh.SCRATCH / "scale"


def child_env() -> dict:
    """One thread per rank, no MPI singleton variables, the repository on PYTHONPATH (Debian's
    python runs the DOLFINx worker)."""
    return bh.child_env(pythonpath=True)


def fmt(x, spec=".2f") -> str:
    return bh.fmt(x, spec, "–")


def mib(x) -> str:
    return bh.mib(x)


def md_table(head: list[str], body: list[list[str]]) -> str:
    return bh.md_table(head, body, first="---")

CASES = {
    "2d-direct": dict(dim=2, cell="triangle", preset="direct"),
    "3d-iterative": dict(dim=3, cell="hexahedron", preset="iterative"),
    "2d-iterative": dict(dim=2, cell="triangle", preset="iterative"),
    "3d-direct": dict(dim=3, cell="hexahedron", preset="direct"),
}
# cells per side; each size about twice the one before, so that (1, 2, 4) ranks on them is weak
# scaling. This machine (2 cores, 24 GiB, shared with other engineers' test runs): the largest
# ≲ 1.5M DOFs at most, here less to stay within 40 minutes of a loaded machine; --sizes for
# bigger runs elsewhere (e.g. 2d-direct=432,611,865 3d-iterative=37,47,59: up to 1.5M / 648k).
SIZES = {"2d-direct": [305, 432, 611],          # 187k, 375k, 749k DOFs
         "3d-iterative": [29, 37, 47],          # 81k, 165k, 332k DOFs
         "2d-iterative": [305, 432, 611],
         "3d-direct": [14, 18, 23]}             # 10k, 21k, 41k DOFs
QUICK = {"2d-direct": [60, 85, 120], "3d-iterative": [10, 13, 16], "2d-iterative": [60, 85, 120],
         "3d-direct": [8, 10, 13]}
DEFAULT_CASES = ["2d-direct", "3d-iterative"]
# --phases post: set-up, one solve and the post-processing only (no output, no weak scaling)
POST_SIZES = {**SIZES, "2d-direct": [432, 611], "3d-iterative": [37, 47]}  # 375k, 749k; 165k, 332k
PHASES = ("setup", "assembly", "factorization", "solve", "post", "output")
TARGET = (64, 50e6)  # ranks, DOFs of the model
TRACE_FRAMES = 1
PARTS = ("mesh", "operator", "element", "vectors", "other")
PARSOLVE_CODES = ("parsolve",)


def dofs_of(case: str, n: int) -> int:
    dim = CASES[case]["dim"]
    return dim * (n + 1) ** dim


def scene_text(case: str, n: int) -> str:
    c = CASES[case]
    if c["dim"] == 2:
        mesh = f'generator = "rectangle"\nlx = 1.0\nly = 1.0\nnx = {n}\nny = {n}\ncell = "{c["cell"]}"'
        model, left, right = 'hypothesis = "plane_strain"', "left", "right"
        traction, comps = "[0.0, -1.0]", '["x", "y"]'
    else:
        mesh = (f'generator = "box"\nlx = 1.0\nly = 1.0\nlz = 1.0\nnx = {n}\nny = {n}\nnz = {n}\n'
                f'cell = "{c["cell"]}"')
        model, left, right = 'hypothesis = "3d"', "xmin", "xmax"
        traction, comps = "[0.0, 0.0, -1.0]", '["x", "y", "z"]'
    return f"""title = "bench_scale {case} n={n}"
[mesh]
{mesh}
[model]
{model}
[[materials]]
E = 1.0
nu = 0.3
[[loads]]
name = "end"
region = "{right}"
traction = {traction}
[[relations]]
name = "clamp"
type = "dirichlet"
region = "{left}"
components = {comps}
[steps]
count = 1
[solver]
preset = "{c['preset']}"
"""


def tag_of(code: str, case: str, n: int, nranks: int) -> str:
    return f"{code}_{case}_{n}_np{nranks}"


# ------------------------------------------------------------------------------------------------
# memory helpers (both workers)


def held_bytes(roots: dict[str, list]) -> dict[str, int]:
    """numpy memory held by objects, per category: every array reachable from a category's
    roots through parsolve objects' attributes, dicts, lists and tuples (not through PETSc or
    MPI objects), counted once (views by their base) and in the first category that reaches
    it. Held memory, not temporaries: the peak resident memory shows those."""
    seen: set[int] = set()
    bases: set[int] = set()
    out = {}
    for cat, objs in roots.items():
        total, stack = 0, list(objs)
        while stack:
            o = stack.pop()
            if id(o) in seen:
                continue
            seen.add(id(o))
            if isinstance(o, np.ndarray):
                base = o
                while isinstance(base.base, np.ndarray):
                    base = base.base
                if id(base) not in bases:
                    bases.add(id(base))
                    total += base.nbytes
            elif isinstance(o, dict):
                stack.extend(o.values())
            elif isinstance(o, (list, tuple, set, frozenset)):
                stack.extend(o)
            elif type(o).__module__.startswith("parsolve"):
                stack.extend(vars(o).values() if hasattr(o, "__dict__") else ())
                stack.extend(getattr(o, k) for k in getattr(type(o), "__slots__", ())
                             if hasattr(o, k))
        out[cat] = total
    return out


def parsolve_categories(system, step: tuple | None) -> dict[str, int]:
    """mesh: the model's mesh; operator: the node pattern, the saddle operator, the relations'
    block; element: the effects and their composition (element work arrays); vectors: the
    step's solution, multipliers and output fields; other: the rest of the system and model
    (partition, numbering, relations, regions)."""
    model = system.model
    roots = {"mesh": [model.mesh],
             "operator": [getattr(system, k, None) for k in ("pattern", "op", "block")],
             "element": [model.effects, getattr(system, "composition", None)],
             "vectors": list(step or ()),
             "other": [system, model]}
    return held_bytes(roots)


# ------------------------------------------------------------------------------------------------
# parsolve worker (parsolve's venv, under mpirun)


class Recorder:
    """Per-rank phase seconds and memory snapshots; reduced over ranks by ``result``."""

    def __init__(self, comm, trace: bool):
        self.comm, self.trace = comm, trace
        self.seconds = dict.fromkeys(PHASES, 0.0)
        self.cpu = dict.fromkeys(PHASES, 0.0)
        self.memory: dict[str, dict] = {}
        self.extra: dict = {}
        self.snap_seconds = self.snap_cpu = 0.0  # spent measuring memory: not in the phases

    def timed(self, phase: str, fn, after=None):
        """fn timed into ``phase``, minus the snapshots taken while it ran; then ``after``."""
        def wrapper(*args, **kwargs):
            t0, c0, s0, sc0 = time.perf_counter(), cpu_seconds(), self.snap_seconds, self.snap_cpu
            out = fn(*args, **kwargs)
            self.seconds[phase] += time.perf_counter() - t0 - (self.snap_seconds - s0)
            self.cpu[phase] += cpu_seconds() - c0 - (self.snap_cpu - sc0)
            if after is not None:
                after(out)
            return out
        return wrapper

    def snap(self, name: str, parts=None, **extra) -> None:
        """Resident memory now and at its peak; ``parts()``: held numpy bytes by category;
        with tracing, the traced (Python + numpy) memory now and its peak since the last snap."""
        from mpi4py import MPI

        t0, c0 = time.perf_counter(), cpu_seconds()
        m = proc_memory()
        row = {"rss": m["rss"], "hwm": m["hwm"], **extra}
        if parts is not None:
            row.update({f"np_{k}": v for k, v in parts().items()})
        if self.trace:
            import tracemalloc

            row["traced"], row["traced_peak"] = tracemalloc.get_traced_memory()
            tracemalloc.reset_peak()
        keys = sorted(row)
        vals = np.array([float(row[k]) for k in keys])
        mx, sm = np.empty_like(vals), np.empty_like(vals)
        self.comm.Allreduce(vals, mx, op=MPI.MAX)
        self.comm.Allreduce(vals, sm, op=MPI.SUM)
        self.memory[name] = {**{f"{k}_max": float(v) for k, v in zip(keys, mx)},
                             **{f"{k}_mean": float(v) / self.comm.size for k, v in zip(keys, sm)}}
        self.snap_seconds += time.perf_counter() - t0
        self.snap_cpu += cpu_seconds() - c0

    def result(self) -> dict:
        from mpi4py import MPI

        seconds, cpu = dict(self.seconds), dict(self.cpu)
        seconds["solve"] -= seconds["factorization"]  # solver.solve factorizes first
        cpu["solve"] -= cpu["factorization"]
        slowest = {k: self.comm.allreduce(v, op=MPI.MAX) for k, v in seconds.items()}
        cpu = {k: self.comm.allreduce(v, op=MPI.MAX) for k, v in cpu.items()}
        return {"seconds": slowest, "cpu": cpu, "memory": self.memory,
                "snap_seconds": self.comm.allreduce(self.snap_seconds, op=MPI.MAX), **self.extra}


class NullWriter:
    """Takes every call of a result writer and writes nothing (--phases post: no output)."""

    def __getattr__(self, name):
        return lambda *args, **kwargs: None


def instrument(drv, rec: Recorder, output: bool = True) -> dict:
    """Wrap the driver's calls to time and measure each phase (the package is not changed).
    Returns the objects caught on the way (system, matrix, solver, the step's primal vector,
    the unwrapped assembly). ``output`` False: no result file (a NullWriter takes the steps)."""
    held: dict = {}
    mat_bytes = _mat_bytes

    def on_system(system):
        held["system"] = system
        held["assemble"] = system.assemble
        rec.snap("system")
        system.assemble = rec.timed("assembly", system.assemble, on_matrix)
        for name in ("gather", "unpack"):  # the solution back to fields (if the driver has them)
            if hasattr(system, name):
                setattr(system, name, rec.timed("post", getattr(system, name)))

    def on_matrix(mat):
        held["mat"] = mat
        rec.snap("assembly", lambda: parsolve_categories(held["system"], None),
                 mat_bytes=mat_bytes(mat))

    def on_solver(solver):
        held["solver"] = solver
        if hasattr(solver, "_prepare"):  # the factorization, when the operator changed
            solver._prepare = rec.timed("factorization", solver._prepare,
                                        lambda _: rec.snap("factorization"))
        solver.solve = rec.timed("solve", solver.solve, lambda _: rec.snap("solve"))

    drv.SaddleSystem = rec.timed("setup", drv.SaddleSystem, on_system)
    drv.make_solver = rec.timed("setup", drv.make_solver, on_solver)
    step_outputs = rec.timed("post", drv.step_outputs)

    def outputs(comm, system, q, multipliers, *args, **kwargs):
        out = step_outputs(comm, system, q, multipliers, *args, **kwargs)
        held["q"] = q
        # (the driver passes its step context: the categories walk the system caught above)
        rec.snap("post", lambda: parsolve_categories(held["system"], (q, multipliers, out)))
        return out

    drv.step_outputs = outputs
    make_writer = drv.result_writer

    def writer_of(*args, **kwargs):
        """The result file's creation, steps and closing: the output phase."""
        if not output:
            return NullWriter()
        writer = rec.timed("output", make_writer)(*args, **kwargs)
        for name in ("write_step", "close"):
            setattr(writer, name, rec.timed("output", getattr(writer, name)))
        return writer

    drv.result_writer = writer_of
    return held


def _mumps(solver) -> dict:
    pc = solver.ksp.getPC()
    if pc.getType() not in ("lu", "cholesky") or pc.getFactorMatrix().getType() != "mumps":
        return {}
    F = pc.getFactorMatrix()
    g = {k: int(F.getMumpsInfog(k)) for k in (16, 18, 21, 22, 29)}
    return dict(estimated_mb_max=g[16], allocated_mb_max=g[18], used_mb_max=g[21],
                used_mb_sum=g[22], flops=float(F.getMumpsRinfog(3)),
                factor_entries=float(g[29]) if g[29] >= 0 else -float(g[29]) * 1e6)


def parsolve_worker(case: str, n: int, h5: str, json_out: str, trace: bool,
                    phases: str = "all", petsc: dict | None = None) -> None:
    """One parsolve run, measured; ``petsc``: solver options as given on parsolve's command
    line (over the preset's; --gamg's variants)."""
    if trace:
        import tracemalloc

        tracemalloc.start(TRACE_FRAMES)
    from mpi4py import MPI

    import parsolve.driver as drv
    from parsolve.mesh import memory
    from parsolve.model import build_model
    from parsolve.scene import load_scene

    comm = MPI.COMM_WORLD
    rec = Recorder(comm, trace)
    rec.snap("start")
    scene_file = Path(h5).with_suffix(".toml")
    if comm.rank == 0:
        scene_file.write_text(scene_text(case, n))
    comm.Barrier()
    held = instrument(drv, rec, output=phases == "all")
    t_wall, cpu = time.perf_counter(), cpu_seconds()

    def model_of():
        scene = load_scene(scene_file)
        with memory.agreed_over(comm):
            return build_model(scene, comm)   # each rank its part of the mesh

    model = rec.timed("setup", model_of)()
    rec.snap("model")
    lines: list[str] = []
    status = drv.run(comm, model, h5, dict(petsc or {}), log=lines.append)
    share = (cpu_seconds() - cpu) / (time.perf_counter() - t_wall)  # this rank's
    t_wall = comm.allreduce(time.perf_counter() - t_wall, op=MPI.MAX)
    share = comm.allreduce(share, op=MPI.MIN)
    rec.snap("end")
    # a second assembly (the matrix alone, the factor still held): the re-assembly's rate
    comm.Barrier()
    c0, t0 = cpu_seconds(), time.perf_counter()
    held["assemble"]()
    rec.extra["reassembly"] = comm.allreduce(cpu_seconds() - c0, op=MPI.MAX)
    rec.extra["reassembly_wall"] = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    rec.snap("reassembly", lambda: parsolve_categories(held["system"], None))
    out = rec.result()
    mumps = _mumps(held["solver"])
    its = held["solver"].ksp.getIterationNumber()
    checks = None if phases == "all" else _q_checks(comm, held["q"], model.mesh)
    if comm.rank == 0:
        out.update(code="parsolve", case=case, n=n, nranks=comm.size, dofs=dofs_of(case, n),
                   status=status, t_wall=t_wall, cpu_share=share, iterations=its, mumps=mumps,
                   trace=trace, log=lines, phases=phases,
                   **(_solution_checks(h5) if phases == "all" else checks))
        Path(json_out).write_text(json.dumps(out, indent=1))


def _solution_checks(h5: str) -> dict:
    """||u||₂, max |u|, u at the corner x = y (= z) = 1, and the file's /timings (the file's
    points: a distributed mesh's rank 0 holds only its part)."""
    import h5py

    with h5py.File(h5, "r") as f:
        u = f["fields/displacement"][-1]
        points = f["mesh/points"][...]
        timings = {k: float(f[f"timings/{k}"][()].sum()) for k in f["timings"]}
        residual = float(f["steps/residual"][-1])
    corner = np.flatnonzero(np.all(np.isclose(points, 1.0), axis=1))[0]
    return dict(unorm=float(np.linalg.norm(u)), umax=float(np.abs(u).max()),
                corner=u[corner].tolist(), timings=timings, relres=residual)


def _q_checks(comm, q: np.ndarray, mesh) -> dict:
    """||u||₂, max |u|, u at the corner x = y (= z) = 1, from the step's primal vector on this
    rank's part (its nodes: owned first, then ghosts; each node counted by its owner;
    collective)."""
    from mpi4py import MPI

    owned = mesh.n_owned
    u = q.reshape(len(mesh.points), -1)[:owned]
    hit = np.flatnonzero(np.all(np.isclose(mesh.points[:owned], 1.0), axis=1))
    corner = u[hit[0]] if hit.size else np.zeros(u.shape[1])
    corner = comm.allreduce(corner, op=MPI.SUM)   # one owner holds it
    return dict(unorm=float(np.sqrt(comm.allreduce(float(np.sum(u * u)), op=MPI.SUM))),
                umax=comm.allreduce(float(np.abs(u).max()) if u.size else 0.0, op=MPI.MAX),
                corner=np.asarray(corner).tolist())


# ------------------------------------------------------------------------------------------------
# DOLFINx worker (Debian's python: scripts/bench_peers.py's dolfinx_phases)


def dolfinx_worker(case: str, n: int, mesh_file: str, options: str, out_file: str,
                   json_out: str, quadrature: tuple[int, ...] = ()) -> None:
    import bench_peers
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    c = CASES[case]
    t0 = time.perf_counter()
    r = bench_peers.dolfinx_phases(mesh_file, c["cell"], json.loads(options), out_file,
                                   comm=comm, jit_cache=str(SCRATCH / "jit"),
                                   near_null=c["preset"] == "iterative",
                                   quadrature=quadrature)
    wall = time.perf_counter() - t0
    forms = r["seconds"]["forms"]  # JIT: not a phase (a C compiler runs in a child)
    share = sum(r["cpu"].get(p, 0.0) for p in PHASES) / sum(r["seconds"].get(p, 0.0)
                                                           for p in PHASES)
    wall = comm.allreduce(wall, op=MPI.MAX)
    if comm.rank == 0:
        mem = r["memory"]
        out = dict(code="dolfinx", case=case, n=n, nranks=comm.size, dofs=r["dofs"],
                   seconds={p: r["seconds"].get(p, 0.0) for p in PHASES},
                   cpu={p: r["cpu"].get(p, 0.0) for p in PHASES},
                   memory={k: _dolfinx_mem(v) for k, v in mem.items()},
                   mumps={k: v for k, v in mem["factorization"].items()
                          if not k.startswith(("rss", "hwm"))},
                   iterations=r["iterations"], relres=r["relres"], unorm=r["unorm"],
                   umax=r["umax"], corner=r["corner"], t_forms=forms,
                   reassembly=r["cpu"]["reassembly"],
                   quadrature={str(q): {k: r["cpu"][f"{k}_q{q}"] for k in ("assembly", "reassembly")}
                               for q in quadrature},
                   t_wall=wall, cpu_share=share,
                   versions=r["versions"], status="complete" if r["converged_reason"] > 0
                   else f"failed: reason {r['converged_reason']}")
        Path(json_out).write_text(json.dumps(out, indent=1))


def _dolfinx_mem(row: dict) -> dict:
    """The memory figures of a snapshot (rss_*, hwm_*, mat_bytes_*), as the parsolve worker's."""
    return {k: v for k, v in row.items() if k.startswith(("rss", "hwm", "mat_bytes"))}


# ------------------------------------------------------------------------------------------------
# driver


def save_mesh(case: str, n: int) -> Path:
    from parsolve.mesh.generators import box, rectangle

    path = SCRATCH / f"mesh_{case.split('-')[0]}_{n}.npz"
    if not path.exists():
        c = CASES[case]
        mesh = (rectangle(1.0, 1.0, n, n, cell=c["cell"]) if c["dim"] == 2
                else box(1.0, 1.0, 1.0, n, n, n, cell=c["cell"]))
        np.savez(path, points=mesh.points, cells=mesh.cells)
    return path


def solver_options(case: str) -> dict:
    """parsolve's preset options for this case (symmetric, no multipliers): DOLFINx gets them."""
    from parsolve.solvers.linear import preset_options

    return preset_options(CASES[case]["preset"], True, False)


def launch(code: str, case: str, n: int, nranks: int, trace: bool, timeout: float,
           phases: str = "all", baseline: str | None = None,
           quadrature: tuple[int, ...] = (), petsc: dict | None = None,
           tag: str | None = None) -> dict:
    """One run in a fresh process. ``code``: parsolve, dolfinx, or baseline (parsolve's worker
    on the package found in the folder ``baseline``, e.g. an unchanged copy of main)."""
    tag = tag or tag_of(code, case, n, nranks)
    js = SCRATCH / f"{tag}.json"
    js.unlink(missing_ok=True)
    env = child_env()
    if code in PARSOLVE_CODES + ("baseline",):
        args = [VENV_PY, __file__, "--worker", "parsolve", case, str(n), "--h5",
                str(SCRATCH / f"{tag}.h5"), "--json", str(js), "--phases", phases] \
            + (["--trace"] if trace else []) \
            + (["--options", json.dumps(petsc)] if petsc else [])
        if code == "baseline":
            env["PYTHONPATH"] = str(Path(baseline).resolve())
    else:
        args = [DEBIAN_PY, __file__, "--worker", "dolfinx", case, str(n), "--mesh-file",
                str(save_mesh(case, n)), "--options", json.dumps(solver_options(case)),
                "--json", str(js)]
        # the other degrees on hexahedra only (a P1 triangle's default is parsolve's one point)
        args += ["--quadrature",
                 *(map(str, quadrature) if CASES[case]["cell"] == "hexahedron" else ())]
        if phases == "all":  # no output file: no output phase
            args += ["--h5", str(SCRATCH / f"{tag}.xdmf")]
    cmd = ["bash", str(SCRIPTS / "mpirun.sh"), "-n", str(nranks), *args]
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True,
                              timeout=timeout)
        failed = proc.returncode != 0 or not js.exists()
        tail = " / ".join((proc.stdout + proc.stderr).strip().splitlines()[-4:])
    except subprocess.TimeoutExpired:
        failed, tail = True, f"timed out after {timeout:.0f} s"
    wall = time.perf_counter() - t0
    for junk in SCRATCH.glob(f"{tag}.*"):  # results: only the JSON is kept
        if junk.suffix in (".h5", ".xdmf") or junk.name.endswith(".xdmf.h5"):
            junk.unlink(missing_ok=True)
    if failed:
        return dict(code=code, case=case, n=n, nranks=nranks, dofs=dofs_of(case, n),
                    failed=tail[-600:], process_wall=wall, phases=phases)
    out = json.loads(js.read_text())
    out["code"] = code
    out["process_wall"] = wall
    out["loadavg"] = os.getloadavg()[0]
    return out


def plan(cases: list[str], sizes: dict, ranks: list[int], weak: list[int]) -> list[tuple]:
    """(case, n, nranks) in run order: every size at every rank count, then the weak-scaling
    points not measured yet (weak[i] ranks on sizes[i])."""
    runs = []
    for case in cases:
        for n in sizes[case]:
            runs += [(case, n, p) for p in ranks]
        runs += [(case, sizes[case][i], p) for i, p in enumerate(weak)
                 if i < len(sizes[case]) and (case, sizes[case][i], p) not in runs]
    return runs


def run_all(args) -> dict:
    SCRATCH.mkdir(parents=True, exist_ok=True)
    info = machine_info()
    post = args.phases == "post"
    sizes = {**(QUICK if args.quick else POST_SIZES if post else SIZES), **args.sizes}
    rows = []
    t_start = time.perf_counter()
    weak = [] if post else args.weak
    codes = (["baseline"] if args.baseline else []) + list(PARSOLVE_CODES) \
        + ([] if args.no_peers else ["dolfinx"])
    for case, n, p in plan(args.cases, sizes, args.ranks, weak):
        for code in codes:  # one after the other: the same load on the machine
            if code == "dolfinx":
                save_mesh(case, n)
            r = launch(code, case, n, p, args.trace, args.timeout, args.phases,
                       args.baseline, tuple(args.quadrature))
            rows.append(r)
            print(progress_line(r), flush=True)
    info["loadavg_end"] = os.getloadavg()
    return dict(machine=info, elapsed=time.perf_counter() - t_start, rows=rows,
                sizes={c: sizes[c] for c in args.cases}, ranks=args.ranks, weak=weak,
                cases=args.cases, trace=args.trace, phases=args.phases,
                baseline=args.baseline, baseline_label=args.baseline_label)


def progress_line(r: dict) -> str:
    head = f"[bench_scale] {r['code']:13s} {r['case']:12s} n={r['n']:4d} np={r['nranks']} " \
           f"DOFs={r['dofs']:>9,}"
    if "failed" in r:
        return f"{head}  FAILED: {r['failed']}"
    s = r["cpu"]
    return (f"{head}  peak/rank {peak(r) / MiB:7.0f} MiB  "
            + "CPU s: " + " ".join(f"{k} {s[k]:.2f}" for k in PHASES)
            + f"  wall {r['process_wall']:.0f} s, cpu share {r.get('cpu_share', 0):.2f}")


# ------------------------------------------------------------------------------------------------
# analysis


def peak(r: dict) -> float:
    """Peak resident memory per rank (max over ranks) over the whole run, bytes."""
    return max(v.get("hwm_max", 0.0) for v in r["memory"].values())


def memory_parts(r: dict) -> dict:
    """The split of one run, bytes per rank (max over ranks): the process before the mesh
    (start), held numpy by category at its largest (parsolve), the matrix, MUMPS (used and
    estimated), and for DOLFINx the resident growth over its set-up (mesh + spaces, C++)."""
    m = r["memory"]
    out = {"peak": peak(r), "start": m["start"]["rss_max"]}
    for part in PARTS:
        out[part] = max((v[f"np_{part}_max"] for v in m.values() if f"np_{part}_max" in v),
                        default=None)
    out["traced_peak"] = max((v["traced_peak_max"] for v in m.values()
                              if "traced_peak_max" in v), default=None)
    out["matrix"] = max((v.get("mat_bytes_max", 0.0) for v in m.values()), default=0.0)
    mumps = r.get("mumps") or {}
    out["mumps"] = mumps["used_mb_max"] * 1e6 if "used_mb_max" in mumps else None
    out["mumps_est"] = mumps["estimated_mb_max"] * 1e6 if "estimated_mb_max" in mumps else None
    if r["code"] == "dolfinx":
        out["mesh"] = m["setup"]["rss_max"] - m["start"]["rss_max"]
    return out


def fit(points: list[tuple[float, float, float]]) -> dict | None:
    """y = a + b·N + c·N/P, a, b, c ≥ 0, least squares on the relative error (every subset of
    the terms is tried, the best non-negative one kept); points (N, P, y)."""
    pts = [(N, P, y) for N, P, y in points if y is not None and y > 0]
    if len({(N, P) for N, P, _ in pts}) < 3 or len({P for _, P, _ in pts}) < 2:
        return None
    N, P, y = (np.array(v, dtype=float) for v in zip(*pts))
    X = np.column_stack([np.ones_like(N), N, N / P])
    best = None
    for mask in ((1, 1, 1), (1, 1, 0), (1, 0, 1), (0, 1, 1), (1, 0, 0), (0, 1, 0), (0, 0, 1)):
        cols = [k for k in range(3) if mask[k]]
        sol, *_ = np.linalg.lstsq(X[:, cols] / y[:, None], np.ones_like(y), rcond=None)
        if np.any(sol < 0):
            continue
        coef = np.zeros(3)
        coef[cols] = sol
        err = float(np.sum((X @ coef / y - 1) ** 2))
        if best is None or err < best[0]:
            best = (err, coef)
    coef = best[1]
    return dict(a=float(coef[0]), b=float(coef[1]), c=float(coef[2]),
                worst=float(np.max(np.abs(X @ coef / y - 1))), points=len(pts))


def at(f: dict | None, N: float, P: float) -> float | None:
    return None if f is None else f["a"] + f["b"] * N + f["c"] * N / P


def ok_rows(rows, code=None, case=None):
    return [r for r in rows if "failed" not in r and (code is None or r["code"] == code)
            and (case is None or r["case"] == case)]


def fits(out: dict) -> dict:
    """Per case and code: the fits of peak memory per rank, of each memory part, and of each
    phase's time (1 and 2 ranks only: 4 ranks on 2 cores time the oversubscription)."""
    res = {}
    for case in out["cases"]:
        for code in PARSOLVE_CODES + ("dolfinx",):
            rows = ok_rows(out["rows"], code, case)
            if not rows:
                continue
            f = {"peak": fit([(r["dofs"], r["nranks"], peak(r)) for r in rows])}
            if any(memory_parts(r)["mumps"] for r in rows):  # the peak besides MUMPS's factor
                f["rest"] = fit([(r["dofs"], r["nranks"],
                                  peak(r) - (memory_parts(r)["mumps"] or 0.0)) for r in rows])
            for part in PARTS + ("matrix", "mumps"):
                f[part] = fit([(r["dofs"], r["nranks"], memory_parts(r)[part]) for r in rows])
            timed = [r for r in rows if r["nranks"] <= 2]
            for ph in PHASES:
                f[f"t_{ph}"] = fit([(r["dofs"], r["nranks"], r["cpu"][ph]) for r in timed])
            f["t_total"] = fit([(r["dofs"], r["nranks"], sum(r["cpu"].values()))
                                for r in timed])
            res[f"{case}/{code}"] = f
    return res


# ------------------------------------------------------------------------------------------------
# tables


def pairs(out: dict):
    """(parsolve row, DOLFINx row or None) for every parsolve run, in run order."""
    peers = {(r["case"], r["n"], r["nranks"]): r for r in ok_rows(out["rows"], "dolfinx")}
    for r in out["rows"]:
        if r["code"] in PARSOLVE_CODES:
            yield r, peers.get((r["case"], r["n"], r["nranks"]))


def label(r: dict) -> str:
    return r["case"]


def memory_table(out: dict) -> str:
    head = ["case", "DOFs", "np", "parsolve peak MiB/rank", "DOLFINx", "ratio",
            *(f"{k} np" for k in PARTS), "PETSc Mat", "DOLFINx Mat", "MUMPS used (INFOG 21)",
            "DOLFINx MUMPS", "DOLFINx mesh+spaces ΔRSS", "cpu"]
    body = []
    for p, d in pairs(out):
        if "failed" in p:
            body.append([label(p), f"{p['dofs']:,}", str(p["nranks"]), "FAILED"]
                        + ["–"] * (len(head) - 4))
            continue
        a = memory_parts(p)
        b = memory_parts(d) if d else {}
        body.append([label(p), f"{p['dofs']:,}", str(p["nranks"]), mib(a["peak"]),
                     mib(b.get("peak")), fmt(a["peak"] / b["peak"]) if b else "–",
                     *(mib(a[k]) for k in PARTS), mib(a["matrix"]), mib(b.get("matrix")),
                     mib(a["mumps"]), mib(b.get("mumps")), mib(b.get("mesh")),
                     cpu_cell(p, d)])
    return md_table(head, body)


def cpu_cell(p: dict, d: dict | None) -> str:
    """CPU seconds / wall seconds of the run (lowest rank): well under 1, other processes took
    the cores (parsolve / DOLFINx)."""
    return "/".join(fmt(x.get("cpu_share")) for x in (p, d) if x)


def phase_table(out: dict) -> str:
    head = ["case", "DOFs", "np"] + [f"{ph} (×DOLFINx)" for ph in PHASES] + \
           ["total (×DOLFINx)", "wall s (DOLFINx)", "its (DOLFINx)"]
    body = []
    for p, d in pairs(out):
        if "failed" in p:
            continue
        cells = []
        for ph in PHASES + ("total",):
            a = sum(p["cpu"].values()) if ph == "total" else p["cpu"][ph]
            b = None
            if d:
                b = sum(d["cpu"].values()) if ph == "total" else d["cpu"][ph]
            cells.append(f"{a:.2f} ({fmt(a / b) if b else '–'})")
        its = f"{p['iterations']} ({d['iterations']})" if d else str(p["iterations"])
        wall = f"{sum(p['seconds'].values()):.1f}" + (f" ({sum(d['seconds'].values()):.1f})"
                                                       if d else "")
        body.append([label(p), f"{p['dofs']:,}", str(p["nranks"]), *cells, wall, its])
    return md_table(head, body)


def dolfinx_phase_table(out: dict) -> str:
    head = ["case", "DOFs", "np"] + [f"{ph} s" for ph in PHASES] + ["forms (JIT, wall) s"]
    body = [[d["case"], f"{d['dofs']:,}", str(d["nranks"])]
            + [fmt(d["cpu"][ph]) for ph in PHASES] + [fmt(d.get("t_forms"))]
            for d in ok_rows(out["rows"], "dolfinx")]
    return md_table(head, body)


def falls_table(out: dict) -> tuple[str, list[str]]:
    """Per case and size: 2 ranks / 1 rank of each memory part (target ≤ 0.6 for mesh, vectors,
    matrix)."""
    head = ["case", "DOFs", "peak", *(f"{k} np" for k in PARTS), "PETSc Mat", "MUMPS used",
            "DOLFINx peak"]
    body, worst = [], {}
    by = {(r["code"], r["case"], r["n"], r["nranks"]): r for r in ok_rows(out["rows"])}
    for (code, case, n, p), r1 in by.items():
        if code not in PARSOLVE_CODES or p != 1 or (code, case, n, 2) not in by:
            continue
        a, b = memory_parts(r1), memory_parts(by[(code, case, n, 2)])
        d1, d2 = by.get(("dolfinx", case, n, 1)), by.get(("dolfinx", case, n, 2))

        def q(k):
            return fmt(b[k] / a[k]) if a.get(k) and b.get(k) is not None else "–"

        body.append([label(by[(code, case, n, 2)]), f"{r1['dofs']:,}", q("peak"),
                     *(q(k) for k in PARTS), q("matrix"), q("mumps"),
                     fmt(peak(d2) / peak(d1)) if d1 and d2 else "–"])
        for k in ("mesh", "vectors", "operator", "matrix"):
            if a.get(k) and b.get(k) is not None:
                worst.setdefault((label(by[(code, case, n, 2)]), k), []).append(b[k] / a[k])
    return md_table(head, body), worst


def weak_table(out: dict) -> str:
    """Weak scaling: weak[i] ranks on sizes[i]; correctness: u against the same mesh at the other
    rank counts (parsolve) and against DOLFINx (same mesh, same ranks)."""
    head = ["case", "np", "DOFs", "DOFs/rank", "peak MiB/rank", "DOLFINx", "CPU s (max rank)",
            "DOLFINx", "‖u‖₂", "max Δu vs parsolve other np (rel.)",
            "vs DOLFINx (rel.)"]
    body = []
    rows = ok_rows(out["rows"])
    codes = [c for c in PARSOLVE_CODES if any(x["code"] == c for x in out["rows"])]
    for case, code in ((c, k) for c in out["cases"] for k in codes):
        for i, p in enumerate(out["weak"]):
            sizes = out["sizes"][case]
            if i >= len(sizes):
                continue
            n = sizes[i]
            r = next((x for x in rows if (x["code"], x["case"], x["n"], x["nranks"])
                      == (code, case, n, p)), None)
            d = next((x for x in rows if (x["code"], x["case"], x["n"], x["nranks"])
                      == ("dolfinx", case, n, p)), None)
            name = case
            if r is None:
                body.append([name, str(p), "–", "–", "FAILED"] + ["–"] * 6)
                continue
            # the same mesh on other rank counts
            same = [x for x in rows if x["code"] in PARSOLVE_CODES and x["case"] == case
                    and x["n"] == n and (x["nranks"] != p or x["code"] != code)]
            body.append([name, str(p) + (" (oversubscribed)" if p > (os.cpu_count() or 2) else ""),
                         f"{r['dofs']:,}", f"{r['dofs'] // p:,}", mib(peak(r)),
                         mib(peak(d)) if d else "–", f"{sum(r['cpu'].values()):.2f}",
                         f"{sum(d['cpu'].values()):.2f}" if d else "–", f"{r['unorm']:.10g}",
                         fmt(max((rel_diff(r, x) for x in same), default=None), ".1e"),
                         fmt(rel_diff(r, d), ".1e") if d else "–"])
    return md_table(head, body)


def rel_diff(a: dict, b: dict) -> float:
    """Largest relative difference of ||u||, max|u| and the corner displacement."""
    ca, cb = np.array(a["corner"]), np.array(b["corner"])
    scale = max(np.abs(ca).max(), 1e-300)
    return float(max(abs(a["unorm"] - b["unorm"]) / a["unorm"],
                     abs(a["umax"] - b["umax"]) / a["umax"], np.abs(ca - cb).max() / scale))


def fit_table(fs: dict) -> str:
    head = ["case / code", "quantity", "a", "b (per DOF)", "c (per DOF per rank)",
            "worst misfit", f"at {TARGET[0]} ranks × {TARGET[1] / 1e6:.0f}M DOFs"]
    body = []
    for key, f in fs.items():
        for q, v in f.items():
            if v is None:
                continue
            if q.startswith("t_"):
                vals = [f"{v['a']:.3g} s", f"{v['b'] * 1e6:.3g} µs", f"{v['c'] * 1e6:.3g} µs"]
                model = f"{at(v, TARGET[1], TARGET[0]):,.0f} s"
            else:
                vals = [f"{v['a'] / MiB:.0f} MiB", f"{v['b']:.0f} B", f"{v['c']:,.0f} B"]
                model = f"{at(v, TARGET[1], TARGET[0]) / 2 ** 30:,.2f} GiB"
            body.append([key, q, *vals, f"{v['worst']:.0%}", model])
    return md_table(head, body)


def factor_growth(case: str, n_big: int, N: float) -> tuple[float, float]:
    """Nested-dissection growth from n_big to N DOFs: (factor memory, flops) multipliers."""
    if CASES[case]["dim"] == 2:
        return (N / n_big) * np.log(N) / np.log(n_big), (N / n_big) ** 1.5
    return (N / n_big) ** (4 / 3), (N / n_big) ** 2


def memory_model(fs: dict, case: str, code: str, rows: list[dict]) -> dict | None:
    """Memory per rank at TARGET: the fit of (peak − MUMPS used) plus MUMPS's factor grown
    by nested dissection from the largest run (total used, spread evenly over the ranks); for
    an iterative case, the fit of the peak."""
    P, N = TARGET
    f = fs.get(f"{case}/{code}")
    if not f or not f.get("peak"):
        return None
    mine = [r for r in rows if r["code"] == code and r["case"] == case]
    big = max(mine, key=lambda r: (r["dofs"], -r["nranks"]))
    mu = big.get("mumps") or {}
    if not mu.get("used_mb_sum") or not f.get("rest"):
        return dict(total=at(f["peak"], N, P), rest=at(f["peak"], N, P), factor=0.0)
    factor = mu["used_mb_sum"] * 1e6 * factor_growth(case, big["dofs"], N)[0] / P
    rest = at(f["rest"], N, P)
    return dict(total=rest + factor, rest=rest, factor=factor)


def model_lines(out: dict, fs: dict) -> list[str]:
    """The 64 × 50M model per case, parsolve against DOLFINx."""
    P, N = TARGET
    rows = ok_rows(out["rows"])
    lines = []
    for case, code in ((c, k) for c in out["cases"] for k in PARSOLVE_CODES):
        p, d = fs.get(f"{case}/{code}"), fs.get(f"{case}/dolfinx")
        mp, md = (memory_model(fs, case, c, rows) for c in (code, "dolfinx"))
        if not mp:
            continue
        held = sum(p[k]["b"] for k in PARTS if p.get(k)) * N  # what no rank count divides
        name = case
        line = (f"- **{name}** at {P} ranks × {N / 1e6:.0f}M DOFs, memory per rank: parsolve "
                f"**{mp['total'] / 2 ** 30:.1f} GiB**")
        if mp["factor"]:
            line += (f" ({mp['rest'] / 2 ** 30:.1f} GiB besides MUMPS + "
                     f"{mp['factor'] / 2 ** 30:.1f} GiB of factor)")
        line += (f", of which {held / 2 ** 30:.1f} GiB of numpy arrays every rank holds whole "
                 f"(the b·N terms of mesh, vectors, operator, element, other)")
        if md:
            line += f"; DOLFINx **{md['total'] / 2 ** 30:.1f} GiB** (×{mp['total'] / md['total']:.1f})"
        line += f"; the plain fit of the peak gives {at(p['peak'], N, P) / 2 ** 30:.1f} GiB"
        if d and d.get("peak"):
            line += f" (DOLFINx {at(d['peak'], N, P) / 2 ** 30:.1f})"
        lines.append(line + ".")
        tp = [at(p[f"t_{ph}"], N, P) for ph in PHASES]
        if all(t is not None for t in tp):
            tline = ("  - CPU time per rank: " + ", ".join(f"{ph} {t:,.0f} s"
                                                          for ph, t in zip(PHASES, tp))
                     + f" (total {sum(tp):,.0f} s")
            td = [at(d[f"t_{ph}"], N, P) for ph in PHASES] if d else []
            if td and all(t is not None for t in td):
                tline += f"; DOLFINx {sum(td):,.0f} s"
            lines.append(tline + ").")
        big = max((r for r in rows if r["code"] == code and r["case"] == case),
                  key=lambda r: (r["dofs"], -r["nranks"]))
        mu = big.get("mumps") or {}
        if mu.get("used_mb_sum"):
            grow, fl = factor_growth(case, big["dofs"], N)
            lines.append(
                f"  - MUMPS from the largest 1-rank run ({big['dofs']:,} DOFs, "
                f"{mu['used_mb_sum']:,} MB used, {mu['flops']:.2e} flops), grown as nested "
                f"dissection ({'N log N' if CASES[case]['dim'] == 2 else 'N^(4/3)'} memory, "
                f"{'N^1.5' if CASES[case]['dim'] == 2 else 'N^2'} flops): "
                f"{mu['used_mb_sum'] * grow / 1e3:,.0f} GB in all, {mu['flops'] * fl:.2e} flops, "
                f"{big['cpu']['factorization'] * fl / P:,.0f} s on {P} ranks at this core's "
                f"rate with perfect speed-up"
                + (f" (the linear fit above says {tp[2]:,.0f} s)." if tp[2] is not None
                   else " (no linear fit: too few sizes)."))
    return lines


ASSUMPTIONS = """Assumptions of the model: memory per rank and each phase's time are a + b·N + c·N/P
(a: the process and libraries; b·N: what every rank holds or does whole — full-length
vectors, gathers, rank 0's whole mesh before it distributes it; c·N/P: the distributed part), fitted by least squares on the
relative error over the runs of this table (memory: 1, 2 and 4 ranks; time: 1 and 2 ranks, the
4-rank runs sharing 2 cores). Extrapolated {grow} in N and 32× in P: it assumes the same problem
family (structured block, one linear step), ranks with the memory bandwidth of these cores, and
no term the runs cannot see — communication growing with P (allgather and reduce of full-length
vectors cost ∝ N per rank and step over the network, counted only through b), load imbalance,
and a direct factorization whose fill and flops grow faster than N (nested dissection: factor
entries ∝ N log N in 2D, N^(4/3) in 3D; flops ∝ N^1.5, N^2): for the direct case the linear
fit underestimates the factorization and its memory: the direct model is the fit of the peak
without MUMPS's factor plus that factor grown by nested dissection from the largest run and
spread evenly over the ranks (MUMPS's own per-rank balance is not modelled). GAMG's iterations
are taken as constant (measured: nearly flat with N). CPU time, not wall: the runs shared 2
cores with other jobs."""


MEMORY_TARGET = 1.2      # issue 16: peak memory per rank ≤ 1.2× DOLFINx's (1, 2, 4 ranks)
BYTES_PER_DOF = 2600     # issue 16: 3D iterative, 1 rank
FALL_TARGET = 0.55       # issue 16: per-rank peak at 2 ranks ≤ 0.55× 1 rank's
TIME_TARGET = 1.5        # issue 16: first assembly, post-processing, set-up ≤ 1.5× DOLFINx


def _verdict(ok: bool) -> str:
    return "met" if ok else "**MISSED**"


def target_table(out: dict) -> str:
    """Issue 16's targets, one row per measured case / size / ranks and quantity."""
    head = ["target", "case", "DOFs", "np", "parsolve", "DOLFINx", "ratio", "limit", "verdict"]
    body = []
    rows = ok_rows(out["rows"])
    by = {(r["code"], r["case"], r["n"], r["nranks"]): r for r in rows}
    oversub = os.cpu_count() or 2
    for p, d in pairs(out):   # memory: every rank count
        if "failed" in p or not d or "failed" in d:
            continue
        q = peak(p) / peak(d)
        body.append(["peak memory per rank ≤ 1.2× DOLFINx", p["case"], f"{p['dofs']:,}",
                     str(p["nranks"]), mib(peak(p)) + " MiB", mib(peak(d)) + " MiB",
                     fmt(q), f"≤ {MEMORY_TARGET}", _verdict(q <= MEMORY_TARGET)])
    for p in rows:   # bytes per DOF, 3D iterative, 1 rank
        if p["code"] == "parsolve" and p["case"] == "3d-iterative" and p["nranks"] == 1:
            b = peak(p) / p["dofs"]
            d = by.get(("dolfinx", p["case"], p["n"], 1))
            body.append(["peak B/DOF, 3D iterative, 1 rank", p["case"], f"{p['dofs']:,}", "1",
                         f"{b:,.0f}", f"{peak(d) / d['dofs']:,.0f}" if d else "–", "–",
                         f"≤ {BYTES_PER_DOF}", _verdict(b <= BYTES_PER_DOF)])
    for code in ("parsolve", "dolfinx"):   # 2 ranks / 1 rank
        for (c, case, n, np_), r1 in by.items():
            r2 = by.get((code, case, n, 2))
            if c != code or np_ != 1 or r2 is None:
                continue
            q = peak(r2) / peak(r1)
            body.append([f"peak per rank, 2 ranks ≤ 0.55× 1 rank ({code})", case,
                         f"{r1['dofs']:,}", "2 / 1", mib(peak(r2)) + " / " + mib(peak(r1)),
                         "–", fmt(q), f"≤ {FALL_TARGET}",
                         _verdict(q <= FALL_TARGET) if code == "parsolve" else "(reference)"])
    for p, d in pairs(out):   # times: 1 and 2 ranks (4 ranks share 2 cores)
        if "failed" in p or not d or "failed" in d or p["nranks"] > oversub:
            continue
        # equal quadrature: on hexahedra (P1 triangles: UFL's default is parsolve's one point)
        quad = (d.get("quadrature") or {}) if CASES[p["case"]]["cell"] == "hexahedron" else {}
        items = [("first assembly ≤ 1.5× DOLFINx", p["cpu"]["assembly"], d["cpu"]["assembly"],
                  "UFL default", TIME_TARGET, "le"),
                 *[("first assembly ≤ 1.5× DOLFINx", p["cpu"]["assembly"], v["assembly"],
                    f"degree {q}", TIME_TARGET, "le") for q, v in quad.items()],
                 ("re-assembly ≥ DOLFINx's rate", p.get("reassembly"), d.get("reassembly"),
                  "UFL default", 1.0, "le"),
                 *[("re-assembly ≥ DOLFINx's rate", p.get("reassembly"), v["reassembly"],
                    f"degree {q}", 1.0, "le") for q, v in quad.items()],
                 ("post-processing ≤ 1.5× DOLFINx", p["cpu"]["post"], d["cpu"]["post"], "",
                  TIME_TARGET, "le"),
                 ("set-up ≤ 1.5× DOLFINx", p["cpu"]["setup"], d["cpu"]["setup"], "",
                  TIME_TARGET, "le")]
        for name, a, b, note, limit, _ in items:
            if a is None or not b:
                continue
            q = a / b
            label_ = name + (f" (DOLFINx quadrature: {note})" if note else "")
            body.append([label_, p["case"], f"{p['dofs']:,}", str(p["nranks"]), f"{a:.3f} s",
                         f"{b:.3f} s", fmt(q), f"≤ {limit}", _verdict(q <= limit)])
    return md_table(head, body)


TARGET_NOTES = """Times are CPU seconds (max over ranks) of parsolve and DOLFINx run one after the
other on each configuration (the machine is shared: ratios, not seconds, are what compares);
4-rank runs share 2 cores, so only their memory counts. *first assembly*: parsolve's first
`SaddleSystem.assemble` (its pattern is built in the set-up, by `SaddleSystem`); DOLFINx's
create_matrix (its pattern) + assemble_matrix + the right-hand side. *re-assembly*: parsolve's
`assemble()` once more after the step; DOLFINx's assemble_matrix into the same (zeroed) matrix;
ratio = parsolve's time / DOLFINx's (≤ 1: at least DOLFINx's rate). Quadrature: parsolve
integrates Q1 hexahedra with 2×2×2 Gauss points and P1 triangles with one point; DOLFINx with
UFL's estimated degree (4 on Q1 hexahedra: 27 points; 0 on P1 triangles: one point), and on
hexahedra also at degree 2 (2×2×2 points: parsolve's rule; the run's matrix is the default one's).
*set-up*: parsolve's load_scene + build_model (mesh generation included) + SaddleSystem +
make_solver; DOLFINx's create_mesh (from the arrays, given on rank 0) + spaces + BC + meshtags
(forms' JIT apart)."""


def markdown(out: dict) -> str:
    fs = fits(out)
    falls, _ = falls_table(out)
    m = out["machine"]
    load = "; ".join(f"{k.split('_')[1]}: " + " / ".join(f"{x:.1f}" for x in m[k])
                     for k in ("loadavg_start", "loadavg_end") if k in m)
    sizes = "; ".join(f"{c}: n = {', '.join(map(str, out['sizes'][c]))} "
                      f"({', '.join(f'{dofs_of(c, n):,}' for n in out['sizes'][c])} DOFs)"
                      for c in out["cases"])
    trace_note = ("parsolve runs traced by tracemalloc (--trace): their times carry its "
                  "overhead." if out["trace"] else "")
    parts = [
        "# Scale benchmark: memory and phases against DOLFINx 0.5, weak scaling, 64-rank model",
        "",
        (__doc__ or "").split("Usage")[0].strip(),
        "",
        f"Machine: {m['machine']}, {m['cpus']} cores, {m['mem_gib']:.1f} GiB, shared with other "
        f"engineers' test runs (load average 1/5/15 min at {load}); run started {m['date']}, "
        f"{out['elapsed'] / 60:.1f} min. Sizes: {sizes}. On this machine the runs stay ≲ 1.5M "
        "DOFs (its memory is shared), and were cut further to keep near 40 minutes under the "
        "load above; `--sizes` runs bigger ones elsewhere. " + trace_note,
        "",
        "## Peak memory per rank (MiB, max over ranks) and its parts",
        "",
        "*np* columns: numpy arrays parsolve holds (at the larger of two snapshots: after "
        "assembly, after post-processing), by what holds them: mesh = the model's mesh; "
        "operator = node pattern + saddle operator (values, positions, columns) + relation "
        "block; element = the effects and their composition (element work arrays); vectors = "
        "the step's solution, multipliers and output fields (rank 0 holds the gathered ones); "
        "other = partition, numbering, relations, regions. PETSc Mat: allocated nonzeros × 12 B "
        "+ row offsets. MUMPS used = INFOG(21) (max over ranks; the direct case). DOLFINx "
        "mesh+spaces = resident growth over its set-up (its data live in C++). *cpu*: CPU "
        "seconds / wall seconds of the run, parsolve/DOLFINx (1 = a core to itself).",
        "",
        memory_table(out),
        "",
        "### 2 ranks / 1 rank, per rank (target ≤ 0.6 for mesh, vectors, matrix)",
        "",
        falls,
        "",
        "## Time per phase (CPU s, max over ranks; ×DOLFINx = parsolve / DOLFINx, < 1: faster)",
        "",
        "CPU seconds, not wall: the machine is shared (see *cpu* above: the share of a core each "
        "run got); wall seconds of the whole run in the last column but one.",
        "",
        phase_table(out),
        "",
        "DOLFINx's phases:",
        "",
        dolfinx_phase_table(out),
        "",
        f"## Weak scaling ({', '.join(map(str, out['weak']))} ranks on the sizes above; more ranks "
        "than cores are oversubscribed: correctness only)",
        "",
        weak_table(out),
        "",
        "## Fits and the model",
        "",
        fit_table(fs),
        "",
        "Times in the fits: CPU seconds (max over ranks).",
        "",
        *model_lines(out, fs),
        "",
        ASSUMPTIONS.format(grow=" and ".join(
            f"{TARGET[1] / dofs_of(c, max(out['sizes'][c])):,.0f}× ({c})" for c in out["cases"])),
        "",
        "## Targets",
        "",
        target_table(out),
        "",
        TARGET_NOTES,
        "",
        *cause_lines(out),
        "",
        *note_lines(out),
        "",
        "Rerun: `.venv/bin/python scripts/bench_scale.py` (needs `bash scripts/bench_env.sh` for "
        "DOLFINx); `--sizes CASE=n1,n2,n3`, `--cases`, `--trace`, `--report`.",
    ]
    return "\n".join(parts) + "\n"


# where a run's resident peak grows: (label, snapshot before, snapshot after)
GROWTH = (("mesh + model", "start", "model"), ("SaddleSystem", "model", "system"),
          ("assembly", "system", "assembly"), ("factorization", "assembly", "factorization"),
          ("solve + post + output", "factorization", "end"), ("re-assembly", "end", "reassembly"))


def _hwm(r: dict, snap: str) -> float | None:
    m = r.get("memory", {}).get(snap)
    return m["hwm_max"] if m else None


def growth_table(out: dict) -> tuple[str, list[str]]:
    """The 2-rank / 1-rank peak of parsolve at each case's largest size with both, split by
    phase: how much the resident peak (VmHWM, max over ranks) grew over it at 1 and 2 ranks;
    the base (the process before anything: Python, numpy, PETSc, MPI) does not split."""
    head = ["case", "DOFs", "peak 1 / 2 ranks MiB", "ratio", "base MiB",
            "ratio if all above the base halved"] + [f"{g[0]} MiB (1 → 2 ranks)" for g in GROWTH]
    body, worst = [], []
    by = {(r["case"], r["n"], r["nranks"]): r for r in ok_rows(out["rows"], "parsolve")}
    for case in out["cases"]:
        both = [n for (c, n, p) in by if c == case and p == 1 and (c, n, 2) in by]
        if not both:
            continue
        n = max(both)
        r1, r2 = by[(case, n, 1)], by[(case, n, 2)]
        p1, p2, base = peak(r1), peak(r2), _hwm(r1, "start") or 0.0
        ideal = (base + (p1 - base) / 2) / p1
        cells = []
        for label_, a, b in GROWTH:
            g1 = [(_hwm(r, b) or 0.0) - (_hwm(r, a) or 0.0) for r in (r1, r2)]
            cells.append(f"{mib(g1[0])} → {mib(g1[1])}")
            worst.append((g1[1] - g1[0] / 2, label_, case))
        body.append([case, f"{r1['dofs']:,}", f"{mib(p1)} / {mib(p2)}", fmt(p2 / p1),
                     mib(base), fmt(ideal), *cells])
    return md_table(head, body), worst


SETUP_CAUSES = """*Set-up* (3D): profiled on this machine (cProfile and getrusage, 3d-iterative n = 54,
1 rank, 2026-12-02, load average 2 to 17) after the det J check (15× faster: cache-sized
batches, cell-last), the facet grouping (a sorting network instead of row sorts, a two-key
lexsort instead of four, the facet direction column by column), the regions' facet matching
(among the candidate facets only) and the pattern's int64 temporaries per pair were cut: of
2.2 to 2.5 CPU s, the mesh and model take 0.5 to 0.8 (the box's generation 0.1 to 0.2, the
cell checks and facets 0.3 to 0.4, regions, effects, loads and relations 0.15), `SaddleSystem`
1.5 to 1.6: the node-pair pattern 0.8 (one stable sort of 28 keys per hexahedron, 4.4M, and
the pair slots of every cell) and the saddle operator 0.7 (its CSR columns, in
parsolve/la/petsc.py). Half of the pattern's time is the kernel's (system time), clearing the
fresh pages of its arrays of more than 32 MiB, which glibc maps anew each time (about 0.3 s per
GB here). DOLFINx's set-up builds no matrix pattern (its create_matrix is counted in its first
assembly above). At 2 ranks PT-Scotch itself (MatPartitioning.apply) and the blocks' exchanges
add to both ranks' time, and a rank waiting for another spins (MPI's busy wait is CPU time:
on a loaded machine a descheduled partner inflates both codes' 2-rank CPU seconds). Against
the code before these cuts (main at 56d2db7), one fresh process each, alternately, same load
(1 rank, n = 54): set-up 2.70 to 2.87 CPU s before, 2.33 to 2.45 after; the mesh and model
1.35 to 1.46 → 0.70 to 0.77, `SaddleSystem` + make_solver 1.33 to 1.41 → 1.62 to 1.69 (its
system time: the model phase now leaves less freed memory in the heap, 126 MiB instead of 194,
so the pattern and operator fault more fresh pages; a larger malloc mmap threshold would keep
them, at the price of memory held)."""


def cause_lines(out: dict) -> list[str]:
    """Why the missed targets are missed, from the runs' own memory snapshots (and the
    set-up's profile)."""
    table, worst = growth_table(out)
    lines = ["### Causes of the missed targets", "",
             "*Per-rank peak at 2 ranks ≤ 0.55× 1 rank*: where parsolve's peak grows, at each "
             "case's largest size run on both (VmHWM growth over each phase, max over ranks):",
             "", table, ""]
    if worst:
        top = sorted(worst, reverse=True)[:3]
        lines.append("The phases whose 2-rank growth is furthest above half their 1-rank growth: "
                     + "; ".join(f"{lab} ({case}, {mib(extra)} MiB over half)"
                                 for extra, lab, case in top)
                     + ". The base alone keeps the ratio above 0.5 (last column but the phases); "
                     "the factorization is MUMPS's factor (2D; its own per-rank memory falls "
                     "0.6×, INFOG(21) above) or GAMG's parallel hierarchy (3D: it grows more on "
                     "2 ranks than on 1, DOLFINx's alike, whose ratio is in the table above); "
                     "solve + post + output holds rank 0's gathered fields for the result file "
                     "(whole-length on rank 0 at any rank count). The mesh's own share is "
                     "rank 0's whole mesh during the set-up, below the later peak.")
    lines += ["", SETUP_CAUSES]
    return lines


def note_lines(out: dict) -> list[str]:
    notes = []
    notes.append("- Fits: with only 1, 2 and 4 ranks, what does not fall from 1 to 2 ranks goes "
                 "into b·N. DOLFINx's 3D peak barely falls from 1 to 2 ranks here (GAMG's "
                 "parallel set-up adds about as much as the split saves at these sizes), so its "
                 "3D extrapolation is pessimistic; parsolve's b·N is backed by the arrays it holds "
                 "whole (full-length vectors, rank 0's whole mesh before it distributes it) "
                 "and by the fit's noise on small parts.")
    for r in out["rows"]:
        if "failed" in r:
            notes.append(f"- FAILED: {r['code']} {r['case']} n={r['n']} np={r['nranks']}: "
                         f"{r['failed']}")
    d = next(iter(ok_rows(out["rows"], "dolfinx")), None)
    if d:
        notes.append("- DOLFINx: " + ", ".join(f"{k} {v}" for k, v in d["versions"].items()))
    return notes


def report(out: dict) -> int:
    md = markdown(out)
    print(md)
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_scale.md").write_text(md)
    (RESULTS / "bench_scale.json").write_text(json.dumps({**out, "fits": fits(out)}, indent=1))
    return 0


# ------------------------------------------------------------------------------------------------
# --phases post: the post-processing against DOLFINx (and a baseline), into bench_post.md


POST_TARGET = 1.5  # issue 8: post-processing within 1.5× DOLFINx's time


def post_rows(out: dict):
    """(case, n, np) → {code: row} for every configuration, in run order."""
    by: dict = {}
    for r in out["rows"]:
        by.setdefault((r["case"], r["n"], r["nranks"]), {})[r["code"]] = r
    return by


def _ok(r: dict | None) -> bool:
    return r is not None and "failed" not in r


def _held(r: dict, part: str, snap: str) -> float | None:
    return r["memory"].get(snap, {}).get(f"np_{part}_max")


def post_table(out: dict) -> tuple[str, list[str]]:
    """Post-processing CPU seconds (max over ranks) of the baseline, parsolve and DOLFINx, the
    ratios, and the verdicts against the target."""
    base = bool(out.get("baseline"))
    head = ["case", "DOFs", "np"] + (["baseline post s (×DOLFINx)"] if base else []) + \
        ["parsolve post s (×DOLFINx)", "DOLFINx post s"] + (["speed-up"] if base else []) + \
        ["‖u‖ rel. diff. vs DOLFINx"]
    body, verdicts = [], []
    for (case, n, p), codes in post_rows(out).items():
        d, a, b = codes.get("dolfinx"), codes.get("parsolve"), codes.get("baseline")
        td = d["cpu"]["post"] if _ok(d) else None

        def cell(r):
            if not _ok(r):
                return "FAILED" if r else "–"
            t = r["cpu"]["post"]
            return f"{t:.3f} ({fmt(t / td) if td else '–'})"

        row = [case, f"{dofs_of(case, n):,}", str(p)] + ([cell(b)] if base else [])
        row += [cell(a), fmt(td, ".3f")]
        if base:
            row.append(fmt(b["cpu"]["post"] / a["cpu"]["post"]) + "×"
                       if _ok(a) and _ok(b) and a["cpu"]["post"] > 0 else "–")
        row.append(fmt(abs(a["unorm"] - d["unorm"]) / d["unorm"], ".1e")
                   if _ok(a) and _ok(d) else "–")
        body.append(row)
        if _ok(a) and td:
            ratio = a["cpu"]["post"] / td
            verdicts.append(f"{case} {dofs_of(case, n):,} DOFs np={p}: {ratio:.2f}× DOLFINx — "
                            + ("met" if ratio <= POST_TARGET else "MISSED"))
    return md_table(head, body), verdicts


def post_memory_table(out: dict) -> str:
    """Element arrays held after the assembly (the effects' work arrays), peak memory per rank,
    first and second assembly (CPU s) of the baseline and parsolve."""
    codes = (["baseline"] if out.get("baseline") else []) + ["parsolve"]
    head = ["case", "DOFs", "np"]
    for c in codes:
        head += [f"{c}: element np after assembly MiB", "after post",
                 "peak MiB/rank through the step", "with the re-assembly", "assembly s",
                 "re-assembly s"]
    head += ["DOLFINx peak MiB/rank"]
    body = []
    for (case, n, p), by in post_rows(out).items():
        row = [case, f"{dofs_of(case, n):,}", str(p)]
        for c in codes:
            r = by.get(c)
            if not _ok(r):
                row += ["–"] * 6
                continue
            row += [mib(_held(r, "element", "assembly")), mib(_held(r, "element", "post")),
                    mib(r["memory"]["end"]["hwm_max"]), mib(peak(r)),
                    fmt(r["cpu"]["assembly"]), fmt(r.get("reassembly"))]
        d = by.get("dolfinx")
        row.append(mib(peak(d)) if _ok(d) else "–")
        body.append(row)
    return md_table(head, body)


def post_phase_table(out: dict) -> str:
    """Every phase run (CPU s, max over ranks) of every code, for context."""
    head = ["case", "DOFs", "np", "code"] + [ph for ph in PHASES if ph != "output"] + \
        ["cpu share", "load avg"]
    body = []
    for (case, n, p), by in post_rows(out).items():
        for code, r in by.items():
            if not _ok(r):
                continue
            body.append([case, f"{dofs_of(case, n):,}", str(p), code]
                        + [fmt(r["cpu"][ph]) for ph in PHASES if ph != "output"]
                        + [fmt(r.get("cpu_share")), fmt(r.get("loadavg"), ".1f")])
    return md_table(head, body)


def post_markdown(out: dict) -> str:
    m = out["machine"]
    table, verdicts = post_table(out)
    label = out.get("baseline_label") or out.get("baseline") or ""
    lines = [
        "# Post-processing against DOLFINx 0.5 (target: within 1.5× DOLFINx's time)",
        "",
        "`scripts/bench_scale.py --phases post`: the problems of `bench_scale.md` (a clamped "
        "block under an end traction, one linear step), run as set-up, assembly, one solve and "
        "the post-processing only (no result file, no output phase), each a fresh process under "
        "scripts/mpirun.sh, one thread per rank, the codes one after the other on each "
        "configuration so that they share the machine's load.",
        "",
        "post: parsolve: gather + unpack + step_outputs (cell-mean stresses, volume-weighted "
        "nodal averages of the stress at the cells' nodes, relation outputs); DOLFINx: "
        "DG0 interpolation of σ(u) (the cell's centre) + a lumped projection on P1 "
        "(∫σ·w / ∫w, assembled vectors with ghost updates). CPU seconds, max over ranks.",
        "",
        (f"baseline: parsolve from `{out['baseline']}` ({label}), run by the same worker in "
         "the same run." if out.get("baseline") else ""),
        "",
        f"Machine: {m['machine']}, {m['cpus']} cores, {m['mem_gib']:.1f} GiB, shared with other "
        f"engineers' runs (load average at start {m['loadavg_start'][0]:.1f}, at end "
        f"{m['loadavg_end'][0]:.1f}); run started {m['date']}, {out['elapsed'] / 60:.1f} min.",
        "",
        "## Post-processing time (CPU s, max over ranks)",
        "",
        table,
        "",
        *[f"- {v}" for v in verdicts],
        "",
        "## Memory: element arrays held, peak per rank; assembly and re-assembly",
        "",
        "element np: numpy arrays the effects and their composition hold (bench_scale.md's "
        "*element*), after the first assembly and after the post-processing; peak through the "
        "step: VmHWM at the end of the step (set-up, assembly, factorization, solve, post); "
        "re-assembly: a second `SaddleSystem.assemble` after the step, with the factor still "
        "held (CPU s, max over ranks), and the peak with it.",
        "",
        post_memory_table(out),
        "",
        "## Every phase run (CPU s, max over ranks)",
        "",
        post_phase_table(out),
        "",
        "Rerun: `.venv/bin/python scripts/bench_scale.py --phases post [--baseline DIR "
        "--baseline-label TEXT] [--cases ...] [--sizes CASE=n1,n2] [--ranks 1 2]`; "
        "`--phases post --report` for the tables again from bench_post.json.",
    ]
    return "\n".join(lines) + "\n"


def collect(args) -> dict:
    """The runs of a --phases post plan whose JSON is in the scratch folder (a run cut short,
    or runs made one by one): the same tables from what finished."""
    sizes = {**POST_SIZES, **args.sizes}
    codes = (["baseline"] if args.baseline else []) + ["parsolve"] \
        + ([] if args.no_peers else ["dolfinx"])
    rows, stamps = [], []
    for case, n, p in plan(args.cases, sizes, args.ranks, []):
        for code in codes:
            js = SCRATCH / f"{tag_of(code, case, n, p)}.json"
            if js.exists():
                r = json.loads(js.read_text())
                r["code"] = code
                rows.append(r)
                stamps.append(js.stat().st_mtime)
    info = machine_info()
    info["loadavg_end"] = os.getloadavg()
    return dict(machine=info, elapsed=(max(stamps) - min(stamps)) if stamps else 0.0, rows=rows,
                sizes={c: sizes[c] for c in args.cases}, ranks=args.ranks, weak=[],
                cases=args.cases, trace=False, phases="post", baseline=args.baseline,
                baseline_label=args.baseline_label, collected=True)


def post_report(out: dict) -> int:
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_post.json").write_text(json.dumps(out, indent=1))
    text = post_markdown(out)
    print(text)
    (RESULTS / "bench_post.md").write_text(text)
    return 0


# ------------------------------------------------------------------------------------------------
# --gamg: 3D GAMG at 1 and 2 ranks, the summed peak's ratio, option by option


GAMG_CASE = "3d-iterative"
# 397,953 and 823,875 DOFs (80: 1.59M, about 6 GiB summed at 2 ranks, on a machine to itself)
GAMG_SIZES = [50, 64]
GAMG_SMOKE = [4]
GAMG_TARGET = 1.3          # summed peak at 2 ranks ≤ 1.3× the peak at 1 rank
GAMG_MEANINGFUL = 100_000  # DOFs below which each rank's process base (~90 MiB) decides it
#: option sets measured against the preset (given as on parsolve's command line, over it):
#: the candidate causes of the 2-rank set-up's growth, one at a time
GAMG_VARIANTS = {
    "preset": {},
    # the preset before its products were freed (solvers.options.AMG_PRODUCTS)
    "productskept": {"mat_product_clear": "false"},
    # the distributed P^T A P without its stored intermediates (A P, P's transposed parts)
    "allatonce": {"matptap_via": "allatonce"},
    "allatoncekept": {"matptap_via": "allatonce", "mat_product_clear": "false"},
    "allatoncemergedkept": {"matptap_via": "allatonce_merged", "mat_product_clear": "false"},
    # the distributed product's other algorithm that stores A P
    "scalable": {"matptap_via": "scalable"},
    # no aggressive (MIS-2) coarsening on the first level (3.18's -pc_gamg_square_graph)
    "no_aggressive": {"pc_gamg_square_graph": "0"},
    # coarse grids repartitioned, or gathered on one rank
    "repartition": {"pc_gamg_repartition": "true"},
    "one_rank_coarse": {"pc_gamg_process_eq_limit": "1000000"},
}


def one_rank_twin(name: str) -> str:
    """The variant whose 1-rank run is this one's: its options without a distributed P^T A P
    algorithm (parsolve leaves that out on one rank)."""
    from parsolve.solvers.options import DISTRIBUTED_PTAP

    options = {k: v for k, v in GAMG_VARIANTS[name].items()
               if not (k == "matptap_via" and v in DISTRIBUTED_PTAP)}
    return next((v for v, o in GAMG_VARIANTS.items() if o == options), name)


def gamg_runs(args) -> dict:
    """Every variant on every size at 1 and 2 ranks (parsolve only, one solve, no output)."""
    SCRATCH.mkdir(parents=True, exist_ok=True)
    info = machine_info()
    sizes = GAMG_SMOKE if args.smoke else args.gamg_sizes or GAMG_SIZES
    names = ["preset"] if args.smoke else args.gamg_variants or list(GAMG_VARIANTS)
    rows, t0 = [], time.perf_counter()
    for n in sizes:
        for name in names:
            for p in (1, 2):
                if p == 1 and one_rank_twin(name) != name and one_rank_twin(name) in names:
                    continue   # (its 1-rank run is another variant's)
                r = launch("parsolve", GAMG_CASE, n, p, False, args.timeout, "post",
                           petsc=GAMG_VARIANTS[name],
                           tag=f"gamg_{name}_{n}_np{p}".replace(" ", "_"))
                r.update(variant=name, options=GAMG_VARIANTS[name])
                rows.append(r)
                print(progress_line(r), name, flush=True)
    info["loadavg_end"] = os.getloadavg()
    out = dict(machine=info, elapsed=time.perf_counter() - t0, rows=rows, sizes=sizes,
               variants=names)
    return out if args.smoke or not args.gamg_add else _merged(out)


def gamg_collect() -> dict:
    """The table from every --gamg run's JSON in the scratch folder (runs made by several
    invocations, e.g. sizes run side by side)."""
    rows, stamps = [], []
    for name, options in GAMG_VARIANTS.items():
        for js in sorted(SCRATCH.glob(f"gamg_{name}_*_np*.json")):
            n, p = js.stem.removeprefix(f"gamg_{name}_").split("_np")
            if not n.isdigit():
                continue   # (another variant whose name starts alike)
            r = json.loads(js.read_text())
            r.update(code="parsolve", variant=name, options=options)
            rows.append(r)
            stamps.append(js.stat().st_mtime)
    info = machine_info()
    info["loadavg_end"] = os.getloadavg()
    return dict(machine=info, elapsed=(max(stamps) - min(stamps)) if stamps else 0.0,
                rows=rows, sizes=sorted({r["n"] for r in rows}),
                variants=[v for v in GAMG_VARIANTS if any(r["variant"] == v for r in rows)],
                collected=True)


def _merged(out: dict) -> dict:
    """The new runs over the published JSON's (--gamg-add: a variant or size added without
    running the others again); each run keeps its own machine line."""
    path = RESULTS / "bench_scale_gamg.json"
    if not path.exists():
        return out
    old = json.loads(path.read_text())
    new = {(r["variant"], r["n"], r["nranks"]) for r in out["rows"]}
    for r in out["rows"]:
        r["machine"] = out["machine"]
    rows = [r for r in old["rows"] if (r["variant"], r["n"], r["nranks"]) not in new]
    return dict(machine=old["machine"], elapsed=old["elapsed"] + out["elapsed"],
                rows=rows + out["rows"], sizes=sorted(set(old["sizes"]) | set(out["sizes"])),
                variants=[v for v in GAMG_VARIANTS if v in old["variants"] + out["variants"]],
                added=old.get("added", []) + [out["machine"]])


def summed_peak(r: dict) -> float:
    """The run's peak resident memory summed over its ranks (each rank's VmHWM at the end of
    the step: set-up, assembly, GAMG's set-up, solve, post-processing), bytes."""
    return r["memory"]["end"]["hwm_mean"] * r["nranks"]


def gamg_growth(r: dict) -> float:
    """How much GAMG's set-up raised the resident peak, max over ranks, bytes."""
    m = r["memory"]
    return m["factorization"]["hwm_max"] - m["assembly"]["hwm_max"]


def _options_text(options: dict) -> str:
    return " ".join(f"-{k}" + (f" {v}" if v != "" else "") for k, v in options.items()) or "–"


def gamg_table(out: dict) -> tuple[str, list[str]]:
    """One row per variant and size: both runs' peaks, the ratio, GAMG's share, the Krylov
    iterations, the CPU seconds and u against the preset's on 1 rank."""
    head = ["variant", "options (over the preset)", "DOFs", "peak 1 rank MiB",
            "peak per rank, 2 ranks MiB", "summed 2 ranks MiB", "ratio 2 / 1", "KB/DOF 1 / 2",
            "GAMG set-up +MiB 1 / per rank 2", "its 1 / 2", "set-up CPU s 1 / 2",
            "solve CPU s 1 / 2", "max rel. Δu vs preset", "verdict"]
    by = {(r["variant"], r["n"], r["nranks"]): r for r in out["rows"]}
    body, verdicts = [], []
    for n in out["sizes"]:
        ref = by.get(("preset", n, 1))
        for name in out["variants"]:
            r1, r2 = by.get((name, n, 1)), by.get((name, n, 2))
            twin = by.get((one_rank_twin(name), n, 1)) if name in GAMG_VARIANTS else None
            if r1 is None and twin is not None:
                r1 = {**twin, "options": GAMG_VARIANTS[name]}
            if r2 is None:
                continue   # (a variant not run at this size)
            if _ok(r2) and r1 is None:   # (a 2-rank run alone: GAMG's growth per rank)
                body.append([name, _options_text(r2["options"]), f"{r2['dofs']:,}", "–",
                             mib(r2["memory"]["end"]["hwm_max"]), mib(summed_peak(r2)), "–",
                             f"– / {summed_peak(r2) / r2['dofs'] / 1e3:.2f}",
                             f"– / {mib(gamg_growth(r2))}", f"– / {r2['iterations']}",
                             f"– / {r2['cpu']['factorization']:.1f}",
                             f"– / {r2['cpu']['solve']:.1f}",
                             f"{abs(r2['unorm'] / ref['unorm'] - 1.0):.1e}" if _ok(ref) else "–",
                             "(2 ranks only)"])
                continue
            if not _ok(r1) or not _ok(r2):
                why = (r1 or r2 or {}).get("failed", "not run")
                body.append([name, _options_text(GAMG_VARIANTS.get(name, {})),
                             f"{dofs_of(GAMG_CASE, n):,}", "FAILED: " + str(why)[:80]]
                            + [""] * (len(head) - 4))
                continue
            p1, p2 = summed_peak(r1), summed_peak(r2)
            ratio = p2 / p1
            du = max(abs(r["unorm"] / ref["unorm"] - 1.0) for r in (r1, r2)) if _ok(ref) else None
            verdict = ("met" if ratio <= GAMG_TARGET else "**MISSED**") \
                if r1["dofs"] >= GAMG_MEANINGFUL else "(process base)"
            verdicts.append(verdict)
            dofs = r1["dofs"]
            body.append([name, _options_text(r1["options"]), f"{dofs:,}", mib(p1),
                         mib(r2["memory"]["end"]["hwm_max"]), mib(p2), fmt(ratio),
                         f"{p1 / dofs / 1e3:.2f} / {p2 / dofs / 1e3:.2f}",
                         f"{mib(gamg_growth(r1))} / {mib(gamg_growth(r2))}",
                         f"{r1['iterations']} / {r2['iterations']}",
                         f"{r1['cpu']['factorization']:.1f} / {r2['cpu']['factorization']:.1f}",
                         f"{r1['cpu']['solve']:.1f} / {r2['cpu']['solve']:.1f}",
                         "–" if du is None else f"{du:.1e}", verdict])
    return md_table(head, body), verdicts


GAMG_NOTES = """Peaks: VmHWM (/proc/self/status) of each rank at the end of the step (set-up,
assembly, GAMG's set-up, CG's solve, the post-processing; no result file), summed over the
ranks; the target: the sum at 2 ranks ≤ 1.3× the peak at 1 rank. Variants: options over the
preset, one candidate cause at a time ("kept": each product's intermediates kept,
-mat_product_clear false; a distributed P^T A P algorithm does nothing on one rank, where the run
without it stands in). *GAMG set-up*: how much GAMG's PCSetUp
raised the resident peak over the assembly's (at 1 rank partly hidden under the assembly's own
earlier peak, whose temporaries were freed). CPU seconds, max over ranks (the machine is
shared; 2 ranks share its 2 cores with the other jobs). Δu: ‖u‖₂ against the preset's on 1
rank (the solver's tolerance: rtol 1e-10 on the true residual). Below 100k DOFs no verdict:
each rank's process base (Python, numpy, PETSc, MPI: ~90 MiB) decides the ratio."""


def gamg_markdown(out: dict) -> str:
    table, verdicts = gamg_table(out)
    m = out["machine"]
    when = (f"runs of several invocations (side by side, under the load of their time), "
            f"collected {m['date']}, the last {out['elapsed'] / 60:.1f} min after the first; "
            f"load average at collection {m['loadavg']:.1f}" if out.get("collected") else
            f"{bh.load_line(m['loadavg_start'], m['loadavg_end'])}; run started {m['date']}, "
            f"{out['elapsed'] / 60:.1f} min")
    return "\n".join([
        "# 3D GAMG at 1 and 2 ranks: the summed peak, option by option", "",
        f"{GAMG_CASE} (parsolve's iterative preset: CG + GAMG with the rigid-body modes) on the "
        "clamped unit cube under an end traction, N³ Q1 hexahedra, one linear step. Machine: "
        f"{m['cpus']} cores, {m['mem_gib']} GiB, shared with other jobs; {when}.", "",
        table, "", GAMG_NOTES, "",
        "Rerun: `.venv/bin/python scripts/bench_scale.py --gamg` (`--gamg-sizes 50 64`, "
        "`--gamg-variants preset ...`; `--gamg --collect`: the table from every run's JSON in "
        "the scratch folder; `--gamg --report`: again from the published JSON).",
    ]) + "\n"


def gamg_report(out: dict) -> int:
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_scale_gamg.json").write_text(json.dumps(out, indent=1))
    text = gamg_markdown(out)
    print(text)
    (RESULTS / "bench_scale_gamg.md").write_text(text)
    return 0


# ------------------------------------------------------------------------------------------------
# command line


def parse_sizes(items: list[str]) -> dict:
    out = {}
    for item in items:
        case, _, ns = item.partition("=")
        if case not in CASES or not ns:
            raise SystemExit(f"--sizes: expected CASE=n1,n2,... with CASE in {list(CASES)}, "
                             f"got {item!r}")
        out[case] = [int(x) for x in ns.split(",")]
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--cases", nargs="+", choices=list(CASES), default=DEFAULT_CASES)
    p.add_argument("--sizes", nargs="+", default=[], metavar="CASE=n1,n2,n3",
                   help="cells per side for a case (default: " + "; ".join(
                       f"{c}={','.join(map(str, s))}" for c, s in SIZES.items()) + ")")
    p.add_argument("--ranks", nargs="+", type=int, default=[1, 2])
    p.add_argument("--weak", nargs="+", type=int, default=[1, 2, 4],
                   help="weak scaling: these ranks on the 1st, 2nd, 3rd size")
    p.add_argument("--quick", action="store_true", help="small sizes (a smoke test)")
    p.add_argument("--no-peers", action="store_true", help="parsolve only")
    p.add_argument("--trace", action="store_true",
                   help="parsolve: tracemalloc's peak of Python + numpy memory per phase (slower)")
    p.add_argument("--timeout", type=float, default=900.0, help="seconds per run")
    p.add_argument("--report", action="store_true", help="tables again from the JSON")
    p.add_argument("--phases", choices=("all", "post"), default="all",
                   help="post: set-up, one solve and the post-processing only, against DOLFINx "
                        "(and --baseline), into bench_post.md")
    p.add_argument("--baseline", metavar="DIR",
                   help="also run parsolve's package from DIR (e.g. a copy of main: `git archive "
                        "main | tar -x -C DIR`) in the same run, as 'baseline'")
    p.add_argument("--baseline-label", default="", help="what DIR holds (e.g. a commit)")
    p.add_argument("--collect", action="store_true",
                   help="with --phases post: the tables from the runs' JSON in the scratch "
                        "folder (what finished of a run cut short)")
    p.add_argument("--worker", nargs=3, metavar=("CODE", "CASE", "N"), help=argparse.SUPPRESS)
    p.add_argument("--h5", help=argparse.SUPPRESS)
    p.add_argument("--json", help=argparse.SUPPRESS)
    p.add_argument("--quadrature", nargs="*", type=int, default=[2],
                   help="DOLFINx on hexahedra: also assemble the stiffness at these quadrature "
                        "degrees (first and again; default 2 = parsolve's 2×2×2 Gauss points; "
                        "UFL's own estimate, 4 = 27 points, is the run's)")
    p.add_argument("--gamg", action="store_true",
                   help="3D GAMG only, at 1 and 2 ranks: the summed peak's ratio per option set "
                        "(scripts/results/bench_scale_gamg.md)")
    p.add_argument("--gamg-sizes", nargs="+", type=int, default=[],
                   help="with --gamg: cells per side (default: "
                        + ", ".join(map(str, GAMG_SIZES)) + ")")
    p.add_argument("--gamg-variants", nargs="+", choices=list(GAMG_VARIANTS), default=[],
                   help="with --gamg: the option sets (default: all)")
    p.add_argument("--gamg-add", action="store_true",
                   help="with --gamg: keep the published runs of other variants and sizes")
    p.add_argument("--mesh-file", help=argparse.SUPPRESS)
    p.add_argument("--options", help=argparse.SUPPRESS)
    bh.add_smoke(p)
    args = p.parse_args(argv)
    if args.smoke and not args.worker:   # one small size per case, 1 rank; DOLFINx if installed
        args.sizes = [f"{c}={QUICK[c][0] // 3 if c.startswith('2d') else 4}" for c in args.cases]
        args.ranks, args.weak = [1], []
        args.no_peers = args.no_peers or not bh.peer_available("dolfinx")
    if args.worker:
        code, case, n = args.worker
        if code == "parsolve":
            parsolve_worker(case, int(n), args.h5, args.json, args.trace, args.phases,
                            json.loads(args.options) if args.options else None)
        else:
            dolfinx_worker(case, int(n), args.mesh_file, args.options, args.h5, args.json,
                           tuple(args.quadrature))
        return 0
    if args.gamg:
        if args.collect:
            return gamg_report(gamg_collect())
        if args.report:
            return gamg_report(json.loads((RESULTS / "bench_scale_gamg.json").read_text()))
        return gamg_report(gamg_runs(args))
    if args.collect:
        args.sizes = parse_sizes(args.sizes)
        return post_report(collect(args))
    if args.report:
        if args.phases == "post":
            return post_report(json.loads((RESULTS / "bench_post.json").read_text()))
        return report(json.loads((RESULTS / "bench_scale.json").read_text()))
    args.sizes = parse_sizes(args.sizes)
    out = run_all(args)
    code = post_report(out) if args.phases == "post" else report(out)
    if args.smoke:   # the 1- vs 2-rank GAMG table at its smallest size too
        code = code or gamg_report(gamg_runs(args))
    return code


if __name__ == "__main__":
    sys.exit(main())
