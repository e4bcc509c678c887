"""Facet topology of a single-cell-type mesh: local facets, boundary facets, orientation.

Conventions (meshio/VTK node ordering, see ``mesh.CELL_INFO``):

* ``FACETS[cell_type]`` lists, for each local facet, the local node indices in the node
  order of the facet cell type (line: v0, v1; line3: v0, v1, mid; triangle; triangle6:
  v0, v1, v2, m01, m12, m20; quad), oriented so that the right-hand-rule normal points
  out of a positively oriented cell. In 2D the outward normal of the facet (a, b) is
  (dy, -dx); in 3D it is (b - a) x (c - a).
* A cell is positively oriented when its Jacobian determinant is positive
  (counter-clockwise polygons in 2D).
"""

from __future__ import annotations

import numpy as np

from parsolve.errors import InputError
from parsolve.fem.elements import element, quadrature
from parsolve.mesh.mesh import Mesh

FACETS: dict[str, list[tuple[int, ...]]] = {
    "triangle": [(0, 1), (1, 2), (2, 0)],
    "triangle6": [(0, 1, 3), (1, 2, 4), (2, 0, 5)],
    "quad": [(0, 1), (1, 2), (2, 3), (3, 0)],
    "quad9": [(0, 1, 4), (1, 2, 5), (2, 3, 6), (3, 0, 7)],
    "quad8": [(0, 1, 4), (1, 2, 5), (2, 3, 6), (3, 0, 7)],
    "tetra": [(0, 2, 1), (0, 1, 3), (1, 2, 3), (0, 3, 2)],
    "tetra10": [
        (0, 2, 1, 6, 5, 4),
        (0, 1, 3, 4, 8, 7),
        (1, 2, 3, 5, 9, 8),
        (0, 3, 2, 7, 9, 6),
    ],
    "hexahedron": [
        (0, 3, 2, 1),  # z = 0
        (4, 5, 6, 7),  # z = 1
        (0, 1, 5, 4),  # y = 0
        (1, 2, 6, 5),  # x = 1
        (2, 3, 7, 6),  # y = 1
        (3, 0, 4, 7),  # x = 0
    ],
    # the hexahedron's faces with their edges' midside nodes (quad8 order), hexahedron27's
    # with their centres too (quad9)
    "hexahedron20": [
        (0, 3, 2, 1, 11, 10, 9, 8),
        (4, 5, 6, 7, 12, 13, 14, 15),
        (0, 1, 5, 4, 8, 17, 12, 16),
        (1, 2, 6, 5, 9, 18, 13, 17),
        (2, 3, 7, 6, 10, 19, 14, 18),
        (3, 0, 4, 7, 11, 16, 15, 19),
    ],
    "hexahedron27": [
        (0, 3, 2, 1, 11, 10, 9, 8, 24),
        (4, 5, 6, 7, 12, 13, 14, 15, 25),
        (0, 1, 5, 4, 8, 17, 12, 16, 22),
        (1, 2, 6, 5, 9, 18, 13, 17, 21),
        (2, 3, 7, 6, 10, 19, 14, 18, 23),
        (3, 0, 4, 7, 11, 16, 15, 19, 20),
    ],
}

# Number of corner (vertex) nodes of each facet/cell type; corners always come first in
# meshio ordering, so the corners alone identify a facet.
NUM_VERTICES: dict[str, int] = {
    "line": 2,
    "line3": 2,
    "triangle": 3,
    "triangle6": 3,
    "quad": 4,
    "quad9": 4,
    "quad8": 4,
    "tetra": 4,
    "tetra10": 4,
    "hexahedron": 8,
    "hexahedron20": 8,
    "hexahedron27": 8,
}

# Node permutation that reverses a cell's orientation (keeps meshio ordering valid).
FLIP: dict[str, list[int]] = {
    "triangle": [0, 2, 1],
    "triangle6": [0, 2, 1, 5, 4, 3],
    "quad": [0, 3, 2, 1],
    "quad9": [0, 3, 2, 1, 7, 6, 5, 4, 8],
    "quad8": [0, 3, 2, 1, 7, 6, 5, 4],
    "tetra": [0, 2, 1, 3],
    "tetra10": [0, 2, 1, 3, 6, 5, 4, 7, 9, 8],
    "hexahedron": [0, 3, 2, 1, 4, 7, 6, 5],
    # (ξ, η swapped: the edges and faces follow their corners)
    "hexahedron20": [0, 3, 2, 1, 4, 7, 6, 5, 11, 10, 9, 8, 15, 14, 13, 12, 16, 19, 18, 17],
    "hexahedron27": [0, 3, 2, 1, 4, 7, 6, 5, 11, 10, 9, 8, 15, 14, 13, 12, 16, 19, 18, 17,
                     22, 23, 20, 21, 24, 25, 26],
}


# --------------------------------------------------------------------------------------
# Boundary facets
# --------------------------------------------------------------------------------------


def _row_groups(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group identical rows of a non-negative integer array: (group id of each row, group
    counts); groups are numbered in the rows' lexicographic order.

    The leading columns are packed into one int64 while their ids fit, the others into a
    second one when they do not: a sort of one key (or a lexsort of two) is much faster than
    a lexsort of every column or ``np.unique(axis=0)``. Only the keys' order matters, not the
    order of equal rows, so the sort need not be stable."""
    order, gid_sorted, counts = sorted_row_groups(keys)
    inv = np.empty(keys.shape[0], dtype=np.int64)
    inv[order] = gid_sorted
    return inv, counts


def sorted_row_groups(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``_row_groups`` in sorted order: (the order that sorts the rows, the group of each
    sorted row, the group counts): the rows of a group are consecutive in the order."""
    n = keys.shape[0]
    if n == 0:
        return (np.zeros(0, dtype=np.int64),) * 3
    base = int(keys.max()) + 1
    width = keys.shape[1]
    fit = 1                                      # columns per int64
    while fit < width and base ** (fit + 1) < 2**62:
        fit += 1
    packs = [keys[:, 0] if width == 1 else   # (one column: itself, not a copy)
             _pack(keys, range(start, min(start + fit, width)), base)
             for start in range(0, width, fit)]
    order = np.argsort(packs[0]) if len(packs) == 1 else np.lexsort(packs[::-1])
    new = np.empty(n, dtype=bool)
    new[0] = True
    new[1:] = False
    for packed in packs:
        sp = packed[order]
        new[1:] |= sp[1:] != sp[:-1]
        del sp
    del packs
    gid_sorted = np.cumsum(new) - 1
    del new
    return order, gid_sorted, np.bincount(gid_sorted)


def _pack(keys: np.ndarray, columns, base: int) -> np.ndarray:
    """The given columns of each row as one int64 in base ``base`` (the caller made it fit)."""
    packed = np.zeros(keys.shape[0], dtype=np.int64)
    for col in columns:
        packed *= base
        packed += keys[:, col]
    return packed


def _all_facets(cells: np.ndarray, cell_type: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every local facet of every cell, facet-major: (nodes, owner cell, local index)."""
    local = FACETS[cell_type]
    ncells = cells.shape[0]
    nodes = np.concatenate([cells[:, list(f)] for f in local], axis=0)
    owner = np.tile(np.arange(ncells, dtype=np.int64), len(local))
    lidx = np.repeat(np.arange(len(local), dtype=np.int64), ncells)
    return nodes, owner, lidx


def _sorted_vertex_keys(facet_nodes: np.ndarray, facet_type: str) -> np.ndarray:
    """Corner node ids of each facet in increasing order (identifies the facet)."""
    nv = NUM_VERTICES[facet_type]
    # a sorting network of min/max over whole columns: several times faster than a row sort
    # (numpy sorts each short row on its own)
    cols = [facet_nodes[:, k] for k in range(nv)]
    for i, j in _NETWORK[nv]:
        cols[i], cols[j] = np.minimum(cols[i], cols[j]), np.maximum(cols[i], cols[j])
    return np.column_stack(cols) if facet_nodes.shape[0] else np.sort(facet_nodes[:, :nv], axis=1)


# compare-exchange steps that sort 2, 3 and 4 values
_NETWORK = {2: [(0, 1)], 3: [(0, 1), (1, 2), (0, 1)],
            4: [(0, 1), (2, 3), (0, 2), (1, 3), (1, 2)]}


def _sort_by_owner(nodes, owner, lidx):
    # deterministic output: ordered by (owner cell, local facet)
    order = np.lexsort((lidx, owner))
    return nodes[order], owner[order], lidx[order]


def _single_facets(nodes, owner, lidx, facet_type):
    """Keep the facets whose vertex set appears exactly once in ``nodes``."""
    inv, counts = _row_groups(_sorted_vertex_keys(nodes, facet_type))
    keep = counts[inv] == 1
    return _sort_by_owner(nodes[keep], owner[keep], lidx[keep])


def boundary_facets(mesh: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Facets that belong to exactly one cell.

    Returns (facet_nodes (nf, nodes_per_facet), owner cell (nf,), local facet index
    (nf,)), with facet nodes in the outward orientation of ``FACETS``.
    """
    nodes, owner, lidx = _all_facets(mesh.cells, mesh.cell_type)
    return _single_facets(nodes, owner, lidx, mesh.facet_type)


def facets_from_nodes(
    mesh: Mesh, node_mask: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boundary facets all of whose nodes are selected by ``node_mask`` (bool over points).

    Same return triple as :func:`boundary_facets`.
    """
    node_mask = np.asarray(node_mask, dtype=bool)
    if node_mask.shape != (mesh.num_points,):
        raise ValueError(f"node_mask must have shape ({mesh.num_points},)")
    # An interior facet with all its nodes selected is seen from both its cells, so it
    # also appears twice among the candidates: counting within the candidates is enough
    # (and much cheaper than the full boundary when few nodes are selected).
    cells = mesh.cells
    parts = []
    for li, f in enumerate(FACETS[mesh.cell_type]):
        owner = np.flatnonzero(node_mask[cells[:, list(f)]].all(axis=1))
        parts.append((cells[owner][:, list(f)], owner, np.full(owner.size, li, dtype=np.int64)))
    nodes, owner, lidx = (np.concatenate(p) for p in zip(*parts))
    return _single_facets(nodes, owner, lidx, mesh.facet_type)


def _candidate_boundary(mesh: Mesh, corners: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The boundary facets (``boundary_facets``' triple and order) whose corners are all among
    ``corners``' node ids: the only ones a facet of ``corners`` can be. An interior facet
    among them is seen from both its cells, so counting within them is enough (as
    ``facets_from_nodes``) and far cheaper than the whole boundary for a side of the mesh."""
    mask = np.zeros(mesh.num_points, dtype=bool)
    valid = (corners >= 0) & (corners < mesh.num_points)   # others match nothing
    mask[corners[valid]] = True
    nv = corners.shape[1]
    cells = mesh.cells
    parts = []
    for li, f in enumerate(FACETS[mesh.cell_type]):
        owner = np.flatnonzero(mask[cells[:, list(f[:nv])]].all(axis=1))
        parts.append((cells[owner][:, list(f)], owner, np.full(owner.size, li, dtype=np.int64)))
    nodes, owner, lidx = (np.concatenate(p) for p in zip(*parts))
    return _single_facets(nodes, owner, lidx, mesh.facet_type)


def match_facets(
    mesh: Mesh, facet_nodes: np.ndarray, source: str | None = None, key: str | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Find the owning boundary cell of given facets (any node order).

    ``facet_nodes`` is (n, k) with the facet's corner nodes in its first columns (meshio
    ordering of a linear or quadratic facet). Returns (owner cell, local facet index,
    facet nodes in the outward orientation of ``FACETS``). Raises InputError when a
    facet is not a boundary facet of the mesh.
    """
    facet_nodes = np.asarray(facet_nodes, dtype=np.int64)
    nv = NUM_VERTICES[mesh.facet_type]
    if facet_nodes.ndim != 2 or facet_nodes.shape[1] < nv:
        raise InputError(
            f"facets must have at least {nv} nodes ({mesh.facet_type} facets)", source, key
        )
    bnodes, bowner, blidx = _candidate_boundary(mesh, facet_nodes[:, :nv])
    nb = bnodes.shape[0]
    keys = np.concatenate(
        [
            _sorted_vertex_keys(bnodes, mesh.facet_type),
            _sorted_vertex_keys(facet_nodes, mesh.facet_type),
        ]
    )
    inv, counts = _row_groups(keys)
    pos = np.full(counts.shape[0], -1, dtype=np.int64)
    pos[inv[:nb]] = np.arange(nb)
    found = pos[inv[nb:]]
    if np.any(found < 0):
        bad = facet_nodes[np.argmax(found < 0), :nv].tolist()
        raise InputError(
            f"{np.count_nonzero(found < 0)} facet(s) are not boundary facets of the mesh "
            f"(first: nodes {bad})",
            source,
            key,
        )
    return bowner[found], blidx[found], bnodes[found]


# --------------------------------------------------------------------------------------
# Geometry: Jacobians, signed measures, orientation
# --------------------------------------------------------------------------------------


def jacobian_dets(
    points: np.ndarray, cell_type: str, cells: np.ndarray, xi: np.ndarray | None = None
) -> np.ndarray:
    """Jacobian determinants (ncells, nq) at reference points (default: quadrature points)."""
    if xi is None:
        xi = quadrature(cell_type, 4)[0]
    g = element(cell_type).grad_shape(xi)
    jac = np.einsum("cia,qib->cqab", points[cells], g, optimize=True)
    return small_dets(jac)


def small_dets(m: np.ndarray) -> np.ndarray:
    """Determinants of (..., d, d) matrices, d = 1, 2, 3, by their formula: numpy's ``det``
    calls LAPACK once per matrix (14 s for 1M tetrahedra × 14 points, against under 1 s)."""
    d = m.shape[-1]
    if d == 1:
        return m[..., 0, 0].copy()
    if d == 2:
        return m[..., 0, 0] * m[..., 1, 1] - m[..., 0, 1] * m[..., 1, 0]
    if d != 3:
        return np.linalg.det(m)
    a, b, c = m[..., 0, :], m[..., 1, :], m[..., 2, :]
    return (a[..., 0] * (b[..., 1] * c[..., 2] - b[..., 2] * c[..., 1])
            - a[..., 1] * (b[..., 0] * c[..., 2] - b[..., 2] * c[..., 0])
            + a[..., 2] * (b[..., 0] * c[..., 1] - b[..., 1] * c[..., 0]))


def cell_measures(mesh: Mesh) -> np.ndarray:
    """Signed area/volume of every cell (exact for the supported geometries)."""
    xi, w = quadrature(mesh.cell_type, 4)  # exact for the geometries generated here
    return jacobian_dets(mesh.points, mesh.cell_type, mesh.cells, xi) @ w


ORIENT_BLOCK = 4096    # cells per block of orient_cells' Jacobians (~8 MB for tetra10: a rank's
#                        fixed transient, whatever its share of the mesh)


def orient_cells(
    points: np.ndarray, cell_type: str, cells: np.ndarray
) -> tuple[np.ndarray, int]:
    """Reorder the nodes of negatively oriented cells; returns (cells, number flipped).
    The Jacobians are evaluated by blocks of ``ORIENT_BLOCK`` cells (all at once they were a
    (cells, points, dim, dim) array: 1.5 GB at 1.3M tetrahedra)."""
    xi, w = quadrature(cell_type, 3)
    neg = np.zeros(cells.shape[0], dtype=bool)
    for start in range(0, cells.shape[0], ORIENT_BLOCK):
        stop = start + ORIENT_BLOCK
        neg[start:stop] = jacobian_dets(points, cell_type, cells[start:stop], xi) @ w < 0
    n = int(np.count_nonzero(neg))
    if n:
        cells = cells.copy()
        cells[neg] = cells[neg][:, FLIP[cell_type]]
    return cells, n
