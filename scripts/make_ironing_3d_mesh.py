"""Two boxes in one Gmsh 2.2 mesh file: a slab and a die resting on it (3D ironing, 3D sliding
tests). Writes configs/contact_ironing_3d.msh when run without arguments:

    .venv/bin/python scripts/make_ironing_3d_mesh.py [OUT.msh]

Cells "base" (the slab) and "die"; facet groups base_<side> and die_<side> for the sides
xmin, xmax, ymin, ymax, zmin, zmax of each box (parsolve.mesh.generators.box's names); the
nodes of the two boxes are distinct (the die's bottom lies on the slab's top, not tied to it).
``warp`` maps every point (both boxes: e.g. onto a cylinder) before writing.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from mesh_files import write_bodies
from parsolve.mesh.generators import box

SIDES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")
# configs/contact_ironing_3d.toml: the slab (lx, ly, lz, nx, ny, nz) and the die (the same,
# then its origin), the die centred across the slab, its nodes off the slab's lines (no
# coincident points, no slave on an edge of the slab's faces at the start)
SLAB = (2.0, 0.5, 0.5, 16, 4, 2)
DIE = (0.25, 0.2, 0.125, 2, 3, 1, (0.3, 0.15, 0.5))


def two_boxes(path, base_box=SLAB, die_box=DIE, cell: str = "hexahedron", warp=None) -> None:
    """Write the slab-and-die mesh (``base_box`` = (lx, ly, lz, nx, ny, nz), ``die_box`` the
    same and its origin) to ``path``."""
    base = box(*base_box, cell=cell)
    die = box(*die_box[:6], cell=cell, origin=die_box[6])
    off = base.num_points
    points = np.vstack([base.points, die.points])
    points = points if warp is None else warp(points)
    faces = [(f"base_{s}", base.facet_groups[s]) for s in SIDES]
    faces += [(f"die_{s}", die.facet_groups[s] + off) for s in SIDES]
    facet_type = "quad" if cell == "hexahedron" else "triangle"
    write_bodies(path, points, [("base", base.cells), ("die", die.cells + off)], faces, cell,
                 facet_type)


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else \
        Path(__file__).resolve().parents[1] / "configs" / "contact_ironing_3d.msh"
    two_boxes(out)
    print(out)
