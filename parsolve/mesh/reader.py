"""Reading meshes with meshio into a :class:`Mesh` (one volume cell type + named groups).

Groups come from Gmsh physical groups (``cell_data["gmsh:physical"]`` with names from
``field_data``; unnamed tags are named by their number) and from meshio's generic
``cell_sets``/``point_sets`` (VTU/XDMF/Abaqus...). By the dimension of their elements:

* volume dimension -> ``cell_groups`` (indices of volume cells),
* volume dimension - 1 -> ``facet_groups`` (facet node ids, must be of the facet type),
* lower dimensions (points, and edges in 3D) -> ``node_groups``.

Points are kept as in the file (orphan points included). Negatively oriented cells
(e.g. clockwise triangles) have their nodes reordered so that every Jacobian is positive.
"""

from __future__ import annotations

import contextlib
import io
import os

import numpy as np

from parsolve.errors import InputError
from parsolve.mesh import gmsh
from parsolve.mesh.mesh import CELL_INFO, Mesh, volume_type
from parsolve.mesh.topology import orient_cells

_KEY = "mesh.file"


def _dim_of(cell_type: str) -> int | None:
    """Topological dimension of a meshio cell type (None if unknown)."""
    try:  # meshio's own table covers every type it can read (private, so guarded)
        from meshio._mesh import topological_dimension
    except ImportError:  # pragma: no cover
        topological_dimension = {}
    if cell_type in topological_dimension:
        return int(topological_dimension[cell_type])
    fallback = {"vertex": 0, "line": 1, "line3": 1, **{t: d for t, (d, _) in CELL_INFO.items()}}
    return fallback.get(cell_type)


def read_mesh(path: str) -> Mesh:
    """Read a mesh file (Gmsh MSH 4.1 and 2.2 by ``gmshmesh``, any other format by meshio); errors
    are InputError with source=path."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputError("mesh file not found", source=path, key=_KEY)
    if not os.path.isfile(path):
        raise InputError("mesh path is not a file", source=path, key=_KEY)
    if gmsh.ours(path):
        from parsolve.mesh.gmshmesh import read_whole

        return read_whole(path, _KEY)
    import meshio  # slow import: only when a file is actually read

    # meshio prints its reasons and may even sys.exit() on unreadable files: capture
    # the output and turn every failure into a one-line InputError.
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            m = meshio.read(path)
    except (Exception, SystemExit) as e:  # noqa: BLE001 - meshio raises anything
        reasons = [ln.strip() for ln in out.getvalue().splitlines() if ln.strip()]
        if not isinstance(e, SystemExit) and str(e).strip():
            reasons.insert(0, str(e).strip().splitlines()[0])
        reason = reasons[0] if reasons else type(e).__name__
        raise InputError(f"cannot read mesh ({reason})", source=path, key=_KEY) from None
    return mesh_from_meshio(m, source=path)


def mesh_from_meshio(m, source: str | None = None) -> Mesh:
    """Convert a ``meshio.Mesh`` (see module docstring for the rules)."""

    def fail(msg: str) -> InputError:
        return InputError(msg, source=source, key=_KEY)

    blocks = [(b.type, np.asarray(b.data, dtype=np.int64)) for b in m.cells]
    dims = [_dim_of(t) for t, _ in blocks]
    vtype, ftype, vdim = volume_type([t for t, _ in blocks], dims, fail)

    points = np.asarray(m.points, dtype=float)
    if points.ndim != 2 or points.shape[1] < vdim:
        raise fail(f"{vdim}D cells need {vdim} coordinates per point")
    if points.shape[1] > vdim:
        extra = points[:, vdim:]
        scale = max(float(np.abs(points).max(initial=0.0)), 1.0)
        if extra.size and np.ptp(extra, axis=0).max() > 1e-12 * scale:
            raise fail(f"{vdim}D mesh with non-constant z coordinates")
        points = np.ascontiguousarray(points[:, :vdim])

    # each block -> (category, offset into that category's concatenated array)
    categories = []
    offsets = {"cell": 0, "facet": 0}
    cell_parts, facet_parts = [], []
    for (t, data), d in zip(blocks, dims):
        if t == vtype:
            categories.append(("cell", offsets["cell"]))
            offsets["cell"] += len(data)
            cell_parts.append(data)
        elif t == ftype:
            categories.append(("facet", offsets["facet"]))
            offsets["facet"] += len(data)
            facet_parts.append(data)
        elif d is not None and d < vdim - 1:
            categories.append(("node", 0))
        else:
            categories.append((None, 0))  # e.g. line facets in a triangle6 mesh
    cells = np.concatenate(cell_parts)
    facets = np.concatenate(facet_parts) if facet_parts else np.zeros((0, 0), dtype=np.int64)
    for arr in (cells, facets):
        if arr.size and (arr.min() < 0 or arr.max() >= len(points)):
            raise fail("cells refer to points that do not exist")

    # name -> category -> list of index arrays (cell/facet indices, or node ids)
    members: dict[str, dict[str, list[np.ndarray]]] = {}

    def add(name: str, block: int, rows: np.ndarray) -> None:
        t, data = blocks[block]
        cat, off = categories[block]
        if rows.size == 0:
            return
        if cat is None:
            raise fail(
                f"group {name!r} has {t} elements, expected {vtype} cells, {ftype} "
                "facets or lower-dimensional entities"
            )
        idx = data[rows].ravel() if cat == "node" else rows + off
        members.setdefault(name, {}).setdefault(cat, []).append(idx)

    # Gmsh physical groups
    physical = m.cell_data.get("gmsh:physical")
    if physical is not None:
        names = {}
        for name, value in (m.field_data or {}).items():
            v = np.asarray(value).ravel()
            if v.size == 2:
                names[(int(v[1]), int(v[0]))] = name  # (dim, tag) -> name
        for b, tags in enumerate(physical):
            tags = np.asarray(tags).ravel()
            if dims[b] is None:
                continue
            for tag in np.unique(tags):
                if tag <= 0:  # 0: no physical group in MSH 2
                    continue
                name = names.get((dims[b], int(tag)), str(int(tag)))
                add(name, b, np.flatnonzero(tags == tag))

    # meshio's generic named sets
    for name, per_block in (m.cell_sets or {}).items():
        if name.startswith("gmsh:"):
            continue
        for b, rows in enumerate(per_block):
            if rows is not None and b < len(blocks):
                add(name, b, np.asarray(rows, dtype=np.int64).ravel())
    point_sets = getattr(m, "point_sets", None) or {}
    for name, ids in point_sets.items():
        members.setdefault(name, {}).setdefault("node", []).append(
            np.asarray(ids, dtype=np.int64).ravel()
        )

    cell_groups, facet_groups, node_groups = {}, {}, {}
    for name, cats in members.items():
        for cat, parts in cats.items():
            idx = np.unique(np.concatenate(parts))  # sets may repeat physical groups
            if cat == "cell":
                cell_groups[name] = idx
            elif cat == "facet":
                facet_groups[name] = facets[idx]
            else:
                if idx.size and (idx[0] < 0 or idx[-1] >= len(points)):
                    raise fail(f"group {name!r} refers to points that do not exist")
                node_groups[name] = idx

    with np.errstate(invalid="ignore"):  # NaN coordinates are reported by mesh.checks
        cells, _ = orient_cells(points, vtype, cells)
    return Mesh(
        points=points,
        cell_type=vtype,
        cells=cells,
        cell_groups=cell_groups,
        facet_groups=facet_groups,
        node_groups=node_groups,
    )
