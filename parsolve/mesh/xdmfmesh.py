"""An XDMF + HDF5 mesh (as meshio and DOLFINx write it) read by slices: every rank a contiguous
hyperslab of the topology and geometry datasets (``slices.SliceSource``), never the whole.

The mesh is the first uniform grid with a geometry and a topology of one supported cell type
(``mesh.CELL_INFO``; XDMF's node order is meshio's), its data in HDF5 (``file.h5:/path``,
relative to the .xdmf). Regions, each tag value > 0 a group named by the value (as a Gmsh
physical group without a name):

* cell tags on the mesh grid — an integer attribute centred on the cells, ``gmsh:physical``
  if there is one (meshio's name when it converted a Gmsh file: the groups ``reader.read_mesh``
  gives), else the first: cell groups;
* DOLFINx's mesh tags — other grids with a topology and an integer cell attribute (the tagged
  entities by their nodes): of the cell type, cell groups (each tagged cell found among the
  cells by its sorted nodes, at the rank a hash of them names); of the facet type, facet groups.

A file the slices cannot read (a "Mixed" topology, data inline in the XML, a time series of
grids) is read whole by meshio on rank 0 (``open_xdmf`` returns None).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from parsolve.collective import agree
from parsolve.errors import InputError
from parsolve.mesh.blocks import exchange
from parsolve.mesh.gmshmesh import _in_range, _oriented, _planar, read_rows
from parsolve.mesh.mesh import CELL_INFO
from parsolve.mesh.partition import block_starts
from parsolve.mesh.slices import hash_ranks
from parsolve.mesh.topology import NUM_VERTICES, sorted_row_groups

_KEY = "mesh.file"
# XDMF topology types -> meshio cell types (those a mesh can have)
TYPES = {"Triangle": "triangle", "Triangle_6": "triangle6", "Quadrilateral": "quad",
         "Tetrahedron": "tetra", "Tetrahedron_10": "tetra10", "Hexahedron": "hexahedron",
         "Polyline": "line", "Edge_3": "line3"}


def is_xdmf(path: str) -> bool:
    return os.fspath(path).lower().endswith((".xdmf", ".xdmf3"))


@dataclass
class Layout:
    """Where the mesh's datasets are: (HDF5 file, dataset path) of each."""

    path: str
    cell_type: str
    topology: tuple[str, str]
    geometry: tuple[str, str]
    cell_tags: tuple[str, str] | None = None        # on the mesh grid
    entity_tags: list[tuple[str, tuple[str, str], tuple[str, str]]] = field(
        default_factory=list)                       # (cell or facet, topology, values)


def _item(grid_child, xdmf: str) -> tuple[str, str] | None:
    """(HDF5 file, dataset) of an element's one DataItem; None if it is not in HDF5."""
    items = grid_child.findall("DataItem")
    if len(items) != 1 or items[0].get("Format", "XML") != "HDF" or not items[0].text:
        return None
    name, _, dataset = items[0].text.strip().partition(":")
    return os.path.join(os.path.dirname(os.path.abspath(xdmf)), name), dataset


def scan(path: str, key: str = _KEY) -> Layout | None:
    """The layout of ``path`` (None: not for slices). InputError for an unreadable file."""
    if not os.path.isfile(path):
        raise InputError("mesh file not found" if not os.path.exists(path)
                         else "mesh path is not a file", path, key)
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise InputError(f"cannot read mesh ({exc})", path, key) from None
    grids = [g for g in root.iter("Grid") if g.get("GridType", "Uniform") == "Uniform"]
    if any(g.get("GridType") == "Collection" for g in root.iter("Grid")):
        return None
    mesh, lay = None, None
    for g in grids:
        topo, geo = g.find("Topology"), g.find("Geometry")
        cell = TYPES.get(topo.get("TopologyType", "") if topo is not None else "")
        if lay is None and geo is not None and cell in CELL_INFO:
            top, xyz = _item(topo, path), _item(geo, path)
            if top is None or xyz is None:
                return None
            mesh, lay = g, Layout(path, cell, top, xyz)
    if lay is None:
        return None
    facet = CELL_INFO[lay.cell_type][1]
    tags = [(a.get("Name", ""), _item(a, path)) for a in mesh.findall("Attribute")
            if a.get("Center") == "Cell"]
    tags = sorted((t for t in tags if t[1] is not None), key=lambda t: t[0] != "gmsh:physical")
    lay.cell_tags = tags[0][1] if tags else None
    for g in grids:
        topo, attr = g.find("Topology"), g.find("Attribute")
        if g is mesh or topo is None or attr is None or attr.get("Center") != "Cell":
            continue
        kind = TYPES.get(topo.get("TopologyType", ""))
        entity = "cell" if kind == lay.cell_type else "facet" if kind == facet else None
        top, values = _item(topo, path), _item(attr, path)
        if entity and top and values:
            lay.entity_tags.append((entity, top, values))
    return lay


def open_xdmf(comm, path: str, key: str = _KEY) -> "XdmfSlices | None":
    """The slices of ``path``, or None for the rank-0 path.
    Collective; InputError on every rank."""
    lay = agree(comm, scan, path, key)   # (a small XML file: every rank parses it)
    return None if lay is None else XdmfSlices(comm, lay, key)


class _Files:
    """The HDF5 files of a layout, each opened once."""

    def __init__(self, xdmf: str, key: str):
        self.xdmf, self.key, self.open = xdmf, key, {}

    def __call__(self, where: tuple[str, str]):
        import h5py

        name, dataset = where
        if name not in self.open:
            try:
                self.open[name] = h5py.File(name, "r")
            except OSError as exc:
                raise InputError(f"cannot read the mesh's HDF5 file {name} ({exc})", self.xdmf,
                                 self.key) from None
        if dataset not in self.open[name]:
            raise InputError(f"no dataset {dataset} in {name}", self.xdmf, self.key)
        return self.open[name][dataset]

    def close(self) -> None:
        for f in self.open.values():
            f.close()


class XdmfSlices:
    """An XDMF mesh as a ``slices.SliceSource``: this rank's rows, read at construction
    (collective: the cells' orientation and the DOLFINx cell tags ask other ranks)."""

    def __init__(self, comm, lay: Layout, key: str = _KEY):
        size, rank = comm.size, comm.rank
        files = _Files(lay.path, key)
        try:
            top, geo = files(lay.topology), files(lay.geometry)
            self.path, self.cell_type = lay.path, lay.cell_type
            self.dim = CELL_INFO[lay.cell_type][0]
            self.num_cells, self.num_points = int(top.shape[0]), int(geo.shape[0])
            if self.num_cells == 0:
                raise InputError("the mesh has no cells", lay.path, key)
            cs = block_starts(self.num_cells, size)
            ps = block_starts(self.num_points, size)
            self._cs = int(cs[rank]), int(cs[rank + 1])
            self._ps = int(ps[rank]), int(ps[rank + 1])
            cells = np.asarray(top[slice(*self._cs)], dtype=np.int64)
            self._points = _planar(comm, np.asarray(geo[slice(*self._ps)], dtype=float), self.dim,
                                   lay.path, key)
            agree(comm, _in_range, cells, "cells refer to points that do not exist", lay.path,
                  key, self.num_points)
            self._cells = _oriented(comm, cells, ps, self._points, lay.cell_type)
            values = [] if lay.cell_tags is None else [
                np.asarray(files(lay.cell_tags)[slice(*self._cs)], dtype=np.int64).ravel()]
            facets = []
            for entity, where, tags in lay.entity_tags:
                n = int(files(where).shape[0])
                a, b = n * rank // size, n * (rank + 1) // size
                rows = np.asarray(files(where)[a:b], dtype=np.int64).reshape(b - a, -1)
                vals = np.asarray(files(tags)[a:b], dtype=np.int64).ravel()
                if entity == "cell":
                    values.append(_cell_values(comm, self._cells, rows, vals, lay.cell_type))
                else:
                    facets.append((rows, vals, np.arange(a, b, dtype=np.int64)))
        finally:
            files.close()
        self._values = values
        self.cell_groups = _names(comm, values)
        self.facet_groups = _names(comm, [v for _, v, _ in facets])
        self.node_groups: tuple[str, ...] = ()
        self._facets = {name: _facet_rows(facets, int(name)) for name in self.facet_groups}

    def cells(self, start: int, stop: int) -> np.ndarray:
        return self._mine(self._cells, self._cs, start, stop)

    def points(self, start: int, stop: int) -> np.ndarray:
        return self._mine(self._points, self._ps, start, stop)

    def cell_flags(self, start: int, stop: int) -> np.ndarray:
        self._mine(self._cells, self._cs, start, stop)
        out = np.zeros((stop - start, len(self.cell_groups)), dtype=bool)
        for k, name in enumerate(self.cell_groups):
            for v in self._values:
                out[:, k] |= v == int(name)
        return out

    def node_flags(self, start: int, stop: int) -> np.ndarray:
        return np.zeros((stop - start, 0), dtype=bool)

    def facet_slice(self, name: str, rank: int, size: int) -> tuple[np.ndarray, np.ndarray]:
        return self._facets[name]

    _mine = staticmethod(read_rows)


def _names(comm, values: list[np.ndarray]) -> tuple[str, ...]:
    """The tag values > 0 of every rank, as group names in increasing value."""
    mine = np.unique(np.concatenate(values)) if values else np.zeros(0, np.int64)
    found = np.unique(np.concatenate(comm.allgather(mine)))
    return tuple(str(int(v)) for v in found if v > 0)


def _facet_rows(facets, value: int) -> tuple[np.ndarray, np.ndarray]:
    """The rows of this rank's share of the facet tags with ``value`` and their row numbers."""
    rows = [(r[v == value], at[v == value]) for r, v, at in facets]
    return np.concatenate([r for r, _ in rows]), np.concatenate([a for _, a in rows])


def _cell_values(comm, cells: np.ndarray, tagged: np.ndarray, values: np.ndarray,
                 cell_type: str) -> np.ndarray:
    """Each slice cell's tag among DOLFINx's tagged cells (given by their nodes; 0: none):
    cells and tagged cells meet by their sorted corner nodes at the rank a hash of them names,
    and the tags go back to the cells' slices."""
    corners = slice(0, NUM_VERTICES[cell_type])
    here = np.arange(cells.shape[0], dtype=np.int64)
    rank_col = np.full(cells.shape[0], comm.rank, np.int64)

    def rows(nodes, a, b):   # sorted corners, then two payload columns
        key = np.sort(nodes[:, corners], axis=1)
        return np.column_stack([key, a, b])

    mine = rows(cells, here, rank_col)
    tags = rows(tagged, values, np.full(values.size, -1, np.int64))
    both = np.concatenate([mine, tags])
    got, _ = exchange(comm, both, hash_ranks(both[:, :-2], comm.size))
    o, g, _ = sorted_row_groups(got[:, :-2])
    got, g = got[o], g
    is_tag = got[:, -1] < 0
    value_of = np.zeros(g.max() + 1 if g.size else 0, np.int64)
    value_of[g[is_tag]] = got[is_tag, -2]
    cell_rows = got[~is_tag]
    back, _ = exchange(comm, np.column_stack([cell_rows[:, -2], value_of[g[~is_tag]]]),
                       cell_rows[:, -1])
    out = np.zeros(cells.shape[0], np.int64)
    out[back[:, 0]] = back[:, 1]
    return out
