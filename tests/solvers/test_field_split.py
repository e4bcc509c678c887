"""One fieldsplit block per field, named after it (solver.split = "fields")."""

import numpy as np

from conftest import solve_in_process

TWO_FIELDS = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 8
ny = 8
cell = "quad"
[model]
dimension = 2
[[diffusion]]
field = "h"
[[diffusion.materials]]
conductivity = 1.0
[[diffusion]]
field = "T"
[[diffusion.materials]]
conductivity = 3.0
[[loads]]
name = "s1"
field = "h"
source = 1.0
[[loads]]
name = "s2"
field = "T"
source = 2.0
[[relations]]
name = "h0"
type = "dirichlet"
field = "h"
region = "left"
[[relations]]
name = "T0"
type = "dirichlet"
field = "T"
region = "right"
[solver]
preset = "{preset}"
{split}
"""


def test_one_block_per_field_named_after_it():
    split = 'split = "fields"\n[solver.petsc]\nfieldsplit_h_pc_type = "jacobi"\nfieldsplit_T_pc_type = "jacobi"'
    system, solver, mat, rhs, x = solve_in_process(TWO_FIELDS.format(preset="iterative", split=split))
    pc = solver.ksp.getPC()
    assert pc.getType() == "fieldsplit"
    names = [k.getOptionsPrefix() for k in pc.getFieldSplitSubKSP()]
    assert names == ["parsolve_fieldsplit_h_", "parsolve_fieldsplit_T_"]
    _, _, _, _, xd = solve_in_process(TWO_FIELDS.format(preset="direct", split=""))
    assert np.abs(x.array - xd.array).max() <= 1e-8 * np.abs(xd.array).max()
