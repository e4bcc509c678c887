"""More ranks than cells on the distributed mesh: a rank whose part holds no cell and no node
still takes part in every collective step (relations, solve, Newton, outputs) and the results
are those of the one rank alone."""

import pytest
from mpi4py import MPI

from conftest import assert_same_results, run_scene
from helpers.scene import scene, shipped

# the gas-solubility scene on two triangles: a relation of per-node groups, transient fields
SOLUBILITY_PAIR = scene(shipped("solubility_well_mixed.toml"), mesh={"nx": 1, "ny": 1})

PLASTIC_PAIR = """
[mesh]
generator = "box"
lx = 2.0
ly = 1.0
lz = 1.0
nx = 2
ny = 1
nz = 1
[model]
hypothesis = "3d"
[[materials]]
model = "von_mises"
E = 200e3
nu = 0.3
sigma_y = 250.0
H = 2e3
[[relations]]
name = "clamp"
type = "dirichlet"
region = "xmin"
components = ["x", "y", "z"]
[[relations]]
name = "pull"
type = "mean"
region = "xmax"
component = "x"
value = 4e-3
[steps]
count = 4
"""

ELASTIC_PAIR = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 1.0
nx = 2
ny = 1
cell = "quad"
[model]
hypothesis = "plane_stress"
[[materials]]
E = 1.0
nu = 0.3
[[loads]]
name = "pull"
region = "right"
traction = [1.0, 0.0]
[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x", "y"]
"""


@pytest.mark.parametrize("scene", [ELASTIC_PAIR, PLASTIC_PAIR, SOLUBILITY_PAIR],
                         ids=["elastic", "plastic", "solubility"])
def test_two_cells_on_any_number_of_ranks(scene, shared_tmp, comm):
    parts = run_scene(scene, shared_tmp / "parts.h5")
    whole = run_scene(scene, shared_tmp / f"whole{MPI.COMM_WORLD.rank}.h5", comm=MPI.COMM_SELF)
    assert_same_results(parts, whole, 1e-10)
    # the plastic pair yields (strain 2e-3 at the end, 1.25e-3 at yield): the pull's force
    # falls below the elastic line through the first step (elastic at 5e-4)
    if scene is PLASTIC_PAIR:
        force = abs(parts["relations/pull/multiplier"][:, 0])
        assert force.size == 4 and force[-1] < 0.8 * 4 * force[0]
