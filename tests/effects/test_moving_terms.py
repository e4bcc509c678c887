"""A declared term whose domain moves between steps, through the whole run: an effect ties a
node of a block's top to the node of the same cell diagonally under it, and the tie moves
along the block at every step (``Term.nodes`` given anew in ``begin_step``, the effect
``restructured``): the system derives its pattern again, builds the operator anew and the
solver sets itself up on it, and each step's answer is that of a run with fixed springs
between the same nodes (``[[springs]]``: a pattern made once), at 1, 2, 3 and 4 ranks.

The tie's nodes share a cell, so that the owner of either holds both whatever the partition;
a tuple some node's owner does not declare is refused, and pairs no cell joins (new pattern
entries) are tests/la/test_pattern_moves.py's. The solver's choice of factorization rests on
a symmetry test every rank answers alike: an unmirrored coupling on one rank once made that
rank choose LU while the others chose Cholesky, and the run hung in MUMPS at 3 ranks."""

import numpy as np
import pytest
from mpi4py import MPI

from parsolve.effects import registry
from parsolve.effects.base import Effect, displacement_field
from parsolve.fem.element_matrices import Term, TermMatrices
from parsolve.loads.base import Instant

BLOCK = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 0.5
nx = 8
ny = 2
cell = "quad"
[model]
hypothesis = "plane_stress"
[regions]
{regions}
[[materials]]
E = 100.0
nu = 0.3
[[loads]]
name = "lift"
region = "top"
traction = [0.5, 2.0]
[[relations]]
name = "base"
type = "dirichlet"
region = "bottom"
components = ["x", "y"]
{extra}
[steps]
times = {times}
"""
STIFF = 300.0
AT = {1.0: 0.5, 2.0: 1.25, 3.0: 1.75}   # where the tie is at each step's time


class MovingTie(Effect):
    """Springs (stiffness STIFF per component) between (x(t), 0.5) and (x(t) + 0.25, 0.25), on
    the ranks that hold both nodes."""

    name = "moving_tie"
    linear = False
    restructures = True

    def __init__(self, ctx):
        self.mesh = ctx.mesh
        self.u = displacement_field(ctx.fields)
        self.x = AT[1.0]
        self.term = Term(self.u, self.u, self._tie(self.x), linear=False)

    def _tie(self, x: float) -> np.ndarray:
        def node(px, py):
            hit = np.flatnonzero(np.all(np.abs(self.mesh.points - [px, py]) < 1e-9, axis=1))
            return hit[0] if hit.size else -1
        a, b = node(x, 0.5), node(x + 0.25, 0.25)
        return np.array([[a, b]]) if a >= 0 and b >= 0 else np.zeros((0, 2), dtype=np.int64)

    def terms(self) -> list[Term]:
        return [self.term]

    def term_values(self, term: Term, cells: np.ndarray) -> TermMatrices:
        k = len(term.nodes)
        values = np.zeros((2, 2, 2, 2, k))
        values[0, 0] = values[1, 1] = (STIFF * np.array([[1.0, -1.0], [-1.0, 1.0]]))[:, :, None]
        return TermMatrices(term, values.reshape(4, 2, 2, k))

    def begin_step(self, q, active, at: Instant) -> bool:
        # every rank alike (the restructure is collective), whether it holds the tie or not
        if AT[at.t] != self.x:
            self.x = AT[at.t]
            self.term.nodes = self._tie(self.x)
            self.restructured = True
        return False

    def refresh(self, q, lam, active) -> bool:   # (so that the step's hooks call it)
        return False


@pytest.fixture
def moving_tie(monkeypatch):
    def parse(t, dim):
        t.done()
        return None
    entry = registry.Entry("moving_tie", False, parse, lambda spec, ctx: MovingTie(ctx),
                           coupling=True)
    monkeypatch.setitem(registry.EFFECTS, "moving_tie", entry)


def test_a_tie_that_moves_between_steps_answers_as_fixed_springs(moving_tie, run):
    moved = run(BLOCK.format(regions="", extra="[moving_tie]", times="[1.0, 2.0, 3.0]"))
    u = moved["fields/displacement"]
    assert moved["timings/pattern"].shape == (3,)   # the hooks' restructures timed per step
    for k, (t, x) in enumerate(AT.items()):
        springs = f"""[[springs]]
name = "tie"
region = "up"
target = "down"
stiffness = [{STIFF}, {STIFF}]"""
        regions = f'up = "x == {x} and y == 0.5"\ndown = "x == {x + 0.25} and y == 0.25"'
        fixed = run(BLOCK.format(regions=regions, extra=springs, times=f"[{t}]"))
        scale = np.abs(fixed["fields/displacement"]).max()
        np.testing.assert_allclose(u[k], fixed["fields/displacement"][0], rtol=0,
                                   atol=1e-11 * scale)
    # the tie matters: the steps differ beyond the load's ramp
    assert np.abs(u[1] / 2.0 - u[0]).max() > 1e-3 * np.abs(u[0]).max()


def test_the_moved_pattern_is_preallocated_exactly(moving_tie):
    """The operator after a restructure is a new PETSc matrix on arrays laid out exactly for
    the new pattern (a pattern derived again, not the old one grown): no entry inserted at
    assembly (0 mallocs: never PETSc's slow insertion), its entries exactly those of the
    operator's value array; on every rank."""
    import tomllib

    from petsc4py import PETSc

    from parsolve.model import build_model
    from parsolve.scene import parse_scene
    from parsolve.solvers.system import SaddleSystem

    text = BLOCK.format(regions="", extra="[moving_tie]", times="[1.0, 2.0]")
    model = build_model(parse_scene(tomllib.loads(text), "t.toml", text), MPI.COMM_WORLD)
    system = SaddleSystem(MPI.COMM_WORLD, model)
    tie, = [e for e in model.effects if isinstance(e, MovingTie)]
    first, pattern = system.assemble(), system.pattern
    tie.begin_step(None, {}, Instant(2.0))
    assert tie.restructured
    system.restructure()
    moved = system.assemble()
    assert moved is not first
    info = moved.getInfo(PETSc.Mat.InfoType.LOCAL)
    assert info["mallocs"] == 0 and info["nz_used"] == system.op.data.size, info
    assert system.pattern is not pattern
