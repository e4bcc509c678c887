"""A quarter of a thick ring a ≤ r ≤ b of six-node triangles whose nodes, mid-edge ones
included, lie on the exact circles (curved second-order cells, as Gmsh writes them with
``Mesh.ElementOrder = 2``), in one Gmsh 2.2 file. Writes configs/thick_cylinder_p2.msh when run
without arguments:

    .venv/bin/python scripts/make_thick_cylinder_mesh.py [OUT.msh]

Cells "ring"; facet groups "inner" (r = a) and "outer" (r = b); a = 1, b = 2, 8 × 16 cells
(radial × angular), each quad of the (r, θ) grid cut in two triangles.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from mesh_files import write_bodies
from parsolve.mesh.generators import rectangle


def quarter_ring(path, a: float = 1.0, b: float = 2.0, nr: int = 8, nt: int = 16) -> None:
    flat = rectangle(b - a, np.pi / 2, nr, nt, cell="triangle6", origin=(a, 0.0))
    r, theta = flat.points[:, 0], flat.points[:, 1]
    points = np.column_stack([r * np.cos(theta), r * np.sin(theta)])
    write_bodies(path, points, [("ring", flat.cells)],
                 [("inner", flat.facet_groups["left"]), ("outer", flat.facet_groups["right"])],
                 "triangle6", "line3")


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else \
        Path(__file__).resolve().parents[1] / "configs" / "thick_cylinder_p2.msh"
    quarter_ring(out)
    print(out)
