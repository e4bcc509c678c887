"""Mesh validity: coordinates, cell shapes (Jacobians), cells folded over their neighbours;
unused and duplicate points are warnings (Gmsh writes the first often; the second is a crack).

``check_mesh`` raises InputError for invalid coordinates and returns the warnings for what is
legitimate but worth saying; the cells are checked by blocks of cells on every rank
(``mesh.blocks``, which uses the pieces here: ``jacobian_range_of``, ``raise_jacobians``,
``facet_direction``). Everything is vectorised over cells (in chunks, so that a million
quadratic tetrahedra stay within a few hundred MB).
"""

from __future__ import annotations

import numpy as np

from parsolve.errors import InputError
from parsolve.fem.elements import default_degree, element, quadrature
from parsolve.mesh.mesh import Mesh
from parsolve.mesh.topology import _row_groups

MAX_COORDINATE = 1e50      # beyond this, products of lengths overflow (see scene.MAX_MAGNITUDE)
RELATIVE_JACOBIAN = 1e-10  # det J below this times (cell size)^dim: collapsed
SHOW = 5                   # ids named in a message
# cells per batch of det J: its 9 terms (points × cells each) stay in cache, 15 times faster
# than batches of 100k cells, whose terms went through memory
JACOBIAN_CHUNK = 8192


def _ids(ids: np.ndarray) -> str:
    ids = np.asarray(ids)
    shown = ", ".join(str(int(i)) for i in ids[:SHOW])
    return shown + (f", ... ({ids.size} in all)" if ids.size > SHOW else "")


def check_mesh(mesh: Mesh, source: str | None, key: str | None) -> list[str]:
    """Raise InputError for invalid coordinates; return the warnings. The cells are checked
    by blocks (``mesh.blocks.check_cells``), in every run."""
    check_points(mesh, source, key)
    return unused_warning(mesh) + duplicate_warning(mesh)


def check_points(mesh: Mesh, source: str | None, key: str | None) -> None:
    pts = mesh.points
    finite = np.isfinite(pts).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise InputError(f"{bad.size} point(s) have non-finite coordinates (NaN or inf): "
                         f"points {_ids(bad)}", source, key)
    huge = np.abs(pts).max(axis=1) > MAX_COORDINATE
    if huge.any():
        bad = np.flatnonzero(huge)
        raise InputError(f"{bad.size} point(s) have absurd coordinates (beyond "
                         f"{MAX_COORDINATE:g}): points {_ids(bad)}", source, key)


def reference_points(cell_type: str) -> np.ndarray:
    """Where det J is checked: the quadrature points of the stiffness, and the nodes
    (a P2 cell can fold at a corner while its Gauss points look fine). One point suffices
    for P1 simplices, whose Jacobian is constant."""
    ref = element(cell_type)
    if cell_type in ("triangle", "tetra"):
        return ref.nodes[:1]
    return np.concatenate([quadrature(cell_type, default_degree(cell_type, "stiffness"))[0],
                           ref.nodes], axis=0)


def jacobian_range_of(coords: np.ndarray, cell_type: str, dim: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per cell given by its nodes' coordinates (ncells, nen, dim): (min det J, max det J)
    over ``reference_points``, and the cell size^dim."""
    n = coords.shape[0]
    xi = reference_points(cell_type)
    g = element(cell_type).grad_shape(xi)                           # (nq, nen, dim)
    nq, nen = g.shape[:2]
    grad = g.transpose(0, 2, 1).reshape(nq * dim, nen)              # rows (point, b)
    lo, hi, scale = np.empty(n), np.empty(n), np.empty(n)
    for start in range(0, n, JACOBIAN_CHUNK):                       # batches, not cells
        stop = min(start + JACOBIAN_CHUNK, n)
        x = coords[start:stop]                                      # (nc, nen, dim)
        # cell-last (a, node, cell): J[a, point, b, cell] = sum over nodes of x_a dN/dxi_b,
        # one matrix product per coordinate, every term of det J a contiguous row per point
        xt = np.ascontiguousarray(x.transpose(2, 1, 0))
        det = _det((grad @ xt).reshape(dim, nq, dim, stop - start))  # (nq, nc)
        det.min(axis=0, out=lo[start:stop])
        det.max(axis=0, out=hi[start:stop])
        scale[start:stop] = (xt.max(axis=1) - xt.min(axis=1)).max(axis=0) ** dim
    return lo, hi, scale


def _det(j: np.ndarray) -> np.ndarray:
    """det of J (a, nq, b, nc) over (a, b), written out: LAPACK per 3 × 3 is 50 times slower."""
    if j.shape[0] == 2:
        return j[0, :, 0] * j[1, :, 1] - j[0, :, 1] * j[1, :, 0]
    c = [[j[a, :, b] for b in range(3)] for a in range(3)]
    return (c[0][0] * (c[1][1] * c[2][2] - c[1][2] * c[2][1])
            - c[0][1] * (c[1][0] * c[2][2] - c[1][2] * c[2][0])
            + c[0][2] * (c[1][0] * c[2][1] - c[1][1] * c[2][0]))


def raise_jacobians(ids: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: np.ndarray,
                    cell_type: str, source: str | None, key: str | None) -> None:
    """The InputError for the invalid cells ``ids`` (increasing) with their det J range."""
    kind = (("inverted" if hi[0] < -tol[0] else "collapsed (zero area/volume)") if hi[0] <= tol[0]
            else "folded or bow-tie (det J changes sign)" if lo[0] < -tol[0]
            else "degenerate (det J vanishes at a point)")
    raise InputError(f"{ids.size} invalid {cell_type} cell(s): cells {_ids(ids)}; cell "
                     f"{ids[0]} is {kind} (det J from {lo[0]:.3g} to {hi[0]:.3g})",
                     source, key)


def facet_direction(nodes: np.ndarray) -> np.ndarray:
    """Orientation of each facet's corner cycle: True when, starting at its smallest node,
    it goes on to the smaller of its two neighbours (edges: a < b)."""
    n = nodes.shape[1]
    if n == 2:
        return nodes[:, 0] < nodes[:, 1]
    # column by column (numpy's argmin over short rows goes row by row): the smallest node's
    # two neighbours in the cycle, the first smallest as argmin's
    cols = [nodes[:, k] for k in range(n)]
    low, after, before = cols[0], cols[1 % n], cols[n - 1]
    for k in range(1, n):
        less = cols[k] < low
        low = np.where(less, cols[k], low)
        after = np.where(less, cols[(k + 1) % n], after)
        before = np.where(less, cols[k - 1], before)
    return after < before


def unused_warning(mesh: Mesh) -> list[str]:
    ids = mesh.unused_points()
    if ids.size == 0:
        return []
    return [f"{ids.size} point(s) are used by no cell (points {_ids(ids)}): they are left out "
            "of the system"]


def duplicate_points(mesh: Mesh, relative: float = 1e-10) -> np.ndarray:
    """(npairs, 2) ids of used points at the same place (within ``relative`` × extent),
    found by rounding coordinates onto a grid of that spacing."""
    used = np.setdiff1d(np.arange(mesh.num_points), mesh.unused_points())
    if used.size < 2:
        return np.zeros((0, 2), dtype=np.int64)
    pts = mesh.points[used]
    lo = pts.min(axis=0)
    extent = max(float(np.ptp(pts, axis=0).max()), 1e-300)
    grid = np.rint((pts - lo) / (relative * extent)).astype(np.int64)
    group, counts = _row_groups(grid)
    dup = np.flatnonzero(counts[group] > 1)
    if dup.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    order = dup[np.argsort(group[dup], kind="stable")]
    g = group[order]
    start = np.r_[True, g[1:] != g[:-1]]
    first = order[np.maximum.accumulate(np.where(start, np.arange(order.size), 0))]
    pairs = used[np.column_stack([first[~start], order[~start]])]
    return pairs[np.lexsort(pairs.T[::-1])]


def duplicate_warning(mesh: Mesh) -> list[str]:
    pairs = duplicate_points(mesh)
    if pairs.size == 0:
        return []
    a, b = pairs[0]
    where = ", ".join(f"{c:g}" for c in mesh.points[a])
    return [f"{len(pairs)} point(s) duplicate another (first: points {a} and {b} at ({where})): "
            "the cells on either side are not connected there (a crack?)"]
