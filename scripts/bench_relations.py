"""Benchmark: the iterative preset on relations (contact, friction, mortar) against MUMPS, as
the mesh is refined: Krylov iterations per linear solve, time and peak memory of the whole run,
and the crossover size where the iterative preset becomes the faster one.

Cases (each run in its own process, so that its peak memory is its own; one rank):
  friction  configs/contact_friction_3d.toml (a box held only by contact, Coulomb friction,
            non-associated dual), 2 steps, nx, ny, nz × f: 1×, 8×, 64× the cells (f = 1, 2, 4)
  ironing   configs/contact_ironing_3d.toml (finite sliding, node-to-face rows between two
            deformable bodies), 1× (its mesh file), 8× (both boxes' cells × 2 per direction),
            the first 4 steps
  mortar    configs/contact_mortar_sphere_3d.toml (3D mortar, two deformable bodies), 1× and
            8× (n_fine, n_coarse, n_depth × 2)
Per run: DOFs, global (Newton) iterations, linear solves, Krylov iterations per solve (min,
mean, max; the iterative preset at its tolerance, rtol 2.5e-14), wall time, peak resident memory
(VmHWM) of the process, and whether the answers equal the direct preset's (1e-8 of scale).

    .venv/bin/python scripts/bench_relations.py [--smoke] [--gamma] [--max-factor 4]
        → table, scripts/results/bench_relations.md and bench_relations.json
        (--smoke: the 1× friction box and its 2-rank scale run only, files in a temporary
        folder; --gamma: the Krylov iterations against γ and the AMG on the friction box 1×, 8×)
    nice -n 5 .venv/bin/python scripts/bench_relations.py --scale 4,8 --ranks 2
        → the scale runs only: the friction box refined f× per direction on 2 ranks against
        plain elasticity (its base clamped, CG + GAMG) on the same mesh: time per Newton
        iteration, Krylov iterations, peak memory summed over the ranks
        (scripts/results/bench_relations_scale.md; --variants F: at f = F the friction box
        again with each of VARIANTS, the condensed V-cycle's alternatives, in the same run)
    nice -n 5 .venv/bin/python scripts/bench_relations.py --growth [--max-factor 8]
        → what the Krylov iterations' growth with the mesh comes from: the friction box
        refined 1×, 8×, 64× (512× with --max-factor 8) with S solved by the preset's V-cycle,
        exactly (LU: to 40k DOFs) and by the V-cycle's alternatives (GROWTH_VARIANTS), the
        clamped box's elasticity under the same V-cycle, the ironing 1× and 8× (--cases
        friction leaves it out); the hierarchy's levels at each size
        (scripts/results/bench_relations_growth.md; --petsc: options added to every run, the
        table then in the scratch folder; --smoke, and the plain --smoke run: the 1× box,
        one step)
    nice -n 5 .venv/bin/python scripts/bench_relations.py --weak --steps 1
        → weak scaling: the friction box and plain elasticity at about 16k DOFs per rank on
        1, 2, 4 ranks (oversubscribed: iterations and memory only), the peak memory per rank
        fitted as a + b·N + c·N/P and the Krylov iterations as α + β·log10 N, extrapolated to
        1024 ranks × 10⁹ DOFs (scripts/results/bench_relations_weak.md)
    nice -n 10 .venv/bin/python scripts/bench_relations.py --big 16 --ranks 2 [--timeout S]
        → one large run (not in CI): the friction box refined f× per direction (16: 931k
        DOFs, 21: 2.08M) on the iterative preset, its Newton and Krylov iterations, set-up
        and solve times, peak memory per rank; beside it MUMPS' own estimate of its
        factorization at that size (its analysis only: the factorization is never started),
        and with --big-elasticity the clamped box's elasticity run on the same mesh, the
        ratios of peak memory and time per Newton iteration (wall, and CPU summed over the
        ranks) friction over elasticity (scripts/results/bench_relations_big.md, the
        measurements in bench_relations_big.json; --big-publish renders the table again
        from that file without running anything; --big-after runs the elasticity again after
        the friction run and gives the ratios against both: the load changes over a long run)
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import bench_harness as bh
from bench_scenes import _dumps, _shipped

CHILD = "--child"
ESTIMATE = "--estimate"   # a child that runs MUMPS' analysis only (``estimate_child``)


# ------------------------------------------------------------------------------ scenes

def friction_scene(factor: int, steps: int = 2) -> str:
    scene = _shipped("contact_friction_3d.toml")
    for key in ("nx", "ny", "nz"):
        scene["mesh"][key] *= factor
    scene["steps"]["count"] = steps
    scene["steps"]["end"] = 0.125 * steps   # the first steps of the shipped eight
    return _dumps(scene)


def elastic_scene(factor: int, steps: int = 2, held: bool = False) -> str:
    """The friction box's mesh and load, plain elasticity: its base clamped instead of in
    contact (CG + GAMG on the stiffness alone: the reference of the scale runs). ``held``:
    the base rows multiplied instead of eliminated, which the iterative preset condenses
    (Dirichlet-type nodal rows): its V-cycle is then the friction box's own (GAMG, threshold
    0, the finest level's SOR sweeps) on S = K with the base held (``--growth``)."""
    scene = _shipped("contact_friction_3d.toml")
    for key in ("nx", "ny", "nz"):
        scene["mesh"][key] *= factor
    scene.pop("contact")
    scene["relations"] += [{"name": f"base_{c}", "type": "dirichlet", "region": "zmin",
                            "component": c, **({"eliminate": False} if held else {})}
                           for c in "xyz"]
    scene["steps"]["count"] = steps
    scene["steps"]["end"] = 0.125 * steps
    return _dumps(scene)


def mortar_scene(factor: int) -> str:
    scene = _shipped("contact_mortar_sphere_3d.toml")
    for key in ("n_fine", "n_coarse", "n_depth"):
        scene["mesh"][key] *= factor
    return _dumps(scene)


def ironing_scene(folder: Path, factor: int) -> str:
    from make_ironing_3d_mesh import DIE, SLAB, two_boxes

    scene = _shipped("contact_ironing_3d.toml")
    path = bh.ROOT / "configs" / scene["mesh"]["file"]
    if factor > 1:
        path = folder / f"ironing_3d_{factor}.msh"
        slab = SLAB[:3] + tuple(n * factor for n in SLAB[3:])
        die = DIE[:3] + tuple(n * factor for n in DIE[3:6]) + DIE[6:]
        two_boxes(path, slab, die)
    scene["mesh"]["file"] = str(path)
    scene["steps"]["times"] = scene["steps"]["times"][:6]   # the press and the drag's start
    return _dumps(scene)


# ------------------------------------------------------------------------------ one run

def child(scene_path: str, preset: str, out: str, options: str) -> None:
    """Run a scene in this process; print one JSON line: DOFs, iterations, Krylov iterations of
    every linear solve, wall time, peak memory."""
    from mpi4py import MPI

    from parsolve.driver import run
    from parsolve.model import build_model
    from parsolve.scene import load_scene
    from parsolve.solvers import linear

    krylov: list[int] = []
    solve = linear.LinearSolver.solve

    pieces: dict[str, float] = {}   # the matrices after the first solve (BENCH_PIECES set)

    choices: list[str] = []   # the iterative preset's preconditioner, as chosen per operator

    progress = Progress(os.environ.get("BENCH_LOG") if MPI.COMM_WORLD.rank == 0 else None)
    vcycle = {"made": 0, "kept": 0}   # the condensed V-cycle's hierarchy: made, kept

    def counted(self, rhs, x):
        its = solve(self, rhs, x)
        krylov.append(int(its))
        amg = self.condensed.amg if self.condensed is not None else None
        if amg is not None:
            vcycle.update(made=amg.made, kept=amg.kept)
        if "levels" not in vcycle:   # (the condensed V-cycle's, else the KSP's own AMG's)
            vcycle["levels"] = hierarchy(amg.pc if amg is not None else self.ksp.getPC())
        progress(f"linear solve {len(krylov)}: {its} Krylov iterations, set-up "
                 f"{setup['s']:.1f} s so far, V-cycle made {vcycle['made']} / kept "
                 f"{vcycle['kept']}, resident {bh.proc_memory()['rss'] / bh.MiB:.0f} MiB "
                 "(rank 0)")
        if self.choice and self.choice not in choices:
            choices.append(self.choice)
        if os.environ.get("BENCH_PIECES") and not pieces:
            pieces.update(matrix_pieces(self))
        return its

    linear.LinearSolver.solve = counted
    setup = {"mib": 0.0, "s": 0.0}   # the largest set-up's resident memory added, all set-ups' time
    prepare = linear.LinearSolver._prepare

    def measured(self):
        rss, t0 = bh.proc_memory()["rss"], time.perf_counter()
        prepare(self)
        setup["s"] += time.perf_counter() - t0
        setup["mib"] = max(setup["mib"], (bh.proc_memory()["rss"] - rss) / bh.MiB)

    linear.LinearSolver._prepare = measured
    scene = load_scene(Path(scene_path))
    scene.solver.preset = preset
    t0, cpu0 = time.perf_counter(), bh.cpu_seconds()
    model = build_model(scene, MPI.COMM_WORLD)
    dofs = model.mesh.num_global_points * model.ncomp   # (collective: before the run)
    progress(f"{dofs:,} DOFs, {MPI.COMM_WORLD.size} ranks, model built")
    status = run(MPI.COMM_WORLD, model, out, json.loads(options), log=progress)
    progress(f"run {status}")
    wall, cpu = time.perf_counter() - t0, bh.cpu_seconds() - cpu0
    import h5py

    # no collective after the run: petsc4py's garbage cleanup (collective) may run on one rank
    # while another waits in an mpi4py call (a 2-rank child hung so). Every rank prints its
    # own peak memory; rank 0 the rest; the parent sums.
    if MPI.COMM_WORLD.rank:
        print(json.dumps(dict(rank=MPI.COMM_WORLD.rank, hwm=bh.proc_memory()["hwm"],
                              setup=setup, pieces=pieces, cpu=cpu)))
        return
    with h5py.File(out, "r") as f:
        iterations = int(f["steps/iterations"][()].sum())
        dofs = int(f.attrs.get("dofs", dofs))
    print(json.dumps(dict(status=status, dofs=dofs, iterations=iterations, krylov=krylov,
                          wall=wall, hwm=bh.proc_memory()["hwm"], ranks=MPI.COMM_WORLD.size,
                          setup=setup, pieces=pieces, choices=choices, vcycle=vcycle,
                          cpu=cpu)))


def hierarchy(pc) -> list[int]:
    """The global rows of each level of a multigrid PC, finest first (one level: not a
    multigrid, its operator's rows)."""
    if pc.getType() not in ("gamg", "ml", "mg"):
        return [pc.getOperators()[0].getSize()[0]] if pc.getType() != "python" else []
    return [pc.getMGSmoother(lv).getOperators()[0].getSize()[0]
            for lv in reversed(range(pc.getMGLevels()))]


class Progress:
    """Progress lines of a child (``BENCH_LOG``: the file they are appended to, with the UTC
    time and the seconds since the child started; None: dropped)."""

    def __init__(self, path: str | None):
        self.path, self.t0 = path, time.perf_counter()

    def __call__(self, *words) -> None:
        if self.path:
            with open(self.path, "a") as f:
                print(f"{bh.utc_now()} {time.perf_counter() - self.t0:8.1f} s",
                      " ".join(str(w) for w in words), file=f, flush=True)


def estimate_child(scene_path: str, preset: str, out: str, options: str) -> None:
    """MUMPS' own estimate of the direct preset's factorization of the scene's first
    operator: its analysis, then a factorization refused at once (ICNTL(23), the working
    memory allowed, set to 1 MB: error -19 before any allocation); prints INFOG(16) (MiB, the
    largest rank's) and INFOG(17) (all ranks') and the analysis' time."""
    from mpi4py import MPI
    from petsc4py import PETSc

    from parsolve.model import build_model
    from parsolve.scene import load_scene
    from parsolve.solvers import options as opt
    from parsolve.solvers.linear import preset_options
    from parsolve.solvers.system import SaddleSystem

    comm = MPI.COMM_WORLD
    model = build_model(load_scene(Path(scene_path)), comm)
    dofs = model.mesh.num_global_points * model.ncomp
    mat = SaddleSystem(comm, model).assemble()
    settings = {**preset_options("direct", symmetric=False, has_multipliers=True),
                "mat_mumps_icntl_23": "1"}
    settings.pop("ksp_error_if_not_converged")
    ksp = PETSc.KSP().create(comm)
    ksp.setOptionsPrefix("estimate_")
    ksp.setOperators(mat)
    t0 = time.perf_counter()
    with opt.inserted("estimate_", settings, record=False):
        ksp.setFromOptions()
        try:
            ksp.setUp()
        except PETSc.Error:
            pass   # (-19: the estimate is what was asked)
    F = ksp.getPC().getFactorMatrix()
    info = {k: int(F.getMumpsInfog(k)) for k in (1, 16, 17)}
    if comm.rank == 0:
        print(json.dumps(dict(status="estimated", dofs=dofs, infog=info,
                              analysis=time.perf_counter() - t0, hwm=bh.proc_memory()["hwm"])))
    else:
        print(json.dumps(dict(rank=comm.rank, hwm=bh.proc_memory()["hwm"])))


def matrix_pieces(solver) -> dict[str, float]:
    """MiB on this rank of each matrix the first set-up of ``solver`` holds: the Newton matrix
    M, the KSP's operator and preconditioning matrix (each counted once), the fieldsplit's
    blocks, GAMG's coarse operators and interpolations; and the resident memory then."""
    seen: set[int] = set()

    def size(mat) -> float:
        if mat is None or mat.handle in seen:
            return 0.0
        seen.add(mat.handle)
        kind = mat.getType()
        if kind == "nest":
            m, n = mat.getNestSize()
            return sum(size(mat.getNestSubMatrix(i, j)) for i in range(m) for j in range(n))
        if "aij" not in kind:
            return 0.0
        return bh.mat_bytes(mat) / bh.MiB

    out = {"M": size(solver.operator)}
    ksp = solver.ksp
    op, pmat = ksp.getOperators()
    out["KSP operator"] = size(op)
    out["KSP pmat"] = size(pmat)
    pc = ksp.getPC()
    if pc.getType() == "python" and solver.condensed is not None:   # (solvers.condensed)
        out["condensed S"] = size(solver.condensed.S)
        mg = solver.condensed.amg.pc
    elif pc.getType() == "fieldsplit":
        kq, kl = pc.getFieldSplitSubKSP()
        out["fieldsplit q block"] = size(kq.getOperators()[1])
        out["Schur pmat"] = size(kl.getOperators()[1])
        mg = kq.getPC()
    else:
        mg = pc
    if mg.getType() in ("gamg", "ml"):
        levels = mg.getMGLevels()
        out["GAMG coarse operators"] = sum(
            size(mg.getMGSmoother(lv).getOperators()[0]) for lv in range(levels - 1))
        out["GAMG interpolations"] = sum(size(mg.getMGInterpolation(lv))
                                         for lv in range(1, levels))
    out["RSS"] = bh.proc_memory()["rss"] / bh.MiB
    return out


def json_objects(text: str) -> list[dict]:
    """The JSON objects printed in ``text`` (the ranks' lines may run into each other)."""
    decoder, out, i = json.JSONDecoder(), [], text.find("{")
    while i >= 0:
        try:
            obj, end = decoder.raw_decode(text, i)
            out.append(obj)
            i = text.find("{", end)
        except json.JSONDecodeError:
            i = text.find("{", i + 1)
    return out


def run_child(cmd: list[str], timeout: float | None) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of a child run in its own process group, the whole group
    stopped (SIGTERM, then SIGKILL) when it runs past ``timeout`` seconds (status None)."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=bh.child_env(), cwd=bh.ROOT, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
        return proc.returncode, out, err
    except subprocess.TimeoutExpired:
        for sig, wait in ((signal.SIGTERM, 20), (signal.SIGKILL, None)):
            try:
                os.killpg(proc.pid, sig)
                out, err = proc.communicate(timeout=wait)
                break
            except subprocess.TimeoutExpired:
                continue
        return None, out, f"stopped after {timeout:.0f} s (--timeout)"


def one_run(folder: Path, name: str, text: str, preset: str, options: dict | None = None,
            ranks: int = 1, timeout: float | None = None, mode: str = CHILD) -> dict:
    scene = folder / f"{name}.toml"
    scene.write_text(text)
    out = folder / f"{name}_{preset}.h5"
    args = [__file__, mode, str(scene), preset, str(out), json.dumps(options or {})]
    cmd = bh.mpirun(ranks, args) if ranks > 1 else [bh.VENV_PY, *args]
    code, stdout, stderr = run_child(cmd, timeout)
    lines = json_objects(stdout)
    main_line = [ln for ln in lines if "status" in ln]
    if code is None or code or not main_line:
        return dict(status=f"failed: {(stderr or stdout).strip()[-300:]}", out=str(out))
    hwm = [ln["hwm"] for ln in lines]
    setup = [ln.get("setup", {}).get("mib", 0.0) for ln in lines]
    pieces: dict[str, float] = {}
    for ln in lines:
        for key, mib in ln.get("pieces", {}).items():
            pieces[key] = pieces.get(key, 0.0) + mib
    cpu = [ln.get("cpu", 0.0) for ln in lines]
    return {**main_line[-1], "hwm": sum(hwm), "hwm_rank": max(hwm), "setup_rank": max(setup),
            "cpu_rank": max(cpu), "cpu_sum": sum(cpu),
            "setup_sum": sum(setup), "out": str(out), "pieces": pieces}


def same_answers(a: str, b: str) -> str:
    """'yes' when the two result files hold the same answers to 1e-8 of their scale."""
    sys.path.insert(0, str(bh.ROOT / "tests"))
    try:
        from conftest import read_results
        from solvers.test_iterative_scenes import assert_same_answers
    except ImportError:
        return "?"
    try:
        ra, rb = read_results(Path(a)), read_results(Path(b))
        assert (ra["steps/iterations"] == rb["steps/iterations"]).all()
        assert_same_answers(ra, rb)
        return "yes"
    except (AssertionError, OSError, KeyError) as exc:
        return f"no ({str(exc)[:40]})"


# ------------------------------------------------------------------------------ tables

def krylov_cells(r: dict) -> list[str]:
    k = r.get("krylov") or []
    if not k:
        return ["-", "-", "-"]
    return [str(min(k)), f"{sum(k) / len(k):.1f}", str(max(k))]


def preconditioner_of(r: dict) -> str:
    """The iterative preset's preconditioner(s) in the run (solvers.linear's choice)."""
    names = {c.split(":")[0] for c in r.get("choices") or []}
    return " + ".join(sorted(names)) or "-"


def row(case: str, factor: int, d: dict, i: dict, a: dict | None = None) -> list[str]:
    """``i``: the iterative preset as it chooses; ``a``: the same forced onto the augmented
    form (-condensed false; None: the preset chose it already)."""
    ok = d.get("status") == "complete" and i.get("status") == "complete"
    a = a or {}
    same = same_answers(i["out"], d["out"]) if ok else \
        f"direct: {d.get('status', '')[:30]}; iterative: {i.get('status', '')[:30]}"
    if a.get("status") == "complete" and d.get("status") == "complete":
        same += " / " + same_answers(a["out"], d["out"])
    return [case, f"{factor}×", f"{d.get('dofs', i.get('dofs', 0)):,}",
            str(i.get("iterations", "-")), str(len(i.get("krylov", []))), preconditioner_of(i),
            " / ".join(krylov_cells(i)), " / ".join(krylov_cells(a)) if a else "(same)",
            bh.fmt(d.get("wall"), ".1f"), bh.fmt(i.get("wall"), ".1f"),
            bh.fmt(a.get("wall"), ".1f") if a else "-",
            bh.mib(d.get("hwm")), bh.mib(i.get("hwm")), bh.mib(a.get("hwm")) if a else "-",
            same]


HEAD = ["case", "cells", "DOFs", "Newton its", "solves", "preconditioner",
        "Krylov min / mean / max", "augmented Krylov", "MUMPS s", "iterative s", "augmented s",
        "MUMPS MiB", "iterative MiB", "augmented MiB", "same answers (iterative / augmented)"]


def crossover(results: list[dict]) -> str:
    """Where the iterative run becomes faster than MUMPS, on the friction series."""
    series = [(r["dofs"], r["direct"]["wall"], r["iterative"]["wall"]) for r in results
              if r["case"] == "friction" and "wall" in r["direct"] and "wall" in r["iterative"]]
    if not series:
        return "no friction run completed"
    faster = [n for n, d, i in series if i < d]
    slower = [n for n, d, i in series if i >= d]
    if faster and (not slower or min(faster) > max(slower)):
        lo = max(slower) if slower else None
        return (f"the iterative preset is faster from {min(faster):,} DOFs on"
                + (f" (slower at {lo:,})" if lo else ""))
    return "no crossover in the sizes run: " + ", ".join(
        f"{n:,} DOFs {i / d:.2f}× MUMPS' time" for n, d, i in series)


def gamma_study(folder: Path) -> list[list[str]]:
    """Krylov iterations on the friction box against γ and the AMG (1×, 2×)."""
    rows = []
    for amg in ("gamg", "ml", "hypre"):
        for gamma in ("0.01", "0.1", "1", "10"):
            cells = [amg, gamma]
            for factor in (1, 2):
                r = one_run(folder, f"gamma_{factor}", friction_scene(factor), "iterative",
                            {"fieldsplit_q_pc_type": amg, "augmented_gamma": gamma})
                cells += [" / ".join(krylov_cells(r)) if r.get("krylov") else r["status"][:30]]
            rows.append(cells)
    return rows


SCALE_HEAD = ["problem", "refinement", "DOFs", "ranks", "Newton its", "Krylov mean / max",
              "V-cycle made / kept", "s per Newton it", "CPU s per Newton it",
              "set-up s per solve",
              "set-up MiB per rank",
              "peak MiB per rank", "peak MiB (all ranks)", "KB/DOF",
              "ratio to elasticity"]


#: the condensed V-cycle's alternatives (``--variants F``), each a friction run beside the preset's
#: (FINE_SWEEPS on its finest level; its hierarchy kept across the Newton iterations while it
#: serves; its Galerkin products freed, "allatonce" from ALLATONCE_ROWS on several ranks)
VARIANTS = {
    "8 fine sweeps (before)": {"condensed_fine_sweeps": "8"},
    "6 fine sweeps": {"condensed_fine_sweeps": "6"},
    "3 fine sweeps": {"condensed_fine_sweeps": "3"},
    "allatonce products": {"matptap_via": "allatonce"},
}


def scale_study(folder: Path, factors: list[int], ranks: int, steps: int = 2,
                variants: int = 0, petsc: dict | None = None) -> list[list[str]]:
    """The friction box (iterative preset) against plain elasticity (CG + GAMG) on the same
    mesh and ranks: time per Newton iteration, peak memory summed over the ranks; the matrices'
    memory piece by piece (``matrix_pieces``). At the refinement ``variants`` the friction box
    again with each of VARIANTS (``petsc``: the options of every friction run)."""
    os.environ["BENCH_PIECES"] = "1"   # (the children inherit it)
    rows, pieces, load0 = [], [], os.getloadavg()
    for f in factors:
        runs = {"friction": one_run(folder, f"scale_friction_{f}", friction_scene(f, steps),
                                    "iterative", petsc, ranks=ranks),
                "elasticity": one_run(folder, f"scale_elastic_{f}", elastic_scene(f, steps),
                                      "iterative", ranks=ranks)}
        for name, options in (VARIANTS.items() if f == variants else ()):
            runs[f"friction, {name}"] = one_run(
                folder, f"scale_friction_{f}", friction_scene(f, steps), "iterative",
                {**(petsc or {}), **options}, ranks=ranks)
        base = runs["elasticity"]
        for name, r in runs.items():
            if r.get("status") != "complete":
                rows.append([name, f"{f}³×", "-", str(ranks), r["status"][:60], *["-"] * 10])
                continue
            k = r["krylov"] or [0]
            per_it = r["wall"] / max(r["iterations"], 1)
            cpu_it = r["cpu_rank"] / max(r["iterations"], 1)
            ratio = "-"
            if name.startswith("friction") and base.get("status") == "complete":
                its = max(base["iterations"], 1)
                ratio = (f"time {per_it / (base['wall'] / its):.2f}× "
                         f"(CPU {cpu_it / (base['cpu_rank'] / its):.2f}×), "
                         f"memory {r['hwm'] / base['hwm']:.2f}×")
            rows.append([name, f"{f}³×", f"{r['dofs']:,}", str(ranks), str(r["iterations"]),
                         f"{sum(k) / len(k):.1f} / {max(k)}", made_kept(r), f"{per_it:.2f}",
                         f"{cpu_it:.2f}",
                         f"{r['setup']['s'] / max(len(r['krylov']), 1):.2f}",
                         f"{r['setup_rank']:.0f}", bh.mib(r.get("hwm_rank")), bh.mib(r["hwm"]),
                         f"{r['hwm'] / r['dofs'] / 1e3:.1f}", ratio])
        print(bh.text_table(SCALE_HEAD, rows[-len(runs):]), flush=True)
        pieces += [piece_row(name, f, r) for name, r in runs.items()]
        publish_scale(rows, pieces, ranks, steps, load0)   # after every size: a stopped run
    return rows                                            # keeps its rows


def made_kept(r: dict) -> str:
    """The condensed V-cycle's set-ups that made its hierarchy / kept it ("-": none)."""
    v = r.get("vcycle") or {}
    return f"{v['made']} / {v['kept']}" if v.get("made") else "-"


PIECES = ["M", "KSP operator", "KSP pmat", "fieldsplit q block", "Schur pmat", "condensed S",
          "GAMG coarse operators", "GAMG interpolations", "RSS"]
PIECES_HEAD = ["problem", "refinement", "Newton matrix M", "KSP operator", "KSP pmat (its own)",
               "fieldsplit q block (its own)", "Schur pmat", "condensed S",
               "AMG coarse operators", "AMG interpolations", "resident after the first solve",
               "peak"]


def piece_row(name: str, f: int, r: dict) -> list[str]:
    """MiB summed over the ranks of each matrix after the first solve (``matrix_pieces``)."""
    got = r.get("pieces") or {}
    return [name, f"{f}³×", *(f"{got[k]:.1f}" if k in got else "-" for k in PIECES),
            bh.mib(r.get("hwm"))]


GAMG_HEAD = ["ranks", "PtAP (-matptap_via)", "DOFs", "CG its", "set-up s",
             "set-up MiB per rank", "set-up MiB (all ranks)", "peak MiB per rank",
             "peak MiB (all ranks)", "peak / 1 rank's"]


def gamg_study(folder: Path, factor: int) -> list[list[str]]:
    """GAMG's set-up on the clamped box (plain elasticity, CG + GAMG, one step) on 1 and 2
    ranks, with PETSc's three distributed Galerkin products P^T A P: the resident memory the
    set-up adds per rank, its time, the run's peak against the 1-rank run's."""
    runs = [(1, "")] + [(2, via) for via in ("", "scalable", "allatonce")]
    rows, base = [], None
    for ranks, via in runs:
        r = one_run(folder, f"gamg_{factor}", elastic_scene(factor, 1), "iterative",
                    {"matptap_via": via} if via else {}, ranks=ranks)
        name = via or ("default (nonscalable)" if ranks > 1 else "sequential")
        if r.get("status") != "complete":
            rows.append([str(ranks), name, r["status"][:60], *["-"] * 7])
            continue
        base = base or r
        k = r["krylov"] or [0]
        rows.append([str(ranks), name, f"{r['dofs']:,}", str(max(k)),
                     f"{r['setup']['s']:.1f}", f"{r['setup_rank']:.0f}",
                     f"{r['setup_sum']:.0f}", bh.mib(r["hwm_rank"]), bh.mib(r["hwm"]),
                     f"{r['hwm'] / base['hwm']:.2f}×"])
        print(bh.text_table(GAMG_HEAD, rows[-1:]), flush=True)
    return rows


#: the weak scaling runs: (ranks, refinement f of the friction box per direction) at about 16k
#: DOFs per rank (f = 4, 5, 6: 16,875, 31,713, 53,391 DOFs), the 1-rank mesh on 2 and 4 ranks
#: (the same N, more P: what separates the fit's b·N from its c·N/P), and 122,451 DOFs on 2
#: ranks (61k per rank: a partition whose ghost layer is a smaller share)
WEAK = [(1, 4), (2, 5), (4, 6), (2, 4), (4, 4), (2, 8)]
WEAK_HEAD = ["problem", "ranks", "refinement", "DOFs", "DOFs per rank", "Newton its",
             "Krylov mean / max", "peak MiB per rank (largest)", "peak MiB (all ranks)",
             "KB/DOF (all ranks)", "ratio to elasticity"]
#: the model's target: 1024 ranks, 10⁹ DOFs
MODEL = (1024, 1.0e9)


def fit_memory(points: list[tuple[int, int, float]]) -> tuple[float, float, float]:
    """(a, b, c) of peak MiB per rank = a + b·N + c·N/P, least squares over (P, N, MiB)."""
    import numpy as np

    A = np.array([[1.0, n, n / p] for p, n, _ in points])
    y = np.array([m for _, _, m in points])
    return tuple(float(v) for v in np.linalg.lstsq(A, y, rcond=None)[0])


def fit_surface(points: list[tuple[int, int, float]]) -> tuple[float, float, float]:
    """(a, c, g) of peak MiB per rank = a + c·N/P + g·(N/P)^(2/3), least squares over
    (P, N, MiB): no term growing with N on every rank, the ghost layer as the part's surface."""
    import numpy as np

    A = np.array([[1.0, n / p, (n / p) ** (2 / 3)] for p, n, _ in points])
    y = np.array([m for _, _, m in points])
    return tuple(float(v) for v in np.linalg.lstsq(A, y, rcond=None)[0])


def fit_iterations(points: list[tuple[int, float]]) -> tuple[float, float]:
    """(α, β) of Krylov iterations per solve = α + β·log10(N), least squares over (N, its)."""
    import numpy as np

    A = np.array([[1.0, np.log10(n)] for n, _ in points])
    return tuple(float(v) for v in np.linalg.lstsq(A, np.array([k for _, k in points]),
                                                   rcond=None)[0])


def weak_study(folder: Path, steps: int) -> None:
    """The friction box (iterative preset) and plain elasticity (CG + GAMG) at about 16k DOFs
    per rank on 1, 2 and 4 ranks (oversubscribed: iterations and memory, not time), the 1-rank
    mesh again on 2 and 4 ranks; the peak memory per rank fitted as a + b·N + c·N/P and the
    mean Krylov iterations per solve as α + β·log10 N, extrapolated to ``MODEL``."""
    rows, runs = [], {"friction": [], "elasticity": []}
    for ranks, f in WEAK:
        pair = {"friction": one_run(folder, f"weak_friction_{f}_{ranks}",
                                    friction_scene(f, steps), "iterative", ranks=ranks),
                "elasticity": one_run(folder, f"weak_elastic_{f}_{ranks}",
                                      elastic_scene(f, steps), "iterative", ranks=ranks)}
        for name, r in pair.items():
            if r.get("status") != "complete":
                rows.append([name, str(ranks), f"{f}³×", r["status"][:60], *["-"] * 7])
                continue
            runs[name].append((ranks, r))
            k = r["krylov"] or [0]
            base = pair["elasticity"]
            ratio = (f"memory {r['hwm'] / base['hwm']:.2f}×" if name == "friction"
                     and base.get("status") == "complete" else "-")
            rows.append([name, str(ranks), f"{f}³×", f"{r['dofs']:,}",
                         f"{r['dofs'] // ranks:,}", str(r["iterations"]),
                         f"{sum(k) / len(k):.1f} / {max(k)}", bh.mib(r["hwm_rank"]),
                         bh.mib(r["hwm"]), f"{r['hwm'] / r['dofs'] / 1e3:.1f}", ratio])
        print(bh.text_table(WEAK_HEAD, rows[-2:]), flush=True)
        publish_weak(rows, runs, steps)


def model_lines(runs: dict) -> list[str]:
    """The fitted memory and iteration models in words, at ``MODEL``."""
    P, N = MODEL
    lines = []
    for name, got in runs.items():
        if len(got) < 3:
            lines.append(f"- {name}: fewer than 3 runs completed, no fit.")
            continue
        points = [(p, r["dofs"], r["hwm_rank"] / bh.MiB) for p, r in got]
        a, b, c = fit_memory(points)
        a2, c2, g2 = fit_surface(points)
        surface = a2 + c2 * N / P + g2 * (N / P) ** (2 / 3)
        its = [(r["dofs"], sum(r["krylov"]) / len(r["krylov"])) for _, r in got if r["krylov"]]
        alpha, beta = fit_iterations(its)
        per_rank = a + b * N + c * N / P
        lines.append(
            f"- {name}: peak MiB per rank = {a:.0f} + {b * 1e3:.4f}·N/1000 + "
            f"{c * 1e3:.3f}·(N/P)/1000 (N DOFs, P ranks; least squares over {len(got)} runs); "
            f"at {P} ranks × {N:.0e} DOFs ({N / P:,.0f} DOFs per rank): "
            f"**{per_rank / 1024:.1f} GiB per rank** ({a / 1024:.2f} fixed, "
            f"{b * N / 1024:.2f} growing with N on every rank, {c * N / P / 1024:.2f} "
            f"distributed); fitted instead as a + c·N/P + g·(N/P)^(2/3) (nothing growing "
            f"with N on every rank, the ghost layer as the part's surface): {a2:.0f} + "
            f"{c2 * 1e3:.3f}·(N/P)/1000 + {g2:.3f}·(N/P)^(2/3): **{surface / 1024:.1f} GiB per "
            f"rank** ({surface * P / 1024 ** 2:.1f} TiB in all); "
            f"Krylov iterations per solve (mean) = {alpha:.1f} + "
            f"{beta:.2f}·log10 N: **{alpha + beta * math.log10(N):.1f} at 10⁹ DOFs**.")
    return lines


def publish_weak(rows: list, runs: dict, steps: int) -> None:
    machine = bh.machine_info()
    text = "\n".join([
        "# Weak scaling of the friction box: 1, 2, 4 ranks", "",
        f"{machine['date']}, {machine['cpu']}, {machine['cpus']} CPUs (4 ranks oversubscribed: "
        "iterations and memory only, no times). The 3D friction box "
        f"(`contact_friction_3d.toml`, its first {steps} step{'s' if steps > 1 else ''}) "
        "refined f× per direction on the iterative preset, and the same mesh with its base "
        "clamped (plain elasticity, CG + GAMG); about 16k DOFs per rank, and the 1-rank mesh "
        "again on 2 and 4 ranks; peak memory: VmHWM.", "",
        bh.md_table(WEAK_HEAD, rows, first="---"), "",
        "The model (a fit, not a measurement; memory per rank a + b·N + c·N/P as the "
        "elasticity model of docs/performance.md; iterations α + β·log10 N):", "",
        *model_lines(runs), ""])
    bh.publish("bench_relations_weak.md", text)


#: the exact solve of S in place of the V-cycle (``--growth``): MUMPS' LU under the condensed
#: preconditioner's prefix, factored anew at every set-up (a kept factorization would be an
#: earlier S's); GMRES then converges in the iterations of M⁻¹ applied exactly
EXACT_S = {"condensed_pc_type": "lu", "condensed_pc_factor_mat_solver_type": "mumps",
           "condensed_reuse_growth": "0"}
#: the largest DOFs at which the growth study solves S exactly (MUMPS' fill of a 3D S)
EXACT_MAX_DOFS = 40_000
GROWTH_HEAD = ["problem", "S solved by", "refinement", "DOFs", "AMG levels (rows)",
               "Newton its", "solves", "Krylov mean / max", "mean / max without 1-its",
               "growth from 1× (mean / max)", "residual reduction per iteration"]
#: the Krylov relative tolerance of the iterative preset (solvers.linear.preset_options): GMRES
#: on a saddle system, CG on a stiffness alone; a solve of k iterations reduced the residual
#: by about rtol^(1/k) per iteration
RTOL = 2.5e-14
CG_RTOL = 1e-10
#: the elasticity reference of the iterative preset's own (CG + GAMG with its Chebyshev
#: smoothing, no multiplier), beside the condensed V-cycle's
CLAMPED = "elasticity, base clamped"


#: the V-cycle's alternatives of the growth study (friction box): what its growth comes from
GROWTH_VARIANTS = {
    # the levels below the first coarse one out of the question: that coarse operator solved
    # by LU (GAMG stops coarsening below this many rows)
    "V-cycle, two levels (first coarse LU)": {"condensed_pc_gamg_coarse_eq_limit": "5000"},
    # the first coarsening not aggressive (GAMG squares the graph on the first level: about
    # 35x fewer rows; without, about 5x)
    "V-cycle, graph not squared": {"condensed_pc_gamg_square_graph": "0"},
    # the best ratio found (the growth 1x to 64x; none met 1.5x): a full multigrid cycle on
    # the unsquared hierarchy (each level's V-cycle started from the coarser one's answer)
    "full cycle, graph not squared": {"condensed_pc_gamg_square_graph": "0",
                                      "condensed_pc_mg_type": "full"},
}


#: the refinement per direction up to which every growth series runs; above it (122k DOFs at
#: 8) the preset's friction and the held elasticity only
GROWTH_ALL_TO = 4


def growth_series(folder: Path, factors: list[int], ironing: bool, steps: int) -> list:
    """(problem, S's solve, refinement, scene, options) of each growth run, series by series:
    the friction box on the preset, with S solved exactly and with GROWTH_VARIANTS; the
    clamped box's elasticity (its base held by condensed rows) under the same V-cycle, and
    on the preset's CG + GAMG (its base eliminated); the ironing on the preset and exact (1×,
    8×). Above GROWTH_ALL_TO the preset's series only."""
    friction = [("V-cycle (preset)", {}), ("exact (LU)", EXACT_S), *GROWTH_VARIANTS.items()]
    runs = [("friction", solve, f, friction_scene(f, steps), options)
            for solve, options in friction for f in factors
            if f <= GROWTH_ALL_TO or not options]
    runs += [("elasticity, base held", "V-cycle (preset)", f,
              elastic_scene(f, steps, held=True), {}) for f in factors]
    runs += [(CLAMPED, "(no S: CG + GAMG, Chebyshev)", f, elastic_scene(f, steps), {})
             for f in factors if f <= GROWTH_ALL_TO]
    if ironing:
        texts = {f: ironing_scene(folder, f) for f in (1, 2)}
        runs += [("ironing", solve, f, texts[f], options)
                 for solve, options in (("V-cycle (preset)", {}), ("exact (LU)", EXACT_S))
                 for f in (1, 2)]
    return runs


def growth_cells(k: list[int], rtol: float = RTOL) -> tuple[float, int, str, str]:
    """(mean, max, "mean / max" of the solves that took more than one iteration: a solve
    whose right-hand side GMRES meets at once, e.g. a converged Newton's last, says nothing
    of the preconditioner; the residual's reduction per iteration of their mean, about
    rtol^(1/mean): how near the preconditioner is to S⁻¹)."""
    more = [n for n in k if n > 1]
    if not more:
        return sum(k) / len(k), max(k), "-", "-"
    mean = sum(more) / len(more)
    return (sum(k) / len(k), max(k), f"{mean:.1f} / {max(more)}",
            f"{rtol ** (1.0 / mean):.1e}")


def growth_study(folder: Path, factors: list[int], ironing: bool, steps: int,
                 petsc: dict) -> None:
    """Krylov iterations per solve as the mesh is refined (1×, 8×, 64×, ...): the preset's
    V-cycle against an exact solve of S (what is left is the V-cycle's) and against the
    same V-cycle on plain elasticity of the same meshes (the V-cycle's own growth on this
    mesh family); the hierarchy's levels at each size. ``petsc``: options added to every
    run (an experiment: the table then goes to the scratch folder, not the published one)."""
    rows, results, load0 = [], [], os.getloadavg()
    first: dict[tuple, tuple] = {}
    for problem, solve, f, text, options in growth_series(folder, factors, ironing, steps):
        if options is EXACT_S and results and any(
                r["problem"] == problem and r["factor"] == f and r.get("dofs", 0) > EXACT_MAX_DOFS
                for r in results):
            continue
        name = f"growth_{problem.split(',')[0]}_{f}"
        r = one_run(folder, name, text, "iterative", {**petsc, **options})
        results.append(dict(r, problem=problem, solve=solve, factor=f))
        if r.get("status") != "complete" or not r.get("krylov"):
            rows.append([problem, solve, f"{f ** 3}×", str(r.get("status"))[:60], *["-"] * 7])
            continue
        mean, top, more, factor = growth_cells(r["krylov"],
                                               CG_RTOL if problem == CLAMPED else RTOL)
        base = first.setdefault((problem, solve), (mean, top))
        levels = (r.get("vcycle") or {}).get("levels") or []
        rows.append([problem, solve, f"{f ** 3}×", f"{r['dofs']:,}",
                     " / ".join(f"{n:,}" for n in levels) if len(levels) > 1 else "-",
                     str(r["iterations"]), str(len(r["krylov"])), f"{mean:.1f} / {top}", more,
                     f"{mean / base[0]:.2f}× / {top / base[1]:.2f}×", factor])
        print(bh.text_table(GROWTH_HEAD, rows[-1:]), flush=True)
        publish_growth(rows, results, steps, load0, petsc)


def publish_growth(rows: list, results: list, steps: int, load0: tuple, petsc: dict) -> None:
    machine = bh.machine_info()
    fits = []
    for key in dict.fromkeys((r["problem"], r["solve"]) for r in results):
        its = [(r["dofs"], sum(r["krylov"]) / len(r["krylov"])) for r in results
               if (r["problem"], r["solve"]) == key and r.get("krylov")]
        if len(its) >= 2:
            alpha, beta = fit_iterations(its)
            fits.append(f"- {key[0]}, {key[1]}: mean Krylov iterations per solve = "
                        f"{alpha:.1f} {'−' if beta < -0.005 else '+'} {abs(beta):.2f}·log10 N "
                        f"({len(its)} sizes)")
    text = "\n".join([
        "# Growth of the Krylov iterations with the mesh: what grows", "",
        f"{machine['date']}, {machine['cpu']}, {machine['cpus']} CPUs, one rank; "
        + bh.load_line(load0, os.getloadavg()) + " (iterations are not affected by the load)."
        + (f" Options added to every run: `{json.dumps(petsc)}`." if petsc else ""), "",
        "Krylov (GMRES on the saddle system, rtol 2.5e-14) iterations per linear solve of "
        f"the whole run (friction box and elasticity: the first {steps} steps; ironing: the "
        "first 4), the iterative preset's condensed preconditioner with S solved by its "
        "V-cycle (GAMG, threshold 0, SOR on the finest level: `parsolve/solvers/vcycle.py`) "
        "or exactly (MUMPS' LU on S: `-condensed_pc_type lu`; what grows beside it is the "
        "V-cycle's) or by the V-cycle's alternatives (`GROWTH_VARIANTS`: the first coarse "
        "operator solved by LU, a two-level cycle; GAMG's first coarsening without its "
        "squared graph; that with a full multigrid cycle); the clamped box (`elastic_scene`) "
        "with its base rows multiplied, which "
        "the preset condenses like the contact rows: plain elasticity under the same V-cycle; "
        "the same box clamped (its base rows eliminated): the preset's CG + GAMG with "
        f"GAMG's own Chebyshev smoothing, rtol {CG_RTOL:g}, no S. "
        "AMG levels: the rows of each level's operator at the first solve, finest first "
        "(the coarsest solved by LU). Solves of one iteration (a right-hand side GMRES meets "
        "at once) are left out of the second mean / max; the residual's reduction per "
        f"iteration is that mean's, about rtol^(1 / mean) (the preset's rtol, {RTOL:g} on "
        f"the saddle systems). Above {GROWTH_ALL_TO ** 3}× the preset's series only.", "",
        bh.md_table(GROWTH_HEAD, rows, first="---"), "",
        "Fitted (least squares over the sizes, as the weak-scaling table's):", "", *fits, ""])
    name = "bench_relations_growth"
    if petsc:   # (an experiment: never over the published table)
        bh.scratch("relations_growth").joinpath(name + ".md").write_text(text)
        bh.write_json(bh.scratch("relations_growth") / (name + ".json"),
                      dict(machine=machine, petsc=petsc, results=results))
        return
    bh.publish(name + ".md", text)
    bh.write_json(bh.PUBLISHED / (name + ".json"), dict(machine=machine, results=results))


BIG_HEAD = ["problem", "refinement", "DOFs", "ranks", "Newton its", "linear solves",
            "Krylov min / mean / max", "set-up s per solve", "wall s", "wall s per Newton it",
            "CPU s per Newton it (all ranks)", "peak MiB per rank", "peak MiB (all ranks)",
            "KB/DOF"]
BIG_JSON = "bench_relations_big.json"   # the big study's measurements (``--big-publish``)


def big_study(folder: Path, factor: int, ranks: int, steps: int, timeout: float | None,
              elasticity: bool, petsc: dict | None = None) -> dict:
    """One large run of the friction box on the iterative preset (``petsc``: its options), and
    before it on request the clamped box's elasticity (short: the reference is there even if
    the friction run is stopped), then MUMPS' estimate of the direct preset's factorization at
    that size (``estimate_child``). The measurements are written (BIG_JSON) and the table
    rendered from them after every run: a study stopped halfway leaves what it measured."""
    end = None if timeout is None else time.monotonic() + timeout   # (the whole study's)
    study = dict(machine=bh.machine_info(), factor=factor, ranks=ranks, steps=steps,
                 petsc=petsc or {}, load0=os.getloadavg(), runs={}, mumps=None)
    runs = [("elasticity", elastic_scene(factor, steps), {})] if elasticity else []
    runs.append(("friction", friction_scene(factor, steps), petsc or {}))

    def save() -> None:
        study["load1"] = os.getloadavg()
        big_timings(study)
        bh.write_json(bh.PUBLISHED / BIG_JSON, study)
        publish_big(study)

    for name, text, options in runs:
        r = one_run(folder, f"big_{name}_{factor}", text, "iterative", options, ranks=ranks,
                    timeout=left(end))
        study["runs"][name] = r
        print(bh.text_table(BIG_HEAD, [big_row(name, factor, ranks, r)]), flush=True)
        save()
    study["mumps"] = one_run(folder, f"big_friction_{factor}", friction_scene(factor, steps),
                             "direct", ranks=ranks, timeout=left(end), mode=ESTIMATE)
    print(mumps_words(study["mumps"], ranks), flush=True)
    save()
    return study


def big_after(folder: Path) -> dict:
    """The elasticity run of the last big study (BIG_JSON) again, after its friction run, on
    the same mesh and ranks ("elasticity, after"): over a long friction run the machine's
    load changes, and the CPU time of a loaded machine's run grows with the load (its shared
    caches and memory bandwidth): the ratios are given against both elasticity runs."""
    study = bh.read_json(bh.PUBLISHED / BIG_JSON)
    factor, ranks, steps = study["factor"], study["ranks"], study["steps"]
    r = one_run(folder, f"big_elasticity_{factor}", elastic_scene(factor, steps), "iterative",
                ranks=ranks)
    study["runs"]["elasticity, after"] = r
    print(bh.text_table(BIG_HEAD, [big_row("elasticity, after", factor, ranks, r)]), flush=True)
    study["load1"] = os.getloadavg()
    big_timings(study)
    bh.write_json(bh.PUBLISHED / BIG_JSON, study)
    publish_big(study)
    return study


def left(end: float | None) -> float | None:
    """Seconds to ``end`` (time.monotonic), at least one."""
    return None if end is None else max(end - time.monotonic(), 1.0)


def per_newton(r: dict) -> tuple[float, float]:
    """(wall s, CPU s summed over the ranks) per Newton iteration of a completed run: the
    whole run's (model built, every step, output) over its Newton iterations."""
    its = max(r["iterations"], 1)
    return r["wall"] / its, r.get("cpu_sum", 0.0) / its


def big_row(name: str, factor: int, ranks: int, r: dict) -> list[str]:
    if r.get("status") != "complete":
        return [name, f"{factor}³×", "-", str(ranks), r["status"][:80], *["-"] * 9]
    k = r["krylov"] or [0]
    wall_it, cpu_it = per_newton(r)
    return [name, f"{factor}³×", f"{r['dofs']:,}", str(ranks), str(r["iterations"]),
            str(len(r["krylov"])), " / ".join(krylov_cells(r)),
            f"{r['setup']['s'] / max(len(k), 1):.1f}", f"{r['wall']:.0f}", f"{wall_it:.1f}",
            f"{cpu_it:.1f}", bh.mib(r["hwm_rank"]), bh.mib(r["hwm"]),
            f"{r['hwm'] / r['dofs'] / 1e3:.1f}"]


def big_ratios(runs: dict) -> str:
    """Friction over elasticity on the same mesh and ranks, against the targets (peak memory
    ≤ 1.3×, time per Newton iteration ≤ 1.5×), or why there is no ratio: against each
    elasticity run (the one before the friction run, and ``--big-after``'s after it)."""
    f = runs.get("friction")
    refs = {name: r for name, r in runs.items() if name.startswith("elasticity")
            and r.get("status") == "complete"}
    if not (f and f.get("status") == "complete" and refs):
        return "No ratio: the friction run and the elasticity run did not both complete"
    return " ".join(_ratio_words(f, name, e) for name, e in refs.items())


def _ratio_words(f: dict, name: str, e: dict) -> str:
    (fw, fc), (ew, ec) = per_newton(f), per_newton(e)
    mem, rank, wall = f["hwm"] / e["hwm"], f["hwm_rank"] / e["hwm_rank"], fw / ew
    cpu = fc / ec if ec else float("nan")

    def met(x: float, limit: float) -> str:
        return f"{x:.2f}× ({'met' if x <= limit else 'missed'}: ≤ {limit}×)"

    which = "the elasticity run after it" if "after" in name else "the elasticity run before it"
    return (f"Friction over {which} (same mesh and ranks): peak memory summed over the "
            f"ranks {met(mem, 1.3)}, of the largest rank {rank:.2f}×; time per Newton "
            f"iteration, CPU summed over the ranks {met(cpu, 1.5)}, wall {met(wall, 1.5)} "
            "(the CPU time is the less disturbed by the machine's other jobs; both are the "
            "whole run's over its Newton iterations, the model's build and the output "
            "included).")


def big_timings(study: dict) -> bool:
    """Each completed run's own timings (s, all steps; its result file's ``timings`` group:
    set-up in "factorization", Krylov in "solve"), added where missing; True if any was."""
    import h5py

    added = False
    for r in study["runs"].values():
        if r.get("status") == "complete" and "timings" not in r and Path(r["out"]).exists():
            with h5py.File(r["out"], "r") as f:
                r["timings"] = {k: float(f[f"timings/{k}"][()].sum()) for k in f["timings"]}
            added = True
    return added


def time_words(runs: dict) -> str:
    """Where each run's time went (its own timings)."""
    names = [("factorization", "set-up"), ("solve", "Krylov"), ("assembly", "assembly"),
             ("contact", "contact"), ("output", "output")]
    parts = []
    for name, r in runs.items():
        t = r.get("timings")
        if t:
            its = max(r["iterations"], 1)
            parts.append(f"{name} {t.get('total', 0):.0f} s in its steps: " + ", ".join(
                f"{word} {t[k]:.0f} s ({t[k] / its:.1f} per Newton iteration)"
                for k, word in names if k in t))
    return ("Where the time goes (rank 0's wall time, the runs' own timings): "
            + "; ".join(parts)) if parts else ""


def mumps_words(e: dict | None, ranks: int) -> str:
    if e is None:
        return "(the MUMPS estimate not run yet)"
    if e.get("status") != "estimated":
        return f"MUMPS' analysis did not finish: {e['status'][:120]}"
    g = e["infog"]
    return (f"MUMPS (the direct preset's LU, QAMD), from its analysis of the same operator "
            f"on {ranks} ranks ({e['analysis']:.0f} s, peak {bh.mib(e['hwm_rank'])} MiB "
            f"per rank): {g['17']:,} MB for the factorization in core, "
            f"{g['16']:,} MB on the largest rank (INFOG(17), INFOG(16); its "
            f"factorization refused at once, INFOG(1) = {g['1']}; the machine has "
            f"{bh.machine_info()['mem_gib']} GiB)")


def publish_big(study: dict) -> None:
    """bench_relations_big.md rendered from the big study's measurements (``big_study``'s, or
    BIG_JSON read back by ``--big-publish``)."""
    machine, steps, ranks = study["machine"], study["steps"], study["ranks"]
    rows = [big_row(name, study["factor"], ranks, r) for name, r in study["runs"].items()]
    text = "\n".join([
        "# Frictional contact at scale: the largest run", "",
        f"{machine['date']}, {machine['cpu']}, {machine['cpus']} CPUs, {ranks} ranks, the "
        f"machine shared (times noisy: {bh.load_line(study['load0'], study['load1'])}). The 3D "
        "friction box (`contact_friction_3d.toml`, its "
        f"first {steps} step{'s' if steps > 1 else ''}) refined {study['factor']}× per "
        "direction on the iterative preset (GMRES on the saddle system, the nodal rows "
        "condensed, one GAMG V-cycle on the condensed operator), beside the same box with its "
        "base clamped (plain elasticity, CG + GAMG); Krylov iterations per linear solve; "
        "set-up: the condensation and the AMG's, per linear solve; time per Newton iteration: "
        "the whole run's wall time, and its CPU time summed over the ranks, over its Newton "
        "iterations; peak memory: VmHWM. The measurements: `" + BIG_JSON + "`.", "",
        bh.md_table(BIG_HEAD, rows, first="---"), "", big_ratios(study["runs"]), "",
        *([time_words(study["runs"]) + ".", ""] if time_words(study["runs"]) else []),
        mumps_words(study["mumps"], ranks) + ".", ""])
    bh.publish("bench_relations_big.md", text)


def publish_gamg(rows: list, factor: int) -> None:
    machine = bh.machine_info()
    text = "\n".join([
        "# GAMG's set-up on 1 and 2 ranks", "",
        f"{machine['date']}, {machine['cpu']}, {machine['cpus']} CPUs, the machine shared "
        f"(times noisy). The friction box's mesh refined {factor}× per direction, its base "
        "clamped (plain elasticity, CG + GAMG, one step); set-up memory: the resident memory "
        "PCSetUp added (per rank: the largest); peak: VmHWM of the run. `-matptap_via` reaches "
        "GAMG's Galerkin products under no options prefix (`solvers.options.UNPREFIXED`).", "",
        bh.md_table(GAMG_HEAD, rows, first="---"), ""])
    bh.publish("bench_relations_gamg.md", text)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    bh.add_smoke(p)
    p.add_argument("--max-factor", type=int, default=4, help="largest friction refinement f")
    p.add_argument("--gamma", action="store_true", help="the γ and AMG study")
    p.add_argument("--scale", type=str, default="",
                   help="the scale runs only: friction box refinements f (comma-separated) on "
                        "--ranks ranks, against plain elasticity with GAMG (scale table)")
    p.add_argument("--ranks", type=int, default=2, help="ranks of the scale runs")
    p.add_argument("--variants", type=int, default=0,
                   help="with --scale: at this refinement the friction box again with each "
                        "of the condensed V-cycle's alternatives (VARIANTS)")
    p.add_argument("--weak", action="store_true",
                   help="the weak scaling runs only: the friction box and plain elasticity "
                        "at about 16k DOFs per rank on 1, 2, 4 ranks (and the 1-rank mesh on "
                        "2 and 4), the memory model fitted (bench_relations_weak.md)")
    p.add_argument("--growth", action="store_true",
                   help="the growth runs only: Krylov iterations per solve of the friction box "
                        "refined 1×, 8×, ... (to --max-factor per direction) with S solved by "
                        "the V-cycle and exactly, the clamped box's elasticity under the same "
                        "V-cycle, the ironing 1× and 8× (unless --cases leaves it out): "
                        "bench_relations_growth.md; with --smoke the 1× box, one step")
    p.add_argument("--steps", type=int, default=2, help="load steps of the scale runs")
    p.add_argument("--cases", type=str, default="friction,ironing,mortar",
                   help="the series to run, or single sizes as case:factor (comma-separated: "
                        "friction,ironing:1,mortar)")
    p.add_argument("--no-augmented", action="store_true",
                   help="no run forced onto the augmented form beside a condensed one")
    p.add_argument("--gamg", type=int, default=0,
                   help="the GAMG set-up table only: the clamped box refined f× on 1 and 2 "
                        "ranks, PETSc's PtAP algorithms (bench_relations_gamg.md)")
    p.add_argument("--big", type=int, default=0,
                   help="one large run only (not in CI): the friction box refined f× per "
                        "direction on --ranks ranks, MUMPS' estimate beside it "
                        "(bench_relations_big.md)")
    p.add_argument("--big-elasticity", action="store_true",
                   help="with --big: the clamped box's elasticity run too")
    p.add_argument("--big-after", action="store_true",
                   help="the elasticity run of the last --big study again, after its friction "
                        "run (bench_relations_big.json): the ratios against both")
    p.add_argument("--big-publish", action="store_true",
                   help="bench_relations_big.md rendered again from the measurements of the "
                        "last --big run (bench_relations_big.json), nothing run")
    p.add_argument("--timeout", type=float, default=None,
                   help="seconds after which the --big runs are stopped (their rows say so)")
    p.add_argument("--petsc", type=str, default="{}",
                   help="PETSc options of the friction runs of --big and --scale, of every "
                        "run of --growth (its table then in the scratch folder) (JSON, "
                        "under the solver's prefix as a scene's)")
    p.add_argument("--log", type=str, default="",
                   help="file the runs append their progress to (each linear solve)")
    args = p.parse_args()
    if args.log:
        os.environ["BENCH_LOG"] = str(Path(args.log).resolve())   # (the children inherit it)
    petsc = json.loads(args.petsc)
    if args.big_after:
        big_after(bh.scratch("relations_big"))
        return
    if args.big_publish:
        study = bh.read_json(bh.PUBLISHED / BIG_JSON)
        if big_timings(study):   # (a study measured before its timings were recorded)
            bh.write_json(bh.PUBLISHED / BIG_JSON, study)
        publish_big(study)
        return
    if args.big:
        big_study(bh.scratch("relations_big"), args.big, args.ranks, args.steps, args.timeout,
                  args.big_elasticity, petsc)
        return
    if args.weak:
        weak_study(bh.scratch("relations_weak"), args.steps)
        return
    if args.growth:
        factors = [1] if bh.SMOKE else [2 ** i for i in range(int(math.log2(args.max_factor)) + 1)]
        growth_study(bh.scratch("relations_growth"), factors,
                     "ironing" in args.cases.split(",") and not bh.SMOKE,
                     1 if bh.SMOKE else args.steps, petsc)
        return
    if args.gamg:
        publish_gamg(gamg_study(bh.scratch("relations_gamg"), args.gamg), args.gamg)
        return
    if args.scale or bh.SMOKE:
        factors = [1] if bh.SMOKE else [int(f) for f in args.scale.split(",")]
        rows = scale_study(bh.scratch("relations_scale"), factors, args.ranks, args.steps,
                           1 if bh.SMOKE else args.variants, petsc)
        if args.scale:
            return
    folder = bh.scratch("relations")
    load0, machine = os.getloadavg(), bh.machine_info()
    cases = [("friction", 1, friction_scene(1))]
    if not bh.SMOKE:
        f = 2
        while f <= args.max_factor:
            cases.append(("friction", f ** 3, friction_scene(f)))
            f *= 2
        cases += [("ironing", 1, ironing_scene(folder, 1)), ("ironing", 8, ironing_scene(folder, 2)),
                  ("mortar", 1, mortar_scene(1)), ("mortar", 8, mortar_scene(2))]
        chosen = args.cases.split(",")   # a series ("mortar") or one size ("ironing:8")
        cases = [c for c in cases if c[0] in chosen or f"{c[0]}:{c[1]}" in chosen]
    results, rows = [], []
    for case, factor, text in cases:
        name = f"{case}_{factor}"
        d = one_run(folder, name, text, "direct")
        i = one_run(folder, name, text, "iterative")
        a = None   # the augmented form beside the condensed one (the path it replaces)
        if preconditioner_of(i).startswith("condensed") and not args.no_augmented:
            a = one_run(folder, f"{name}_augmented", text, "iterative", {"condensed": "false"})
        results.append(dict(case=case, factor=factor, dofs=d.get("dofs", i.get("dofs", 0)),
                            direct=d, iterative=i, augmented=a))
        rows.append(row(case, factor, d, i, a))
        print(bh.text_table(HEAD, rows[-1:]), flush=True)
        # written after every case: a run stopped halfway leaves what it measured
        text = report(rows, results, machine, load0)
    if args.gamma and not bh.SMOKE:
        grows = gamma_study(folder)
        text = report(rows, results, machine, load0, grows)
    print(text)
    if bh.SMOKE:   # (CI's smoke stage runs --smoke alone: the growth mode at its smoke size)
        growth_study(bh.scratch("relations_growth"), [1], False, 1, {})


def publish_scale(rows: list, pieces: list, ranks: int, steps: int, load0: tuple) -> None:
    machine = bh.machine_info()
    text = "\n".join([
        "# Relations at scale: the friction box against plain elasticity", "",
        f"{machine['date']}, {machine['cpu']}, {machine['cpus']} CPUs, {ranks} ranks, the "
        "machine shared (times noisy). The 3D friction box (`contact_friction_3d.toml`, its "
        f"first {steps} step{'s' if steps > 1 else ''}) refined f× per direction on the iterative preset, against the same "
        "box with its base clamped (CG + GAMG); time per Newton iteration: the run's wall "
        "time, and the CPU time of its busiest rank (less disturbed by the machine's load), "
        "over its Newton iterations; V-cycle made / kept: the condensed V-cycle's set-ups "
        "that made its hierarchy, that kept it; set-up MiB: the resident memory the largest "
        "preconditioner set-up added on a rank (the condensation and its V-cycle; GAMG's for "
        "elasticity); peak memory: VmHWM summed over the ranks. "
        + bh.load_line(load0, os.getloadavg()) + ".", "",
        bh.md_table(SCALE_HEAD, rows, first="---"), "",
        "The friction rows after the first: the condensed V-cycle's alternatives "
        "(`VARIANTS`), each the preset with its options.", "",
        "The matrices piece by piece after the first linear solve (MiB summed over the ranks: "
        "allocated nonzeros × (value + column index) + row offsets; a matrix shared by two "
        "roles counted once, at its first; M is the Newton matrix, on the saddle operator's own "
        "arrays), the resident memory then and the run's peak:", "",
        bh.md_table(PIECES_HEAD, pieces, first="---"), ""])
    bh.publish("bench_relations_scale.md", text)


def report(rows: list, results: list, machine: dict, load0, gamma_rows: list | None = None) -> str:
    """The report (markdown) and the JSON of the runs so far, written."""
    cross = crossover(results)
    lines = ["# Relations on the iterative preset", "",
             f"{machine['date']}, {machine['cpu']}, {machine['cpus']} CPUs, one rank; "
             + bh.load_line(load0, os.getloadavg()) + " (the machine is shared: times are "
             "noisy, iterations and memory are not).", "",
             "The iterative preset (GMRES, rtol 2.5e-14) against MUMPS (the direct preset), "
             "each run in its own process (peak memory: VmHWM); Krylov iterations per linear "
             "solve of the whole run. The preset chooses per operator: `condensed` when every "
             "relation row is nodal (GMRES on M itself, preconditioned by the rows condensed "
             "node by node and one GAMG V-cycle, SOR on its finest level, on the condensed "
             "primal operator; "
             "`parsolve/solvers/condensed.py`), else `augmented` (GMRES on the augmented "
             "Lagrangian form T M x = T b, γ = 3 on the rows of one node, its Schur fieldsplit: "
             "one GAMG V-cycle, threshold 0, four Chebyshev steps per level (point-block "
             "Jacobi where the node blocks are invertible), on "
             "K + γ/k Aₕᵀ Aₕ, Jacobi on the sparse Schur approximation; "
             "`parsolve/solvers/augmented.py`). Where it condenses, the same run forced onto "
             "the augmented form (`-condensed false`) stands beside it.", "",
             bh.md_table(HEAD, rows, first="---"), "", f"Crossover: {cross}.", ""]
    if gamma_rows:
        lines += ["## γ and the AMG", "", "Krylov iterations (min / mean / max) on the friction "
                  "box, 1× and 8×.", "",
                  bh.md_table(["AMG", "γ", "1×", "8×"], gamma_rows, first="---"), ""]
    text = "\n".join(lines)
    bh.publish("bench_relations.md", text)
    bh.write_json(bh.PUBLISHED / "bench_relations.json",
                  dict(machine=machine, results=results, crossover=cross))
    return text


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == CHILD:
        child(*sys.argv[2:6])
    elif len(sys.argv) > 1 and sys.argv[1] == ESTIMATE:
        estimate_child(*sys.argv[2:6])
    else:
        main()
