"""Scenes and checks of the XDMF beside a result file, shared by tests/io/test_xdmf.py and
tests/io/test_parallel_output.py (both output modes must write the same XDMF)."""

import numpy as np
import pytest

SCENE_2D = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 1.0
nx = 8
ny = 4
cell = "triangle"

[model]
hypothesis = "plane_stress"
thickness = 1.0

[[materials]]
E = 1000.0
nu = 0.25

[[loads]]
name = "pull"
region = "right"
traction = [1.0, 0.5]

[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x", "y"]

[steps]
count = 3
"""

SCENE_3D = """
[mesh]
generator = "box"
lx = 4.0
ly = 1.0
lz = 1.0
nx = 4
ny = 2
nz = 2
cell = "tetra"

[model]
hypothesis = "3d"

[[materials]]
E = 1000.0
nu = 0.3

[[loads]]
name = "end"
region = "xmax"
traction = [0.2, 0.1, -0.3]

[[relations]]
name = "clamp"
type = "dirichlet"
region = "xmin"
components = ["x", "y", "z"]

[steps]
count = 2
"""


def tensor6(voigt: np.ndarray, dim: int) -> np.ndarray:
    """Independent reordering: XDMF Tensor6 (xx, xy, xz, yy, yz, zz) from DESIGN's Voigt order."""
    names = {2: ["xx", "yy", "xy"], 3: ["xx", "yy", "zz", "yz", "xz", "xy"]}[dim]
    out = np.zeros(voigt.shape[:-1] + (6,))
    for k, name in enumerate(["xx", "xy", "xz", "yy", "yz", "zz"]):
        if name in names:
            out[..., k] = voigt[..., names.index(name)]
    return out


def full_tensor(t6: np.ndarray) -> np.ndarray:
    """The 9 components VTK's reader makes of a Tensor6, row by row."""
    xx, xy, xz, yy, yz, zz = t6.T
    return np.stack([xx, xy, xz, xy, yy, yz, xz, yz, zz], axis=1)


def meshio_reads_every_step(path, data: dict, dim: int) -> None:
    """meshio's XDMF reader finds every step of the result ``path`` (read as ``data``)."""
    import meshio

    node, cell = 7, 5
    with meshio.xdmf.TimeSeriesReader(path.with_suffix(".xdmf")) as r:
        points, cells = r.read_points_cells()
        np.testing.assert_array_equal(points, data["mesh/points"])
        assert r.num_steps == len(data["steps/time"])
        for k in range(r.num_steps):
            t, point_data, cell_data = r.read_data(k)
            assert t == data["steps/time"][k]
            u = point_data["displacement"]
            assert u.shape == (len(points), 3)
            np.testing.assert_array_equal(u[node, :dim], data["fields/displacement"][k, node])
            np.testing.assert_array_equal(u[:, dim:], 0.0)
            s = cell_data["stress"][0]
            assert s.shape == (len(cells[0].data), 6)
            np.testing.assert_array_equal(s[cell], tensor6(data["cell_fields/stress"][k, cell], dim))


def vtk_reads_every_step(path, data: dict, dim: int) -> None:
    """VTK's XDMF reader (ParaView's) finds every step (skipped without vtk)."""
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    node, cell = 7, 5
    reader = vtk.vtkXdmfReader()
    reader.SetFileName(str(path.with_suffix(".xdmf")))
    reader.UpdateInformation()
    times = reader.GetOutputInformation(0).Get(vtk.vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    np.testing.assert_array_equal(times, data["steps/time"])
    for k, t in enumerate(times):
        reader.UpdateTimeStep(t)
        grid = reader.GetOutputDataObject(0)
        assert grid.GetNumberOfPoints() == len(data["mesh/points"])
        u = grid.GetPointData().GetArray("displacement")
        assert u.GetNumberOfComponents() == 3 and u.GetNumberOfTuples() == grid.GetNumberOfPoints()
        u = vtk_to_numpy(u)
        np.testing.assert_array_equal(u[node, :dim], data["fields/displacement"][k, node])
        np.testing.assert_array_equal(u[:, dim:], 0.0)
        s = grid.GetCellData().GetArray("stress")
        # VTK's (XDMF 2) reader expands a Tensor6 to the full 3 × 3 tensor
        assert s.GetNumberOfComponents() == 9 and s.GetNumberOfTuples() == grid.GetNumberOfCells()
        expected = full_tensor(tensor6(data["cell_fields/stress"][k], dim)[None, cell])[0]
        np.testing.assert_array_equal(vtk_to_numpy(s)[cell], expected)
