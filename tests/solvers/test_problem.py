"""The nonlinear problem (``solvers.problem``) through its callbacks, the relation policies
(``solvers.policies``) on their own, and the two drivers over one problem (Newton,
arc-length), with numbers from closed forms: a bar of E = 1e3, ν = 0, length 1, height 0.1,
clamped on the left and pulled by a traction p on the right (u = p x / E, exact on quads)."""

from __future__ import annotations

import dataclasses
import numpy as np
import pytest
from mpi4py import MPI

from helpers.control import closed_form, newton_of, without_control, BAR as LOCALIZATION_BAR
from helpers.stop_bar import stop_bar
from parsolve.solvers.arc_length import ArcLength
from parsolve.solvers.newton import NewtonSolver


def problem_of(text: str, comm=MPI.COMM_WORLD) -> tuple:
    """(scene, system, problem) as the driver builds them."""
    scene, _, system, problem, _ = newton_of(text, comm)
    return scene, system, problem


def test_residual_of_a_linear_bar_before_and_after_the_step():
    """At q = 0 the residual is the whole load (relative 1 exactly); one Newton solve through
    the callbacks gives u_end = p L / E = 3e-4; at the converged state the residual is below
    1e-10 of the forces in play, after one iteration."""
    scene, system, problem = problem_of(stop_bar())
    f_known = problem.begin(1.0)
    lin = problem.form()
    r_norm, ref = problem.norms(f_known, lin.f_int)
    assert r_norm == pytest.approx(ref, rel=1e-14) and ref > 0
    x = problem.solve(problem.jacobian(lin.kmat), problem.rhs(1.0, lin.f_int, f_known))
    assert problem.ctx.max_abs(x.q) == pytest.approx(3e-4, rel=1e-12)

    _, _, problem = problem_of(stop_bar())
    result = NewtonSolver(problem, scene.nonlinear).step(1.0)
    assert result.iterations == 1
    r_norm, ref = problem.norms(problem.external(1.0), problem.form().f_int)
    assert r_norm <= 1e-10 * ref
    assert problem.size() == pytest.approx(3e-4, rel=1e-12)
    clamp = problem.multipliers(1.0, result.f_int)["clamp"]   # the load, 0.3 · 0.1
    # (eliminated rows are held per rank: each rank its own DOFs' reactions)
    assert abs(MPI.COMM_WORLD.allreduce(float(clamp.sum()))) == pytest.approx(0.03, rel=1e-10)


def test_restore_then_the_same_step_again_gives_the_same_numbers():
    """The stop bar: reached at t = 1/3, λ = (0.01 - 0.03 t) / (0.1 dual) after. A step taken,
    undone (``restore``) and taken again ends bitwise where it ended the first time."""
    scene, _, problem = problem_of(stop_bar(dual=-1.0, value=1e-4))
    newton = NewtonSolver(problem, scene.nonlinear)
    newton.step(0.25)
    snap = problem.snapshot()
    first = newton.step(0.5)
    q, lam, active = problem.q.copy(), problem.lam.copy(), problem.active.active.copy()
    stop = problem.multipliers(0.5, first.f_int)["stop"]
    np.testing.assert_allclose(stop, [(0.01 - 0.015) / -0.1], rtol=1e-10)
    problem.restore(snap)
    np.testing.assert_array_equal(problem.q, snap[0])
    assert not problem.active.active[-1]        # the stop open again, as at t = 0.25
    again = newton.step(0.5)
    assert again.iterations == first.iterations
    np.testing.assert_array_equal(problem.q, q)
    np.testing.assert_array_equal(problem.lam, lam)
    np.testing.assert_array_equal(problem.active.active, active)


@pytest.mark.parametrize("dual", [-1.0, 2.0])
def test_orientation_from_the_unit_response(dual):
    """A K⁻¹ D of the stop: the mean end displacement under the traction ``dual`` alone,
    dual · L / E; the orientation is its opposite sign (the reaction pushes the end back)."""
    _, _, problem = problem_of(stop_bar(dual=dual, value=1e-4))
    policies = problem.policies
    kmat = problem.form().kmat
    k = [r.name for r in problem.ctx.multiplied].index("stop")
    rows = np.arange(problem.rset.rows_of(k).start, problem.rset.rows_of(k).stop)
    dq = policies.unit_response(kmat, rows, policies.dual_column(k))
    rate = problem.ctx.relation_primal(problem.ctx.multiplied[k], dq)
    np.testing.assert_allclose(rate, [dual * 1e-3], rtol=1e-10)
    assert problem.first_tangent(0.25, problem.form()) == 0   # no maximum group: no predictor
    np.testing.assert_array_equal(policies.active.orient[rows], [-np.sign(dual)])


BLOCK = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 0.5
nx = 4
ny = 2
cell = "quad"
[model]
hypothesis = "plane_strain"
[[materials]]
E = 1000.0
nu = 0.3
[[loads]]
name = "press"
region = "top"
traction = [0.0, -2.0]
[[relations]]
name = "hold_x"
type = "dirichlet"
region = "left"
components = ["x"]
[[contact]]
name = "base"
slave = "bottom"
obstacle = { plane = { origin = [0.0, -0.01], normal = [0.0, 1.0] } }
[steps]
count = 1
"""


def test_a_block_held_only_by_contact_starts_closed():
    """A block 0.01 above a plane, held in x, pressed down by 2 per unit length: nothing holds
    it in y but the contact, so the first solve fails with the rows open. ``close_contact``
    closes the five bottom rows once (then has nothing to close); Newton does so itself, and
    the contact rows carry the load, 2 · 1 = 2, with the block on the plane."""
    scene, _, problem = problem_of(BLOCK)
    policies = problem.policies
    assert not problem.active.active.any()
    held = MPI.COMM_WORLD.allreduce   # the contact's rows are held by their slave's owner
    assert policies.close_contact() and held(int(problem.active.active.sum())) == 5
    assert not policies.close_contact()

    scene, _, problem = problem_of(BLOCK)
    result = NewtonSolver(problem, scene.nonlinear).step(1.0)
    assert held(int(problem.enforced.sum())) == 5
    # each rank holds its slave nodes' rows: gathered in the relation's row order
    rel = next(r for r in problem.rset.relations if r.name == "base_normal")
    parts = MPI.COMM_WORLD.allgather((rel.row_ids(),
                                      problem.multipliers(1.0, result.f_int)["base_normal"]))
    ids, values = (np.concatenate(a) for a in zip(*parts))
    reaction = values[np.argsort(ids)]
    np.testing.assert_allclose(reaction, [-0.25, -0.5, -0.5, -0.5, -0.25], rtol=1e-10)
    gap = problem.rset.primal_values(problem.q) - problem.rset.targets(1.0)
    assert np.abs(gap).max(initial=0.0) <= 1e-12   # (a rank may hold none of the rows)


def test_fixed_dofs_are_told_by_their_owners():
    """``_fixed``: of the input DOFs of every node this rank holds (ghosts included), those an
    eliminated relation holds are the x DOFs of the left edge (hold_x), each told by its
    node's owner. An eliminated DOF not owned here (a broken ownership) is refused naming the
    relation, where a -1 used to write the last entry."""
    _, _, problem = problem_of(BLOCK)
    policies, mesh = problem.policies, problem.ctx.mesh
    nodes = mesh.global_nodes.astype(np.int64)
    dofs = np.sort((nodes[:, None] * 2 + np.arange(2)).ravel())
    problem.ctx.dofs.index_inputs([dofs])   # (collective: the DOF map learns them all)
    expected = np.sort(nodes[mesh.points[:, 0] == 0.0] * 2)
    np.testing.assert_array_equal(policies._fixed(dofs), expected)
    hold = problem.ctx.eliminated[0]
    far = np.append(hold.a_dofs, 2 * 15)   # (node 15: the 4 × 2 mesh has 0..14)
    problem.ctx.eliminated[0] = dataclasses.replace(hold, a_dofs=far)
    with pytest.raises(RuntimeError, match=f"relation 'hold_x' \\(eliminated\\): 1 input DOFs "
                                           f"not owned by rank {MPI.COMM_WORLD.rank}"):
        policies._fixed(dofs)


def test_arc_length_over_the_problem_follows_the_softening_bar():
    """Crisfield's arc-length as a driver over the problem: the localization bar with three
    columns (``test_distributed_arc_length``) through its limit point, every step's load
    factor on the closed form of the damaged column's strain (1e-8), up then down."""
    text = without_control(LOCALIZATION_BAR)
    for old, new in (("nx = 29", "nx = 3"),
                     ('middle = "x > 14/29 and x < 15/29"', 'middle = "x > 1/3 and x < 2/3"'),
                     ('matrix = "secant"', 'matrix = "tangent"'), ("count = 24", "count = 20"),
                     ("[nonlinear]\n", '[nonlinear]\nmethod = "arc_length"\nmax_iterations = 30'
                                       '\narc_length = { pattern = "pull", length = 3e-5 }\n')):
        text = text.replace(old, new)
    scene, system, problem = problem_of(text)
    arc = ArcLength(problem, scene.nonlinear)
    ctx, comm = problem.ctx, MPI.COMM_WORLD
    x = ctx.mesh.points[:ctx.mesh.n_owned, 0]
    mus, strains = [], []
    for t in scene.times:
        arc.step(t)
        u = ctx.values(problem.q)[next(iter(ctx.fields)).name][:ctx.mesh.n_owned, 0]
        sums = comm.allreduce(np.array([u[np.isclose(x, 1 / 3)].sum(), np.isclose(x, 1 / 3).sum(),
                                        u[np.isclose(x, 2 / 3)].sum(), np.isclose(x, 2 / 3).sum()]))
        strains.append((sums[2] / sums[3] - sums[0] / sums[1]) * 3.0)
        mus.append(arc.mu)
    mus = np.array(mus)
    np.testing.assert_allclose(mus, closed_form(np.array(strains))[1], rtol=1e-8)
    peak = int(np.argmax(mus))
    assert 0 < peak < len(mus) - 1 and mus[-1] < 0.1 * mus[peak]
