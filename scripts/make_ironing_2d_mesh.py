"""Two rectangles in one Gmsh 2.2 mesh file: a base and a die resting on it (2D ironing, 2D
finite-sliding tests, bench_friction's refined ironing). Writes configs/contact_ironing_2d.msh
when run without arguments:

    .venv/bin/python scripts/make_ironing_2d_mesh.py [OUT.msh]

Cells "base" ([0, lx] × [0, ly], nx × ny quads) and "die" (its lx, ly, nx, ny and left end x0,
on top of the base); facet groups base_top/bottom/left/right and die_top/bottom; the nodes of
the two bodies are distinct (the die's bottom lies on the base's top, not tied to it).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from mesh_files import write_bodies
from parsolve.mesh.generators import rectangle

# configs/contact_ironing_2d.toml: the slab (lx, ly, nx, ny) and the die (the same, then x0)
SLAB, DIE = (4.0, 1.0, 32, 8), (0.5, 0.25, 4, 2, 0.5)


def base_and_die(path, base_box=SLAB, die_box=DIE) -> None:
    """Write the base-and-die mesh (``base_box`` = (lx, ly, nx, ny), ``die_box`` the same and
    the die's left end x0) to ``path``."""
    lx, ly, nx, ny = base_box
    base = rectangle(lx, ly, nx, ny)
    dlx, dly, dnx, dny, x0 = die_box
    die = rectangle(dlx, dly, dnx, dny, origin=(x0, ly))
    off = base.num_points
    points = np.vstack([base.points, die.points])
    lines = [(f"base_{s}", base.facet_groups[s]) for s in ("top", "bottom", "left", "right")]
    lines += [(f"die_{s}", die.facet_groups[s] + off) for s in ("top", "bottom")]
    write_bodies(path, points, [("base", base.cells), ("die", die.cells + off)], lines,
                 "quad", "line")


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else \
        Path(__file__).resolve().parents[1] / "configs" / "contact_ironing_2d.msh"
    base_and_die(out)
    print(out)
