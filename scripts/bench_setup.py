#!/usr/bin/env python3
"""Set-up benchmark: the node-pair pattern, the saddle operator's construction, and MUMPS's
ordering on 1 and 2 ranks.

Section *pattern* (1 rank, all nodes owned): `node_pattern` and `NodePattern.block_positions`,
the current builder ("new") against the one it replaced ("old", kept in scripts/baselines/pattern_reference.py
as the reference), interleaved in the same process, best of the repeats.

Section *first* (1 rank): first assembly as scripts/bench_assembly.py defines it --
`SaddleSystem(comm, model)` + the first `assemble()` -- with the old and the new builder in the
same process (the old one patched in), split into node_pattern, block_positions,
`SaddleOperator(...)` (includes block_positions) and the first `petsc_matrix()`; DOLFINx 0.5's
first assembly (create_matrix + assemble_matrix, scripts/bench_peers.py) in the same run, 2D
only (bench_peers builds no 3D mesh).

Section *compare* (1 rank; `--compare REF`): the assembly code as it is at git ref REF
(parsolve/la/pattern.py, parsolve/la/petsc.py, parsolve/fem/element_matrices.py, read with
`git show` into a temporary folder and patched in) against the working tree, on the same model
in the same process, alternately, best of the repeats: set-up (`SaddleSystem`), first
`assemble()`, first assembly (both), re-assembly (best of 3 more `assemble()`), CPU and wall
seconds; the two matrices must agree (the same product with a random vector, bit for bit).
Memory, in a fresh process per version: numpy arrays the pattern and operator hold, split into
those PETSc works on (new: the operator's value, column and row arrays are the matrix's own)
and those beside the matrix; the matrix (allocated entries × 12 B + row offsets, whoever owns
them); the element arrays (the effects' work arrays: the same code in both); the growth of
resident memory over set-up + two assemblies, and of its peak. DOLFINx 0.5's first assembly
(create_matrix + assemble_matrix) in the same run: 2D on the same arrays (bench_peers.run_peer),
3D on its own box (bench_peers.run_dolfinx_box) with UFL's quadrature degree and with degree 2
(parsolve's 2×2×2 points). 3D runs use the iterative preset (no solve is made: assembly only).

Section *mumps* (1 and 2 ranks): the saddle system of a clamped 2D / 3D block under an end
traction, factorised by MUMPS (the direct preset's options: Cholesky when symmetric, LU with a
non-associated relation) with each ordering: analysis + factorisation time (ksp.setUp, slowest
rank), RINFOG(3) (flops of the elimination), INFOG(29) (entries in the factors) and INFOG(7)
(ordering MUMPS actually used: 0 AMD, 2 AMF, 3 SCOTCH, 4 PORD, 5 METIS, 6 QAMD; a library
missing from MUMPS's build falls back to another). Cases: "none" (clamp eliminated: K alone), "side" (a `mean`
relation on the right side whose dual is a traction over that side, controlled_bar.toml's
relation) and "body" (the same relation with a body force over the whole domain as dual: a
dense column and row).

Section *mesh* (1, 2 and 4 ranks): the mesh stage alone (`model._distributed_mesh`: read or
generate, check, partition, distribute, number the nodes) of a box of 6·n³ tetrahedra, three
ways: a Gmsh file (`.msh`, MSH 2.2 binary, read by slices), the same mesh converted to the
parallel file (`.h5`, read by slices), the generator (`box`, built by slices) and the XDMF +
HDF5 file DOLFINx reads (`xdmf`, read by slices: `mesh.xdmfmesh`); and DOLFINx 0.5 in the same
run on the same mesh written once as XDMF + HDF5 (`dolfinx`: `XDMFFile.read_mesh` -- read by
slices, PT-Scotch on the distributed graph, distribution, ghost cells sharing a facet -- then
`VectorFunctionSpace(P1)`, the DOF numbering; FFCx's JIT warmed up on a one-cell mesh first).
Wall seconds of the slowest rank and CPU seconds of the busiest (best of the repeats; ranks
waiting in MPI yield their core: `mpi_yield_when_idle`), against the same way at 1 rank and
against DOLFINx at the same number of ranks; each rank's peak resident memory (VmHWM, the
process's whole life: Python, numpy, PETSc and MPI included; petsc4py is imported before the
stage at every rank count, as every run does, since the partition alone imports it and only on
several ranks), rank 0's against the mean of the others; the largest rank's peak against 1
rank's (`peak vs 1 rank`), and the same net of the process before the stage (`net vs 1 rank`:
the mesh stage's own memory, (peak − resident before, after freed heap pages are returned:
`mesh.memory.release`) against 1 rank's).

Section *gmsh* (a Gmsh MSH 4.1 file of the same box, binary, written once by meshio, and the
same as MSH 2.2):
`parsolve mesh convert` of it to the parallel file, by meshio (the file read whole, then
written; `gmsh`'s reader switched off) and by parsolve's reader (`mesh.gmshmesh.convert`:
streamed by chunks), each in a fresh process: seconds, peak resident memory and its growth
over the process before the conversion; then the mesh stage as in section *mesh* at 1, 2 and 4
ranks from the .msh given directly: `msh41` read by slices (`mesh.gmshmesh.GmshSlices`: rank 0
scans the block headers, every rank reads its rows), `msh22` the MSH 2.2 file by slices,
`meshio41` the 4.1 file read whole by meshio on rank 0, `h5` its converted file.

Usage (from the repository root):
    .venv/bin/python scripts/bench_setup.py                 # everything
    .venv/bin/python scripts/bench_setup.py --sections pattern first --quick
    .venv/bin/python scripts/bench_setup.py --sections mesh --mesh-n 56   # 1.05M tetrahedra
    .venv/bin/python scripts/bench_setup.py --sections gmsh --gmsh-n 56 --mesh-folder /tmp/m
    .venv/bin/python scripts/bench_setup.py --sections gmsh --gmsh-n 80 --gmsh-ways convert \
        msh41 meshio41 --mesh-ranks 1 4 --mesh-repeats 1   # 3.07M: the mesh dominates
    .venv/bin/python scripts/bench_setup.py --report      # table again from bench_results/setup.json
    .venv/bin/python scripts/bench_setup.py --sections compare --compare HEAD~3
    .venv/bin/python scripts/bench_setup.py --smoke      # CI: smallest sizes, files in a temp folder
Writes bench_results/setup.json and scripts/results/bench_setup.md.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import bench_harness as bh
from bench_harness import ROOT, SCRIPTS

PYTHON = bh.VENV_PY
RESULTS = bh.SCRATCH          # bench_results/ (a temporary folder in smoke mode)
COMMITTED = bh.PUBLISHED      # scripts/results/ (idem)

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
    from mpi4py import MPI

    return build_model(parse_scene(tomllib.loads(text), "bench.toml", text), MPI.COMM_WORLD)


def slowest(comm, seconds: float) -> float:
    from mpi4py import MPI
    return comm.allreduce(seconds, op=MPI.MAX)


# ------------------------------------------------------------------------------------------------
# children (one process per size, so that memory is returned between sizes)


def child_pattern(cell: str, n: int, repeats: int) -> dict:
    import numpy as np
    from baselines.pattern_reference import reference_block_positions, reference_pattern

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
    from baselines.pattern_reference import reference_block_positions, reference_pattern

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


COMPARED = ("parsolve/la/pattern.py", "parsolve/la/petsc.py", "parsolve/fem/element_matrices.py")
COMPARE_CASES = {"quick": [("triangle", 223), ("quad", 223), ("hexahedron", 20)],
                 "full": [("triangle", 223), ("triangle", 707), ("quad", 223), ("quad", 707),
                          ("hexahedron", 32), ("hexahedron", 69)]}


def compare_scene(cell: str, n: int) -> str:
    dim = 3 if cell == "hexahedron" else 2
    text = scene(dim, n, cell)
    return text.replace('preset = "direct"', 'preset = "iterative"') if dim == 3 else text


def extract_ref(ref: str, dest: Path) -> str:
    """The compared files as they are at ``ref`` into dest/ref_<name>.py; returns the commit."""
    for path in COMPARED:
        text = subprocess.run(["git", "show", f"{ref}:{path}"], cwd=ROOT, check=True, text=True,
                              capture_output=True).stdout
        (dest / f"ref_{Path(path).stem}.py").write_text(text)
    return subprocess.run(["git", "rev-parse", "--short", ref], cwd=ROOT, check=True, text=True,
                          capture_output=True).stdout.strip()


def assembly_versions(refdir: str | None) -> dict:
    """{"ref": ..., "new": ...}: node_pattern, SaddleOperator and the element reductions of each
    version (the reference's from the files extract_ref wrote)."""
    import importlib.util

    import parsolve.fem.element_matrices as em
    import parsolve.la.pattern as pat
    import parsolve.la.petsc as pet

    def version(p, o, e):
        return dict(node_pattern=p.node_pattern, SaddleOperator=o.SaddleOperator,
                    em_reduce=e.ElementMatrices.reduce, bm_reduce=e.BlockMatrices.reduce)

    out = {"new": version(pat, pet, em)}
    if refdir:
        mods = {}
        for path in COMPARED:
            name = f"ref_{Path(path).stem}"
            spec = importlib.util.spec_from_file_location(name, Path(refdir) / f"{name}.py")
            mods[name] = importlib.util.module_from_spec(spec)
            sys.modules[name] = mods[name]
            spec.loader.exec_module(mods[name])
        out["ref"] = version(mods["ref_pattern"], mods["ref_petsc"], mods["ref_element_matrices"])
    return out


def use_version(v: dict) -> None:
    import parsolve.fem.element_matrices as em
    import parsolve.solvers.system as system_mod

    system_mod.node_pattern = v["node_pattern"]
    system_mod.SaddleOperator = v["SaddleOperator"]
    em.ElementMatrices.reduce = v["em_reduce"]
    em.BlockMatrices.reduce = v["bm_reduce"]


def child_compare(cell: str, n: int, repeats: int, refdir: str) -> dict:
    """Set-up, first assembly and re-assembly of both versions, alternately in this process."""
    import numpy as np
    from mpi4py import MPI

    import parsolve.solvers.system as system_mod

    comm = MPI.COMM_WORLD
    dim = 3 if cell == "hexahedron" else 2
    model = build(compare_scene(cell, n))
    versions = assembly_versions(refdir)
    best: dict[str, float] = {}
    x = y = None
    for rep in range(repeats):
        for tag in (("ref", "new") if rep % 2 == 0 else ("new", "ref")):
            use_version(versions[tag])
            gc.collect()
            c0, w0 = time.process_time(), time.perf_counter()
            system = system_mod.SaddleSystem(comm, model)
            c1, w1 = time.process_time(), time.perf_counter()
            mat = system.assemble()
            c2, w2 = time.process_time(), time.perf_counter()
            re_c, re_w = [], []
            for _ in range(3):
                c3, w3 = time.process_time(), time.perf_counter()
                mat = system.assemble()
                re_c.append(time.process_time() - c3)
                re_w.append(time.perf_counter() - w3)
            got = dict(setup_cpu=c1 - c0, setup_wall=w1 - w0, asm1_cpu=c2 - c1, asm1_wall=w2 - w1,
                       first_cpu=c2 - c0, first_wall=w2 - w0, re_cpu=min(re_c), re_wall=min(re_w))
            for key, value in got.items():
                best[f"{key}_{tag}"] = min(best.get(f"{key}_{tag}", np.inf), value)
            if rep == 0:   # the same matrix: its product with one random vector, bit for bit
                if x is None:
                    x = mat.createVecRight()
                    x.setArray(np.random.default_rng(0).random(x.getLocalSize()))
                b = mat.createVecLeft()
                mat.mult(x, b)
                if y is None:
                    y = b.array.copy()
                else:
                    best["product_max_diff"] = float(np.abs(b.array - y).max())
                best[f"nnz_{tag}"] = int(mat.getInfo()["nz_used"])
            mat = None
            system.op.mat.destroy()
            del system
            gc.collect()
    return dict(section="compare", cell=cell, n=n, dofs=dofs_of(dim, n), repeats=repeats,
                **best)


def child_memory(cell: str, n: int, tag: str, refdir: str) -> dict:
    """Memory of one version (fresh process): held numpy arrays, the matrix, resident growth."""
    import numpy as np
    from mpi4py import MPI
    from petsc4py import PETSc

    import parsolve.solvers.system as system_mod
    from bench_scale import held_bytes, proc_memory

    comm = MPI.COMM_WORLD
    dim = 3 if cell == "hexahedron" else 2
    model = build(compare_scene(cell, n))
    use_version(assembly_versions(refdir if tag == "ref" else None)[tag])
    gc.collect()
    m0 = proc_memory()
    system = system_mod.SaddleSystem(comm, model)
    mat = system.assemble()
    mat = system.assemble()
    gc.collect()
    m1 = proc_memory()
    op = system.op
    # arrays PETSc works on (the new operator's): part of the matrix, not beside it
    shared = [getattr(op, k) for k in ("data", "cols_d", "rowptr_d", "rowptr_o")] \
        if hasattr(op, "cols_d") else []
    # the reference's classes live in ref_* modules, which held_bytes does not walk: start
    # from their attribute dictionaries
    held = held_bytes({"petsc": shared, "operator": [vars(system.pattern), vars(op)],
                       "element": [model.effects, system.composition]})
    # entries × (value + column) + row offsets: MatGetInfo's nz_allocated is 0 for a Mat on
    # the caller's arrays, so both versions are counted from the entries used
    isize = np.dtype(PETSc.IntType).itemsize
    nnz = int(mat.getInfo()["nz_used"])
    matrix = nnz * (8 + isize) + (mat.getLocalSize()[0] + 1) * isize
    return dict(section="memory", cell=cell, n=n, dofs=dofs_of(dim, n), tag=tag,
                shared=held["petsc"], beside=held["operator"], element=held["element"],
                matrix=matrix, nnz=nnz,
                rss_growth=m1["rss"] - m0["rss"], hwm_growth=m1["hwm"] - m0["hwm"])


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


MESH_FOLDER = {"path": RESULTS / "meshes"}   # --mesh-folder
GMSH_WAYS = ["convert", "msh41", "msh22", "meshio41", "h5"]   # section gmsh's


def gmsh_files(n: int, ways: list[str] = GMSH_WAYS) -> dict[str, str]:
    """A box of 6·n³ tetrahedra as a Gmsh MSH 4.1 binary file, as MSH 2.2 and its parallel
    file (each made once, when a way needs it), and the scene [mesh] lines of section gmsh's
    ways."""
    import meshio

    from parsolve.mesh.cli import convert
    from parsolve.mesh.generators import box

    folder = MESH_FOLDER["path"]
    folder.mkdir(parents=True, exist_ok=True)
    msh, h5 = folder / f"box_tetra_{n}_41.msh", folder / f"box_tetra_{n}_41.h5"
    msh22 = folder / f"box_tetra_{n}_22.msh"
    if not msh.exists() or "msh22" in ways and not msh22.exists():
        whole = box(1.0, 1.0, 1.0, n, n, n, cell="tetra")
        mesh = meshio.Mesh(whole.points, [("tetra", whole.cells)])
        meshio.write(str(msh), mesh, file_format="gmsh", binary=True)
        if "msh22" in ways:
            meshio.write(str(msh22), mesh, file_format="gmsh22", binary=True)
    if "h5" in ways and not h5.exists():
        convert(str(msh), str(h5))
    return {"msh": str(msh), "msh41": f'file = "{msh}"', "meshio41": f'file = "{msh}"',
            "msh22": f'file = "{msh22}"', "h5": f'file = "{h5}"'}


def child_convert(way: str, msh: str, out: str) -> dict:
    """``parsolve mesh convert`` of ``msh`` in this fresh process (``way`` meshio: parsolve's
    Gmsh reader switched off): seconds, CPU seconds, peak memory and the peak before."""
    import h5py  # noqa: F401 - both ways' imports before the baseline
    import meshio  # noqa: F401

    from parsolve.mesh import cli, gmsh

    if way == "meshio":
        gmsh.ours = lambda path: False
    gc.collect()
    before = bh.proc_memory()
    t0, c0 = time.perf_counter(), time.process_time()
    line = cli.convert(msh, out, force=True)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"way": way, "summary": line, "cells": int(line.split(": ")[1].split()[0]),
            "seconds": seconds, "cpu": cpu, "hwm": bh.proc_memory()["hwm"],
            "before": before["rss"], "size": os.path.getsize(msh)}


def convert_table(rows: list[dict]) -> str:
    head = ["convert by", "cells", ".msh MiB", "seconds (CPU)", "peak MiB",
            "peak − process before MiB", "B per cell"]
    out = [[r["way"], str(r["cells"]), bh.mib(r["size"]), f"{r['seconds']:.2f} ({r['cpu']:.2f})",
            bh.mib(r["hwm"]), bh.mib(r["hwm"] - r["before"]),
            f"{(r['hwm'] - r['before']) / max(r['cells'], 1):.0f}"] for r in rows]
    return bh.md_table(head, out)


def mesh_files(n: int) -> dict[str, str]:
    """A box of 6·n³ tetrahedra as a Gmsh file and as the parallel file (made once, kept in
    the scratch folder), and the scene [mesh] lines of the three ways."""
    import meshio

    from parsolve.mesh.cli import convert
    from parsolve.mesh.generators import box

    folder = MESH_FOLDER["path"]
    folder.mkdir(parents=True, exist_ok=True)
    msh, h5 = folder / f"box_tetra_{n}.msh", folder / f"box_tetra_{n}.h5"
    # DOLFINx's: it reads the data from the .h5 named as the .xdmf, whatever the XML says
    xdmf = folder / f"box_tetra_{n}_dolfinx.xdmf"
    if not msh.exists() or not xdmf.exists():
        whole = box(1.0, 1.0, 1.0, n, n, n, cell="tetra")
        mesh = meshio.Mesh(whole.points, [("tetra", whole.cells)])
        meshio.write(str(msh), mesh, file_format="gmsh22", binary=True)
        write_xdmf(xdmf, xdmf.with_suffix(".h5"), whole.points, whole.cells)
    if not h5.exists():
        convert(str(msh), str(h5))
    return {"msh": f'file = "{msh}"', "h5": f'file = "{h5}"', "dolfinx": str(xdmf),
            "xdmf": f'file = "{xdmf}"',
            "box": f'generator = "box"\nlx = 1.0\nly = 1.0\nlz = 1.0\nnx = {n}\nny = {n}\n'
                   f'nz = {n}\ncell = "tetra"'}


def write_xdmf(xdmf: Path, data: Path, points, cells) -> None:
    """A tetrahedral mesh as XDMF + HDF5 the way meshio and DOLFINx write it (grid "Grid")."""
    import h5py

    with h5py.File(data, "w") as f:
        f["points"], f["cells"] = points, cells.astype("int64")
    item = ('<DataItem DataType="{}" Dimensions="{} {}" Format="HDF" Precision="8">'
            f'{data.name}:/{{}}</DataItem>')
    xdmf.write_text(
        '<Xdmf Version="3.0"><Domain><Grid Name="Grid"><Geometry GeometryType="XYZ">'
        + item.format("Float", *points.shape, "points") + '</Geometry><Topology '
        f'TopologyType="Tetrahedron" NumberOfElements="{len(cells)}" NodesPerElement="4">'
        + item.format("Int", *cells.shape, "cells") + "</Topology></Grid></Domain></Xdmf>")


def child_mesh(way: str, n: int, mesh_lines: str, repeats: int) -> dict:
    """The mesh stage of a 3D scene on this many ranks: time (best of the repeats) and every
    rank's peak memory."""
    from mpi4py import MPI

    from parsolve.mesh import memory
    from parsolve.model import _distributed_mesh
    from parsolve.scene import parse_scene
    import tomllib

    if way == "dolfinx":
        return child_dolfinx_mesh(n, mesh_lines, repeats)
    if way == "meshio41":   # the MSH 4.1 file read whole by meshio on rank 0
        from parsolve.mesh import gmsh

        gmsh.ours = lambda path: False
    from petsc4py import PETSc  # noqa: F401 - every run's; the partition's on 2+ ranks only

    comm = MPI.COMM_WORLD
    text = (f"[mesh]\n{mesh_lines}\n[model]\nhypothesis = \"3d\"\n[[materials]]\n"
            "E = 1.0\nnu = 0.3\n[solver]\npreset = \"iterative\"\n")
    scene = parse_scene(tomllib.loads(text), "bench.toml")
    seconds, cpu = [], []
    gc.collect()
    memory.release()   # (the process's live memory: no freed heap pages of the imports)
    before = comm.gather(bh.proc_memory()["rss"], root=0)
    for _ in range(repeats):
        part = None
        gc.collect()
        comm.Barrier()
        t0, c0 = time.perf_counter(), time.process_time()
        part = _distributed_mesh(scene, comm)
        cpu.append(slowest(comm, time.process_time() - c0))
        seconds.append(slowest(comm, time.perf_counter() - t0))
    hwm = comm.gather(bh.proc_memory()["hwm"], root=0)
    return {"way": way, "n": n, "cells": part.num_global_cells,
            "points": part.num_global_points, "nranks": comm.size,
            "seconds": min(seconds), "all_seconds": seconds, "cpu": min(cpu), "hwm": hwm,
            "before": before}


def child_dolfinx_mesh(n: int, xdmf: str, repeats: int) -> dict:
    """DOLFINx 0.5: ``XDMFFile.read_mesh`` + ``VectorFunctionSpace(P1)`` of the file, after the
    JIT of the coordinate and P1 elements on a one-cell mesh (FFCx's cache filled: not timed)."""
    from dolfinx import fem, io, mesh as dmesh
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    warm = dmesh.create_unit_cube(comm, 1, 1, 1, dmesh.CellType.tetrahedron)
    fem.VectorFunctionSpace(warm, ("Lagrange", 1))
    del warm
    seconds, cpu = [], []
    for _ in range(repeats):
        msh = space = None
        gc.collect()
        comm.Barrier()
        t0, c0 = time.perf_counter(), time.process_time()
        with io.XDMFFile(comm, xdmf, "r") as f:
            msh = f.read_mesh(name="Grid")
        space = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
        cpu.append(slowest(comm, time.process_time() - c0))
        seconds.append(slowest(comm, time.perf_counter() - t0))
    cells = msh.topology.index_map(3).size_global
    dofs = space.dofmap.index_map.size_global * space.dofmap.index_map_bs
    hwm = comm.gather(bh.proc_memory()["hwm"], root=0)
    return {"way": "dolfinx", "n": n, "cells": cells, "points": dofs // 3, "nranks": comm.size,
            "seconds": min(seconds), "all_seconds": seconds, "cpu": min(cpu), "hwm": hwm}


def mesh_table(rows: list[dict]) -> str:
    """Wall seconds (CPU seconds of the busiest rank in brackets: on a shared machine the wall
    time counts the other jobs too; Open MPI polls while it waits, so CPU counts the waits)."""
    head = ["mesh", "cells", "ranks", "seconds (CPU)", "vs 1 rank", "vs DOLFINx",
            "rank 0 peak MiB", "others' mean MiB", "rank 0 / others", "peak vs 1 rank",
            "net vs 1 rank"]

    def both(a: dict, b: dict | None) -> str:
        if not b:
            return ""
        cpu = f" ({a['cpu'] / b['cpu']:.2f})" if "cpu" in a and "cpu" in b else ""
        return f"{a['seconds'] / b['seconds']:.2f}{cpu}"

    ones = {(r["way"], r["n"]): r for r in rows if r["nranks"] == 1}
    peer = {(r["n"], r["nranks"]): r for r in rows if r["way"] == "dolfinx"}
    out = []
    for r in rows:
        others = r["hwm"][1:]
        mean = sum(others) / len(others) if others else None
        one = ones.get((r["way"], r["n"])) if r["nranks"] > 1 else None
        theirs = peer.get((r["n"], r["nranks"])) if r["way"] != "dolfinx" else None
        cpu = f" ({r['cpu']:.2f})" if "cpu" in r else ""
        out.append([r["way"], str(r["cells"]), str(r["nranks"]), f"{r['seconds']:.2f}{cpu}",
                    both(r, one), both(r, theirs), bh.mib(r["hwm"][0]),
                    bh.mib(mean) if mean else "", f"{r['hwm'][0] / mean:.2f}" if mean else "",
                    *_peak_ratios(r, one)])
    return bh.md_table(head, out)


def _peak_ratios(r: dict, one: dict | None) -> list[str]:
    """The largest rank's peak against 1 rank's, raw and net of the process before the stage
    (rows without "before": older runs, DOLFINx)."""
    if not one:
        return ["", ""]
    raw = f"{max(r['hwm']) / one['hwm'][0]:.2f}"
    if "before" not in r or "before" not in one:
        return [raw, ""]
    net = max(h - b for h, b in zip(r["hwm"], r["before"])) / (one["hwm"][0] - one["before"][0])
    return [raw, f"{net:.2f}"]


MODEL_RANKS, MODEL_DOFS = 1024, 1e9


def fit_split(points: list[tuple[float, float, float]]) -> dict | None:
    """y = a + c·N/P, a, c ≥ 0 (no whole-mesh term: what the slice path is built to be),
    least squares on the relative error, as ``bench_scale.fit``; points (N, P, y)."""
    import numpy as np

    pts = [(N, P, y) for N, P, y in points if y]
    if len(pts) < 3:
        return None
    N, P, y = (np.array(v, dtype=float) for v in zip(*pts))
    X = np.column_stack([np.ones_like(N), N / P])
    best = None
    for cols in ([0, 1], [1]):   # a dropped when it would be negative
        sol, *_ = np.linalg.lstsq(X[:, cols] / y[:, None], np.ones_like(y), rcond=None)
        coef = np.zeros(2)
        coef[cols] = sol
        err = float(np.sum((X @ coef / y - 1) ** 2))
        if np.all(sol >= 0) and (best is None or err < best[0]):
            best = (err, coef)
    if best is None:
        return None
    coef = best[1]
    return dict(a=float(coef[0]), b=0.0, c=float(coef[1]),
                worst=float(np.max(np.abs(X @ coef / y - 1))), points=len(pts))


def mesh_model(rows: list[dict]) -> str:
    """Fits y = a + b·N + c·N/P (N: DOFs = 3 × nodes; ``bench_scale.fit``), and y = a + c·N/P
    (``fit_split``), of each way's time (CPU s of the busiest rank: 4 ranks oversubscribe 2
    cores, but a waiting rank yields its core, so its CPU seconds are still its work) and peak
    resident memory per rank, on 1, 2 and 4 ranks, and their values at MODEL_RANKS ×
    MODEL_DOFS."""
    from bench_scale import at, fit

    head = ["mesh", "quantity", "fit", "a", "b (whole)", "c (÷ P)", "worst fit error", "points",
            f"model: {MODEL_RANKS} ranks × 10⁹ DOFs"]
    out = []
    for way in dict.fromkeys(r["way"] for r in rows):
        mine = [r for r in rows if r["way"] == way and "points" in r]
        if len({r["n"] for r in mine}) < 2:
            continue
        times = [(3.0 * r["points"], r["nranks"], r.get("cpu")) for r in mine]
        peaks = [(3.0 * r["points"], r["nranks"], float(max(r["hwm"]))) for r in mine]
        for kind, fitter in (("a + b·N + c·N/P", fit), ("a + c·N/P", fit_split)):
            f = fitter(times)
            if f:
                out.append([way, "CPU s", kind, f"{f['a']:.2f} s", f"{f['b'] * 1e6:.2f} µs/DOF",
                            f"{f['c'] * 1e6:.2f} µs/DOF", f"{f['worst']:.0%}", str(f["points"]),
                            f"{at(f, MODEL_DOFS, MODEL_RANKS):,.1f} s"])
            f = fitter(peaks)
            if f:
                out.append([way, "peak / rank", kind, f"{f['a'] / 2**20:.0f} MiB",
                            f"{f['b']:.1f} B/DOF", f"{f['c']:.1f} B/DOF", f"{f['worst']:.0%}",
                            str(f["points"]), f"{at(f, MODEL_DOFS, MODEL_RANKS) / 2**30:,.2f} GiB"])
    return bh.md_table(head, out, first="---", rest="---:") if out else ""


# ------------------------------------------------------------------------------------------------
# driver


def spawn(args: list[str], nranks: int = 1, timeout: float = 1800.0):
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.json"
        cmd = [PYTHON, str(Path(__file__).resolve()), "--child", *args, "--json", str(out)]
        if nranks > 1:
            cmd = ["bash", str(SCRIPTS / "mpirun.sh"), "-n", str(nranks), *cmd]
        env = bh.child_env()
        if args[0] == "mesh":
            # a rank waiting in MPI yields the core instead of polling it: at 2 ranks on 2
            # shared cores (Open MPI polls unless oversubscribed) the CPU seconds then count
            # the work, not the waits for a rank the other jobs descheduled
            env["OMPI_MCA_mpi_yield_when_idle"] = "1"
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
    cpu = bh.cpu_model()
    load = os.getloadavg()
    return (f"Machine: {cpu}, {os.cpu_count()} cores; load average {load[0]:.2f} at the end "
            f"(> 2 means other jobs shared the cores: compare ratios within a row); "
            f"run {time.strftime('%Y-%m-%d %H:%M:%S')} UTC.")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sections", nargs="+", default=["pattern", "first", "mumps"],
                   choices=["pattern", "first", "mumps", "compare", "mesh", "gmsh"])
    p.add_argument("--compare", default=None, metavar="REF",
                   help="git ref of the assembly code to compare with (section compare)")
    p.add_argument("--compare-cases", nargs="+", default=None, metavar="CELL:N",
                   help="e.g. triangle:707 hexahedron:69 (default: 2D N=223, 707; 3D N=32, 69)")
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
    p.add_argument("--mesh-n", type=int, nargs="+", default=[32, 44, 56],
                   help="hexes per side of the mesh section's boxes (6·n³ tetrahedra; 56: 1.05M); "
                   "the .msh (rank 0's path, minutes) at the largest only")
    p.add_argument("--mesh-ways", nargs="+", default=["msh", "h5", "xdmf", "box", "dolfinx"],
                   choices=["msh", "h5", "xdmf", "box", "dolfinx"],
                   help="the mesh section's ways")
    p.add_argument("--mesh-ranks", type=int, nargs="+", default=[1, 2, 4])
    p.add_argument("--mesh-repeats", type=int, default=2, help="the mesh section's repeats "
                   "(best of)")
    p.add_argument("--gmsh-n", type=int, nargs="+", default=[56],
                   help="hexes per side of section gmsh's box (56: 1.05M tetrahedra)")
    p.add_argument("--gmsh-ways", nargs="+", default=GMSH_WAYS, choices=GMSH_WAYS,
                   help="section gmsh's ways (convert: both conversions)")
    p.add_argument("--mesh-folder", default=None,
                   help="where the mesh sections' files are written once (default: "
                   "bench_results/meshes)")
    p.add_argument("--child", nargs="+", default=None, help=argparse.SUPPRESS)
    p.add_argument("--json", default=None, help=argparse.SUPPRESS)
    bh.add_smoke(p)
    a = p.parse_args()
    if a.smoke:   # smallest sizes of every default section; DOLFINx only if installed
        a.quick, a.n2d, a.n3d, a.repeats, a.mumps_2d, a.mumps_3d = True, [8], [3], 1, 8, 3
        a.mesh_n, a.gmsh_n, a.mesh_repeats = [4], [4], 1
        a.sections = sorted(set(a.sections) | {"mesh", "gmsh"})
        a.no_peers = a.no_peers or not bh.peer_available("dolfinx")
    if a.child:
        kind, *rest = a.child
        if kind == "pattern":
            out = child_pattern(rest[0], int(rest[1]), int(rest[2]))
        elif kind == "first":
            out = child_first(rest[0], int(rest[1]), int(rest[2]))
        elif kind == "compare":
            out = child_compare(rest[0], int(rest[1]), int(rest[2]), rest[3])
        elif kind == "mesh":
            out = child_mesh(rest[0], int(rest[1]), rest[2], int(rest[3]))
        elif kind == "convert":
            out = child_convert(rest[0], rest[1], rest[2])
        elif kind == "memory":
            out = child_memory(rest[0], int(rest[1]), rest[2], rest[3])
        else:
            out = child_mumps(int(rest[0]), int(rest[1]), rest[2])
        from mpi4py import MPI
        if MPI.COMM_WORLD.rank == 0:
            Path(a.json).write_text(json.dumps(out))
        return

    if a.mesh_folder:
        MESH_FOLDER["path"] = Path(a.mesh_folder)
    s2, s3 = (QUICK_2D, QUICK_3D) if a.quick else (SIZES_2D, SIZES_3D)
    s2, s3 = a.n2d or s2, a.n3d or s3
    cases = [(c, n, 2) for c in ("triangle", "quad") for n in s2] + [("hexahedron", n, 3) for n in s3]
    saved = RESULTS / "setup.json"
    RESULTS.mkdir(exist_ok=True)
    # sections not run now keep their last results; every row is saved as soon as it is measured
    results = json.loads(saved.read_text()) if saved.exists() else {}
    for section in ("pattern", "first", "mumps", "compare", "mesh", "gmsh", "gmsh_convert"):
        run_now = section.split("_")[0] in a.sections and not a.report
        if run_now or section not in results:
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
    if "compare" in a.sections and not a.report:
        if not a.compare:
            p.error("--sections compare needs --compare REF")
        cases = ([(c.split(":")[0], int(c.split(":")[1])) for c in a.compare_cases]
                 if a.compare_cases else COMPARE_CASES["quick" if a.quick else "full"])
        run_compare(results, a.compare, cases, a.repeats, not a.no_peers, save)
    if "mumps" in a.sections and not a.report:
        sizes = {2: a.mumps_2d if a.smoke or not a.quick else 60,
                 3: a.mumps_3d if a.smoke or not a.quick else 8}
        for dim in (2, 3):
            for control in ("none", "side", "body"):
                for nranks in (1,) if a.smoke else (1, 2):   # smoke: 1 rank
                    rows = spawn(["mumps", str(dim), str(sizes[dim]), control], nranks=nranks)
                    results["mumps"].extend(rows or [])
                    save()
    if "mesh" in a.sections and not a.report:
        t0 = time.time()
        for n in sorted(a.mesh_n):
            lines = mesh_files(n)
            ways = [w for w in a.mesh_ways if (w != "dolfinx" or not a.no_peers)
                    and (w != "msh" or n == max(a.mesh_n))]
            for way, nranks in ((w, r) for w in ways for r in a.mesh_ranks):
                reps = 1 if way == "msh" else a.mesh_repeats
                row = spawn(["mesh", way, str(n), lines[way], str(reps)], nranks=nranks)
                if row:
                    results["mesh"].append(row)
                    save()
                    results["mesh_machine"] = machine() + f" Section mesh: {time.time() - t0:.0f} s."
                    print(f"[mesh] {way} {row['cells']} cells, {nranks} ranks: "
                          f"{row['seconds']:.2f} s (CPU {row['cpu']:.2f}), peaks "
                          f"{[bh.mib(h) for h in row['hwm']]}", flush=True)
    if "gmsh" in a.sections and not a.report:
        run_gmsh(results, a, save)
    write_report(results, time.time() - t_start)


def run_gmsh(results: dict, a, save) -> None:
    """Section gmsh: convert by meshio and by parsolve's reader, then the mesh stage from the
    .msh read by slices, by meshio on rank 0, and from its .h5."""
    t0 = time.time()
    for n in sorted(a.gmsh_n):
        files = gmsh_files(n, a.gmsh_ways)
        for way in ("meshio", "parsolve") if "convert" in a.gmsh_ways else ():
            out = Path(files["msh"]).with_name(f"convert_{way}.h5")
            row = spawn(["convert", way, files["msh"], str(out)])
            out.unlink(missing_ok=True)
            if row:
                results["gmsh_convert"].append(row)
                save()
                print(f"[gmsh] convert by {way}: {row['seconds']:.2f} s, peak "
                      f"{bh.mib(row['hwm'])} MiB", flush=True)
        for way, nranks in ((w, r) for w in GMSH_WAYS[1:] if w in a.gmsh_ways
                            for r in a.mesh_ranks):
            row = spawn(["mesh", way, str(n), files[way], str(a.mesh_repeats)], nranks=nranks)
            if row:
                results["gmsh"].append(row)
                results["gmsh_machine"] = machine() + f" Section gmsh: {time.time() - t0:.0f} s."
                save()
                print(f"[gmsh] {way} {row['cells']} cells, {nranks} ranks: {row['seconds']:.2f} "
                      f"s (CPU {row['cpu']:.2f}), peaks {[bh.mib(h) for h in row['hwm']]}",
                      flush=True)


def run_compare(results: dict, ref: str, cases: list, repeats: int | None, peers: bool,
                save) -> None:
    """Section compare: both versions timed in one child, memory in one fresh child each,
    DOLFINx's first assembly of the same size."""
    import bench_peers

    t0 = time.time()
    with tempfile.TemporaryDirectory() as refdir:
        commit = extract_ref(ref, Path(refdir))
        results["compare_ref"] = f"`{ref}` ({commit})"
        for cell, n in cases:
            dim = 3 if cell == "hexahedron" else 2
            reps = repeats or (3 if dofs_of(dim, n) < 200_000 else 2)
            row = spawn(["compare", cell, str(n), str(reps), refdir])
            if row is None:
                continue
            for tag in ("ref", "new"):
                row[f"memory_{tag}"] = spawn(["memory", cell, str(n), tag, refdir])
            if peers:
                try:
                    if dim == 2:
                        res = bench_peers.run_peer("dolfinx", [n], cells=(cell,), nranks=1,
                                                   repeats=reps, timeout=1800)
                        row["dolfinx"] = [r for r in res["assembly"] if r["n"] == n][0]
                    else:
                        row["dolfinx"] = bench_peers.run_dolfinx_box(n, reps)
                        row["dolfinx_deg2"] = bench_peers.run_dolfinx_box(n, reps, degree=2)
                except Exception as err:  # noqa: BLE001 - report without the peer
                    print(f"[bench] DOLFINx {cell} {n}: {err}"[:2000], file=sys.stderr, flush=True)
            results["compare"].append(row)
            results["compare_machine"] = machine() + f" Section compare: {time.time() - t0:.0f} s."
            save()
            print(f"[compare] {cell} {n}: first cpu ref {row['first_cpu_ref']:.2f} new "
                  f"{row['first_cpu_new']:.2f}; re ref {row['re_cpu_ref']:.2f} new "
                  f"{row['re_cpu_new']:.2f}; dolfinx {row.get('dolfinx', {}).get('t_first')}",
                  flush=True)


def compare_tables(rows: list[dict]) -> list[str]:
    mib = 2.0 ** 20
    out = ["Times: best of the repeats, CPU seconds (wall seconds in brackets); ×faster = ref / "
           "new; ×DOLFINx = DOLFINx's first assembly time / parsolve's (a rate ratio; ≥ 0.5 is the "
           "target of issue 8), on CPU seconds: DOLFINx's = its wall time × its CPU share over "
           "the timed sections (bench_peers' `cpu_share`: the machine is shared), then on wall "
           "seconds in brackets. 3D DOLFINx: UFL's quadrature degree (4) / degree 2 (2×2×2 "
           "points, as parsolve's hexahedra).", "",
           "| cell | DOFs | set-up ref / new s | first assemble() ref / new s | first assembly ref s "
           "| new s | ×faster | re-assembly ref / new s | ×faster | DOLFINx 1st s CPU (wall) "
           "| ×DOLFINx ref | ×DOLFINx new | A·x ref − new |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        peers = [p for p in (r.get("dolfinx"), r.get("dolfinx_deg2")) if p]

        def cpu(p):
            return p["t_first"] * min(p.get("cpu_share", 1.0), 1.0)

        tds = " / ".join(f"{cpu(p):.2f} ({p['t_first']:.2f})" for p in peers) or "–"

        def vs(tag):
            c, w = r[f"first_cpu_{tag}"], r[f"first_wall_{tag}"]
            return " / ".join(f"{cpu(p) / c:.2f} ({p['t_first'] / w:.2f})" for p in peers) or "–"

        out.append(
            f"| {r['cell']} | {r['dofs']:,} | {r['setup_cpu_ref']:.2f} / {r['setup_cpu_new']:.2f} "
            f"| {r['asm1_cpu_ref']:.2f} / {r['asm1_cpu_new']:.2f} | {r['first_cpu_ref']:.2f} "
            f"({r['first_wall_ref']:.2f}) | {r['first_cpu_new']:.2f} ({r['first_wall_new']:.2f}) "
            f"| {r['first_cpu_ref'] / r['first_cpu_new']:.2f} | {r['re_cpu_ref']:.3f} / "
            f"{r['re_cpu_new']:.3f} | {r['re_cpu_ref'] / r['re_cpu_new']:.2f} | {tds} | {vs('ref')} "
            f"| {vs('new')} | {r.get('product_max_diff', float('nan')):.1e} |")
    out += ["", "Memory (MiB), fresh process per version, after set-up + two assemblies: *matrix* "
            "= allocated entries × 12 B + row offsets, owned by PETSc (ref) or by the operator "
            "and used by PETSc in place (new); *beside* = numpy arrays of the node pattern and "
            "the operator that are not the matrix; *element* = the effects' element arrays "
            "(not changed here); ratios to the matrix; RSS / peak growth = resident memory "
            "(VmRSS / VmHWM) after minus before `SaddleSystem`.", "",
            "| cell | DOFs | matrix | beside ref | beside new | beside/matrix ref → new | element "
            "| (beside + element)/matrix ref → new | RSS growth ref / new | peak "
            "growth ref / new |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        a, b = r.get("memory_ref"), r.get("memory_new")
        if not a or not b:
            continue
        mat = b["matrix"]
        tot_a = (a["beside"] + a["element"]) / a["matrix"]
        tot_b = (b["beside"] + b["element"]) / b["matrix"]
        out.append(
            f"| {r['cell']} | {r['dofs']:,} | {mat / mib:.0f} | {a['beside'] / mib:.0f} | "
            f"{b['beside'] / mib:.0f} | {a['beside'] / a['matrix']:.2f} → "
            f"{b['beside'] / b['matrix']:.2f} | {b['element'] / mib:.0f} | {tot_a:.2f} → "
            f"{tot_b:.2f} | {a['rss_growth'] / mib:.0f} / {b['rss_growth'] / mib:.0f} | "
            f"{a['hwm_growth'] / mib:.0f} / {b['hwm_growth'] / mib:.0f} |")
    return out


def write_report(results: dict, seconds: float) -> None:
    """scripts/results/bench_setup.md (sections pattern, first, mumps: rewritten only when one
    of them has rows) and scripts/results/bench_setup_compare.md (section compare)."""
    peers = {tuple(p["key"]): p for p in results.get("peers", [])}
    COMMITTED.mkdir(exist_ok=True)
    intro = __doc__.split("\n\n", 1)[1].split("Usage")[0].strip()
    if results.get("mesh"):
        text = ["# parsolve mesh stage: rank 0's path against the slice path", "",
                [b for b in intro.split("\n\n") if b.startswith("Section *mesh*")][0], "",
                results.get("mesh_machine", machine()), "", mesh_table(results["mesh"]), "",
                "Fits of y = a + b·N + c·N/P and of y = a + c·N/P (N = DOFs = 3 × nodes; CPU "
                "seconds of the busiest rank and peak memory per rank on 1, 2 and 4 ranks; least "
                "squares on the relative error, coefficients ≥ 0) and the model each gives:", "", mesh_model(results["mesh"]), ""]
        md = "\n".join(text)
        (COMMITTED / "bench_setup_mesh.md").write_text(md)
        print(md)
    if results.get("gmsh") or results.get("gmsh_convert"):
        text = ["# parsolve mesh stage from a Gmsh file: meshio against parsolve's reader", "",
                [b for b in intro.split("\n\n") if b.startswith("Section *gmsh*")][0], "",
                results.get("gmsh_machine", machine()), "", "## Convert to the parallel file", "",
                convert_table(results.get("gmsh_convert", [])), "",
                "## The mesh stage from the .msh given directly", "",
                mesh_table(results.get("gmsh", [])), ""]
        md = "\n".join(text)
        (COMMITTED / "bench_setup_gmsh.md").write_text(md)
        print(md)
    if results["pattern"] or results["first"] or results["mumps"]:
        text = ["# parsolve set-up benchmark", "", intro, "", machine() + f" {seconds:.0f} s.", "",
                *results.get("notes", [])]
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
        (COMMITTED / "bench_setup.md").write_text(md)
        print(md)
    if results.get("compare"):
        section = [b for b in intro.split("\n\n") if b.startswith("Section *compare*")]
        text = ["# parsolve assembly: before / after, and DOLFINx's first assembly", "",
                *section, "", results.get("compare_machine", machine()), "",
                *results.get("compare_notes", []), "",
                f"## The assembly code at {results.get('compare_ref', '?')} against the working "
                "tree (1 rank, same run)", "", *compare_tables(results["compare"]), "",
                "Rerun: `.venv/bin/python scripts/bench_setup.py --sections compare --compare REF` "
                "(`--compare-cases triangle:707 hexahedron:69`, `--quick`, `--no-peers`; "
                "`bash scripts/bench_env.sh` once for DOLFINx).", ""]
        md = "\n".join(text)
        (COMMITTED / "bench_setup_compare.md").write_text(md)
        print(md)


if __name__ == "__main__":
    main()
