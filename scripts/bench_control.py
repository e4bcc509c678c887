"""Benchmark: non-associated control against the classical schemes (issue: control).

On the localization bar (severe snap-back) and the plate with a hole (softening past a peak):
  control       parsolve's non-associated maximum-strain control (the shipped scenes)
  arc_length    Crisfield's cylindrical arc-length, bordering, with step cutting, same
                matrix choice (secant / tangent) as the control run
  load          load control (the control pattern ramped to 1.2 × the peak load)
  displacement  displacement control of the loaded edge
For each: steps completed, global iterations (total and per step), time, and where it stopped.
Writes bench_results/control.json, scripts/results/bench_control.md and
scripts/results/bench_control.png (load-displacement curves; needs matplotlib:
apt-get install python3-matplotlib).

    .venv/bin/python scripts/bench_control.py
    .venv/bin/python scripts/bench_control.py --smoke   # the bar, 4 steps; files in a temp folder
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import h5py
import numpy as np
from mpi4py import MPI

import bench_harness as bh
from parsolve.driver import run
from parsolve.errors import SolverError
from parsolve.model import build_model
from parsolve.scene import load_scene

ROOT = bh.ROOT
OUT = bh.SCRATCH              # bench_results/ (a temporary folder in smoke mode)
SMOKE_STEPS = 4               # smoke runs: the localization bar, every method, 4 steps
CASES = {
    "localization_bar": dict(scene="localization_bar.toml", edge=1.0, pattern="pull",
                             control="max_strain", arc=6e-5, arc_steps=60, peak_factor=1.2,
                             disp_end=2.4e-4, point=(1.0, 0.0)),
    "plate_with_hole": dict(scene="plate_hole_control.toml", edge=4.0, pattern="tension",
                            control="max_strain", arc=1.5e-4, arc_steps=40, peak_factor=1.2,
                            disp_end=4e-4, point=(4.0, 0.0)),
}


def strip_control(text: str, name: str) -> str:
    i = text.index(f'[[relations]]\nname = "{name}"')
    j = text.index("[[relations]]", i + 1) if "[[relations]]" in text[i + 1:] else text.index("[steps]")
    return text[:i] + text[j:]


def variants(case: dict, peak: float) -> dict[str, str]:
    text = (ROOT / "configs" / case["scene"]).read_text()
    base = strip_control(text, case["control"])
    nl = "[nonlinear]\n"
    arc = base.replace(nl, nl + f'method = "arc_length"\narc_length = {{ pattern = "{case["pattern"]}", '
                           f'length = {case["arc"]} }}\n')
    arc = arc.replace("count = 24", f"count = {case['arc_steps']}").replace(
        "count = 30", f"count = {case['arc_steps']}")
    load = base.replace("total_force = [1.0, 0.0]", f"total_force = [{case['peak_factor'] * peak}, 0.0]")
    disp = base.replace(f'[[loads]]\nname = "{case["pattern"]}"\nregion = "right"\ntotal_force = [1.0, 0.0]\n', "")
    x, y = case["point"]
    if "[regions]" not in disp:
        disp = disp.replace("[[materials]]", "[regions]\n\n[[materials]]", 1)
    disp = disp.replace("[regions]\n", f"[regions]\nbench_end = {{ point = [{x}, {y}] }}\n")
    disp += f"""
[[relations]]
name = "end_rigid"
type = "equal"
region = "right"
component = "x"

[[relations]]
name = "end_displacement"
type = "dirichlet"
region = "bench_end"
components = ["x"]
value = {case['disp_end']}
"""
    if "right_rigid" in disp:  # the bar already ties its right end
        disp = strip_control(disp, "end_rigid")
    return {"control": text, "arc_length": arc, "load": load, "displacement": disp}


def curve(path: Path, case: dict, method: str):
    with h5py.File(path) as f:
        pts = f["mesh/points"][()]
        u = f["fields/displacement"][()]
        delta = u[:, np.isclose(pts[:, 0], case["edge"]), 0].mean(axis=1) if len(u) else np.zeros(0)
        t = f["steps/time"][()]
        if method == "control":
            force = f[f"relations/{case['control']}/multiplier"][()].sum(axis=1)
        elif method == "arc_length":
            force = t
        elif method == "load":
            force = t * case["peak_factor"] * case["peak"]
        else:  # displacement control: the load is what the support carries
            force = -_edge_reaction(f, case)
        return delta, force, f["steps/iterations"][()], f.attrs["status"]


def _edge_reaction(f, case) -> np.ndarray:
    """Load carried by the controlled edge: minus the reaction of the left support."""
    for name in ("left_x", "symmetry_x"):
        if f"relations/{name}" in f:
            return -f[f"relations/{name}/multiplier"][()].sum(axis=1)
    raise KeyError("no support relation")


def with_matrix(text: str, matrix: str) -> str:
    lines = [ln for ln in text.splitlines() if not ln.startswith("matrix =")
             and not ln.startswith("max_iterations =")]
    text = "\n".join(lines) + "\n"
    return text.replace("[nonlinear]\n", f'[nonlinear]\nmatrix = "{matrix}"\nmax_iterations = 100\n')


def shortened(text: str, steps: int | None) -> str:
    """The scene with ``steps`` steps (None: as shipped)."""
    if steps is None:
        return text
    return text.replace("count = 24", f"count = {steps}").replace("count = 30", f"count = {steps}")


def run_case(name: str, case: dict, steps: int | None = None) -> list[dict]:
    """Every method with both matrices (consistent tangent, secant), so each baseline is shown
    at its best. steps: fewer steps than shipped (smoke runs)."""
    rows = []
    text = shortened((ROOT / "configs" / case["scene"]).read_text(), steps)
    if steps is not None:
        case["arc_steps"] = steps
    shipped = "secant" if 'matrix = "secant"' in text else "tangent"
    path = OUT / f"control_{name}_control_{shipped}.h5"
    _run(text, path)
    d, F, its, status = curve(path, case, "control")
    case["peak"] = float(F.max())
    # smoke: the secant matrix only (the tangent runs diverge on 4 long steps: 100 iterations)
    for matrix in ("tangent", "secant") if steps is None else ("secant",):
        for method, scene in variants(case, case["peak"]).items():
            path = OUT / f"control_{name}_{method}_{matrix}.h5"
            seconds = _run(with_matrix(shortened(scene, steps), matrix), path)
            d, F, its, status = curve(path, case, method)
            rows.append(_row(name, method, seconds, d, F, its, status) | {"matrix": matrix})
    return rows


def _run(text: str, path: Path) -> float:
    src = path.with_suffix(".toml")
    src.write_text(text)
    model = build_model(load_scene(src), MPI.COMM_WORLD)
    t0 = time.perf_counter()
    try:
        run(MPI.COMM_WORLD, model, str(path), {}, log=lambda *a: None)
    except SolverError:
        pass
    return time.perf_counter() - t0


def _row(case, method, seconds, d, F, its, status) -> dict:
    peak = int(np.argmax(F)) if len(F) else -1
    past_peak = bool(len(F) and peak < len(F) - 1 and F[-1] < 0.99 * F[peak])
    snap_back = bool(len(d) > 1 and np.any(np.diff(d[peak:]) < -1e-12)) if peak >= 0 else False
    return dict(case=case, method=method, status=str(status), steps=int(len(F)),
                iterations=int(its.sum()), per_step=float(its.mean()) if len(its) else 0.0,
                seconds=seconds, peak_load=float(F.max()) if len(F) else 0.0,
                past_peak=past_peak, snap_back_traced=snap_back,
                last_delta=float(d[-1]) if len(d) else 0.0, last_load=float(F[-1]) if len(F) else 0.0,
                curve=[d.tolist(), F.tolist()])


def table(rows: list[dict]) -> str:
    head = ("| case | method | matrix | status | steps | global iterations | per step | time (s) | "
            "peak load | past the peak | snap-back traced |\n|---|---|---|---|---|---|---|---|---|---|---|\n")
    lines = [f"| {r['case']} | {r['method']} | {r['matrix']} | {r['status'][:60]} | {r['steps']} | {r['iterations']} | "
             f"{r['per_step']:.2f} | {r['seconds']:.2f} | {r['peak_load']:.4g} | "
             f"{'yes' if r['past_peak'] else 'no'} | {'yes' if r['snap_back_traced'] else 'no'} |"
             for r in rows]
    return head + "\n".join(lines) + "\n"


def picture(rows: list[dict], path: Path) -> None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib missing (apt-get install python3-matplotlib): no picture")
        return
    cases = sorted({r["case"] for r in rows})
    fig, axes = plt.subplots(1, len(cases), figsize=(6 * len(cases), 4.5))
    for ax, case in zip(np.atleast_1d(axes), cases):
        for r in rows:
            if r["case"] == case and r["curve"][0]:
                style = "-o" if r["method"] == "control" else "--x"
                ax.plot(r["curve"][0], r["curve"][1], style, ms=3,
                        label=f"{r['method']}, {r['matrix']} ({r['status'].split(':')[0]})")
        ax.set_title(case)
        ax.set_xlabel("end displacement")
        ax.set_ylabel("load")
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    bh.add_smoke(ap)
    args = ap.parse_args(argv)
    OUT.mkdir(exist_ok=True)
    rows = []
    cases = {"localization_bar": CASES["localization_bar"]} if args.smoke else CASES
    for name, case in cases.items():
        rows += run_case(name, dict(case), SMOKE_STEPS if args.smoke else None)
    text = table(rows)
    print(text)
    bh.write_json(OUT / "control.json", rows)
    md = bh.publish("bench_control.md", "# Control benchmark\n\n" + text)
    picture(rows, md.with_suffix(".png"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
