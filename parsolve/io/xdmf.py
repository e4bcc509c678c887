"""XDMF (v3) description of a parsolve HDF5 file, for ParaView: one grid per saved step."""

from __future__ import annotations

from pathlib import Path

TOPOLOGY = {"triangle": "Triangle", "triangle6": "Triangle_6", "quad": "Quadrilateral",
            "tetra": "Tetrahedron", "tetra10": "Tetrahedron_10", "hexahedron": "Hexahedron"}


def _slab(h5name: str, path: str, step: int, nsteps: int, n: int, ncomp: int) -> str:
    return (f'<DataItem ItemType="HyperSlab" Dimensions="{n} {ncomp}">'
            f'<DataItem Dimensions="3 3" Format="XML">{step} 0 0 1 1 1 1 {n} {ncomp}</DataItem>'
            f'<DataItem Dimensions="{nsteps} {n} {ncomp}" Format="HDF">{h5name}:{path}</DataItem>'
            "</DataItem>")


def _attribute(name: str, center: str, body: str, ncomp: int) -> str:
    kind = "Scalar" if ncomp == 1 else "Vector" if ncomp == 3 else "Matrix"
    return f'<Attribute Name="{name}" AttributeType="{kind}" Center="{center}">{body}</Attribute>'


def write_xdmf(path: Path, h5name: str, cell_type: str, npoints: int, ncells: int, nodes: int,
               dim: int, times: list[float], fields: dict[str, int], cell_fields: dict[str, int]) -> None:
    """fields / cell_fields: name -> number of components."""
    nsteps = len(times)
    geometry = (f'<Geometry GeometryType="{"XY" if dim == 2 else "XYZ"}">'
                f'<DataItem Dimensions="{npoints} {dim}" Format="HDF">{h5name}:/mesh/points</DataItem>'
                "</Geometry>")
    topology = (f'<Topology TopologyType="{TOPOLOGY[cell_type]}" NumberOfElements="{ncells}">'
                f'<DataItem Dimensions="{ncells} {nodes}" Format="HDF">{h5name}:/mesh/cells/{cell_type}'
                "</DataItem></Topology>")
    grids = []
    for step, t in enumerate(times):
        attrs = [_attribute(n, "Node", _slab(h5name, f"/fields/{n}", step, nsteps, npoints, c), c)
                 for n, c in fields.items()]
        attrs += [_attribute(n, "Cell", _slab(h5name, f"/cell_fields/{n}", step, nsteps, ncells, c), c)
                  for n, c in cell_fields.items()]
        grids.append(f'<Grid Name="step {step}" GridType="Uniform"><Time Value="{t!r}"/>'
                     f'{topology}{geometry}{"".join(attrs)}</Grid>')
    text = ('<?xml version="1.0"?>\n<Xdmf Version="3.0"><Domain>'
            '<Grid Name="parsolve" GridType="Collection" CollectionType="Temporal">'
            + "\n".join(grids) + "</Grid></Domain></Xdmf>\n")
    tmp = path.with_suffix(".xdmf.tmp")
    tmp.write_text(text)
    tmp.replace(path)
