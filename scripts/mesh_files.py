"""Gmsh 2.2 mesh files of several bodies, for the scripts that write the shipped meshes
(``make_ironing_2d_mesh.py``, ``make_ironing_3d_mesh.py``)."""

from __future__ import annotations

import numpy as np


def write_bodies(path, points: np.ndarray, bodies: list, facets: list, cell_type: str,
                 facet_type: str) -> None:
    """Write ``points`` (n, dim), the cells of each body (``bodies``: (name, cells), physical
    tags 1, 2, ...) and the facet groups (``facets``: (name, facets), tags 10, 11, ...) as a
    Gmsh 2.2 ASCII file whose physical names are the bodies' and groups' names."""
    import meshio

    dim = points.shape[1]
    blocks = [(cell_type, c) for _, c in bodies] + [(facet_type, f) for _, f in facets]
    tags = [1 + i for i in range(len(bodies))] + [10 + i for i in range(len(facets))]
    phys = [np.full(len(b[1]), tag) for b, tag in zip(blocks, tags)]
    field = {name: np.array([1 + i, dim]) for i, (name, _) in enumerate(bodies)}
    field.update({name: np.array([10 + i, dim - 1]) for i, (name, _) in enumerate(facets)})
    if dim == 2:   # Gmsh points have three coordinates
        points = np.column_stack([points, np.zeros(len(points))])
    mesh = meshio.Mesh(points, blocks, cell_data={"gmsh:physical": phys,
                                                  "gmsh:geometrical": phys},
                       field_data=field)
    meshio.write(str(path), mesh, file_format="gmsh22", binary=False)
