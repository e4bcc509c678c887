"""Every load kind, every relation type and the springs on the distributed mesh when ranks hold none of
their region: a tall strip (2 × 16 cells) whose top, tip and upper cells live on one or two
ranks of 2, 3 or 4. Each case runs on the parts (every rank of the world) and alone (one
rank, the whole mesh, on every rank): the same results to 1e-10 of each quantity, and at
2 ranks or more at least one rank holds none of the region (so the case tests what it
says). Run at 1, 2, 3 and 4 ranks."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from conftest import assert_same_results
from parsolve.model import build_model
from parsolve.scene import load_scene

STRIP = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 16.0
nx = 2
ny = 16
cell = "quad"

[regions]
tip = {{ point = [2.0, 16.0] }}
upper = {{ box = [[0.0, 14.0], [2.0, 16.0]] }}
upper_left = "x < 1e-9 and y > 13.9"
upper_right = "x > 2 - 1e-9 and y > 13.9"
upper_middle = "abs(x - 1) < 1e-9 and y > 13.9"
{physics}
{case}
"""

ELASTIC = """
[model]
hypothesis = "plane_stress"
[[materials]]
E = 100.0
nu = 0.3
[[relations]]
name = "clamp"
type = "dirichlet"
region = "bottom"
components = ["x", "y"]
"""

SCALAR = """
[model]
dimension = 2
[[diffusion]]
field = "h"
[[diffusion.materials]]
conductivity = 2.0
[[relations]]
name = "sink"
type = "dirichlet"
region = "bottom"
value = 0.0
"""

PULL = """
[[loads]]
name = "pull"
region = "top"
nodal = [0.3, 1.0]
"""

# case: (physics, the case's sections, the region some rank must not hold)
CASES = {
    "traction": (ELASTIC, """
[[loads]]
name = "edge"
region = "top"
traction = [1.0, -2.0]
""", "top"),
    "total_force": (ELASTIC, """
[[loads]]
name = "spread"
region = "upper"
total_force = [0.5, 3.0]
""", "upper"),
    "body": (ELASTIC, """
[[loads]]
name = "weight"
region = "upper"
body = [0.0, -1.0]
""", "upper"),
    "nodal": (ELASTIC, PULL, "top"),
    "pressure_expression": (ELASTIC, """
[[loads]]
name = "squeeze"
region = "top"
pressure = "2 + x * t"
""", "top"),
    "gravity": (ELASTIC.replace("nu = 0.3", "nu = 0.3\ndensity = 0.5"), """
[[loads]]
name = "weight"
region = "upper"
gravity = [0.0, -9.81]
""", "upper"),
    "scalar_exchange": (SCALAR, """
[[exchange]]
field = "h"
region = "top"
coefficient = 3.0
ambient = "5 + y * t"
""", "top"),
    "nodal_point": (ELASTIC, """
[[loads]]
name = "poke"
region = "tip"
nodal = [1.0, 0.5]
""", "tip"),
    "dirichlet": (ELASTIC, PULL + """
[[relations]]
name = "held"
type = "dirichlet"
region = "top"
components = ["x"]
value = 0.1
""", "top"),
    "dirichlet_expression": (ELASTIC, PULL + """
[[relations]]
name = "held"
type = "dirichlet"
region = "top"
components = ["y"]
value = "0.01 * x + 0.02"
""", "top"),
    "equal": (ELASTIC, """
[[loads]]
name = "poke"
region = "tip"
nodal = [0.2, 1.0]
[[relations]]
name = "flat"
type = "equal"
region = "top"
component = "y"
""", "top"),
    "mean": (ELASTIC, PULL + """
[[relations]]
name = "level"
type = "mean"
region = "top"
component = "y"
value = 0.2
""", "top"),
    "mean_minus": (ELASTIC, PULL + """
[[relations]]
name = "stretch"
type = "mean"
region = "top"
component = "y"
value = 0.05
minus = { region = "upper_left", component = "y" }
""", "top"),
    "linear": (ELASTIC, PULL + """
[[relations]]
name = "combined"
type = "linear"
value = 0.1
[[relations.terms]]
region = "tip"
component = "x"
[[relations.terms]]
region = "top"
component = "y"
coefficient = 2.0
mean = true
""", "top"),
    "strain": (ELASTIC, PULL + """
[[relations]]
name = "stretch"
type = "strain"
region = "upper"
component = "yy"
value = 0.01
""", "upper"),
    "strain_per_cell": (ELASTIC, PULL + """
[[relations]]
name = "stretch"
type = "strain"
region = "upper"
component = "yy"
per_cell = true
value = 0.01
""", "upper"),
    "control": (ELASTIC, """
[[loads]]
name = "edge"
region = "top"
traction = [0.0, 1.0]
[[relations]]
name = "lift"
type = "dirichlet"
region = "tip"
components = ["y"]
value = 0.1
dual = "edge"
""", "top"),
    "control_maximum": (ELASTIC, """
[[loads]]
name = "edge"
region = "top"
traction = [0.2, 1.0]
[[relations]]
name = "peak"
type = "strain"
region = "upper"
component = "yy"
per_cell = true
maximum = true
sense = "<="
value = 0.01
dual = "edge"
""", "upper"),
    "unilateral": (ELASTIC, """
[[loads]]
name = "push"
region = "top"
traction = [0.0, -1.0]
[[relations]]
name = "stop"
type = "dirichlet"
region = "top"
components = ["y"]
value = -0.05
sense = ">="
""", "top"),
    "periodic": (ELASTIC, PULL + """
[[relations]]
name = "tie"
type = "periodic"
region = "upper_left"
target = "upper_right"
translation = [2.0, 0.0]
components = ["x", "y"]
""", "upper_left"),
    "springs_to_ground": (ELASTIC, PULL + """
[[springs]]
region = "top"
stiffness = [0.5, 2.0]
""", "top"),
    "springs_node_to_node": (ELASTIC, PULL + """
[[springs]]
region = "upper_left"
target = "upper_middle"
translation = [1.0, 0.0]
stiffness = [30.0, 10.0]
""", "upper_left"),
    "scalar_flux": (SCALAR, """
[[loads]]
name = "inflow"
field = "h"
region = "top"
flux = 1.5
""", "top"),
    "scalar_source": (SCALAR, """
[[loads]]
name = "heat"
field = "h"
region = "upper"
source = 0.7
""", "upper"),
    "scalar_total_flux": (SCALAR, """
[[loads]]
name = "inflow"
field = "h"
region = "top"
total_flux = 3.0
""", "top"),
    "scalar_nodal": (SCALAR, """
[[loads]]
name = "well"
field = "h"
region = "tip"
nodal = 2.0
""", "tip"),
    "scalar_dirichlet": (SCALAR, """
[[relations]]
name = "head"
type = "dirichlet"
region = "top"
value = 1.0
""", "top"),
}


def missing_on_some_rank(path, region: str) -> bool:
    """Whether some rank of the distributed mesh owns no node of the region."""
    model = build_model(load_scene(path), MPI.COMM_WORLD)
    reg = model.regions()(region, "test")
    owned = int(np.count_nonzero(reg.nodes < model.mesh.n_owned))
    return min(MPI.COMM_WORLD.allgather(owned)) == 0


@pytest.mark.parametrize("case", sorted(CASES))
def test_region_missing_on_ranks(run, case):
    physics, sections, region = CASES[case]
    text = STRIP.format(physics=physics, case=sections)
    parts = run(text, name=f"empty_{case}_parts")
    if MPI.COMM_WORLD.size > 1:
        assert missing_on_some_rank(run.last.with_suffix(".toml"), region)
    alone = run(text, name=f"empty_{case}_alone", comm=MPI.COMM_SELF)
    assert_same_results(parts, alone, tol=1e-10)
    u = parts["fields/h" if physics is SCALAR else "fields/displacement"]
    assert np.abs(u).max() > 1e-3   # the case loads the strip
