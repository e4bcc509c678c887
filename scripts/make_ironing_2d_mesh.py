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

from parsolve.mesh.generators import rectangle

# configs/contact_ironing_2d.toml: the slab (lx, ly, nx, ny) and the die (the same, then x0)
SLAB, DIE = (4.0, 1.0, 32, 8), (0.5, 0.25, 4, 2, 0.5)


def base_and_die(path, base_box=SLAB, die_box=DIE) -> None:
    """Write the base-and-die mesh (``base_box`` = (lx, ly, nx, ny), ``die_box`` the same and
    the die's left end x0) to ``path``."""
    import meshio

    lx, ly, nx, ny = base_box
    base = rectangle(lx, ly, nx, ny)
    dlx, dly, dnx, dny, x0 = die_box
    die = rectangle(dlx, dly, dnx, dny, origin=(x0, ly))
    off = base.num_points
    points = np.vstack([base.points, die.points])
    lines = [(f"base_{s}", base.facet_groups[s]) for s in ("top", "bottom", "left", "right")]
    lines += [(f"die_{s}", die.facet_groups[s] + off) for s in ("top", "bottom")]
    blocks = [("quad", base.cells), ("quad", die.cells + off)] + [("line", f) for _, f in lines]
    tags = [1, 2] + [10 + i for i in range(len(lines))]
    phys = [np.full(len(b[1]), tag) for b, tag in zip(blocks, tags)]
    field = {"base": np.array([1, 2]), "die": np.array([2, 2])}
    field.update({name: np.array([10 + i, 1]) for i, (name, _) in enumerate(lines)})
    mesh = meshio.Mesh(np.column_stack([points, np.zeros(len(points))]), blocks,
                       cell_data={"gmsh:physical": phys, "gmsh:geometrical": phys},
                       field_data=field)
    meshio.write(str(path), mesh, file_format="gmsh22", binary=False)


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else \
        Path(__file__).resolve().parents[1] / "configs" / "contact_ironing_2d.msh"
    base_and_die(out)
    print(out)
