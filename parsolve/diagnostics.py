"""What a singular system most likely means, said in the model's terms: a body (a connected
set of cells) that no relation holds, for a field whose operator has a kernel without one
(a displacement field: rigid-body motions; a steady scalar field: a constant)."""

from __future__ import annotations

import numpy as np


def bodies(cells: np.ndarray, npoints: int) -> np.ndarray:
    """Component label of every node (the smallest node id of its body); nodes of no cell keep
    their own id. Label propagation over the cells with pointer jumping, vectorised."""
    label = np.arange(npoints)
    while True:
        low = label[cells].min(axis=1)
        new = label.copy()
        np.minimum.at(new, cells, low[:, None])
        new = new[new]                     # pointer jumping: follow the labels' labels
        if np.array_equal(new, label):
            return label
        label = new


def unsupported(model) -> list[str]:
    """One sentence per (body, field) that no relation touches, for fields whose operator is
    singular without one (steady fields). Not on a distributed mesh: a rank's part is not a
    body (it would take the whole mesh's connectivity)."""
    if getattr(model, "distributed", False):
        return []
    mesh, fields = model.mesh, model.fields
    label = bodies(mesh.cells, mesh.num_points)
    used = np.unique(mesh.cells)
    names = np.unique(label[used])
    if model.transient:  # a capacity holds a scalar field; only displacements can float
        checked = [f for f in fields if f.name == "u"]
    else:
        checked = list(fields)
    held = np.zeros((mesh.num_points, fields.ncomp), dtype=bool)
    for r in model.relations:
        node, col = np.divmod(r.a_dofs, fields.ncomp)
        held[node, col] = True
    out = []
    for f in checked:
        cols = fields.columns(f.name)
        body_held = np.zeros(mesh.num_points, dtype=bool)
        np.logical_or.at(body_held, label, held[:, cols].any(axis=1))
        for b in names[~body_held[names]]:
            cells = np.flatnonzero(label[mesh.cells[:, 0]] == b)
            which = f"body of {cells.size} cells (cells {cells[0]}..{cells[-1]})" if names.size > 1 \
                else "the body"
            out.append(f"no relation holds field {f.name!r} on {which}")
    return out
