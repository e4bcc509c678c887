"""Benchmark: an absent effect costs nothing. The same elastic plate (Kirsch, P2) run as a
linear scene (one assembly, one factorization, one back-substitution per step), then with an
effect that changes nothing in the answer but calls for the nonlinear machinery: a unilateral
relation that never becomes active, and a Mazars material loaded below its threshold. The
answers agree; the times show what each machinery costs when a scene asks for it, and that a
scene that does not ask pays nothing.

    .venv/bin/python scripts/bench_effects.py        → table, bench_results/effects.json,
                                                       scripts/results/bench_effects.md
    .venv/bin/python scripts/bench_effects.py --smoke  (the coarsest plate; files in a temp folder)
"""

from __future__ import annotations

import argparse
import time

import h5py
import numpy as np
from mpi4py import MPI

import bench_harness as bh
from parsolve.driver import run
from parsolve.model import build_model
from parsolve.scene import load_scene

ROOT = bh.ROOT
OUT = bh.SCRATCH              # bench_results/ (a temporary folder in smoke mode)
BASE = (ROOT / "configs" / "kirsch.toml").read_text().replace("[output]\nfile = \"kirsch.h5\"\n", "") \
    + "\n[steps]\ncount = 5\n"
VARIANTS = {
    "linear (as shipped)": BASE,
    "+ unilateral relation never active": BASE + """
[[relations]]
name = "far_gap"            # ux of the hole edge >= -1: never reached
type = "mean"
region = "hole"
component = "x"
value = -1.0
sense = ">="
""",
    "+ Mazars below its threshold": BASE.replace(
        "[[materials]]\nE = 210e3\nnu = 0.3",
        '[[materials]]\nmodel = "mazars"\nE = 210e3\nnu = 0.3\neps_d0 = 1.0\nAt = 1.0\nBt = 1e4\n'
        "Ac = 1.2\nBc = 1500.0"),
}


def smallest(text: str) -> str:
    """The Kirsch plate at its coarsest (smoke runs)."""
    return text.replace("n_radial = 48", "n_radial = 6").replace("n_angular = 64", "n_angular = 8")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    bh.add_smoke(ap)
    args = ap.parse_args(argv)
    OUT.mkdir(exist_ok=True)
    rows, reference = [], None
    for name, text in VARIANTS.items():
        text = smallest(text) if args.smoke else text
        src = OUT / f"effects_{len(rows)}.toml"
        src.write_text(text)
        model = build_model(load_scene(src), MPI.COMM_WORLD)
        out = src.with_suffix(".h5")
        t0 = time.perf_counter()
        run(MPI.COMM_WORLD, model, str(out), {}, log=lambda *a: None)
        seconds = time.perf_counter() - t0
        with h5py.File(out) as f:
            u = f["fields/displacement"][()]
            its = f["steps/iterations"][()]
        reference = u if reference is None else reference
        rows.append(dict(variant=name, effects=", ".join(model.scene.effects), seconds=seconds,
                         iterations=int(its.sum()), dofs=int(u.shape[1] * u.shape[2]),
                         max_diff=float(np.abs(u - reference).max() / np.abs(reference).max())))
    head = ("| scene | effects built | DOFs | time for 5 steps (s) | global iterations | "
            "difference in u |\n|---|---|---|---|---|---|\n")
    table = head + "\n".join(f"| {r['variant']} | {r['effects']} | {r['dofs']} | {r['seconds']:.2f} | "
                             f"{r['iterations']} | {r['max_diff']:.1e} |" for r in rows) + "\n"
    print(table)
    bh.write_json(OUT / "effects.json", rows)
    bh.publish("bench_effects.md", "# Effects benchmark\n\n" + table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
