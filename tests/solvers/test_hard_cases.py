"""Hard cases that must stay numerically stable."""

import numpy as np
import pytest
from mpi4py import MPI

from conftest import dense, rel_err, saddle_of_input_dofs, solve_in_process
from parsolve.errors import InputError, SolverError

BAR = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 0.5
nx = 16
ny = 4
cell = "triangle6"
[model]
hypothesis = "plane_stress"
[regions]
corner = {{ point = [0.0, 0.0] }}
[[materials]]
E = {E}
nu = 0.3
[[loads]]
name = "pull"
region = "right"
traction = [1.0, 0.5]
[[relations]]
name = "left"
type = "dirichlet"
region = "left"
components = ["x", "y"]
[[relations]]
name = "right_flat"
type = "equal"
region = "right"
component = "x"
[solver]
preset = "{preset}"
eliminate = {eliminate}
"""


def solution(text, comm=MPI.COMM_WORLD):
    system, solver, mat, rhs, x = solve_in_process(text, comm)
    q, lam = system.unpack(system.gather(x.array.copy()), 1.0)
    return system, q, lam, solver


@pytest.mark.parametrize("preset, eliminate", [("direct", "true"), ("direct", "false"),
                                               ("iterative", "true")])
def test_stiff_material_with_unit_relations(preset, eliminate):
    """E = 2e11 next to unit relation coefficients: relations hold to 1e-10 and the
    displacements are those of E = 1 scaled by 1/E."""
    s_hi, q_hi, lam_hi, _ = solution(BAR.format(E=2e11, preset=preset, eliminate=eliminate))
    s_lo, q_lo, lam_lo, _ = solution(BAR.format(E=1.0, preset=preset, eliminate=eliminate))
    tol = 1e-10 if preset == "direct" else 1e-7
    assert rel_err(q_hi * 2e11, q_lo) < tol
    for rel in s_hi.model.relations:
        primal, b = s_hi.context.relation_primal(rel, q_hi), rel.rhs(1.0)
        assert np.abs(primal - b).max(initial=0.0) <= 1e-10 * np.abs(q_hi).max()   # (rows here)
    for name in lam_lo:  # reactions do not depend on E
        assert rel_err(lam_hi[name], lam_lo[name]) < tol * 10


FLOATING = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 6
ny = 6
cell = "quad"
[model]
hypothesis = "plane_stress"
[[materials]]
E = 100.0
nu = 0.0
[[loads]]
region = "right"
traction = [1.0, 0.0]
[[loads]]
region = "left"
traction = [-1.0, 0.0]
[[relations]]
name = "mean_x"
type = "mean"
region = "all"
component = "x"
[[relations]]
name = "mean_y"
type = "mean"
region = "all"
component = "y"
[[relations]]
name = "no_rotation"
type = "mean"
region = "right"
component = "y"
minus = { region = "left", component = "y" }
"""


def test_body_held_only_by_relations():
    """K alone is singular (rigid modes); three mean relations hold the body. Self-equilibrated
    tension: ux = σ/E (x - 1/2), uy = 0 (ν = 0), and the relations carry no force."""
    system, q, lam, _ = solution(FLOATING)
    iq = saddle_of_input_dofs(MPI.COMM_WORLD, system)
    K = dense(system.op.petsc_matrix())[np.ix_(iq, iq)]
    assert np.linalg.matrix_rank(K, tol=1e-10 * np.abs(K).max()) == K.shape[0] - 3
    pts = system.model.mesh.points
    u = q.reshape(-1, 2)
    np.testing.assert_allclose(u[:, 0], (pts[:, 0] - 0.5) / 100.0, atol=1e-14)
    np.testing.assert_allclose(u[:, 1], 0.0, atol=1e-14)
    for name, value in lam.items():
        assert np.abs(value).max() < 1e-10, name


def test_redundant_relation_names_both():
    """The same DOFs fixed to two different values (the same value is merged: see
    tests/effects/test_loads.py)."""
    text = BAR.format(E=1.0, preset="direct", eliminate="true") + """
[[relations]]
name = "again"
type = "dirichlet"
region = "left"
components = ["x"]
value = 1e-3
"""
    with pytest.raises(InputError, match="'left' and 'again'"):
        solution(text)


@pytest.mark.parametrize("eliminate", ["true", "false"])
def test_dependent_relation_is_a_clear_error(eliminate):
    """A mean condition on an edge that is already fixed node by node: dependent rows, a
    singular system. Detected (null pivot), never inf or NaN."""
    text = BAR.format(E=1.0, preset="direct", eliminate=eliminate) + """
[[relations]]
name = "left_mean"
type = "mean"
region = "left"
component = "x"
"""
    with pytest.raises(SolverError, match="singular|null pivot"):
        solution(text)


DENSE_COLUMN = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 60
ny = 60
cell = "quad"
[model]
hypothesis = "plane_strain"
[[materials]]
E = 1.0
nu = 0.3
[[loads]]
name = "control"
{load}
[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x", "y"]
[[relations]]
name = "drive"
type = "mean"
region = "right"
component = "x"
value = 1e-3
dual = "control"
"""


def test_dense_control_column_does_not_inflate_the_factor():
    """A control vector over every node (a body force) is a dense column of the operator. With
    the default ordering the factor holds barely more entries than with an edge traction."""
    def factor_entries(load):
        _, _, _, solver = solution(DENSE_COLUMN.format(load=load))
        return solver.ksp.getPC().getFactorMatrix().getMumpsInfog(29)

    dense_col = factor_entries('body = [1.0, 0.0]')
    sparse_col = factor_entries('region = "right"\ntraction = [1.0, 0.0]')
    assert dense_col < 1.1 * sparse_col, (dense_col, sparse_col)


def test_a_body_not_held_is_named(run):
    """A singular system says which body no relation holds."""
    import pytest as _pytest

    from parsolve.errors import SolverError

    text = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 4
ny = 4
cell = "quad"
[model]
dimension = 2
[[diffusion]]
field = "h"
[[diffusion.materials]]
conductivity = 1.0
[[loads]]
name = "s"
field = "h"
source = 1.0
"""
    with _pytest.raises(SolverError) as err:
        run(text, name="floating")
    assert "no relation holds field 'h' on the body" in str(err.value)


def test_bodies_are_the_connected_cells():
    import numpy as np

    from parsolve.diagnostics import bodies

    cells = np.array([[0, 1, 2], [2, 3, 4], [5, 6, 7], [8, 7, 9]])
    label = bodies(cells, 11)
    assert list(label) == [0, 0, 0, 0, 0, 5, 5, 5, 5, 5, 10]


def test_branch_watch():
    """The warning of a possible change of equilibrium branch: negative pivots of the tangent
    that change, or an increment over ten times the previous one (nonlinear runs only)."""
    import numpy as np

    from parsolve.driver import BranchWatch

    watch = BranchWatch(nonlinear=True)
    assert watch.check(np.ones(4), 0) is None
    assert watch.check(2 * np.ones(4), 0) is None
    assert "negative pivots went from 0 to 1" in watch.check(2 * np.ones(4), 1)
    assert "25× the previous" in watch.check(50 * np.ones(4), 1)
    linear = BranchWatch(nonlinear=False)
    linear.check(np.ones(4), None)
    assert linear.check(1e6 * np.ones(4), None) is None


def test_mumps_workspace_is_raised_when_too_small(run):
    """The solubility strip at 320 cells delays enough pivots to overflow MUMPS' workspace
    (here with no margin at all; the default 50 % overflows too): INFOG(1) = -9, the
    factorization is redone with a larger margin, the run completes and the file says so."""
    from helpers.scene import scene, shipped

    base = shipped("solubility_grow_shrink.toml")
    assert base["mesh"]["nx"] == 80 and "solver" not in base
    text = scene(base, mesh={"nx": 320}, steps={"count": 10, "end": 0.2},
                 solver={"petsc": {"mat_mumps_icntl_14": 0}})   # no margin for delayed pivots
    res = run(text, name="workspace")
    assert res["attrs"]["status"] == "complete"
    assert "MUMPS workspace too small: margin raised" in res["attrs"].get("warnings", "")
