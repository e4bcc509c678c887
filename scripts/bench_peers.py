#!/usr/bin/env python3
"""Peer benchmarks for parsolve: DOLFINx 0.5 (Debian) and scikit-fem (PyPI) on the same meshes.

Problem (shared with parsolve's benchmarks): 2D linear elasticity, E=1, nu=0.3, plane strain by
default (plane stress on request), on the unit square [0,1]^2 split into n x n quads; the triangle
mesh splits every quad along its (0,0)-(1,1) diagonal (DOLFINx's "right" diagonal). Points are
numbered x-fastest, cells are in meshio/VTK order (`unit_square`), the same arrays go to both peers.
P1 vector ("triangle") and Q1 vector ("quad") elements: 2*(n+1)^2 DOFs.

Solve problem (DOLFINx only): u = 0 on x=0 (clamped left), traction t = TRACTION on x=1, zero
body force. MUMPS LU (preonly) and CG + GAMG with the rigid-body near-nullspace.

The two peers live in different environments, so this file is both a module and a script:

    # DOLFINx: Debian's python (or /work/main/.venv/bin/python, which sees system site-packages)
    /usr/bin/python3 scripts/bench_peers.py dolfinx --n 100 200 --cell triangle quad --json d.json
    /usr/bin/python3 scripts/bench_peers.py dolfinx --n 200 --solve mumps gamg --no-assembly
    OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 \
        mpirun -n 2 /usr/bin/python3 scripts/bench_peers.py dolfinx --n 200 --json d2.json
    # scikit-fem: the bench venv made by scripts/bench_env.sh
    /work/bench-venv/bin/python scripts/bench_peers.py skfem --n 100 200 --cell triangle quad --json s.json
    # sanity: same Frobenius norm from both peers (n=8), DOLFINx on 1 and 2 ranks, repeatable norms
    python scripts/bench_peers.py check
    python scripts/bench_peers.py --smoke        # CI: check at n = 4, peers not installed skipped

From a parsolve benchmark, `run_peer("dolfinx", [100, 200], ...)` runs the right interpreter (under
mpirun if nranks > 1) as a subprocess and returns the parsed JSON.

Timings: time.perf_counter, wall clock, with an MPI barrier on both sides under MPI (so a time is
the slowest rank's). Each figure is the best of `repeats` (default 3 below 200k DOFs, 2 below 600k,
else 1; DOLFINx reassembly always >= 3).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import bench_harness as bh

E_MOD = 1.0
NU = 0.3
TRACTION = (0.0, -1.0)
CELLS = ("triangle", "quad")
SOLVE_METHODS = ("mumps", "gamg")
GAMG_RTOL = 1e-8

DEFAULT_BENCH_VENV = bh.BENCH_VENV
DEBIAN_PYTHON = bh.DEBIAN_PY
proc_memory, mat_bytes, _cpu_idle = bh.proc_memory, bh.mat_bytes, bh.cpu_idle


# --------------------------------------------------------------------------------------------------
# shared problem definition


def unit_square(n: int, cell: str) -> tuple[np.ndarray, np.ndarray]:
    """Structured mesh of [0,1]^2, n x n quads: (points (N,2) float64, cells (M,k) int64, VTK order).

    Node (i, j) -> id j*(n+1) + i at (i/n, j/n). Quads: (v00, v10, v11, v01), counter-clockwise.
    Triangles: each quad -> (v00, v10, v11), (v00, v11, v01), both counter-clockwise.
    """
    if cell not in CELLS:
        raise ValueError(f"cell must be one of {CELLS}, got {cell!r}")
    s = np.linspace(0.0, 1.0, n + 1)
    xx, yy = np.meshgrid(s, s, indexing="xy")  # xx[j, i] = s[i]: x fastest
    points = np.column_stack([xx.ravel(), yy.ravel()])
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="xy")
    v00 = (j * (n + 1) + i).ravel().astype(np.int64)
    v10 = v00 + 1
    v01 = v00 + (n + 1)
    v11 = v01 + 1
    if cell == "quad":
        cells = np.column_stack([v00, v10, v11, v01])
    else:
        t1 = np.column_stack([v00, v10, v11])
        t2 = np.column_stack([v00, v11, v01])
        cells = np.empty((2 * n * n, 3), dtype=np.int64)
        cells[0::2] = t1
        cells[1::2] = t2
    return points, cells


def num_dofs(n: int) -> int:
    """P1/Q1 vector DOFs on the n x n unit square."""
    return 2 * (n + 1) ** 2


def lame(E: float = E_MOD, nu: float = NU, plane: str = "strain") -> tuple[float, float]:
    """(lambda, mu); plane stress uses lambda* = 2 mu lambda / (lambda + 2 mu)."""
    mu = E / (2.0 * (1.0 + nu))
    lmbda = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    if plane == "stress":
        lmbda = 2.0 * mu * lmbda / (lmbda + 2.0 * mu)
    elif plane != "strain":
        raise ValueError(f"plane must be 'strain' or 'stress', got {plane!r}")
    return lmbda, mu


def default_repeats(dofs: int) -> int:
    if dofs < 200_000:
        return 3
    if dofs < 600_000:
        return 2
    return 1


# --------------------------------------------------------------------------------------------------
# DOLFINx 0.5


_JIT_STATE: dict = {"params": None, "compiled": set(), "tmp": None}


def _comm(comm=None):
    if comm is None:
        from mpi4py import MPI

        comm = MPI.COMM_WORLD
    return comm


# wall and CPU seconds of the timed benchmark sections (not mesh/JIT), for the cpu_share check
_CPU = {"wall": 0.0, "cpu": 0.0}


def _cpu_now() -> float:
    """CPU seconds of this process and its finished children (the JIT's C compiler)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _timer(comm):
    """Call with a function: barrier, run, barrier; returns (result, seconds). Unless
    _count=False, the section's wall and CPU time are added to _CPU."""

    def run(fn, *args, _count=True, **kwargs):
        comm.Barrier()
        t0, c0 = time.perf_counter(), _cpu_now()
        out = fn(*args, **kwargs)
        comm.Barrier()
        dt = time.perf_counter() - t0
        if _count:
            _CPU["wall"] += dt
            _CPU["cpu"] += _cpu_now() - c0
        return out, dt

    return run


def _jit_params(comm, jit_cache: str | None):
    """JIT parameters: jit_cache=None -> a fresh temporary cache for this process (so the first
    compilation of each form in the process is cold); 'default' -> DOLFINx's ~/.cache/fenics;
    anything else -> that directory."""
    if jit_cache == "default":
        return {}
    if jit_cache is not None:
        return {"cache_dir": jit_cache}
    if _JIT_STATE["params"] is None:
        path = tempfile.mkdtemp(prefix="bench_peers_jit_") if comm.rank == 0 else None
        path = comm.bcast(path, root=0)
        _JIT_STATE["tmp"] = path
        _JIT_STATE["params"] = {"cache_dir": path}
        if comm.rank == 0:
            import atexit

            atexit.register(shutil.rmtree, path, True)
    return _JIT_STATE["params"]


def _form(ufl_form, jit_params):
    """dolfinx.fem.form without the compiler chatter: FFCx's JIT runs cffi/setuptools, which sets
    the root logger to INFO at every compilation ("INFO:root:running build_ext ..."); root INFO
    records are dropped during the call and the root level is restored after it."""
    import logging

    from dolfinx import fem

    root = logging.getLogger()
    level = root.level

    def drop(rec):
        return rec.levelno >= logging.WARNING

    root.addFilter(drop)
    try:
        return fem.form(ufl_form, jit_params=jit_params)
    finally:
        root.removeFilter(drop)
        root.setLevel(level)


def _dolfinx_mesh(n: int, cell: str, comm):
    """The `unit_square` arrays, given on rank 0 and distributed by DOLFINx (partition + reorder)."""
    import ufl
    from dolfinx import mesh as dmesh
    from dolfinx.cpp.io import perm_vtk

    ufl_cell, ctype, k = {
        "triangle": ("triangle", dmesh.CellType.triangle, 3),
        "quad": ("quadrilateral", dmesh.CellType.quadrilateral, 4),
    }[cell]
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl_cell, 1))
    if comm.rank == 0:
        points, cells = unit_square(n, cell)
        cells = np.ascontiguousarray(cells[:, perm_vtk(ctype, k)])  # VTK -> DOLFINx ordering
    else:
        points = np.zeros((0, 2), dtype=np.float64)
        cells = np.zeros((0, k), dtype=np.int64)
    return dmesh.create_mesh(comm, cells, points, domain)


def _dolfinx_forms(msh, plane: str):
    import ufl
    from dolfinx import fem

    V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    lmbda, mu = lame(E_MOD, NU, plane)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)

    def eps(w):
        return ufl.sym(ufl.grad(w))

    def sigma(w):
        return 2.0 * mu * eps(w) + lmbda * ufl.tr(eps(w)) * ufl.Identity(2)

    a = ufl.inner(sigma(u), eps(v)) * ufl.dx
    return V, a, v


def _dolfinx_dofs(V) -> int:
    return V.dofmap.index_map.size_global * V.dofmap.index_map_bs


def dolfinx_assembly(n: int, cell: str = "triangle", plane: str = "strain",
                     repeats: int | None = None, comm=None, jit_cache: str | None = None) -> dict:
    """Stiffness assembly with DOLFINx: dict(dofs, t_form, t_first, t_reassembly, ...).

    t_form: dolfinx.fem.form(a) (UFL -> FFCx -> C -> cffi; 'jit' says cold or cached);
    t_first: create_matrix (sparsity) + assemble_matrix + A.assemble(), best of `repeats`, each on
    a new matrix (t_create / t_assemble_first split it); t_reassembly: A.zeroEntries() +
    assemble_matrix into the same matrix + A.assemble(). No boundary conditions. fro: the Frobenius
    norm, also checked to be the same after every (re)assembly.
    """
    import dolfinx.fem.petsc as fpetsc
    from petsc4py import PETSc

    comm = _comm(comm)
    timed = _timer(comm)
    dofs = num_dofs(n)
    repeats = repeats or default_repeats(dofs)

    msh, t_mesh = timed(_dolfinx_mesh, n, cell, comm, _count=False)
    (V, a_ufl, _), t_space = timed(_dolfinx_forms, msh, plane, _count=False)
    jit_params = _jit_params(comm, jit_cache)
    key = ("a", cell, plane, jit_params.get("cache_dir", "default"))
    jit = "cached" if key in _JIT_STATE["compiled"] else ("cold" if jit_cache is None else "unknown")
    a, t_form = timed(_form, a_ufl, jit_params, _count=False)
    _JIT_STATE["compiled"].add(key)
    assert _dolfinx_dofs(V) == dofs, (_dolfinx_dofs(V), dofs)

    def assemble(A):
        fpetsc.assemble_matrix(A, a)
        A.assemble()

    def reassemble(A):
        A.zeroEntries()
        assemble(A)

    norms = []
    best = None
    for i in range(repeats):
        A, t_create = timed(fpetsc.create_matrix, a)
        _, t_asm = timed(assemble, A)
        norms.append(A.norm(PETSc.NormType.FROBENIUS))
        if best is None or t_create + t_asm < sum(best):
            best = (t_create, t_asm)
        if i < repeats - 1:
            A.destroy()
    t_create, t_asm = best
    t_first = t_create + t_asm
    t_re = []
    for _ in range(max(repeats, 3)):
        _, t = timed(reassemble, A)
        t_re.append(t)
        norms.append(A.norm(PETSc.NormType.FROBENIUS))
    nnz = A.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"]
    A.destroy()
    fro = norms[0]
    spread = max(abs(x - fro) for x in norms) / fro
    t_reassembly = min(t_re)
    return dict(peer="dolfinx", cell=cell, n=n, plane=plane, nranks=comm.size, dofs=dofs,
                ncells=msh.topology.index_map(2).size_global, nnz=int(nnz), repeats=repeats,
                t_mesh=t_mesh, t_space=t_space, t_form=t_form, jit=jit,
                t_create=t_create, t_assemble_first=t_asm, t_first=t_first,
                t_reassembly=t_reassembly, rate_first=dofs / t_first,
                rate_reassembly=dofs / t_reassembly, fro=fro, fro_rel_spread=spread)


def dolfinx_assembly_box(n: int, repeats: int | None = None, comm=None,
                         jit_cache: str | None = None, degree: int | None = None) -> dict:
    """3D counterpart of ``dolfinx_assembly``: elasticity (E = 1, nu = 0.3) on the unit cube of
    n³ Q1 hexahedra (DOLFINx's own ``create_box``), 3(n+1)³ DOFs. t_first: create_matrix +
    assemble_matrix + A.assemble(), best of ``repeats``, each on a new matrix; t_reassembly:
    zeroEntries + assemble_matrix + assemble (best of >= 3). No boundary conditions, JIT apart.
    degree: the quadrature degree (None: UFL's estimate, 4 here, 27 points per cell under
    FFCx's scheme; 2: the 2×2×2 Gauss points parsolve's hexahedra use)."""
    import dolfinx.fem.petsc as fpetsc
    import ufl
    from dolfinx import fem
    from dolfinx import mesh as dmesh
    from petsc4py import PETSc

    comm = _comm(comm)
    timed = _timer(comm)
    _CPU.update(wall=0.0, cpu=0.0)    # cpu_share of this call's timed sections only
    dofs = 3 * (n + 1) ** 3
    repeats = repeats or default_repeats(dofs)
    msh, t_mesh = timed(dmesh.create_box, comm, [np.zeros(3), np.ones(3)], [n, n, n],
                        dmesh.CellType.hexahedron, _count=False)
    V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    E, nu = E_MOD, NU
    mu, lmbda = E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)

    def eps(w):
        return ufl.sym(ufl.grad(w))

    dx = ufl.dx if degree is None else ufl.dx(metadata={"quadrature_degree": degree})
    a_ufl = ufl.inner(2.0 * mu * eps(u) + lmbda * ufl.tr(eps(u)) * ufl.Identity(3), eps(v)) * dx
    a, t_form = timed(_form, a_ufl, _jit_params(comm, jit_cache), _count=False)
    assert _dolfinx_dofs(V) == dofs, (_dolfinx_dofs(V), dofs)

    def assemble(A):
        fpetsc.assemble_matrix(A, a)
        A.assemble()

    def reassemble(A):
        A.zeroEntries()
        assemble(A)

    best, norms = None, []
    for i in range(repeats):
        A, t_create = timed(fpetsc.create_matrix, a)
        _, t_asm = timed(assemble, A)
        norms.append(A.norm(PETSc.NormType.FROBENIUS))
        if best is None or t_create + t_asm < sum(best):
            best = (t_create, t_asm)
        if i < repeats - 1:
            A.destroy()
    t_re = []
    for _ in range(max(repeats, 3)):
        _, t = timed(reassemble, A)
        t_re.append(t)
        norms.append(A.norm(PETSc.NormType.FROBENIUS))
    nnz = A.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"]
    A.destroy()
    t_create, t_asm = best
    return dict(peer="dolfinx", cell="hexahedron", n=n, nranks=comm.size, dofs=dofs, degree=degree,
                ncells=n ** 3, nnz=int(nnz), repeats=repeats, t_mesh=t_mesh, t_form=t_form,
                t_create=t_create, t_assemble_first=t_asm, t_first=t_create + t_asm,
                t_reassembly=min(t_re), rate_first=dofs / (t_create + t_asm),
                fro=norms[0], fro_rel_spread=max(abs(x - norms[0]) for x in norms) / norms[0],
                cpu_share=_CPU["cpu"] / max(_CPU["wall"], 1e-12))


def run_dolfinx_box(n: int, repeats: int | None = None, degree: int | None = None,
                    timeout: float = 1800.0) -> dict:
    """``dolfinx_assembly_box`` in a fresh Debian-python process (1 rank); its result dict."""
    # run in scripts/: `python -c` puts the working folder first on sys.path
    code = ("import json, sys; import bench_peers as b; "
            "print('RESULT ' + json.dumps(b.dolfinx_assembly_box(int(sys.argv[1]), "
            "int(sys.argv[2]) or None, degree=int(sys.argv[3]) or None)))")
    env = dict(os.environ)
    env.setdefault("OMP_NUM_THREADS", "1")
    proc = subprocess.run([DEBIAN_PYTHON, "-c", code, str(n), str(repeats or 0), str(degree or 0)],
                          env=env, timeout=timeout, text=True, cwd=str(bh.SCRIPTS),
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not line:
        raise RuntimeError(f"dolfinx_assembly_box({n}) failed ({proc.returncode}):\n{proc.stdout[-2000:]}")
    return json.loads(line[-1][len("RESULT "):])


def dolfinx_solve(n: int, method: str = "mumps", cell: str = "triangle", plane: str = "strain",
                  comm=None, jit_cache: str | None = None, rtol: float = GAMG_RTOL) -> dict:
    """Clamped-left / traction-right solve with DOLFINx: dict(dofs, t_solve, iterations, ...).

    method 'mumps': KSP preonly + PC lu + MUMPS; 'gamg': CG + GAMG (near-nullspace = 2D rigid body
    modes from MatNullSpaceCreateRigidBody on the DOF coordinates), stopping on the true residual
    ||b - A u|| <= rtol ||b|| (unpreconditioned norm), zero initial guess; options in 'options'.
    t_setup = KSPSetUp (factorisation / AMG hierarchy), t_solve = KSPSetUp + KSPSolve. Also returns
    the true relative residual ||b - A u|| / ||b||, ||u||_2 and u_y at (1, 1) for cross-checks.
    """
    import ufl
    from dolfinx import fem, mesh as dmesh
    import dolfinx.fem.petsc as fpetsc
    from petsc4py import PETSc

    if method not in SOLVE_METHODS:
        raise ValueError(f"method must be one of {SOLVE_METHODS}, got {method!r}")
    comm = _comm(comm)
    timed = _timer(comm)
    dofs = num_dofs(n)

    msh, t_mesh = timed(_dolfinx_mesh, n, cell, comm, _count=False)
    V, a_ufl, v = _dolfinx_forms(msh, plane)
    fdim = msh.topology.dim - 1
    left = dmesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[0], 0.0))
    right = dmesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[0], 1.0))
    tags = dmesh.meshtags(msh, fdim, right, np.full(len(right), 1, dtype=np.int32))
    ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
    t_vec = fem.Constant(msh, np.array(TRACTION, dtype=PETSc.ScalarType))
    L_ufl = ufl.inner(t_vec, v) * ds(1)
    bc = fem.dirichletbc(np.zeros(2, dtype=PETSc.ScalarType),
                         fem.locate_dofs_topological(V, fdim, left), V)

    jit_params = _jit_params(comm, jit_cache)
    (a, L), t_form = timed(lambda: (_form(a_ufl, jit_params), _form(L_ufl, jit_params)),
                           _count=False)

    def assemble_system():
        A = fpetsc.assemble_matrix(a, bcs=[bc])
        A.assemble()
        b = fpetsc.assemble_vector(L)
        fpetsc.apply_lifting(b, [a], bcs=[[bc]])
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fpetsc.set_bc(b, [bc])
        return A, b

    (A, b), t_assemble = timed(assemble_system)

    prefix = f"bench_{method}_{n}_"
    opts = PETSc.Options()
    if method == "mumps":
        popts = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
    else:
        popts = {"ksp_type": "cg", "ksp_norm_type": "unpreconditioned", "ksp_rtol": rtol,
                 "ksp_atol": 1e-50, "ksp_max_it": 1000,
                 "pc_type": "gamg", "pc_gamg_type": "agg", "pc_gamg_agg_nsmooths": 1,
                 "mg_levels_ksp_type": "chebyshev", "mg_levels_pc_type": "jacobi",
                 "mg_levels_esteig_ksp_type": "cg"}
        # near-nullspace: rigid body modes from the owned DOF coordinates (block size 2)
        nown = V.dofmap.index_map.size_local
        xy = np.ascontiguousarray(V.tabulate_dof_coordinates()[:nown, :2]).ravel()
        coords = PETSc.Vec().createWithArray(xy, bsize=2, comm=comm)
        ns = PETSc.NullSpace().createRigidBody(coords)
        A.setNearNullSpace(ns)
    for k, val in popts.items():
        opts[prefix + k] = val

    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    x = A.createVecRight()
    _, t_setup = timed(ksp.setUp)
    _, t_only = timed(ksp.solve, b, x)
    its = ksp.getIterationNumber()
    reason = ksp.getConvergedReason()
    r = b.duplicate()
    A.mult(x, r)
    r.aypx(-1.0, b)  # r = b - A x
    relres = r.norm() / b.norm()

    # u_y at the corner (1, 1)
    uh = fem.Function(V)
    uh.x.array[: x.getLocalSize()] = x.getArray()
    uh.x.scatter_forward()
    xdof = V.tabulate_dof_coordinates()
    hit = np.flatnonzero(np.isclose(xdof[:, 0], 1.0) & np.isclose(xdof[:, 1], 1.0))
    corner = uh.x.array[2 * hit[0] + 1] if len(hit) else None
    corner = [c for c in comm.allgather(corner) if c is not None][0]

    for k in popts:
        opts.delValue(prefix + k)
    out = dict(peer="dolfinx", cell=cell, n=n, plane=plane, nranks=comm.size, dofs=dofs,
               method=method, options=popts, t_mesh=t_mesh, t_form=t_form, t_assemble=t_assemble,
               t_setup=t_setup, t_solve=t_setup + t_only, t_solve_only=t_only,
               iterations=its, converged_reason=int(reason), relres=float(relres),
               unorm=float(x.norm()), uy_corner=float(corner))
    ksp.destroy()
    A.destroy()
    return out


def dolfinx_versions() -> dict:
    import dolfinx
    import petsc4py
    from petsc4py import PETSc

    return {"dolfinx": dolfinx.__version__, "petsc4py": petsc4py.__version__,
            "petsc": ".".join(map(str, PETSc.Sys.getVersion())), "numpy": np.__version__,
            "python": sys.version.split()[0]}


# --------------------------------------------------------------------------------------------------
# DOLFINx 0.5: every phase of a linear run, with the memory of each (scripts/bench_scale.py)


def mumps_memory(ksp) -> dict:
    """MUMPS's own memory (MB = 1e6 bytes) if the KSP's PC is a MUMPS factorization: INFOG(16)
    estimated in-core factorization memory (max over ranks), INFOG(18) allocated, INFOG(21)
    effectively used (max over ranks), INFOG(22) used (sum), INFO(22) used on this rank;
    RINFOG(3) flops, INFOG(29) factor entries (negative: millions)."""
    pc = ksp.getPC()
    if pc.getType() not in ("lu", "cholesky"):
        return {}
    F = pc.getFactorMatrix()
    if F.getType() != "mumps":
        return {}
    g = {k: int(F.getMumpsInfog(k)) for k in (16, 18, 21, 22, 29)}
    entries = float(g[29]) if g[29] >= 0 else -float(g[29]) * 1e6
    return dict(estimated_mb_max=g[16], allocated_mb_max=g[18], used_mb_max=g[21],
                used_mb_sum=g[22], used_mb_local=int(F.getMumpsInfo(22)),
                flops=float(F.getMumpsRinfog(3)), factor_entries=entries)


def _voigt(s, dim: int):
    """Voigt vector of a symmetric tensor: 2D (xx, yy, xy), 3D (xx, yy, zz, yz, xz, xy)."""
    import ufl

    if dim == 2:
        return ufl.as_vector([s[0, 0], s[1, 1], s[0, 1]])
    return ufl.as_vector([s[0, 0], s[1, 1], s[2, 2], s[1, 2], s[0, 2], s[0, 1]])


def dolfinx_phases(mesh_file: str, cell: str, options: dict, out_file: str | None = None,
                   traction=None, plane: str = "strain", comm=None,
                   jit_cache: str | None = None, near_null: bool = False,
                   quadrature: tuple[int, ...] = ()) -> dict:
    """A clamped block under an end traction, every phase timed and its memory recorded.

    The mesh is read on rank 0 from ``mesh_file`` (npz: ``points`` (N, d), ``cells`` (M, k) in
    meshio/VTK order; 2D triangles/quads or 3D hexahedra/tetrahedra) and distributed by DOLFINx.
    P1/Q1 vector elasticity, E = 1, nu = 0.3 (plane strain in 2D), u = 0 on x = 0, traction
    ``traction`` (default: -1 along the last axis) on x = 1. Phases (barrier, perf_counter; the
    slowest rank's): ``setup`` = create_mesh + function spaces + boundary conditions + meshtags
    (forms excluded: their JIT is ``t_forms``); ``assembly`` = create_matrix + assemble_matrix with
    the BC + the right-hand side (lifting, set_bc); ``factorization`` = KSPSetUp + PCSetUp (the
    MUMPS factorization, or GAMG's hierarchy); ``solve`` = KSPSolve; ``post`` = the stresses:
    cell values (interpolation into DG0, the cell's centre) and nodal averages (a lumped
    projection: ∫σ·w / ∫w on P1, the cells' stresses weighted by their share of each node);
    ``output`` = XDMF/HDF5 of the mesh, u and both stresses (skipped without ``out_file``).
    Not phases (in ``seconds`` and ``cpu`` beside them): ``reassembly`` = assemble_matrix into
    the same matrix again (zeroed; the matrix alone), right after the first assembly; per
    degree q of ``quadrature``, once the phases are done and the first matrix destroyed:
    ``assembly_q{q}`` and ``reassembly_q{q}``, the stiffness at quadrature degree q
    (``forms_q{q}``: its JIT; degree 2 = 2×2×2 Gauss points on a hexahedron, parsolve's rule).
    Returns ``seconds`` and ``cpu`` (CPU seconds, max over ranks: on a shared machine the wall
    time also counts other processes) per phase, ``forms`` among them. ``options``: the KSP's PETSc options (no prefix); ``near_null``: rigid-body modes for GAMG.
    Memory per phase: VmRSS/VmHWM after it (max and mean over ranks), the matrix's bytes and
    MUMPS's INFOG figures. Checks: ||u||₂, max |u|, u at the corner x = y (= z) = 1.
    """
    import ufl
    from dolfinx import fem, io, mesh as dmesh
    import dolfinx.fem.petsc as fpetsc
    from dolfinx.cpp.io import perm_vtk
    from mpi4py import MPI
    from petsc4py import PETSc

    comm = _comm(comm)
    mem: dict[str, dict] = {}
    wall: dict[str, float] = {}
    cpu: dict[str, float] = {}

    def clock(name: str, fn, *args):
        """Barrier, fn(*args), barrier: wall seconds and CPU seconds (max over ranks)."""
        comm.Barrier()
        t0, c0 = time.perf_counter(), _cpu_now()
        out = fn(*args)
        comm.Barrier()
        wall[name] = time.perf_counter() - t0
        cpu[name] = comm.allreduce(_cpu_now() - c0, op=MPI.MAX)
        return out

    def snap(name: str, extra: dict | None = None) -> None:
        m = proc_memory()
        row = {"rss_max": comm.allreduce(m["rss"], op=MPI.MAX),
               "rss_mean": comm.allreduce(m["rss"]) / comm.size,
               "hwm_max": comm.allreduce(m["hwm"], op=MPI.MAX),
               "hwm_mean": comm.allreduce(m["hwm"]) / comm.size}
        mem[name] = {**row, **(extra or {})}

    snap("start")
    kinds = {"triangle": ("triangle", dmesh.CellType.triangle, 3, 2),
             "quad": ("quadrilateral", dmesh.CellType.quadrilateral, 4, 2),
             "tetra": ("tetrahedron", dmesh.CellType.tetrahedron, 4, 3),
             "hexahedron": ("hexahedron", dmesh.CellType.hexahedron, 8, 3)}
    ufl_cell, ctype, k, dim = kinds[cell]
    if comm.rank == 0:
        data = np.load(mesh_file)
        points = np.ascontiguousarray(data["points"][:, :dim], dtype=np.float64)
        cells = np.ascontiguousarray(data["cells"][:, perm_vtk(ctype, k)].astype(np.int64))
        del data
    else:
        points, cells = np.zeros((0, dim)), np.zeros((0, k), dtype=np.int64)
    traction = tuple(traction) if traction is not None else (0.0,) * (dim - 1) + (-1.0,)
    lmbda, mu = lame(E_MOD, NU, plane) if dim == 2 else lame(E_MOD, NU, "strain")

    def eps(w):
        return ufl.sym(ufl.grad(w))

    def sigma(w):
        return 2.0 * mu * eps(w) + lmbda * ufl.tr(eps(w)) * ufl.Identity(dim)

    def setup():
        domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl_cell, 1))
        msh = dmesh.create_mesh(comm, cells, points, domain)
        V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
        fdim = dim - 1
        left = dmesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[0], 0.0))
        right = dmesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[0], 1.0))
        tags = dmesh.meshtags(msh, fdim, right, np.full(len(right), 1, dtype=np.int32))
        bc = fem.dirichletbc(np.zeros(dim, dtype=PETSc.ScalarType),
                             fem.locate_dofs_topological(V, fdim, left), V)
        nv = 3 if dim == 2 else 6
        S_cell = fem.VectorFunctionSpace(msh, ("DG", 0), dim=nv)
        S_node = fem.VectorFunctionSpace(msh, ("Lagrange", 1), dim=nv)
        W = fem.FunctionSpace(msh, ("Lagrange", 1))
        return msh, V, tags, bc, S_cell, S_node, W

    msh, V, tags, bc, S_cell, S_node, W = clock("setup", setup)
    del points, cells
    snap("setup")

    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    uh = fem.Function(V, name="displacement")
    ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
    t_vec = fem.Constant(msh, np.array(traction, dtype=PETSc.ScalarType))
    jit = _jit_params(comm, jit_cache)

    def forms():
        a = _form(ufl.inner(sigma(u), eps(v)) * ufl.dx, jit)
        L = _form(ufl.inner(t_vec, v) * ds(1), jit)
        s_u = _voigt(sigma(uh), dim)
        expr = fem.Expression(s_u, S_cell.element.interpolation_points())
        p = _form(ufl.inner(s_u, ufl.TestFunction(S_node)) * ufl.dx, jit)
        m = _form(ufl.TestFunction(W) * ufl.dx, jit)
        return a, L, expr, p, m

    a, L, expr, p_form, m_form = clock("forms", forms)

    def assembly():
        A = fpetsc.create_matrix(a)
        fpetsc.assemble_matrix(A, a, bcs=[bc])
        A.assemble()
        b = fpetsc.assemble_vector(L)
        fpetsc.apply_lifting(b, [a], bcs=[[bc]])
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fpetsc.set_bc(b, [bc])
        return A, b

    A, b = clock("assembly", assembly)
    snap("assembly", {"mat_bytes_max": comm.allreduce(mat_bytes(A), op=MPI.MAX),
                      "mat_bytes_sum": comm.allreduce(mat_bytes(A))})

    def reassembly(A, form):
        A.zeroEntries()
        fpetsc.assemble_matrix(A, form, bcs=[bc])
        A.assemble()

    clock("reassembly", reassembly, A, a)

    prefix = "bench_scale_"
    opts = PETSc.Options()
    for key, val in options.items():
        opts[prefix + key] = val
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix(prefix)
    if near_null:
        nown = V.dofmap.index_map.size_local
        xyz = np.ascontiguousarray(V.tabulate_dof_coordinates()[:nown, :dim]).ravel()
        coords = PETSc.Vec().createWithArray(xyz, bsize=dim, comm=comm)
        A.setNearNullSpace(PETSc.NullSpace().createRigidBody(coords))
    ksp.setOperators(A)
    ksp.setFromOptions()
    x = A.createVecRight()

    def factorize():
        ksp.setUp()
        ksp.getPC().setUp()

    clock("factorization", factorize)
    snap("factorization", mumps_memory(ksp))
    clock("solve", ksp.solve, b, x)
    r = b.duplicate()
    A.mult(x, r)
    r.aypx(-1.0, b)
    relres = r.norm() / b.norm()
    snap("solve")

    def post():
        uh.x.array[: x.getLocalSize()] = x.getArray()
        uh.x.scatter_forward()
        s_cell = fem.Function(S_cell, name="stress_cells")
        s_cell.interpolate(expr)
        s_node = fem.Function(S_node, name="stress")
        sums = fpetsc.assemble_vector(p_form)
        sums.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        weights = fpetsc.assemble_vector(m_form)
        weights.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        nv = s_node.x.bs
        nown = S_node.dofmap.index_map.size_local
        s_node.x.array[: nown * nv] = (sums.array.reshape(-1, nv)
                                        / weights.array[:, None]).ravel()
        s_node.x.scatter_forward()
        return s_cell, s_node

    s_cell, s_node = clock("post", post)
    snap("post")

    def output():
        with io.XDMFFile(comm, out_file, "w") as f:
            f.write_mesh(msh)
            f.write_function(uh, 1.0)
            f.write_function(s_node, 1.0)
            try:  # DG0: cell data
                f.write_function(s_cell, 1.0)
            except RuntimeError:
                pass

    if out_file:
        clock("output", output)
    snap("output")

    its, reason = ksp.getIterationNumber(), int(ksp.getConvergedReason())
    ksp.destroy()
    A.destroy()
    for q in quadrature:   # the stiffness at another quadrature degree: first and again
        a_q = clock(f"forms_q{q}", _form, ufl.inner(sigma(u), eps(v))
                    * ufl.dx(metadata={"quadrature_degree": q}), jit)

        def first_q():
            A = fpetsc.create_matrix(a_q)
            fpetsc.assemble_matrix(A, a_q, bcs=[bc])
            A.assemble()
            return A

        A = clock(f"assembly_q{q}", first_q)
        clock(f"reassembly_q{q}", reassembly, A, a_q)
        A.destroy()

    nown = V.dofmap.index_map.size_local
    owned = uh.x.array[: nown * dim].reshape(-1, dim)
    xdof = V.tabulate_dof_coordinates()[:nown, :dim]
    hit = np.flatnonzero(np.all(np.isclose(xdof, 1.0), axis=1))
    corner = owned[hit[0]].tolist() if len(hit) else None
    corner = [c for c in comm.allgather(corner) if c is not None][0]
    umax = comm.allreduce(float(np.abs(owned).max()) if nown else 0.0, op=MPI.MAX)
    for key in options:
        opts.delValue(prefix + key)
    return dict(peer="dolfinx", cell=cell, dim=dim, nranks=comm.size,
                dofs=V.dofmap.index_map.size_global * dim,
                ncells=msh.topology.index_map(dim).size_global, options=options,
                seconds=wall, cpu=cpu, iterations=its,
                converged_reason=reason, relres=float(relres), unorm=float(x.norm()),
                umax=umax, corner=corner, memory=mem, versions=dolfinx_versions())


# --------------------------------------------------------------------------------------------------
# scikit-fem


def skfem_assembly(n: int, cell: str = "triangle", plane: str = "strain",
                   repeats: int | None = None) -> dict:
    """Stiffness assembly with scikit-fem: dict(dofs, t_basis, t_first, t_second, ...).

    t_mesh: MeshTri/MeshQuad from `unit_square`; t_basis: Basis(mesh, ElementVector(P1 or Q1))
    (precomputes basis values and quadrature, default intorder); t_first / t_second: the first and
    second asm(linear_elasticity(lambda, mu), basis) on that basis (scipy CSR, duplicates summed);
    best of `repeats`, each on a fresh Basis. t_reassembly is t_second (an alias, for tables).
    """
    import scipy.sparse.linalg as spla
    from skfem import Basis, ElementQuad1, ElementTriP1, ElementVector, MeshQuad, MeshTri, asm
    from skfem.models.elasticity import linear_elasticity

    dofs = num_dofs(n)
    repeats = repeats or default_repeats(dofs)
    lmbda, mu = lame(E_MOD, NU, plane)
    form = linear_elasticity(lmbda, mu)

    t0 = time.perf_counter()
    points, cells = unit_square(n, cell)
    if cell == "quad":
        mesh = MeshQuad(points.T.copy(), cells.T.copy())
        elem = ElementVector(ElementQuad1())
    else:
        mesh = MeshTri(points.T.copy(), cells.T.copy())
        elem = ElementVector(ElementTriP1())
    t_mesh = time.perf_counter() - t0

    best = {"t_basis": np.inf, "t_first": np.inf, "t_second": np.inf}
    norms = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        basis = Basis(mesh, elem)
        t1, c1 = time.perf_counter(), _cpu_now()
        K = asm(form, basis)
        t2, c2 = time.perf_counter(), _cpu_now()
        norms.append(spla.norm(K))
        del K
        t3, c3 = time.perf_counter(), _cpu_now()
        K = asm(form, basis)
        t4, c4 = time.perf_counter(), _cpu_now()
        norms.append(spla.norm(K))
        _CPU["wall"] += (t2 - t1) + (t4 - t3)
        _CPU["cpu"] += (c2 - c1) + (c4 - c3)
        for k, t in (("t_basis", t1 - t0), ("t_first", t2 - t1), ("t_second", t4 - t3)):
            best[k] = min(best[k], t)
        nnz = K.nnz
        del K, basis
    assert basis_dofs_ok(mesh, elem, dofs)
    fro = norms[0]
    return dict(peer="skfem", cell=cell, n=n, plane=plane, nranks=1, dofs=dofs,
                ncells=int(mesh.t.shape[1]), nnz=int(nnz), repeats=repeats, t_mesh=t_mesh,
                t_basis=best["t_basis"], t_first=best["t_first"], t_second=best["t_second"],
                t_reassembly=best["t_second"], rate_first=dofs / best["t_first"],
                rate_reassembly=dofs / best["t_second"], fro=float(fro),
                fro_rel_spread=float(max(abs(x - fro) for x in norms) / fro))


def basis_dofs_ok(mesh, elem, dofs: int) -> bool:
    from skfem import Basis

    return Basis(mesh, elem, intorder=1).N == dofs


def skfem_versions() -> dict:
    import scipy
    import skfem

    return {"skfem": getattr(skfem, "__version__", "?"), "scipy": scipy.__version__,
            "numpy": np.__version__, "python": sys.version.split()[0]}


# --------------------------------------------------------------------------------------------------
# subprocess driver (for parsolve benchmarks, which run in parsolve's own venv)


def peer_python(peer: str) -> str:
    """Interpreter that has the peer: DOLFINx -> this one if it imports dolfinx, else Debian's;
    scikit-fem -> $BENCH_VENV/bin/python (default /work/bench-venv)."""
    if peer == "dolfinx":
        try:
            import dolfinx  # noqa: F401

            return sys.executable
        except ImportError:
            return DEBIAN_PYTHON
    if peer == "skfem":
        return str(DEFAULT_BENCH_VENV / "bin" / "python")
    raise ValueError(peer)


def run_peer(peer: str, ns, cells=("triangle",), nranks: int = 1, solve=(), assembly: bool = True,
             plane: str = "strain", repeats: int | None = None, retries: int = 2,
             wait_quiet: float = 0.0, python: str | None = None, timeout: float | None = 900.0,
             echo: bool = False) -> dict:
    """Run this script for `peer` in a subprocess (under mpirun -n nranks if > 1); return its JSON."""
    python = python or peer_python(peer)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.json"
        cmd = [python, str(Path(__file__).resolve()), peer, "--n", *map(str, ns),
               "--cell", *cells, "--plane", plane, "--retries", str(retries),
               "--wait-quiet", str(wait_quiet), "--json", str(out)]
        if repeats:
            cmd += ["--repeats", str(repeats)]
        if solve:
            cmd += ["--solve", *solve]
        if not assembly:
            cmd += ["--no-assembly"]
        env = dict(os.environ)
        env.setdefault("OMP_NUM_THREADS", "1")
        if nranks > 1:
            cmd = ["mpirun", "-n", str(nranks), *cmd]
            env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
                       OMPI_MCA_rmaps_base_oversubscribe="1")
        proc = subprocess.run(cmd, env=env, timeout=timeout, text=True,
                              stdout=None if echo else subprocess.PIPE,
                              stderr=None if echo else subprocess.STDOUT)
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stdout}")
        return json.loads(out.read_text())


# --------------------------------------------------------------------------------------------------
# output


def _fmt_rate(x: float) -> str:
    return f"{x / 1e6:.2f}M" if x >= 1e6 else f"{x / 1e3:.0f}k"


def assembly_table(rows: list[dict]) -> str:
    head = (f"{'peer':8s} {'np':>2s} {'cell':8s} {'n':>5s} {'dofs':>9s} {'t_form':>7s} {'jit':>6s} "
            f"{'t_first':>8s} {'(create)':>8s} {'t_reasm':>8s} {'DOF/s 1st':>10s} {'DOF/s re':>10s} "
            f"{'fro':>12s}")
    lines = [head, "-" * len(head)]
    for r in rows:
        t_form = r.get("t_form", r.get("t_basis", float("nan")))
        jit = r.get("jit", "basis")
        lines.append(f"{r['peer']:8s} {r['nranks']:2d} {r['cell']:8s} {r['n']:5d} {r['dofs']:9d} "
                     f"{t_form:7.3f} {jit:>6s} {r['t_first']:8.4f} "
                     f"{'' if 't_create' not in r else format(r['t_create'], '8.4f'):>8s} "
                     f"{r['t_reassembly']:8.4f} "
                     f"{_fmt_rate(r['rate_first']):>10s} {_fmt_rate(r['rate_reassembly']):>10s} "
                     f"{r['fro']:12.6f}")
    return "\n".join(lines)


def solve_table(rows: list[dict]) -> str:
    head = (f"{'peer':8s} {'np':>2s} {'cell':8s} {'n':>5s} {'dofs':>9s} {'method':6s} "
            f"{'t_asm':>7s} {'t_setup':>8s} {'t_solve':>8s} {'its':>4s} {'relres':>9s} "
            f"{'uy(1,1)':>12s}")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r['peer']:8s} {r['nranks']:2d} {r['cell']:8s} {r['n']:5d} {r['dofs']:9d} "
                     f"{r['method']:6s} {r['t_assemble']:7.3f} {r['t_setup']:8.3f} "
                     f"{r['t_solve']:8.3f} {r['iterations']:4d} {r['relres']:9.2e} "
                     f"{r['uy_corner']:12.6f}")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------------
# CLI


def wait_quiet(comm=None, max_wait: float = 0.0, idle: float = 0.93, streak: int = 3) -> float:
    """Wait (at most max_wait s) until the CPUs have been idle (> `idle`) `streak` seconds running:
    rank 0 watches /proc/stat while the other ranks sleep in a non-busy Ibarrier loop (a busy MPI
    wait would look like load). Returns the seconds waited (the same on all ranks)."""
    if max_wait <= 0:
        return 0.0
    t0 = time.perf_counter()
    if comm is None or comm.rank == 0:
        ok = 0
        while ok < streak and time.perf_counter() - t0 < max_wait:
            ok = ok + 1 if _cpu_idle(1.0) > idle else 0
    if comm is not None and comm.size > 1:
        req = comm.Ibarrier()
        while not req.Test():
            time.sleep(0.05)
        return comm.bcast(time.perf_counter() - t0, root=0)
    return time.perf_counter() - t0


def _cpu_share(fn, comm, *args, retries: int = 0, wait: float = 5.0, max_wait: float = 0.0):
    """Run fn(*args) and add 'cpu_share': CPU time / wall time of the timed sections (assembly,
    solve; not mesh or JIT), the lowest over ranks. Well below 1 means other processes took CPU
    time from the benchmark (the machine has 2 cores, as many as the ranks used): such timings are
    inflated. Below 0.9 the measurement is redone, after `wait` seconds (or, with max_wait > 0,
    after `wait_quiet`, which also runs before the first attempt), up to `retries` times;
    the result with the highest cpu_share is kept ('attempts' counts the runs), with the first
    run's t_form/jit (only the first can be a cold JIT). Sections shorter than the 10 ms CPU clock
    make cpu_share coarse: it is taken as 1 when the timed sections total < 0.1 s."""
    best = None
    first = None
    waited = 0.0
    for attempt in range(retries + 1):
        waited += wait_quiet(comm, max_wait)
        _CPU.update(wall=0.0, cpu=0.0)
        r = fn(*args)
        share = _CPU["cpu"] / _CPU["wall"] if _CPU["wall"] >= 0.1 else 1.0
        r["cpu_share"] = comm.allreduce(share, op=_mpi_min()) if comm is not None else share
        first = first or r
        if best is None or r["cpu_share"] > best["cpu_share"]:
            best = r
        if r["cpu_share"] >= 0.9:
            break
        if comm is None or comm.rank == 0:
            print(f"[bench_peers] warning: cpu_share {r['cpu_share']:.2f} for n={r['n']} "
                  f"{r['cell']}: other processes are competing for the CPUs"
                  + (", retrying" if attempt < retries else ""), file=sys.stderr, flush=True)
        if attempt < retries and max_wait <= 0:
            time.sleep(wait)
    for k in ("t_form", "jit"):
        if k in first:
            best[k] = first[k]
    best["attempts"] = attempt + 1
    best["waited_quiet"] = waited
    return best


def _mpi_min():
    from mpi4py import MPI

    return MPI.MIN


def _progress(table, rows) -> None:
    """Print the newest row (with the header before the first).

    Assembly columns: t_form = DOLFINx fem.form (JIT; 'cold' = compiled in this process, 'cached'
    = already compiled) or scikit-fem Basis(); (create) = DOLFINx create_matrix, part of t_first;
    t_reasm = DOLFINx re-assembly into the same matrix or scikit-fem's second asm()."""
    lines = table(rows[-1:]).splitlines()
    print("\n".join(lines if len(rows) == 1 else lines[-1:]), flush=True)


def _main_dolfinx(args) -> dict:
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    root = comm.rank == 0
    out = {"peer": "dolfinx", "nranks": comm.size, "versions": dolfinx_versions(),
           "E": E_MOD, "nu": NU, "plane": args.plane, "traction": TRACTION,
           "assembly": [], "solve": []}
    for cell in args.cell:
        for n in args.n:
            if args.assembly:
                r = _cpu_share(dolfinx_assembly, comm, n, cell, args.plane, args.repeats, comm,
                               args.jit_cache, retries=args.retries,
                               max_wait=args.wait_quiet)
                out["assembly"].append(r)
                if root:
                    _progress(assembly_table, out["assembly"])
            for method in args.solve:
                r = _cpu_share(dolfinx_solve, comm, n, method, cell, args.plane, comm,
                               args.jit_cache, retries=args.retries,
                               max_wait=args.wait_quiet)
                out["solve"].append(r)
                if root:
                    _progress(solve_table, out["solve"])
    if root and args.assembly and args.solve:
        print("\n" + assembly_table(out["assembly"]) + "\n\n" + solve_table(out["solve"]))
    return out


def _main_skfem(args) -> dict:
    if args.solve:
        raise SystemExit("skfem: only assembly is benchmarked")
    out = {"peer": "skfem", "nranks": 1, "versions": skfem_versions(), "E": E_MOD, "nu": NU,
           "plane": args.plane, "assembly": [], "solve": []}
    for cell in args.cell:
        for n in args.n:
            r = _cpu_share(skfem_assembly, None, n, cell, args.plane, args.repeats,
                           retries=args.retries, max_wait=args.wait_quiet)
            out["assembly"].append(r)
            _progress(assembly_table, out["assembly"])
    return out


def _main_check(args) -> int:
    """Same Frobenius norm from DOLFINx (1 and 2 ranks) and scikit-fem; repeatable norms; MUMPS
    and GAMG agree."""
    ok = True
    n = args.n[0] if args.n else 8
    # smoke mode: the peers that are not installed are skipped (a full check needs both)
    have = {peer: not args.smoke or bh.peer_available(peer) for peer in ("dolfinx", "skfem")}
    runs = {}
    if have["dolfinx"]:
        runs["dolfinx np=1"] = run_peer("dolfinx", [n], CELLS, solve=SOLVE_METHODS,
                                        plane=args.plane)
        runs["dolfinx np=2"] = run_peer("dolfinx", [n], CELLS, nranks=2, solve=SOLVE_METHODS,
                                        plane=args.plane)
    if have["skfem"]:
        runs["skfem"] = run_peer("skfem", [n], CELLS, plane=args.plane)
    for peer, there in have.items():
        if not there:
            print(f"[check] {peer} not installed: skipped (bash scripts/bench_env.sh)")
    for cell in CELLS if runs else ():
        fros = {k: [r for r in v["assembly"] if r["cell"] == cell][0] for k, v in runs.items()}
        ref = next(iter(fros.values()))["fro"]
        for k, r in fros.items():
            rel = abs(r["fro"] - ref) / ref
            good = rel < 1e-12 and r["fro_rel_spread"] < 1e-14
            ok &= good
            print(f"[check] n={n} {cell:8s} {k:13s} fro={r['fro']:.15f} rel.diff={rel:.1e} "
                  f"spread over (re)assemblies={r['fro_rel_spread']:.1e} {'OK' if good else 'FAIL'}")
        sol = [r for k in ("dolfinx np=1", "dolfinx np=2") if k in runs
               for r in runs[k]["solve"] if r["cell"] == cell]
        uref = sol[0]["uy_corner"] if sol else 0.0
        for r in sol:
            rel = abs(r["uy_corner"] - uref) / abs(uref)
            good = rel < 1e-6 and r["relres"] < 1e-7
            ok &= good
            print(f"[check] n={n} {cell:8s} dolfinx np={r['nranks']} {r['method']:5s} "
                  f"uy(1,1)={r['uy_corner']:.10f} rel.diff={rel:.1e} relres={r['relres']:.1e} "
                  f"its={r['iterations']} {'OK' if good else 'FAIL'}")
    print("[check]", "PASSED" if ok else "FAILED")
    return 0 if ok else 1


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("peer", choices=["dolfinx", "skfem", "check"], nargs="?",
                   help="(--smoke alone: `check` at n = 4 on the peers installed)")
    p.add_argument("--n", type=int, nargs="+", default=None, help="quads per side")
    p.add_argument("--cell", nargs="+", choices=CELLS, default=["triangle"])
    p.add_argument("--plane", choices=["strain", "stress"], default="strain")
    p.add_argument("--repeats", type=int, default=None, help="default: by size (3/2/1)")
    p.add_argument("--solve", nargs="*", choices=SOLVE_METHODS, default=[],
                   help="dolfinx: also time these solves")
    p.add_argument("--no-assembly", dest="assembly", action="store_false",
                   help="dolfinx: only the solves")
    p.add_argument("--jit-cache", default=None,
                   help="dolfinx JIT cache dir; default a fresh temp dir per process (cold JIT "
                        "for the first form per cell), 'default' = ~/.cache/fenics")
    p.add_argument("--retries", type=int, default=2,
                   help="redo a measurement whose cpu_share < 0.9 (CPUs busy) up to this often")
    p.add_argument("--wait-quiet", type=float, default=0.0, metavar="SECONDS",
                   help="before each measurement wait (at most this long) for the CPUs to be idle "
                        "(other jobs on the machine); 0 = don't")
    p.add_argument("--json", default=None, help="write results here (rank 0)")
    bh.add_smoke(p)
    args = p.parse_args(argv)
    if args.smoke:
        args.peer, args.n = args.peer or "check", args.n or [4]
    if args.peer is None:
        p.error("the peer (dolfinx, skfem or check) is required")
    if args.peer == "check":
        return _main_check(args)
    if not args.n:
        p.error("--n is required")
    busy = os.getloadavg()[0]  # recorded only: it lags by a minute (cpu_share is the check)
    out = _main_dolfinx(args) if args.peer == "dolfinx" else _main_skfem(args)
    out["loadavg_before"] = busy
    out["loadavg_after"] = os.getloadavg()[0]
    out["cpus"] = os.cpu_count()
    if args.json and (args.peer != "dolfinx" or _comm().rank == 0):
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
