"""XDMF beside a result, read by meshio and by VTK's XDMF reader (issue 6 §7), and the size of
result files (§3): runs through the real driver, on any number of ranks."""

import h5py
import numpy as np
import pytest

from parsolve.io.xdmf import TENSOR6_FROM_VOIGT

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


@pytest.fixture(params=[(SCENE_2D, 2, 3), (SCENE_3D, 3, 2)], ids=["2d", "3d"])
def result(request, run):
    text, dim, nsteps = request.param
    data = run(text)
    assert len(data["steps/time"]) == nsteps
    return run.last, data, dim


def test_tensor6_mapping_matches_voigt():
    assert tensor6(np.arange(3.0), 2).tolist() == [0, 2, 0, 1, 0, 0]
    for dim, columns in TENSOR6_FROM_VOIGT.items():
        voigt = np.arange(1.0, 4.0 if dim == 2 else 7.0)
        got = [0.0 if c is None else voigt[c] for c in columns]
        np.testing.assert_array_equal(got, tensor6(voigt, dim))


def test_meshio_reads_every_step(result):
    import meshio

    path, data, dim = result
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


def test_vtk_reads_every_step(result):
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    path, data, dim = result
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


def test_xdmf_views_cost_metadata_only(result):
    path, data, dim = result
    sidecar = path.with_suffix(".xdmf.h5")
    with h5py.File(sidecar, "r") as f:
        view = f["fields/displacement/0"]
        assert view.is_virtual and view.shape == (len(data["mesh/points"]), 3)
    with h5py.File(sidecar, "r") as f:
        views = []
        f.visititems(lambda n, o: views.append(n) if isinstance(o, h5py.Dataset) else None)
    # 3 views per step (displacement, nodal stress, cell stress), whatever the mesh size:
    # mappings, not data (the 120 x 60 mesh's data would be 1.2 MB per step)
    assert len(views) == 3 * len(data["steps/time"])
    assert sidecar.stat().st_size <= 4096 + 2048 * len(views)


def data_bytes(path) -> int:
    with h5py.File(path, "r") as f:
        sizes = []
        f.visititems(lambda n, o: sizes.append(o.nbytes) if isinstance(o, h5py.Dataset) else None)
        total = sum(sizes) + sum(len(str(v)) for v in f.attrs.values())
    return total


@pytest.mark.parametrize("nx, ny", [(30, 15), (120, 60)])
def test_one_step_file_within_1_5_times_its_data(run, nx, ny):
    text = SCENE_2D.replace("nx = 8", f"nx = {nx}").replace("ny = 4", f"ny = {ny}") \
                   .replace("count = 3", "count = 1")
    run(text)
    size = run.last.stat().st_size
    ratio = size / data_bytes(run.last)
    assert ratio <= 1.5, (size, ratio)
