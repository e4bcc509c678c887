"""The parallel mesh file: HDF5 in the result file's ``/mesh`` layout, its regions stored so that
every rank reads a contiguous slice of what it needs (``parsolve mesh convert`` writes it).

    /mesh                      attrs: format = "parsolve-mesh", version = 1
    /mesh/points               (npoints, dim) float64      the row is the input node id
    /mesh/cells/<type>         (ncells, nodes) int64       one volume type, meshio node order,
                                                           positively oriented; row = input id
    /mesh/cell_groups/<name>   (ncells,) uint8             1: the cell is in the group
    /mesh/node_groups/<name>   (npoints,) uint8            1: the node is in the group
    /mesh/facet_groups/<name>  (nfacets, facet nodes) int64  the group's facets (node ids)

Cell and node groups are masks (one byte per cell or node and group) so that a rank reads its
slice of a group with its slice of cells or nodes; a facet group is read by slices of its rows.
Reading the file gives the same ``Mesh`` as reading the file it was converted from.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from parsolve.errors import InputError
from parsolve.mesh.mesh import CELL_INFO, Mesh

FORMAT = "parsolve-mesh"
VERSION = 1
_KEY = "mesh.file"


def is_mesh_h5(path: str) -> bool:
    """A path given as the parallel format (by its suffix: the content is checked on reading)."""
    return os.fspath(path).lower().endswith((".h5", ".hdf5"))


def write_mesh(mesh: Mesh, path: str) -> None:
    """Write ``mesh`` (one process) in the layout above."""
    import h5py

    with h5py.File(path, "w") as f:
        g = f.create_group("mesh")
        g.attrs["format"] = FORMAT
        g.attrs["version"] = VERSION
        g.create_dataset("points", data=np.asarray(mesh.points, dtype=float))
        g.create_group("cells").create_dataset(mesh.cell_type,
                                               data=np.asarray(mesh.cells, dtype=np.int64))
        for name, ids in mesh.cell_groups.items():
            g.require_group("cell_groups").create_dataset(name, data=_mask(ids, mesh.num_cells))
        for name, ids in mesh.node_groups.items():
            g.require_group("node_groups").create_dataset(name, data=_mask(ids, mesh.num_points))
        nfn = len(_facet_nodes(mesh.cell_type))
        for name, facets in mesh.facet_groups.items():
            facets = np.asarray(facets, dtype=np.int64).reshape(-1, nfn)
            g.require_group("facet_groups").create_dataset(name, data=facets)


def _mask(ids: np.ndarray, n: int) -> np.ndarray:
    mask = np.zeros(n, dtype=np.uint8)
    mask[np.asarray(ids, dtype=np.int64)] = 1
    return mask


def _facet_nodes(cell_type: str) -> tuple:
    from parsolve.mesh.topology import FACETS

    return FACETS[cell_type][0]


@dataclass
class MeshFile:
    """An open parallel mesh file: its sizes and names, and slices read on demand."""

    path: str
    handle: object
    cell_type: str
    num_cells: int
    num_points: int
    dim: int
    cell_groups: tuple[str, ...]
    node_groups: tuple[str, ...]
    facet_groups: tuple[str, ...]

    def cells(self, start: int, stop: int) -> np.ndarray:
        return np.asarray(self.handle["mesh/cells"][self.cell_type][start:stop], dtype=np.int64)

    def points(self, start: int, stop: int) -> np.ndarray:
        return np.asarray(self.handle["mesh/points"][start:stop], dtype=float)

    def cell_flags(self, start: int, stop: int) -> np.ndarray:
        """(stop - start, number of cell groups) bool: the cells' groups, in name order."""
        return self._flags("cell_groups", self.cell_groups, start, stop)

    def node_flags(self, start: int, stop: int) -> np.ndarray:
        return self._flags("node_groups", self.node_groups, start, stop)

    def _flags(self, group: str, names, start: int, stop: int) -> np.ndarray:
        out = np.zeros((stop - start, len(names)), dtype=bool)
        for k, name in enumerate(names):
            out[:, k] = self.handle["mesh"][group][name][start:stop] != 0
        return out

    def facet_count(self, name: str) -> int:
        return int(self.handle["mesh/facet_groups"][name].shape[0])

    def facets(self, name: str, start: int, stop: int) -> np.ndarray:
        return np.asarray(self.handle["mesh/facet_groups"][name][start:stop], dtype=np.int64)

    def facet_slice(self, name: str, rank: int, size: int) -> tuple[np.ndarray, np.ndarray]:
        """Rank ``rank``'s rows of a facet group (of ``size`` ranks) and their row numbers."""
        n = self.facet_count(name)
        start, stop = n * rank // size, n * (rank + 1) // size
        return self.facets(name, start, stop), np.arange(start, stop, dtype=np.int64)

    def close(self) -> None:
        self.handle.close()


def open_mesh(path: str) -> MeshFile:
    """Open ``path`` read-only (every rank its own handle) and check its layout; InputError
    naming the file and the dataset otherwise. Reads the sizes only."""
    import h5py

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError("mesh file not found" if not os.path.exists(path)
                         else "mesh path is not a file", path, _KEY)
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"cannot read mesh (not an HDF5 file: {exc})", path, _KEY) from None
    try:
        return _checked(path, f)
    except InputError:
        f.close()
        raise


def _checked(path: str, f) -> MeshFile:
    def fail(message: str, key: str) -> InputError:
        return InputError(message, path, key)

    if "mesh" not in f or "points" not in f["mesh"] or "cells" not in f["mesh"]:
        raise fail("no /mesh/points and /mesh/cells (write it with `parsolve mesh convert`)",
                   "/mesh")
    types = list(f["mesh/cells"].keys())
    if len(types) != 1:
        raise fail(f"one volume cell type expected, found {types or 'none'}", "/mesh/cells")
    cell_type = types[0]
    if cell_type not in CELL_INFO:
        raise fail(f"unsupported cell type {cell_type!r} (supported: {', '.join(CELL_INFO)})",
                   f"/mesh/cells/{cell_type}")
    dim = CELL_INFO[cell_type][0]
    points, cells = f["mesh/points"], f["mesh/cells"][cell_type]
    nen = _nodes_per_cell(cell_type)
    if points.ndim != 2 or points.shape[1] != dim or points.dtype.kind != "f":
        raise fail(f"{cell_type} cells need points of shape (npoints, {dim}) of floats, "
                   f"found {points.shape} {points.dtype}", "/mesh/points")
    if cells.ndim != 2 or cells.shape[1] != nen or cells.dtype.kind not in "iu":
        raise fail(f"{cell_type} cells need shape (ncells, {nen}) of integers, found "
                   f"{cells.shape} {cells.dtype}", f"/mesh/cells/{cell_type}")
    if cells.shape[0] == 0:
        raise fail("the mesh has no cells", f"/mesh/cells/{cell_type}")
    names = {}
    for group, rows in (("cell_groups", cells.shape[0]), ("node_groups", points.shape[0])):
        found = f["mesh"].get(group, {})
        for name in found:
            if found[name].shape != (rows,):
                raise fail(f"a mask of shape ({rows},) expected, found {found[name].shape}",
                           f"/mesh/{group}/{name}")
        names[group] = tuple(sorted(found))
    nfn = len(_facet_nodes(cell_type))
    facet = f["mesh"].get("facet_groups", {})
    for name in facet:
        if facet[name].ndim != 2 or facet[name].shape[1] != nfn:
            raise fail(f"facets of {nfn} nodes expected, found shape {facet[name].shape}",
                       f"/mesh/facet_groups/{name}")
    return MeshFile(path, f, cell_type, int(cells.shape[0]), int(points.shape[0]), dim,
                    names["cell_groups"], names["node_groups"], tuple(sorted(facet)))


def _nodes_per_cell(cell_type: str) -> int:
    from parsolve.fem.elements import element

    return int(element(cell_type).nodes.shape[0])


def read_whole(path: str) -> Mesh:
    """The whole mesh of a parallel mesh file on one process (tests, and ``order = 2``
    upgrades, which the slice path does not do)."""
    f = open_mesh(path)
    try:
        cells = f.cells(0, f.num_cells)
        points = f.points(0, f.num_points)
        check_ids(f, cells, f"/mesh/cells/{f.cell_type}")
        cflags, nflags = f.cell_flags(0, f.num_cells), f.node_flags(0, f.num_points)
        mesh = Mesh(points, f.cell_type, cells,
                    cell_groups={n: np.flatnonzero(cflags[:, k]) for k, n in enumerate(f.cell_groups)},
                    node_groups={n: np.flatnonzero(nflags[:, k]) for k, n in enumerate(f.node_groups)})
        for name in f.facet_groups:
            facets = f.facets(name, 0, f.facet_count(name))
            check_ids(f, facets, f"/mesh/facet_groups/{name}")
            mesh.facet_groups[name] = facets
        return mesh
    finally:
        f.close()


def check_ids(f: MeshFile, ids: np.ndarray, key: str) -> None:
    """InputError when node ids fall outside the points (local check: callers agree on it)."""
    if ids.size and (ids.min() < 0 or ids.max() >= f.num_points):
        raise InputError(f"node ids outside 0..{f.num_points - 1}", f.path, key)


