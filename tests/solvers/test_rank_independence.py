"""Results must not depend on the partition: a nonlinear material evaluated near its threshold
gives the same tangent, entry by entry, whatever the number of ranks (issue: a 3D von Mises bar
at 3 ranks picked the plastic branch on one rank and the elastic one on another for the same
cell, from round-off in the cell's geometry)."""

import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from conftest import dense, saddle_of_input_dofs
from helpers.control import VON_MISES, newton_of
from helpers.scene import scene

BAR = tomllib.loads(VON_MISES)   # nx = 5


def tangent_after(comm, text: str, steps: int) -> np.ndarray:
    """Dense consistent tangent (input DOF numbering) at the start of step ``steps + 1``."""
    scene, _, system, problem, newton = newton_of(text, comm)
    for t in scene.times[:steps]:
        newton.step(t)
    kmat = problem.form().kmat
    M = dense(system.assemble(kmat), comm)
    return M[np.ix_(*(2 * (saddle_of_input_dofs(comm, system),)))]



@pytest.mark.parametrize("nx", [4, 5, 7])
def test_von_mises_tangent_is_the_same_on_every_partition(nx):
    text = scene(BAR, mesh={"nx": nx})
    world = tangent_after(MPI.COMM_WORLD, text, 4)   # yielded at step 3: points on the surface
    alone = tangent_after(MPI.COMM_SELF, text, 4)
    scale = np.abs(alone).max()
    assert np.abs(world - alone).max() <= 1e-12 * scale
    assert np.abs(world - world.T).max() <= 1e-12 * scale  # consistent tangent of J2: symmetric


@pytest.mark.parametrize("nx", [4, 5, 7])
def test_von_mises_bar_on_several_meshes(nx, run):
    """The bar that failed at 3 ranks with nx = 4, 5, 7: complete, on the bilinear curve."""
    res = run(scene(BAR, mesh={"nx": nx}), name=f"vm{nx}")
    eps = 4e-3 * res["steps/time"]
    Et = 200e3 * 2e3 / (200e3 + 2e3)
    sigma = np.where(eps < 250 / 200e3, 200e3 * eps, 250 + Et * (eps - 250 / 200e3))
    np.testing.assert_allclose(res["relations/sym_x/multiplier"].sum(axis=1), sigma * 0.04,
                               rtol=1e-8)


def test_cell_geometry_does_not_depend_on_the_batch():
    """The same cells evaluated in batches of different sizes and offsets: identical bits."""
    from parsolve.fem import kernels
    from parsolve.mesh.generators import box

    mesh = box(1.0, 0.7, 0.3, 6, 5, 3, cell="tetra10")
    rng = np.random.default_rng(0)
    coords = mesh.points[mesh.cells] + 1e-3 * rng.standard_normal(mesh.cells.shape + (3,))
    ue = rng.standard_normal((mesh.num_cells, mesh.cells.shape[1] * 3))
    geo = kernels.CellGeometry(coords, mesh.cell_type)
    eps = kernels.strains(geo.strain_operator(), ue)
    for start, stop in ((1, 7), (3, 200), (5, mesh.num_cells)):
        part = kernels.CellGeometry(coords[start:stop], mesh.cell_type)
        assert np.array_equal(part.dNdx, geo.dNdx[start:stop])
        assert np.array_equal(kernels.strains(part.strain_operator(), ue[start:stop]),
                              eps[start:stop])


SHIPPED = sorted(p.name for p in __import__("conftest").CONFIGS.glob("*.toml"))


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scene_does_not_depend_on_the_partition(name, shared_tmp):
    """Every shipped scene on this run's ranks against the same scene on one rank: the same
    active rows exactly, the same numbers to the conditioning of the problem."""
    from conftest import CONFIGS, run_scene

    comm = MPI.COMM_WORLD
    if comm.size == 1:
        pytest.skip("compares a parallel run with a serial one")
    world = run_scene(CONFIGS / name, shared_tmp / "world.h5")
    alone = run_scene(CONFIGS / name, shared_tmp / f"alone{comm.rank}.h5", comm=MPI.COMM_SELF)
    assert world["attrs"]["status"] == alone["attrs"]["status"] == "complete"
    keys = [k for k in alone if k not in ("attrs", "steps/residual")  # round-off:
            and not (k.startswith("balance") and k.endswith("error"))  # residual, balance error
            and not k.startswith("timings")]                          # clocks
    # a multiplier that is zero in exact arithmetic is compared with the others' size
    family = {}
    for k in keys:
        tail = k.rsplit("/", 1)[-1]
        family[tail] = max(family.get(tail, 0.0), float(np.abs(alone[k]).max(initial=0.0)))
    for key in keys:
        value = alone[key]
        if key.endswith("/active"):
            assert np.array_equal(world[key], value), key
        else:
            scale = max(family[key.rsplit("/", 1)[-1]], 1e-300)
            # (plus 1e-13: a quantity zero in exact arithmetic in its whole family, e.g. the
            # flux of a uniform field)
            assert np.abs(world[key] - value).max() <= 1e-7 * scale + 1e-13, key
