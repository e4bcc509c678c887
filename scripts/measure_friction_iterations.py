"""Global (Newton) iterations per step of the contact scenes whose counts issue 17 targets.

  3d     configs/contact_friction_3d.toml refined 1×, 4×, 16× in cells (nx, ny × 1, 2, 4)
  hertz  configs/contact_hertz_cylinder.toml at 160, 320, 640 surface cells (nx, ny × 1, 2, 4):
         a contact zone forming from nothing in one step

    .venv/bin/python scripts/measure_friction_iterations.py [3d] [hertz] [--max 4] [--save DIR]

Prints the iterations of every step, and the worst step, per refinement (iteration counts,
not timings; the wall time of each run is printed for information). ``--save DIR`` keeps the
result files (to compare final fields between branches, ``--compare A B``).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]


def scene_text(name: str, factor: int) -> str:
    text = (ROOT / "configs" / name).read_text()
    text = text.replace("[output]\nfile = ", "# file = ")
    if name == "contact_friction_3d.toml":
        return text.replace("nx = 6\nny = 6", f"nx = {6 * factor}\nny = {6 * factor}")
    return text.replace("nx = 160\nny = 40", f"nx = {160 * factor}\nny = {40 * factor}")


def run_one(text: str, out: Path) -> tuple[np.ndarray, float]:
    from parsolve.driver import run
    from parsolve.model import build_model
    from parsolve.scene import load_scene

    src = out.with_suffix(".toml")
    src.write_text(text)
    comm = MPI.COMM_WORLD
    t0 = time.perf_counter()
    run(comm, build_model(load_scene(src), comm), str(out), {}, None, log=lambda *a: None)
    with h5py.File(out, "r") as f:
        its = f["steps/iterations"][()]
    return its, time.perf_counter() - t0


CASES = {"3d": ("contact_friction_3d.toml", "cells ×{c}"),
         "hertz": ("contact_hertz_cylinder.toml", "{s} surface cells")}


def compare(a: Path, b: Path) -> None:
    """Largest relative difference of the final step's fields between two saved result sets."""
    for fa in sorted(a.glob("*.h5")):
        fb = b / fa.name
        with h5py.File(fa, "r") as x, h5py.File(fb, "r") as y:
            worst = 0.0
            for name in x["fields"]:
                u, v = x["fields"][name][-1], y["fields"][name][-1]
                scale = max(float(np.abs(u).max()), 1e-300)
                worst = max(worst, float(np.abs(u - v).max()) / scale)
            print(f"{fa.name}: largest relative difference of the final fields {worst:.2e}")


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("cases", nargs="*", default=["3d", "hertz"])
    ap.add_argument("--max", type=int, default=4, help="largest refinement factor (1, 2, 4)")
    ap.add_argument("--save", type=Path, default=None)
    ap.add_argument("--compare", type=Path, nargs=2, default=None)
    args = ap.parse_args()
    if args.compare:
        compare(*args.compare)
        return 0
    folder = args.save or Path(tempfile.mkdtemp())
    folder.mkdir(parents=True, exist_ok=True)
    for case in args.cases:
        name, label = CASES[case]
        for factor in (f for f in (1, 2, 4) if f <= args.max):
            its, wall = run_one(scene_text(name, factor), folder / f"{case}_{factor}.h5")
            what = label.format(c=factor * factor, s=160 * factor)
            print(f"{case:5s} {what:18s} iterations per step {its.tolist()}  worst {its.max()}"
                  f"  ({wall:.1f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
