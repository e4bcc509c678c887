"""Nodal fields by lumped L² projection (parsolve.post.projection), alone on known fields and
through ``parsolve post --derive`` on a patch test (1, 2, 3 ranks: the run is parallel, the
post-processing reads the file)."""

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from parsolve.post.cli import main
from parsolve.post.derive import full_tensor, von_mises
from parsolve.post.projection import lumped_weights, nodal_names, project

from post.test_post import A, G, PATCH


def grid(nx: int, ny: int, hx: float, hy: float) -> tuple[np.ndarray, np.ndarray]:
    """A structured quad mesh (counter-clockwise cells)."""
    x, y = np.meshgrid(np.arange(nx + 1) * hx, np.arange(ny + 1) * hy)
    points = np.column_stack([x.ravel(), y.ravel()])
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    n0 = (j * (nx + 1) + i).ravel()
    return points, np.column_stack([n0, n0 + 1, n0 + nx + 2, n0 + nx + 1])


def linear(x: np.ndarray) -> np.ndarray:
    return 3.0 - 2.0 * x[..., 0] + 5.0 * x[..., 1]


def test_lumped_weights_sum_to_each_cell_measure():
    points, cells = grid(3, 2, 0.5, 0.25)
    w = lumped_weights(points, cells, "quad")
    np.testing.assert_allclose(w, 0.125 / 4, rtol=1e-14)     # a rectangle: a quarter each
    # quadratic triangles: the row sums of the mass are 0 at the corners, HRZ's are positive
    tri6 = np.array([[0, 0], [1, 0], [0, 1], [0.5, 0], [0.5, 0.5], [0, 0.5]], dtype=float)
    w6 = lumped_weights(tri6, np.arange(6)[None, :], "triangle6")[0]
    # ∫ N_a² on a triangle of area A: A/30 at the corners, 8A/45 at the midsides; scaled to A
    ref = np.array([1 / 30] * 3 + [8 / 45] * 3)
    np.testing.assert_allclose(w6, 0.5 * ref / ref.sum(), rtol=1e-13)


def test_projection_of_a_constant_field_is_exact_and_a_linear_one_at_symmetric_nodes():
    points, cells = grid(4, 3, 0.5, 0.3)
    centroids = points[cells].mean(axis=1)
    steps = np.stack([np.full((len(cells), 2), [7.5, -1.25]),                 # constant
                      np.column_stack([linear(centroids), 2 * linear(centroids)])])
    nodal = project(points, cells, "quad", steps)
    np.testing.assert_allclose(nodal[0], np.tile([7.5, -1.25], (len(points), 1)), rtol=1e-14)
    # interior nodes: four equal cells about the node, whose means average to f(node)
    x, y = points.T
    inner = (x > 0) & (x < 2.0) & (y > 0) & (y < 0.9 - 1e-12)
    assert inner.sum() == 6
    np.testing.assert_allclose(nodal[1][inner, 0], linear(points[inner]), rtol=1e-13)
    np.testing.assert_allclose(nodal[1][inner, 1], 2 * linear(points[inner]), rtol=1e-13)
    # a corner belongs to one cell: its value is that cell's mean, f(centroid)
    np.testing.assert_allclose(nodal[1][0, 0], linear(np.array([0.25, 0.15])), rtol=1e-14)
    # an edge node between two cells: the mean of their two centroids' values
    np.testing.assert_allclose(nodal[1][1, 0], linear(np.array([0.5, 0.15])), rtol=1e-14)


def test_unused_node_is_nan_and_names_keep_the_runs_fields():
    points, cells = grid(1, 1, 1.0, 1.0)
    points = np.vstack([points, [[5.0, 5.0]]])
    out = project(points, cells, "quad", np.ones((1, 1, 1)))
    np.testing.assert_allclose(out[0, :4, 0], 1.0)
    assert np.isnan(out[0, 4, 0])
    assert nodal_names(["stress", "von_mises"], ["displacement", "stress"]) == \
        {"stress": "stress_projected", "von_mises": "von_mises"}


@pytest.mark.parametrize("cell", ["quad", "triangle6"])
def test_derive_writes_projected_nodal_fields_and_their_xdmf(run, shared_tmp, cell):
    """The patch test's stress is constant: every projected nodal value is σ = C ε exactly,
    von Mises of it too; the maximum of the nodal von Mises field is a curve."""
    run(PATCH.format(cell=cell), name=f"proj_{cell}")
    out = shared_tmp / f"proj_{cell}_{MPI.COMM_WORLD.rank}.h5"
    assert main([str(run.last), "--derive", str(out)]) == 0
    e = np.array([G[0, 0], G[1, 1], G[0, 1] + G[1, 0]])
    C = 100.0 / (1 - 0.25 ** 2) * np.array([[1, 0.25, 0], [0.25, 1, 0], [0, 0, 0.375]])
    sigma = C @ e
    vm = von_mises(full_tensor(sigma, 2))
    with h5py.File(out, "r") as f:
        n = len(f["mesh/points"])
        for step, t in enumerate((0.5, 1.0)):
            np.testing.assert_allclose(f["fields/stress_projected"][step], np.tile(t * sigma, (n, 1)),
                                       rtol=1e-10)
            np.testing.assert_allclose(f["fields/von_mises"][step][:, 0], t * vm, rtol=1e-10)
        assert f["fields/principal_stress"].shape == (2, n, 3)
        assert f["fields/strain"].shape == (2, n, 3)
    xdmf = out.with_suffix(".xdmf").read_text()
    assert 'Name="von_mises"' in xdmf and 'Name="stress_projected"' in xdmf
    assert main([str(out), "--x", "time", "--y", "max:field:von_mises", "--csv",
                 str(out.with_suffix(".csv"))]) == 0
    rows = out.with_suffix(".csv").read_text().splitlines()[1:]
    np.testing.assert_allclose([float(r.split(",")[-1]) for r in rows], [0, 0.5 * vm, vm], rtol=1e-10)
