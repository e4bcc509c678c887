"""XDMF beside a result, read by meshio and by VTK's XDMF reader (issue 6 §7), and the size of
result files (§3): runs through the real driver, on any number of ranks."""

import tomllib

import h5py
import numpy as np
import pytest

from helpers.scene import scene
from helpers.xdmf import SCENE_2D, SCENE_3D, meshio_reads_every_step, tensor6, vtk_reads_every_step
from parsolve.io.xdmf import TENSOR6_FROM_VOIGT

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
    meshio_reads_every_step(*result)


def test_vtk_reads_every_step(result):
    vtk_reads_every_step(*result)


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
    text = scene(tomllib.loads(SCENE_2D), mesh={"nx": nx, "ny": ny}, steps={"count": 1})
    run(text)
    size = run.last.stat().st_size
    ratio = size / data_bytes(run.last)
    assert ratio <= 1.5, (size, ratio)


def test_axisymmetric_tensor_layout():
    """(rr, zz, rz, θθ) → XDMF Tensor6 (xx, xy, xz, yy, yz, zz): θθ is the out-of-plane slot."""
    from parsolve.io.xdmf import layout

    assert layout(4, 2) == ("Tensor6", (0, 2, None, 1, None, 3))
    assert layout(3, 2) == ("Tensor6", (0, 2, None, 1, None, None))
