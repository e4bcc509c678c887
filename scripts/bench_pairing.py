"""Benchmark: contact pairing and relation rows as the contact surface grows.

Master surfaces are curved (2D: y = 0.1 sin(3x) with line / line3 facets; 3D: z = 0.1 sin(3x)
cos(2y) with quad / triangle6 facets), refined with the slave surface (one slave node per
master facet, 0.3 facet sizes above, shifted so that the meshes do not match). Times: pairing (bucket search +
vectorised Newton), and building the normal, tangential and frictional-dual rows. The time per
slave node should stay flat: the work is linear in the surface size.

    .venv/bin/python scripts/bench_pairing.py [--quick | --smoke]   → table, scripts/results/bench_pairing.md
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import bench_harness as bh
from parsolve.contact.pairing import pair_nodes
from parsolve.contact.rows import friction_dual, normal_rows, tangent_rows



def surface_2d(n: int, quadratic: bool):
    x = np.linspace(0.0, 2.0, (2 * n if quadratic else n) + 1)
    pts = np.column_stack([x, 0.1 * np.sin(3 * x)])
    if quadratic:  # line3: (v0, v1, mid)
        v = np.arange(0, 2 * n, 2)
        facets = np.column_stack([v + 2, v, v + 1])  # right to left: outward normal is +y
    else:
        v = np.arange(n)
        facets = np.column_stack([v + 1, v])
    xs = np.linspace(0.013, 1.987, n + 1)
    slave = np.column_stack([xs, 0.1 * np.sin(3 * xs) + 0.3 * 2.0 / n])  # gap 0.3 h
    return pts, facets, slave, ("line3" if quadratic else "line")


def surface_3d(n: int, quadratic: bool):
    m = 2 * n if quadratic else n
    g = np.linspace(0.0, 1.0, m + 1)
    X, Y = np.meshgrid(g, g, indexing="xy")
    pts = np.column_stack([X.ravel(), Y.ravel(), 0.1 * np.sin(3 * X.ravel()) * np.cos(2 * Y.ravel())])
    idx = lambda i, j: i + j * (m + 1)  # noqa: E731
    if quadratic:  # two triangle6 per 2x2 block of grid nodes, counter-clockwise from +z
        i, j = (a.ravel() for a in np.meshgrid(np.arange(0, m, 2), np.arange(0, m, 2)))
        t1 = np.column_stack([idx(i, j), idx(i + 2, j), idx(i + 2, j + 2),
                              idx(i + 1, j), idx(i + 2, j + 1), idx(i + 1, j + 1)])
        t2 = np.column_stack([idx(i, j), idx(i + 2, j + 2), idx(i, j + 2),
                              idx(i + 1, j + 1), idx(i + 1, j + 2), idx(i, j + 1)])
        facets, ftype = np.vstack([t1, t2]), "triangle6"
    else:
        i, j = (a.ravel() for a in np.meshgrid(np.arange(m), np.arange(m)))
        facets = np.column_stack([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)])
        ftype = "quad"
    s = np.linspace(0.007, 0.993, n + 1)
    SX, SY = np.meshgrid(s, s, indexing="xy")
    slave = np.column_stack([SX.ravel(), SY.ravel(),
                             0.1 * np.sin(3 * SX.ravel()) * np.cos(2 * SY.ravel()) + 0.3 / n])
    return pts, facets, slave, ftype


def run_case(make, n: int, quadratic: bool, repeat: int = 3):
    mpts, facets, slave, ftype = make(n, quadratic)
    pts = np.vstack([mpts, slave])
    slaves = np.arange(len(mpts), len(pts))
    best_pair = best_rows = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        p = pair_nodes(pts, slaves, facets, ftype)
        t1 = time.perf_counter()
        q = p.only_paired()
        dim = pts.shape[1]
        s = np.zeros((len(q), dim - 1))
        s[:, 0] = 1.0
        normal_rows(q), tangent_rows(q), friction_dual(q, 0.3, s)
        t2 = time.perf_counter()
        best_pair, best_rows = min(best_pair, t1 - t0), min(best_rows, t2 - t1)
    return len(slaves), len(facets), int(p.paired.sum()), best_pair, best_rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="two sizes; table printed only")
    bh.add_smoke(ap)
    args = ap.parse_args(argv)
    quick = args.quick or args.smoke
    sizes_2d = [1000, 4000, 16000, 64000] if not quick else [1000, 4000]
    sizes_3d = [32, 64, 128, 256] if not quick else [32, 64]
    if args.smoke:
        sizes_2d, sizes_3d = [1000], [16]
    lines = ["| surface | facets | slave nodes | master facets | paired | pairing (s) | "
             "rows (s) | pairing µs/node |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for label, make, sizes in (("2D", surface_2d, sizes_2d), ("3D", surface_3d, sizes_3d)):
        for quadratic in (False, True):
            for n in sizes:
                ns, nf, npd, tp, tr = run_case(make, n, quadratic)
                ftype = make(2, quadratic)[3]
                row = (f"| {label} | {ftype} | {ns} | {nf} | {npd} | {tp:.4f} | {tr:.4f} | "
                       f"{1e6 * tp / ns:.2f} |")
                print(row, flush=True)
                lines.append(row)
    text = ("# Contact pairing benchmark\n\n"
            "`scripts/bench_pairing.py`: best of 3, one process. Curved master surfaces, "
            "non-matching slave nodes 0.3 facet sizes above; default search radius (one facet extent), default tolerance. 'rows' = normal + tangential + frictional "
            "dual rows of the paired nodes.\n\n" + "\n".join(lines) + "\n")
    if not quick or args.smoke:   # smoke: into the harness's temporary folder
        print(f"written {bh.publish('bench_pairing.md', text)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
