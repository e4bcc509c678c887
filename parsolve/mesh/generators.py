"""Structured mesh generators (rectangle, box, quarter plate with a hole, a sphere on a block)
and P2 upgrade.

All meshes are built with vectorised index arithmetic on a structured (i, j[, k]) grid,
with positively oriented cells (positive Jacobian) in meshio/VTK node ordering.
Generated meshes carry facet groups for their boundary sides (see each generator). Each is a
slice source (``SLICED``: any slice of its cells and points built alone, ``mesh.slices``);
the generator functions return its whole mesh.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence

import numpy as np

from parsolve.errors import InputError
from parsolve.mesh.mesh import Mesh
from parsolve.mesh.topology import FACETS

def _check_counts(**counts: int) -> None:
    # ValueError for bad arguments: the caller (scene -> model) adds source and key
    for name, n in counts.items():
        if not isinstance(n, (int, float, np.integer)) or int(n) != n or n < 1:
            raise ValueError(f"{name} must be a positive integer, got {n!r}")


def _check_lengths(origin: Sequence[float], **lengths: float) -> None:
    for name, v in lengths.items():
        if not v > 0:  # also catches nan
            raise ValueError(f"{name} must be positive, got {v!r}")
    if len(origin) != len(lengths):
        raise ValueError(f"origin must have {len(lengths)} coordinates, got {list(origin)}")


def _check_cell(cell: str, allowed: tuple[str, ...]) -> None:
    if cell not in allowed:
        raise ValueError(f"unsupported cell {cell!r} (expected one of {', '.join(allowed)})")


def _nodes_from_facets(mesh: Mesh) -> Mesh:
    # after the P2 upgrade so that side node groups include the midside nodes
    for name, facets in mesh.facet_groups.items():
        mesh.node_groups[name] = np.unique(facets)
    return mesh


# --------------------------------------------------------------------------------------
# rectangle
# --------------------------------------------------------------------------------------


def rectangle(
    lx: float,
    ly: float,
    nx: int,
    ny: int,
    cell: str = "quad",
    origin: Sequence[float] = (0.0, 0.0),
) -> Mesh:
    """Structured mesh of [ox, ox+lx] x [oy, oy+ly] with nx x ny quads (or 2 triangles each).

    cell: "quad", "triangle" or "triangle6". Facet and node groups: "left", "right",
    "bottom", "top". Nodes i + j*(nx+1), quads i + j*nx (triangles 2 per quad).
    """
    return rectangle_slices(lx, ly, nx, ny, cell, origin).whole()


def rectangle_slices(lx: float, ly: float, nx: int, ny: int, cell: str = "quad",
                     origin: Sequence[float] = (0.0, 0.0)) -> GridSlices:
    """``rectangle``'s mesh as a slice source."""
    _check_cell(cell, ("quad", "triangle", "triangle6"))
    _check_counts(nx=nx, ny=ny)
    _check_lengths(origin, lx=lx, ly=ly)
    nx, ny = int(nx), int(ny)
    axes = [o + np.linspace(0.0, length, n + 1) for o, length, n in zip(origin, (lx, ly), (nx, ny))]
    return GridSlices(axes, cell)


# --------------------------------------------------------------------------------------
# box
# --------------------------------------------------------------------------------------

# VTK hexahedron corner offsets (dx, dy, dz)
_HEX_OFFSETS = [
    (0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0),
    (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1),
]  # fmt: skip


def _kuhn_tets() -> np.ndarray:
    """Local hex nodes of the 6 Kuhn (Freudenthal) tets, each positively oriented.

    Every tet is the path 000 -> e_a -> e_a+e_b -> 111 for a permutation (a, b, c) of
    the axes. All hexes are split identically, so each hex face is cut along the
    diagonal through its lowest and highest corners in both neighbours: conforming.
    """
    index = {off: n for n, off in enumerate(_HEX_OFFSETS)}
    tets = []
    for perm in itertools.permutations(range(3)):
        corner = np.zeros(3, dtype=int)
        path = [index[tuple(corner)]]
        for axis in perm:
            corner[axis] = 1
            path.append(index[tuple(corner)])
        v = np.array([_HEX_OFFSETS[n] for n in path], dtype=float)
        if np.linalg.det(v[1:] - v[0]) < 0:  # odd permutation: swap two nodes
            path[1], path[2] = path[2], path[1]
        tets.append(path)
    return np.array(tets, dtype=np.int64)


_KUHN = _kuhn_tets()


def box(
    lx: float,
    ly: float,
    lz: float,
    nx: int,
    ny: int,
    nz: int,
    cell: str = "hexahedron",
    origin: Sequence[float] = (0.0, 0.0, 0.0),
) -> Mesh:
    """Structured mesh of a box with nx x ny x nz hexahedra (or 6 conforming tets each).

    cell: "hexahedron", "tetra" or "tetra10". Facet and node groups: "xmin", "xmax",
    "ymin", "ymax", "zmin", "zmax". Nodes i + j*(nx+1) + k*(nx+1)*(ny+1), hexahedra
    i + j*nx + k*nx*ny (tetrahedra 6 per hexahedron, ``_KUHN``).
    """
    return box_slices(lx, ly, lz, nx, ny, nz, cell, origin).whole()


def box_slices(lx: float, ly: float, lz: float, nx: int, ny: int, nz: int,
               cell: str = "hexahedron", origin: Sequence[float] = (0.0, 0.0, 0.0)
               ) -> GridSlices:
    """``box``'s mesh as a slice source."""
    _check_cell(cell, ("hexahedron", "tetra", "tetra10"))
    _check_counts(nx=nx, ny=ny, nz=nz)
    _check_lengths(origin, lx=lx, ly=ly, lz=lz)
    counts = (int(nx), int(ny), int(nz))
    axes = [o + np.linspace(0.0, length, n + 1)
            for o, length, n in zip(origin, (lx, ly, lz), counts)]
    return GridSlices(axes, cell)


# --------------------------------------------------------------------------------------
# structured grids by slices
# --------------------------------------------------------------------------------------

_SIDES = {2: ("left", "right", "bottom", "top"), 3: ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")}
_SPLIT = {"quad": (1, None), "triangle": (2, np.array([[0, 1, 2], [0, 2, 3]])),
          "hexahedron": (1, None), "tetra": (6, _KUHN)}   # cells per grid cell, their corners


class GridSlices:
    """A structured rectangle or box (nodes along each axis ``axes``) as a slice source of
    ``mesh.slices``: any contiguous slice of its cells and points, the nodes of its sides and
    the facets of its sides among a slice of cells, built from the index arithmetic alone
    (nothing of the whole mesh's size); ``whole`` is the whole mesh. Its cells are linear
    (``cell_type``); a quadratic ``cell`` (triangle6, tetra10) has its midside nodes added by
    ``midside.QuadraticSlices``, in its side groups."""

    path = "<generator>"
    cell_groups: tuple[str, ...] = ()

    def __init__(self, axes: list[np.ndarray], cell: str):
        self.axes, self.cell = axes, cell
        self.dim = len(axes)
        self.cell_type = {"triangle6": "triangle", "tetra10": "tetra"}.get(cell, cell)
        self.n = [a.size - 1 for a in axes]
        self.num_points = int(np.prod([a.size for a in axes]))
        self.num_cells = int(np.prod(self.n)) * _SPLIT[self.cell_type][0]
        self.node_groups = self.facet_groups = _SIDES[self.dim]
        sizes = [a.size for a in axes]
        corners = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)] if self.dim == 2 else _HEX_OFFSETS
        self._offsets = np.array([_flat(c[:self.dim], sizes) for c in corners], dtype=np.int64)

    def _node_index(self, ids: np.ndarray) -> list[np.ndarray]:
        """(i, j[, k]) of node ids."""
        out = []
        for a in self.axes:
            ids, i = np.divmod(ids, a.size)
            out.append(i)
        return out

    def points(self, start: int, stop: int) -> np.ndarray:
        idx = self._node_index(np.arange(start, stop, dtype=np.int64))
        return np.column_stack([a[i] for a, i in zip(self.axes, idx)]).reshape(-1, self.dim)

    def cells(self, start: int, stop: int) -> np.ndarray:
        return self._cells_of(np.arange(start, stop, dtype=np.int64))

    def _cells_of(self, ids: np.ndarray) -> np.ndarray:
        per, split = _SPLIT[self.cell_type]
        grid, sub = np.divmod(ids, per)
        index = []
        for n in self.n:
            grid, i = np.divmod(grid, n)
            index.append(i)
        first = _flat(index, [a.size for a in self.axes])
        corners = first[:, None] + self._offsets[None, :]
        if split is None:
            return corners
        return np.take_along_axis(corners, split[sub], axis=1)

    def _side_axis(self, name: str) -> tuple[int, bool]:
        """(the axis across the side ``name``, whether it is at that axis's last node)."""
        axis, last = divmod(_SIDES[self.dim].index(name), 2)
        return axis, bool(last)

    def _side(self, name: str, ids: np.ndarray) -> np.ndarray:
        """Which node ids lie on the side ``name`` (its axis at its first or last node)."""
        axis, last = self._side_axis(name)
        i = self._node_index(ids)[axis]
        return i == (self.n[axis] if last else 0)

    def node_flags(self, start: int, stop: int) -> np.ndarray:
        ids = np.arange(start, stop, dtype=np.int64)
        return np.column_stack([self._side(name, ids) for name in self.node_groups]
                               ).reshape(stop - start, len(self.node_groups))

    def cell_flags(self, start: int, stop: int) -> np.ndarray:
        return np.zeros((stop - start, 0), dtype=bool)

    def facet_slice(self, name: str, rank: int, size: int) -> tuple[np.ndarray, np.ndarray]:
        """The side's facets (outward, ``topology.FACETS``) among rank ``rank``'s slice of the
        cells, and their places in the whole group (by cell, then local facet: the order of
        ``topology.facets_from_nodes``). Every facet with its nodes on a side is a boundary
        facet: the side is a plane of the box's boundary."""
        return self.facets_among(name, self.num_cells * rank // size,
                                 self.num_cells * (rank + 1) // size)

    def facets_among(self, name: str, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """``facet_slice`` among the cells [start, stop)."""
        axis, last = self._side_axis(name)
        ids = np.arange(start, stop, dtype=np.int64)
        # only the cells of the layer along the side can have a facet on it
        layer = ids // _SPLIT[self.cell_type][0] // int(np.prod(self.n[:axis])) % self.n[axis]
        ids = ids[layer == (self.n[axis] - 1 if last else 0)]
        cells = self._cells_of(ids)
        local = FACETS[self.cell_type]
        rows, keys = [], []
        for li, f in enumerate(local):
            nodes = cells[:, list(f)]
            on = self._side(name, nodes.ravel()).reshape(nodes.shape).all(axis=1)
            rows.append(nodes[on])
            keys.append(ids[on] * len(local) + li)
        keys = np.concatenate(keys)
        order = np.argsort(keys, kind="stable")
        return np.concatenate(rows)[order], keys[order]

    def whole(self) -> Mesh:
        """The whole mesh (one process), quadratic when asked (``make_quadratic``)."""
        mesh = Mesh(self.points(0, self.num_points), self.cell_type, self.cells(0, self.num_cells))
        for name in self.facet_groups:
            mesh.facet_groups[name] = self.facet_slice(name, 0, 1)[0]
        if self.cell != self.cell_type:
            mesh = make_quadratic(mesh)
        return _nodes_from_facets(mesh)


def _flat(index, sizes) -> np.ndarray:
    """Flat id of per-axis indices (x fastest)."""
    out, stride = 0, 1
    for i, size in zip(index, sizes):
        out = out + np.asarray(i, dtype=np.int64) * stride
        stride *= size
    return out


class PlateSlices(GridSlices):
    """``plate_with_hole``'s mesh as a slice source: the (radial, angular) grid of a
    rectangle, its nodes mapped onto the plate node by node (``points``), its sides the
    hole (k = 0), the symmetry lines (j = 0: bottom, j = n_angular: left) and the outer
    edges (k = n_radial, split at the patches' seam j = n_angular // 2: right, top)."""

    SIDE_AXES = {"hole": (0, False), "bottom": (1, False), "left": (1, True), "right": (0, True),
              "top": (0, True)}

    def __init__(self, width: float, height: float, radius: float, t: np.ndarray,
                 n_angular: int, cell: str):
        super().__init__([t, np.arange(n_angular + 1, dtype=float)], cell)
        self.node_groups = self.facet_groups = ("hole", "left", "bottom", "right", "top")
        self.seam = n_angular // 2                     # the lower patch's last column
        jj = np.arange(n_angular + 1)
        lower = jj <= self.seam
        s = np.where(lower, jj / self.seam, (jj - self.seam) / (n_angular - self.seam))
        theta = np.where(lower, s, 1.0 + s) * (np.pi / 4)
        self.inner = radius * np.column_stack([np.cos(theta), np.sin(theta)])
        self.outer = np.where(lower[:, None],
                              np.column_stack([np.full_like(s, width), s * height]),
                              np.column_stack([(1.0 - s) * width, np.full_like(s, height)]))
        # symmetry lines exactly on the axes (cos(pi/2) is not exactly 0)
        self.inner[0, 1] = 0.0
        self.inner[-1, 0] = 0.0
        self.radius = radius

    def midside_points(self, lo: np.ndarray, hi: np.ndarray, mid: np.ndarray) -> np.ndarray:
        """Midside nodes (of edges ``lo``-``hi``) of triangle6 cells on the circle when the edge
        joins two hole nodes (``plate_with_hole``'s projection, row by row)."""
        if self.cell != "triangle6":
            return mid
        on = (self._node_index(lo)[0] == 0) & (self._node_index(hi)[0] == 0)
        p = mid[on]
        mid[on] = self.radius * p / np.linalg.norm(p, axis=1)[:, None]
        return mid

    def points(self, start: int, stop: int) -> np.ndarray:
        k, j = self._node_index(np.arange(start, stop, dtype=np.int64))
        t = self.axes[0][k][:, None]
        return self.inner[j] + t * (self.outer[j] - self.inner[j])

    def _side_axis(self, name: str) -> tuple[int, bool]:
        return self.SIDE_AXES[name]

    def _side(self, name: str, ids: np.ndarray) -> np.ndarray:
        k, j = self._node_index(ids)
        on = {"hole": k == 0, "bottom": j == 0, "left": j == self.n[1]}.get(name)
        if on is None:   # the outer edges, each up to the seam
            edge = k == self.n[0]
            on = edge & (j <= self.seam if name == "right" else j >= self.seam)
        return on


# --------------------------------------------------------------------------------------
# quarter plate with a hole
# --------------------------------------------------------------------------------------


def _graded(n: int, grading: float) -> np.ndarray:
    """n+1 parameters in [0, 1] with geometric sizes, last/first element size = grading."""
    if grading <= 0:
        raise ValueError(f"grading must be positive, got {grading!r}")
    if n == 1 or np.isclose(grading, 1.0):
        return np.linspace(0.0, 1.0, n + 1)
    q = grading ** (1.0 / (n - 1))  # ratio between neighbouring elements
    t = (q ** np.arange(n + 1) - 1.0) / (q**n - 1.0)
    t[-1] = 1.0
    return t


def plate_with_hole(
    width: float,
    height: float,
    radius: float,
    n_radial: int,
    n_angular: int,
    cell: str = "quad",
    grading: float = 4.0,
) -> Mesh:
    """Quarter plate [0, width] x [0, height] minus the disc of ``radius`` at the origin.

    Two structured patches meet along the line from the hole point at 45 degrees to the
    corner (width, height): the lower one maps the arc [0, 45] degrees onto the right
    edge, the upper one the arc [45, 90] degrees onto the top edge, with straight
    "radial" lines between. ``n_angular`` elements along the whole arc (split between
    the patches), ``n_radial`` from hole to outer edge. ``grading`` is the ratio between
    the outermost and the innermost radial element size (geometric progression; 1 means
    uniform), so elements are refined toward the hole.

    cell: "quad", "triangle" or "triangle6" (midside nodes on the hole lie on the circle).
    Facet and node groups: "hole", "left" (x = 0), "bottom" (y = 0), "right" (x = width),
    "top" (y = height). Nodes k + j*(n_radial+1) (k radial, j angular), quads k + j*n_radial
    (triangles 2 per quad).
    """
    mesh = plate_slices(width, height, radius, n_radial, n_angular, cell, grading).whole()
    if cell == "triangle6":
        hole = np.zeros(mesh.num_points, dtype=bool)
        hole[mesh.node_groups["hole"]] = True
        _project_midnodes_to_circle(mesh, hole, radius)
    return mesh


def plate_slices(width: float, height: float, radius: float, n_radial: int, n_angular: int,
                 cell: str = "quad", grading: float = 4.0) -> PlateSlices:
    """``plate_with_hole``'s mesh as a slice source."""
    _check_cell(cell, ("quad", "triangle", "triangle6"))
    _check_counts(n_radial=n_radial, n_angular=n_angular)
    n_radial, n_angular = int(n_radial), int(n_angular)
    if n_angular < 2:
        raise ValueError("n_angular must be at least 2 (one element per patch)")
    if not 0 < radius < min(width, height):
        raise ValueError("radius must be positive and smaller than width and height")
    return PlateSlices(width, height, radius, _graded(n_radial, grading), n_angular, cell)


def _project_midnodes_to_circle(mesh: Mesh, hole: np.ndarray, radius: float) -> None:
    """Move the midside nodes of edges joining two hole nodes onto the circle."""
    hole_full = np.zeros(mesh.num_points, dtype=bool)
    hole_full[: hole.size] = hole
    for a, b, m in ((0, 1, 3), (1, 2, 4), (2, 0, 5)):
        on = hole_full[mesh.cells[:, a]] & hole_full[mesh.cells[:, b]]
        mid = np.unique(mesh.cells[on, m])
        p = mesh.points[mid]
        mesh.points[mid] = radius * p / np.linalg.norm(p, axis=1)[:, None]


# --------------------------------------------------------------------------------------
# sphere on a block (Hertz, quarter model)
# --------------------------------------------------------------------------------------


def _expanding(first: float, length: float, n: int) -> np.ndarray:
    """n+1 coordinates from 0 to ``length``: n cells in geometric progression whose first is
    ``first`` (ratio q from first (q^n - 1)/(q - 1) = length, by bisection on log q: the sum
    grows with q, so the root is unique; q < 1 when n cells of ``first`` exceed the length)."""
    if n == 1 or np.isclose(n * first, length, rtol=1e-12):
        return np.linspace(0.0, length, n + 1)
    k = np.arange(n)
    lo, hi = -50.0 / n, 50.0 / n + np.log(length / first) / max(n - 1, 1)
    for _ in range(200):   # bisection on a scalar: 200 halvings reach round-off
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if first * np.exp(mid * k).sum() < length else (lo, mid)
    sizes = first * np.exp(0.5 * (lo + hi) * k)
    x = np.concatenate([[0.0], np.cumsum(sizes)])
    return x * (length / x[-1])   # the last node exactly at the length


def _refined_line(fine: float, n_fine: int, width: float, n_coarse: int) -> np.ndarray:
    """Coordinates on [0, width]: n_fine equal cells on [0, fine], then n_coarse cells growing
    geometrically from the fine size to the width."""
    h = fine / n_fine
    coarse = fine + _expanding(h, width - fine, n_coarse)
    return np.concatenate([np.linspace(0.0, fine, n_fine + 1), coarse[1:]])


def _profile(r: np.ndarray, radius: float, profile: str) -> np.ndarray:
    """Height of the contact face above its tip at distance r from the axis."""
    if profile == "paraboloid":
        return r * r / (2.0 * radius)
    return radius - np.sqrt(radius * radius - r * r)


class SurfaceGrid(GridSlices):
    """A box grid whose nodes' heights follow a surface: node (i, j, k) at (x_i, y_j,
    face(x_i, y_j) + s_k (top − face(x_i, y_j))), s from 0 to 1 (the sphere body above its
    contact face; positive Jacobians: the map's matrix is triangular, its diagonal positive)."""

    def __init__(self, x: np.ndarray, s: np.ndarray, top: float, face: Callable, cell: str):
        super().__init__([x, x, s], cell)
        self.top, self.face = top, face

    def points(self, start: int, stop: int) -> np.ndarray:
        i, j, k = self._node_index(np.arange(start, stop, dtype=np.int64))
        x, s = self.axes[0], self.axes[2]
        face = self.face(np.hypot(x[i], x[j]))
        return np.column_stack([x[i], x[j], face + s[k] * (self.top - face)]).reshape(-1, 3)


class BodySlices:
    """Grids side by side as one slice source (``mesh.slices``): the nodes and cells of each
    after the former's, a cell group per body, and node and facet groups that are each a side
    of some bodies (``groups``: name -> {body: side})."""

    path = "<generator>"

    def __init__(self, bodies: list[GridSlices], names: tuple[str, ...],
                 groups: dict[str, dict[int, str]]):
        self.bodies, self.cell_groups, self.groups = bodies, names, groups
        self.node_groups = self.facet_groups = tuple(groups)
        self.cell = self.cell_type = bodies[0].cell_type
        self.dim = 3
        self.point_offsets = np.cumsum([0] + [b.num_points for b in bodies])
        self.cell_offsets = np.cumsum([0] + [b.num_cells for b in bodies])
        self.num_points, self.num_cells = int(self.point_offsets[-1]), int(self.cell_offsets[-1])

    def _pieces(self, offsets: np.ndarray, start: int, stop: int):
        """(body, its first row, its row range) of the rows [start, stop)."""
        for b, body in enumerate(self.bodies):
            lo, hi = max(start, offsets[b]), min(stop, offsets[b + 1])
            if lo < hi or (b == 0 and start == stop):
                yield b, body, int(lo - offsets[b]), int(max(hi, lo) - offsets[b])

    def points(self, start: int, stop: int) -> np.ndarray:
        return np.vstack([body.points(lo, hi) for _, body, lo, hi
                          in self._pieces(self.point_offsets, start, stop)])

    def cells(self, start: int, stop: int) -> np.ndarray:
        return np.vstack([body.cells(lo, hi) + self.point_offsets[b] for b, body, lo, hi
                          in self._pieces(self.cell_offsets, start, stop)])

    def node_flags(self, start: int, stop: int) -> np.ndarray:
        out = np.zeros((stop - start, len(self.node_groups)), dtype=bool)
        for b, body, lo, hi in self._pieces(self.point_offsets, start, stop):
            ids = np.arange(lo, hi, dtype=np.int64)
            rows = slice(lo + self.point_offsets[b] - start, hi + self.point_offsets[b] - start)
            for g, sides in enumerate(self.groups.values()):
                if b in sides:
                    out[rows, g] = body._side(sides[b], ids)
        return out

    def cell_flags(self, start: int, stop: int) -> np.ndarray:
        body = np.searchsorted(self.cell_offsets, np.arange(start, stop), side="right") - 1
        return body[:, None] == np.arange(len(self.bodies))[None, :]

    def facet_slice(self, name: str, rank: int, size: int) -> tuple[np.ndarray, np.ndarray]:
        start, stop = self.num_cells * rank // size, self.num_cells * (rank + 1) // size
        local = FACETS[self.cell_type]
        rows, keys = [np.zeros((0, len(local[0])), np.int64)], [np.zeros(0, np.int64)]
        for b, body, lo, hi in self._pieces(self.cell_offsets, start, stop):
            if b in self.groups[name]:
                f, k = body.facets_among(self.groups[name][b], lo, hi)
                rows.append(f + self.point_offsets[b])
                keys.append(k + self.cell_offsets[b] * len(local))
        return np.concatenate(rows), np.concatenate(keys)

    def whole(self) -> Mesh:
        """The whole mesh (one process)."""
        flags = self.cell_flags(0, self.num_cells)
        mesh = Mesh(self.points(0, self.num_points), self.cell_type, self.cells(0, self.num_cells),
                    cell_groups={n: np.flatnonzero(flags[:, k])
                                 for k, n in enumerate(self.cell_groups)})
        for name in self.facet_groups:
            mesh.facet_groups[name] = self.facet_slice(name, 0, 1)[0]
        return _nodes_from_facets(mesh)


def _check_sphere_on_block(radius, width, depth, height, fine, gap, profile, cell) -> None:
    _check_cell(cell, ("hexahedron", "tetra"))
    lengths = dict(radius=radius, width=width, depth=depth, height=height, fine=fine)
    _check_lengths((0.0,) * len(lengths), **lengths)
    if not fine < width:
        raise ValueError(f"fine must be smaller than width, got {fine!r} >= {width!r}")
    if not gap >= 0:
        raise ValueError(f"gap must be zero or positive, got {gap!r}")
    if profile not in ("paraboloid", "sphere"):
        raise ValueError(f"profile must be 'paraboloid' or 'sphere', got {profile!r}")
    corner = np.sqrt(2.0) * width
    if profile == "sphere" and not corner < radius:
        raise ValueError(f"radius must exceed the quarter's diagonal width * sqrt(2) = {corner:g} "
                         f"with profile 'sphere', got {radius!r}")
    top = gap + float(_profile(np.array(corner), radius, profile))
    if not height > top:
        raise ValueError(f"height must exceed the contact face's highest point {top:g} "
                         f"(its corner), got {height!r}")


def sphere_on_block(
    radius: float,
    width: float,
    depth: float,
    height: float,
    fine: float,
    n_fine: int,
    n_coarse: int,
    n_depth: int,
    n_fine_sphere: int | None = None,
    gap: float = 0.0,
    profile: str = "paraboloid",
    cell: str = "hexahedron",
) -> Mesh:
    """Quarter model of Hertz's sphere on a block: two bodies on [0, width]², non-matching.

    The block fills [0, width]² × [−depth, 0]; the sphere body stands on it, its bottom face
    the surface z = gap + f(r) (r = √(x² + y²); f = r²/(2 radius) for ``profile =
    "paraboloid"``, Hertz's own profile, or the sphere radius − √(radius² − r²)) and its top
    the plane z = height. Each is a mapped hexahedral grid refined towards the tip: in x and
    y, equal cells on [0, fine] (n_fine of them for the block, n_fine_sphere for the sphere
    body: ¾ of n_fine by default, so that the contact faces do not match), then n_coarse
    cells growing geometrically to the width; through each body n_depth cells growing from
    the fine size at the contact face. cell: "hexahedron" or "tetra" (6 per hexahedron).
    ``gap`` > 0 keeps the tip off the block's corner node (a duplicate point is warned of).

    Cell groups "block" and "sphere"; facet and node groups "block_top" (the block's contact
    face), "block_bottom", "sphere_surface" (the sphere body's contact face), "sphere_top",
    "xmin" and "ymin" (the symmetry planes x = 0 and y = 0 of both bodies).
    """
    _check_counts(n_fine=n_fine, n_coarse=n_coarse, n_depth=n_depth)
    if n_fine_sphere is None:
        n_fine_sphere = max(1, (3 * int(n_fine) + 2) // 4)
    _check_counts(n_fine_sphere=n_fine_sphere)
    return sphere_slices(radius, width, depth, height, fine, n_fine, n_coarse, n_depth,
                         n_fine_sphere, gap, profile, cell).whole()


def sphere_slices(radius: float, width: float, depth: float, height: float, fine: float,
                  n_fine: int, n_coarse: int, n_depth: int, n_fine_sphere: int | None = None,
                  gap: float = 0.0, profile: str = "paraboloid", cell: str = "hexahedron"
                  ) -> BodySlices:
    """``sphere_on_block``'s mesh as a slice source: the block's grid (nodes i + j (nx+1)
    + k (nx+1)(ny+1), k up to its top z = 0), then the sphere body's (k up from its contact
    face)."""
    _check_counts(n_fine=n_fine, n_coarse=n_coarse, n_depth=n_depth)
    if n_fine_sphere is None:
        n_fine_sphere = max(1, (3 * int(n_fine) + 2) // 4)
    _check_counts(n_fine_sphere=n_fine_sphere)
    _check_sphere_on_block(radius, width, depth, height, fine, gap, profile, cell)
    n_fine, n_coarse, n_depth, n_fine_sphere = map(int, (n_fine, n_coarse, n_depth, n_fine_sphere))
    # the block: fine at its top z = 0
    xb = _refined_line(fine, n_fine, width, n_coarse)
    block = GridSlices([xb, xb, -_expanding(fine / n_fine, depth, n_depth)[::-1]], cell)
    # the sphere body: each column from the contact face up to the top, fine at the face
    xs = _refined_line(fine, n_fine_sphere, width, n_coarse)
    s = _expanding(fine / n_fine_sphere / (height - gap), 1.0, n_depth)
    sphere = SurfaceGrid(xs, s, height, lambda r: gap + _profile(r, radius, profile), cell)
    return BodySlices([block, sphere], ("block", "sphere"), {
        "block_top": {0: "zmax"}, "block_bottom": {0: "zmin"}, "sphere_surface": {1: "zmin"},
        "sphere_top": {1: "zmax"}, "xmin": {0: "xmin", 1: "xmin"}, "ymin": {0: "ymin", 1: "ymin"}})


def sphere_on_block_counts(params: dict, order: int = 1) -> tuple[int, int, int]:
    """(points, cells, dim) of ``sphere_on_block`` from its parameters (nothing built; with
    tetrahedra and ``order = 2``, the midside nodes: one per edge of the Kuhn split)."""
    n_fine, n_coarse, n_depth = (int(params.get(k, 1)) for k in ("n_fine", "n_coarse", "n_depth"))
    n_sphere = int(params.get("n_fine_sphere", max(1, (3 * n_fine + 2) // 4)))
    tetra = params.get("cell", "hexahedron") == "tetra"
    points = cells = 0
    for c in (n_fine + n_coarse, n_sphere + n_coarse):   # each body: c × c × n_depth hexahedra
        d, hexes = n_depth, c * c * n_depth
        points += (c + 1) ** 2 * (d + 1)
        cells += hexes * (6 if tetra else 1)
        if tetra and order == 2:   # grid edges, face diagonals, one body diagonal per hexahedron
            points += (2 * c * (c + 1) * (d + 1) + (c + 1) ** 2 * d
                       + c * c * (d + 1) + 2 * c * (c + 1) * d + hexes)
    return points, cells, 3


# --------------------------------------------------------------------------------------
# quadratic upgrade
# --------------------------------------------------------------------------------------

# local vertex pairs of the midside nodes, in meshio/VTK order
_EDGES = {
    "triangle": [(0, 1), (1, 2), (2, 0)],
    "tetra": [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)],
}


def make_quadratic(mesh: Mesh) -> Mesh:
    """Upgrade triangle -> triangle6 or tetra -> tetra10 by adding unique edge midpoints.

    New nodes are appended after the existing ones (numbered by sorted edge). Groups are
    carried over; facet groups become line3 / triangle6 facets.
    """
    if mesh.cell_type not in _EDGES:
        raise InputError(f"cannot make {mesh.cell_type} cells quadratic (triangle or tetra only)")
    npts = mesh.num_points
    cells = mesh.cells.astype(np.int64)
    edges = np.stack([cells[:, list(e)] for e in _EDGES[mesh.cell_type]], axis=1)  # (nc, ne, 2)
    lo, hi = edges.min(axis=2), edges.max(axis=2)
    # single int64 key per undirected edge: fine up to ~3e9 points
    keys, inv = np.unique(lo * npts + hi, return_inverse=True)
    inv = inv.reshape(lo.shape)
    a, b = keys // npts, keys % npts
    points = np.vstack([mesh.points, 0.5 * (mesh.points[a] + mesh.points[b])])
    new_cells = np.hstack([cells, npts + inv])

    def mid(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        k = np.minimum(u, v) * npts + np.maximum(u, v)
        pos = np.searchsorted(keys, k)
        pos = np.minimum(pos, keys.size - 1)
        if np.any(keys[pos] != k):
            raise InputError("a facet group contains an edge that is not a mesh edge")
        return npts + pos

    facet_groups = {}
    for name, f in mesh.facet_groups.items():
        f = np.asarray(f, dtype=np.int64)
        nv = 2 if mesh.cell_type == "triangle" else 3
        f = f[:, :nv]
        if nv == 2:
            facet_groups[name] = np.column_stack([f, mid(f[:, 0], f[:, 1])])
        else:
            facet_groups[name] = np.column_stack(
                [f, mid(f[:, 0], f[:, 1]), mid(f[:, 1], f[:, 2]), mid(f[:, 2], f[:, 0])]
            )
    return Mesh(
        points,
        mesh.cell_type + ("6" if mesh.cell_type == "triangle" else "10"),
        new_cells,
        cell_groups={k: v.copy() for k, v in mesh.cell_groups.items()},
        facet_groups=facet_groups,
        node_groups={k: v.copy() for k, v in mesh.node_groups.items()},
    )


# facet and node groups every generator creates (scene validation of group names)
GENERATOR_GROUPS: dict[str, tuple[str, ...]] = {
    "rectangle": ("left", "right", "bottom", "top"),
    "box": ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax"),
    "plate_with_hole": ("hole", "left", "bottom", "right", "top"),
    "sphere_on_block": ("block", "sphere", "block_top", "block_bottom", "sphere_surface",
                        "sphere_top", "xmin", "ymin"),
}

# the generators that build any slice of their mesh (``mesh.slices``): linear cells
SLICED: dict[str, Callable] = {"rectangle": rectangle_slices, "box": box_slices,
                               "plate_with_hole": plate_slices, "sphere_on_block": sphere_slices}

GENERATORS: dict[str, Callable[..., Mesh]] = {
    "rectangle": rectangle,
    "box": box,
    "plate_with_hole": plate_with_hole,
    "sphere_on_block": sphere_on_block,
}
