"""Cells by hand for the mesh tests."""

import numpy as np

from parsolve.fem.elements import element
from parsolve.mesh.mesh import Mesh


def reference_cell(cell_type: str) -> Mesh:
    """One cell on the reference element's own nodes (det J > 0 everywhere)."""
    nodes = np.array(element(cell_type).nodes, dtype=float)
    return Mesh(nodes.copy(), cell_type, np.arange(len(nodes))[None, :])
