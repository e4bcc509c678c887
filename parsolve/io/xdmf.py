"""XDMF (v3) description of a parsolve result, read by ParaView / VTK and by meshio.

Layout (``r.h5`` the result):

* ``r.xdmf``: a temporal collection with one uniform grid per finished step. Mesh from
  ``r.h5:/mesh``; every attribute is a plain ``Format="HDF"`` DataItem (meshio reads no
  HyperSlab and no Function) pointing at ``r.xdmf.h5``.
* ``r.xdmf.h5``: per step, one HDF5 *virtual* dataset per field that maps the step's slice of
  ``r.h5`` (no data copied: a few hundred bytes of mapping each). Vectors become 3-component
  "Vector" (2D padded with the fill value 0), symmetric tensors "Tensor6" in XDMF's order
  (xx, xy, xz, yy, yz, zz; 2D stress padded), one component "Scalar", anything else "Matrix".

The XDMF file is appended, not rewritten: the closing tags sit at a known offset and each step
overwrites them with its grid followed by the closing tags, in one ``pwrite``. If that write
fails (disk full) the old closing tags are put back and the file cut to its old length, so the
file is always a complete document. The virtual datasets are resolved by HDF5 when the result
is read: they read the result once the run has closed it (during the run, read ``r.h5`` itself
with ``swmr=True``).
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

TOPOLOGY = {"triangle": "Triangle", "triangle6": "Triangle_6", "quad": "Quadrilateral",
            "quad8": "Quadrilateral_8", "quad9": "Quadrilateral_9", "tetra": "Tetrahedron",
            "tetra10": "Tetrahedron_10",
            "hexahedron": "Hexahedron", "hexahedron20": "Hexahedron_20",
            "hexahedron27": "Hexahedron_27"}
TAIL = b"</Grid></Domain></Xdmf>\n"

# XDMF Tensor6 component k <- Voigt component (DESIGN §5); None: padded with 0
TENSOR6_FROM_VOIGT = {2: (0, 2, None, 1, None, None),   # 2D (xx, yy, xy)
                      3: (0, 5, 4, 1, 3, 2)}           # 3D (xx, yy, zz, yz, xz, xy)


def sidecar_path(result: Path) -> Path:
    """The file of per-step virtual datasets beside ``result``."""
    return Path(result).with_suffix(".xdmf.h5")


def layout(ncomp: int, dim: int) -> tuple[str, tuple]:
    """(AttributeType, source component of each XDMF component, None = 0) for a field."""
    if ncomp == 1:
        return "Scalar", (0,)
    if ncomp == dim:
        return "Vector", tuple(range(dim)) + (None,) * (3 - dim)
    if ncomp == dim * (dim + 1) // 2:
        return "Tensor6", TENSOR6_FROM_VOIGT[dim]
    if dim == 2 and ncomp == 4:   # axisymmetric (rr, zz, rz, θθ): the hoop value is the zz slot
        return "Tensor6", (0, 2, None, 1, None, 3)
    return "Matrix", tuple(range(ncomp))


def _create_view(f: h5py.File, name: str, source_file: str, source: str, step: int, n: int,
                 ncomp: int, columns: tuple) -> None:
    """A virtual dataset (n, len(columns)) — (n,) for one column — whose column k is column
    ``columns[k]`` of ``source[step]`` (0 where None). Low-level h5py: the high-level
    VirtualLayout costs ~3 ms a view."""
    shape = (n,) if len(columns) == 1 else (n, len(columns))
    dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    dcpl.set_fill_value(np.zeros(1))
    for k, c in enumerate(columns):
        if c is None:
            continue
        view = h5py.h5s.create_simple(shape)
        view.select_hyperslab((0,) if len(shape) == 1 else (0, k), (n,) if len(shape) == 1 else (n, 1))
        src = h5py.h5s.create_simple((step + 1, n, ncomp), (h5py.h5s.UNLIMITED, n, ncomp))
        src.select_hyperslab((step, 0, c), (1, n, 1))
        dcpl.set_virtual(view, source_file.encode(), source.encode(), src)
    lcpl = h5py.h5p.create(h5py.h5p.LINK_CREATE)
    lcpl.set_create_intermediate_group(True)
    h5py.h5d.create(f.id, name.encode(), h5py.h5t.IEEE_F64LE, h5py.h5s.create_simple(shape),
                    dcpl=dcpl, lcpl=lcpl)


class XdmfWriter:
    """Appends one grid per finished step to ``<result>.xdmf`` (rank 0 only)."""

    def __init__(self, result: Path, mesh):
        self.result = Path(result)
        self.path = self.result.with_suffix(".xdmf")
        self.sidecar = sidecar_path(self.result)
        self.mesh = mesh
        self.offset: int | None = None  # where the closing tags start
        self.views: h5py.File | None = None  # the sidecar, open for the whole run

    def close(self) -> None:
        if self.views is not None:
            views, self.views = self.views, None
            views.close()

    def append(self, step: int, t: float, fields: dict[str, int], cell_fields: dict[str, int]) -> None:
        """Describe finished step ``step`` (its data already flushed to the result)."""
        items = [(name, "Node", "fields", ncomp, self.mesh.num_points) for name, ncomp in fields.items()]
        items += [(name, "Cell", "cell_fields", ncomp, self.mesh.num_cells)
                  for name, ncomp in cell_fields.items()]
        self._virtual(step, items)
        if self.offset is None:
            self._start()
        self._write(self._grid(step, t, items).encode())

    def _virtual(self, step: int, items: list) -> None:
        """The step's padded / reordered views of the result's datasets (metadata only)."""
        dim = self.mesh.dim
        if self.views is None:
            # earliest file format: a file left open by a crash still opens (no SWMR flags)
            self.views = h5py.File(self.sidecar, "w")
        f = self.views
        for name, _, group, ncomp, n in items:
            _, columns = layout(ncomp, dim)
            _create_view(f, f"{group}/{name}/{step}", self.result.name, f"/{group}/{name}",
                         step, n, ncomp, columns)
        f.flush()  # before the XDMF names them

    def _start(self) -> None:
        """The document with no step yet, written beside and renamed: never half there."""
        mesh, h5 = self.mesh, self.result.name
        head = ('<?xml version="1.0"?>\n<Xdmf Version="3.0"><Domain>\n'
                '<Grid Name="parsolve" GridType="Collection" CollectionType="Temporal">\n').encode()
        tmp = self.path.with_name(self.path.name + ".tmp")
        tmp.write_bytes(head + TAIL)
        tmp.replace(self.path)
        self.offset = len(head)
        nodes = mesh.nodes_per_cell
        self._mesh = (
            f'<Topology TopologyType="{TOPOLOGY[mesh.cell_type]}" NumberOfElements="{mesh.num_cells}">'
            f'<DataItem Dimensions="{mesh.num_cells} {nodes}" NumberType="Int" Precision="8" '
            f'Format="HDF">{h5}:/mesh/cells/{mesh.cell_type}</DataItem></Topology>'
            f'<Geometry GeometryType="{"XY" if mesh.dim == 2 else "XYZ"}">'
            f'<DataItem Dimensions="{mesh.num_points} {mesh.dim}" NumberType="Float" Precision="8" '
            f'Format="HDF">{h5}:/mesh/points</DataItem></Geometry>')

    def _grid(self, step: int, t: float, items: list) -> str:
        attrs = []
        for name, center, group, ncomp, n in items:
            kind, columns = layout(ncomp, self.mesh.dim)
            dims = f"{n}" if len(columns) == 1 else f"{n} {len(columns)}"
            attrs.append(f'<Attribute Name="{name}" AttributeType="{kind}" Center="{center}">'
                         f'<DataItem Dimensions="{dims}" NumberType="Float" Precision="8" '
                         f'Format="HDF">{self.sidecar.name}:/{group}/{name}/{step}</DataItem>'
                         '</Attribute>')
        return (f'<Grid Name="step {step}" GridType="Uniform"><Time Value="{float(t)!r}"/>'
                f'{self._mesh}{"".join(attrs)}</Grid>\n')

    def _write(self, grid: bytes) -> None:
        """Grid + closing tags over the old closing tags, in one write; undone if it fails."""
        fd = os.open(self.path, os.O_WRONLY)
        try:
            data = grid + TAIL
            try:
                written = os.pwrite(fd, data, self.offset)
                if written != len(data):
                    raise OSError(28, os.strerror(28))  # short write: the disk is full
            except OSError:
                os.pwrite(fd, TAIL, self.offset)   # overwrites bytes already allocated
                os.ftruncate(fd, self.offset + len(TAIL))
                raise
            self.offset += len(grid)
        finally:
            os.close(fd)
