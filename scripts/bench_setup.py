#!/usr/bin/env python3
"""Set-up benchmark: the node-pair pattern, the saddle operator's construction, and MUMPS's
ordering on 1 and 2 ranks.

Section *pattern* (1 rank, all nodes owned): `node_pattern` and `NodePattern.block_positions`,
the current builder ("new") against the one it replaced ("old", kept in tests/la/test_pattern.py
as the reference), interleaved in the same process, best of the repeats.

Section *first* (1 rank): first assembly as scripts/bench_assembly.py defines it --
`SaddleSystem(comm, model)` + the first `assemble()` -- with the old and the new builder in the
same process (the old one patched in), split into node_pattern, block_positions,
`SaddleOperator(...)` (includes block_positions) and the first `petsc_matrix()`; DOLFINx 0.5's
first assembly (create_matrix + assemble_matrix, scripts/bench_peers.py) in the same run, 2D
only (bench_peers builds no 3D mesh).

Section *mumps* (1 and 2 ranks): the saddle system of a clamped 2D / 3D block under an end
traction, factorised by MUMPS (the direct preset's options: Cholesky when symmetric, LU with a
non-associated relation) with each ordering: analysis + factorisation time (ksp.setUp, slowest
rank), RINFOG(3) (flops of the elimination), INFOG(29) (entries in the factors) and INFOG(7)
(ordering MUMPS actually used: 0 AMD, 2 AMF, 3 SCOTCH, 4 PORD, 5 METIS, 6 QAMD; a library
missing from MUMPS's build falls back to another). Cases: "none" (clamp eliminated: K alone), "side" (a `mean`
relation on the right side whose dual is a traction over that side, controlled_bar.toml's
relation) and "body" (the same relation with a body force over the whole domain as dual: a
dense column and row).

Usage (from the repository root):
    .venv/bin/python scripts/bench_setup.py                 # everything
    .venv/bin/python scripts/bench_setup.py --sections pattern first --quick
    .venv/bin/python scripts/bench_setup.py --report      # table again from bench_results/setup.json
Writes bench_results/setup.json and scripts/results/bench_setup.md.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = ROOT / "scripts"
PYTHON = str(ROOT / ".venv" / "bin" / "python")
RESULTS = ROOT / "bench_results"
COMMITTED = SCRIPTS / "results"
sys.path.insert(0, str(SCRIPTS))
sys.path.insert(0, str(ROOT / "tests" / "la"))
sys.path.insert(0, str(ROOT))

SIZES_2D = [70, 223, 707, 1000, 1414]        # 2(N+1)² DOFs: 10k, 100k, 1M, 2M, 4M
SIZES_3D = [20, 40, 60, 79]                  # 3(N+1)³ DOFs: 28k, 207k, 681k, 1.54M
QUICK_2D, QUICK_3D = [70, 223], [20]
ORDERINGS = {                                 # name -> MUMPS options
    "AMD": {"mat_mumps_icntl_7": "0"},
    "AMF": {"mat_mumps_icntl_7": "2"},
    "PORD": {"mat_mumps_icntl_7": "4"},
    "SCOTCH": {"mat_mumps_icntl_7": "3"},
    "METIS": {"mat_mumps_icntl_7": "5"},
    "QAMD": {"mat_mumps_icntl_7": "6"},
    "PT-Scotch": {"mat_mumps_icntl_28": "2", "mat_mumps_icntl_29": "1"},
}


def dofs_of(dim: int, n: int) -> int:
    return dim * (n + 1) ** dim


def scene(dim: int, n: int, cell: str, control: str = "none") -> str:
    """Clamped block (left / xmin), traction on the right (right / xmax); control: none, side or
    body (see the module doc)."""
    if dim == 2:
        mesh = f'generator = "rectangle"\nlx = 1.0\nly = 1.0\nnx = {n}\nny = {n}\ncell = "{cell}"'
        hyp, left, right, trac, comps = "plane_strain", "left", "right", "[0.0, -1.0]", '["x", "y"]'
        body = "[1.0, 0.0]"
    else:
        mesh = (f'generator = "box"\nlx = 1.0\nly = 1.0\nlz = 1.0\nnx = {n}\nny = {n}\nnz = {n}\n'
                f'cell = "{cell}"')
        hyp, left, right = "3d", "xmin", "xmax"
        trac, comps, body = "[0.0, 0.0, -1.0]", '["x", "y", "z"]', "[1.0, 0.0, 0.0]"
    text = f"""
[mesh]
{mesh}
[model]
hypothesis = "{hyp}"
[[materials]]
E = 1.0
nu = 0.3
[[loads]]
region = "{right}"
traction = {trac}
[[relations]]
name = "clamp"
type = "dirichlet"
region = "{left}"
components = {comps}
"""
    if control != "none":
        dual = (f'region = "{right}"\ntotal_force = {body}' if control == "side"
                else f"body = {body}")
        text += f"""
[[loads]]
name = "control"
{dual}
[[relations]]
name = "ctrl"
type = "mean"
region = "{right}"
component = "x"
value = 1e-3
dual = "control"
"""
    return text + '\n[solver]\npreset = "direct"\n'


def build(text: str):
    import tomllib

    from parsolve.model import build_model
    from parsolve.scene import parse_scene
    return build_model(parse_scene(tomllib.loads(text), "bench.toml", text))


def slowest(comm, seconds: float) -> float:
    from mpi4py import MPI
    return comm.allreduce(seconds, op=MPI.MAX)


# ------------------------------------------------------------------------------------------------
# children (one process per size, so that memory is returned between sizes)


def child_pattern(cell: str, n: int, repeats: int) -> dict:
    import numpy as np
    from test_pattern import reference_block_positions, reference_pattern

    from parsolve.la.pattern import node_pattern
    from parsolve.mesh.generators import box, rectangle

    dim = 3 if cell == "hexahedron" else 2
    mesh = rectangle(1.0, 1.0, n, n, cell=cell) if dim == 2 else box(1, 1, 1, n, n, n, cell=cell)
    cells, nn = mesh.cells.astype(np.int64), mesh.num_points
    best = {}

    def clock(name, fn, *args):
        t0 = time.perf_counter()
        out = fn(*args)
        best[name] = min(best.get(name, np.inf), time.perf_counter() - t0)
        return out

    for _ in range(repeats):
        for tag, build_p, positions in (("new", node_pattern, None),
                                        ("old", reference_pattern, reference_block_positions)):
            p = clock(f"pattern_{tag}", build_p, cells, 0, nn, dim, nn)
            row_start = np.concatenate([[0], np.cumsum(p.row_nnz())])[:-1]
            bp = clock(f"blockpos_{tag}", positions or p.block_positions, *((p, row_start)
                       if positions else (row_start,)))
            nnzb = p.nnzb
            del p, bp
            gc.collect()
    return dict(section="pattern", cell=cell, n=n, dofs=dofs_of(dim, n), nnzb=nnzb,
                repeats=repeats, **best)


def child_first(cell: str, n: int, repeats: int) -> dict:
    """SaddleSystem + first assemble, old and new builders, with the parts timed by wrappers."""
    import numpy as np
    from mpi4py import MPI
    from test_pattern import reference_block_positions, reference_pattern

    import parsolve.solvers.system as system_mod
    from parsolve.la.pattern import NodePattern, node_pattern
    from parsolve.la.petsc import SaddleOperator

    comm = MPI.COMM_WORLD
    dim = 3 if cell == "hexahedron" else 2
    model = build(scene(dim, n, cell))
    parts: dict[str, float] = {}

    def timed(name, fn):
        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            out = fn(*args, **kwargs)
            parts[name] = parts.get(name, 0.0) + time.perf_counter() - t0
            return out
        return wrapper

    new_positions, init, first_mat = (NodePattern.block_positions, SaddleOperator.__init__,
                                      SaddleOperator.petsc_matrix)
    SaddleOperator.__init__ = timed("operator", init)
    SaddleOperator.petsc_matrix = timed("petsc_matrix", first_mat)
    variants = {"new": (node_pattern, new_positions),
                "old": (reference_pattern, reference_block_positions)}
    best: dict[str, float] = {}
    for _ in range(repeats):
        for tag, (builder, positions) in variants.items():
            system_mod.node_pattern = timed("pattern", builder)
            NodePattern.block_positions = timed("blockpos", positions)
            parts.clear()
            comm.Barrier()
            t0 = time.perf_counter()
            system = system_mod.SaddleSystem(comm, model)
            t1 = time.perf_counter()
            mat = system.assemble()
            t2 = time.perf_counter()
            norm = mat.norm()
            timings = dict(setup=t1 - t0, asm1=t2 - t1, first=t2 - t0, **parts)
            for key, value in timings.items():
                name = f"{key}_{tag}"
                best[name] = min(best.get(name, np.inf), slowest(comm, value))
            best[f"norm_{tag}"] = norm
            del system, mat
            gc.collect()
    assert abs(best["norm_new"] - best["norm_old"]) <= 1e-12 * best["norm_old"]
    return dict(section="first", cell=cell, n=n, dofs=dofs_of(dim, n), nranks=comm.size,
                repeats=repeats, **best)


def child_mumps(dim: int, n: int, control: str) -> list[dict]:
    import numpy as np
    from mpi4py import MPI
    from petsc4py import PETSc

    from parsolve.solvers.linear import preset_options
    from parsolve.solvers.system import SaddleSystem

    comm = MPI.COMM_WORLD
    cell = "quad" if dim == 2 else "hexahedron"
    model = build(scene(dim, n, cell, control))
    system = SaddleSystem(comm, model)
    mat = system.assemble()
    rhs_owned, _ = system.rhs(1.0)
    symmetric = control == "none"
    rows = []
    for k, (name, extra) in enumerate(ORDERINGS.items()):
        prefix = f"bs{k}_"
        opts = PETSc.Options()
        settings = preset_options("direct", symmetric, not symmetric) | extra
        for key, value in settings.items():
            opts[prefix + key] = value
        ksp = PETSc.KSP().create(comm)
        ksp.setOptionsPrefix(prefix)
        ksp.setOperators(mat)
        ksp.setFromOptions()
        b = mat.createVecLeft()
        b.array[:] = rhs_owned
        x = mat.createVecRight()
        row = dict(section="mumps", dim=dim, cell=cell, n=n, dofs=dofs_of(dim, n),
                   nrows=mat.getSize()[0], control=control, nranks=comm.size, ordering=name,
                   factor=settings["pc_type"])
        comm.Barrier()
        t0 = time.perf_counter()
        try:
            ksp.setUp()
        except PETSc.Error:  # e.g. INFOG(1) = -38: no parallel ordering library in this MUMPS
            F = ksp.getPC().getFactorMatrix()
            rows.append(dict(row, error=int(F.getMumpsInfog(1))))
            ksp.destroy()
            continue
        finally:
            for key in settings:
                opts.delValue(prefix + key)
        row["t_fact"] = slowest(comm, time.perf_counter() - t0)
        F = ksp.getPC().getFactorMatrix()
        comm.Barrier()
        t0 = time.perf_counter()
        ksp.solve(b, x)
        row["t_solve"] = slowest(comm, time.perf_counter() - t0)
        r = mat.createVecLeft()
        mat.mult(x, r)
        r.axpy(-1.0, b)
        rows.append(dict(row, flops=F.getMumpsRinfog(3), entries=F.getMumpsInfog(29),
                         used=F.getMumpsInfog(7), residual=r.norm() / max(b.norm(), 1e-300)))
        ksp.destroy()
    return rows


# ------------------------------------------------------------------------------------------------
# driver


def spawn(args: list[str], nranks: int = 1, timeout: float = 1800.0):
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.json"
        cmd = [PYTHON, str(Path(__file__).resolve()), "--child", *args, "--json", str(out)]
        if nranks > 1:
            cmd = ["bash", str(SCRIPTS / "mpirun.sh"), "-n", str(nranks), *cmd]
        env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
        proc = subprocess.run(cmd, env=env, timeout=timeout, text=True, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT)
        if proc.returncode != 0 or not out.exists():
            print(f"[bench] {' '.join(args)} failed ({proc.returncode}):\n{proc.stdout[-3000:]}",
                  file=sys.stderr, flush=True)
            return None
        return json.loads(out.read_text())


def repeats_for(dofs: int) -> int:
    return 3 if dofs < 200_000 else (2 if dofs < 1_500_000 else 1)


def run_dolfinx(ns_by_cell: dict[str, list[int]]) -> dict:
    import bench_peers

    out = {}
    for cell, ns in ns_by_cell.items():
        for n in ns:
            try:
                res = bench_peers.run_peer("dolfinx", [n], cells=(cell,), nranks=1,
                                           repeats=repeats_for(2 * (n + 1) ** 2), timeout=1800)
            except Exception as err:  # noqa: BLE001 - report without the peer
                print(f"[bench] DOLFINx {cell} {n}: {err}"[:2000], file=sys.stderr, flush=True)
                continue
            for row in res.get("assembly", res.get("rows", [])) if isinstance(res, dict) else res:
                if isinstance(row, dict) and row.get("n") == n and row.get("cell") == cell:
                    out[(cell, n)] = row
    return out


def fmt(x: float | None, digits: int = 2) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def ratio(a, b) -> str:
    return "–" if not a or not b else f"{a / b:.1f}"


def pattern_table(rows: list[dict]) -> str:
    head = ("| cell | DOFs | node pairs | node_pattern old s | new s | ×faster | block_positions "
            "old s | new s | ×faster |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|\n")
    body = "".join(
        f"| {r['cell']} | {r['dofs']:,} | {format(r['nnzb'], ',') if 'nnzb' in r else '–'} | {fmt(r['pattern_old'])} | "
        f"{fmt(r['pattern_new'])} | {ratio(r['pattern_old'], r['pattern_new'])} | "
        f"{fmt(r['blockpos_old'])} | {fmt(r['blockpos_new'])} | "
        f"{ratio(r['blockpos_old'], r['blockpos_new'])} |\n" for r in rows)
    return head + body


def first_table(rows: list[dict], peers: dict) -> str:
    head = ("| cell | DOFs | first old s | first new s | ×faster | setup old/new s | "
            "SaddleOperator old/new s | petsc_matrix new s | DOF/s new | DOLFINx 1st s | "
            "×DOLFINx old | ×DOLFINx new |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
            "---:|---:|\n")
    body = ""
    for r in rows:
        peer = peers.get((r["cell"], r["n"]))
        tp = peer["t_first"] if peer else None
        body += (f"| {r['cell']} | {r['dofs']:,} | {fmt(r['first_old'])} | {fmt(r['first_new'])} | "
                 f"{ratio(r['first_old'], r['first_new'])} | {fmt(r['setup_old'])}/"
                 f"{fmt(r['setup_new'])} | {fmt(r['operator_old'])}/{fmt(r['operator_new'])} | "
                 f"{fmt(r['petsc_matrix_new'])} | {r['dofs'] / r['first_new'] / 1e3:.0f}k | "
                 f"{fmt(tp, 3)} | {ratio(tp, r['first_old'])} | {ratio(tp, r['first_new'])} |\n")
    return head + body


def mumps_table(rows: list[dict]) -> str:
    head = ("| problem | DOFs | relation | factor | np | ordering | used (INFOG 7) | "
            "analysis+factor s | flops RINFOG(3) | factor entries INFOG(29) | solve s | "
            "residual |\n|---|---:|---|---|---:|---|---:|---:|---:|---:|---:|---:|\n")
    body = ""
    for r in rows:
        body += (f"| {r['dim']}D {r['cell']} N={r['n']} | {r['dofs']:,} | {r['control']} | "
                 f"{r['factor']} | {r['nranks']} | {r['ordering']} | ")
        if "error" in r:
            body += f"failed: INFOG(1) = {r['error']} | – | – | – | – | – |\n"
        else:
            body += (f"{r['used']} | {r['t_fact']:.2f} | {r['flops']:.3e} | {r['entries']:.3e} | "
                     f"{r['t_solve']:.3f} | {r['residual']:.1e} |\n")
    return head + body


def machine() -> str:
    cpu = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                if ln.startswith("model name")), platform.processor())
    load = os.getloadavg()
    return (f"Machine: {cpu}, {os.cpu_count()} cores; load average {load[0]:.2f} at the end "
            f"(> 2 means other jobs shared the cores: compare ratios within a row); "
            f"run {time.strftime('%Y-%m-%d %H:%M:%S')} UTC.")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sections", nargs="+", default=["pattern", "first", "mumps"],
                   choices=["pattern", "first", "mumps"])
    p.add_argument("--quick", action="store_true", help="small sizes only (a smoke test)")
    p.add_argument("--no-peers", action="store_true")
    p.add_argument("--n2d", type=int, nargs="+", default=None, help="2D sizes (quads per side)")
    p.add_argument("--n3d", type=int, nargs="+", default=None, help="3D sizes (hexes per side)")
    p.add_argument("--repeats", type=int, default=None, help="default: 3/2/1 by size")
    p.add_argument("--peers-from", default=None, metavar="JSON",
                   help="DOLFINx rows from `bench_peers.py dolfinx --json` instead of running it")
    p.add_argument("--report", action="store_true",
                   help="only rewrite the table from bench_results/setup.json")
    p.add_argument("--mumps-2d", type=int, default=300, help="quads per side of the 2D MUMPS case")
    p.add_argument("--mumps-3d", type=int, default=20, help="hexes per side of the 3D MUMPS case")
    p.add_argument("--child", nargs="+", default=None, help=argparse.SUPPRESS)
    p.add_argument("--json", default=None, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.child:
        kind, *rest = a.child
        if kind == "pattern":
            out = child_pattern(rest[0], int(rest[1]), int(rest[2]))
        elif kind == "first":
            out = child_first(rest[0], int(rest[1]), int(rest[2]))
        else:
            out = child_mumps(int(rest[0]), int(rest[1]), rest[2])
        from mpi4py import MPI
        if MPI.COMM_WORLD.rank == 0:
            Path(a.json).write_text(json.dumps(out))
        return

    s2, s3 = (QUICK_2D, QUICK_3D) if a.quick else (SIZES_2D, SIZES_3D)
    s2, s3 = a.n2d or s2, a.n3d or s3
    cases = [(c, n, 2) for c in ("triangle", "quad") for n in s2] + [("hexahedron", n, 3) for n in s3]
    saved = RESULTS / "setup.json"
    RESULTS.mkdir(exist_ok=True)
    # sections not run now keep their last results; every row is saved as soon as it is measured
    results = json.loads(saved.read_text()) if saved.exists() else {}
    for section in ("pattern", "first", "mumps"):
        if (section in a.sections and not a.report) or section not in results:
            results[section] = []
    results.setdefault("peers", [])

    def save():
        saved.write_text(json.dumps(results, indent=1))

    t_start = time.time()
    for section in ("pattern", "first"):
        if section not in a.sections or a.report:
            continue
        for cell, n, dim in cases:
            repeats = a.repeats or repeats_for(dofs_of(dim, n))
            row = spawn([section, cell, str(n), str(repeats)])
            if row:
                results[section].append(row)
                save()
                print(f"[{section}] {cell} {n}: " + ", ".join(
                    f"{k}={v:.3f}" for k, v in row.items() if isinstance(v, float)), flush=True)
    if a.peers_from:
        peer_rows = json.loads(Path(a.peers_from).read_text())["assembly"]
        results["peers"] = [dict(r, key=[r["cell"], r["n"]]) for r in peer_rows if r["nranks"] == 1]
    elif "first" in a.sections and not a.no_peers and not a.report:
        peers = run_dolfinx({c: [n for n in s2] for c in ("triangle", "quad")})
        results["peers"] = [dict(v, key=list(k)) for k, v in peers.items()]
    save()
    if "mumps" in a.sections and not a.report:
        sizes = {2: 60 if a.quick else a.mumps_2d, 3: 8 if a.quick else a.mumps_3d}
        for dim in (2, 3):
            for control in ("none", "side", "body"):
                for nranks in (1, 2):
                    rows = spawn(["mumps", str(dim), str(sizes[dim]), control], nranks=nranks)
                    results["mumps"].extend(rows or [])
                    save()
    write_report(results, time.time() - t_start)


def write_report(results: dict, seconds: float) -> None:
    peers = {tuple(p["key"]): p for p in results.get("peers", [])}
    text = ["# parsolve set-up benchmark", "", __doc__.split("\n\n", 1)[1].split("Usage")[0].strip(),
            "", machine() + f" {seconds:.0f} s.", "", *results.get("notes", [])]
    if results["pattern"]:
        text += ["## Node-pair pattern (1 rank, old = previous builder, same process)", "",
                 pattern_table(results["pattern"])]
    if results["first"]:
        text += ["## First assembly (1 rank): SaddleSystem + first assemble()", "",
                 first_table(results["first"], peers)]
    if results["mumps"]:
        text += ["## MUMPS orderings (direct preset's options otherwise)", "",
                 mumps_table(results["mumps"])]
    md = "\n".join(text)
    COMMITTED.mkdir(exist_ok=True)
    (COMMITTED / "bench_setup.md").write_text(md)
    print(md)


if __name__ == "__main__":
    main()
