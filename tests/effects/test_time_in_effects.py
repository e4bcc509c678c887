"""Time reaches every effect: ``Effect.evaluate`` and ``begin_step`` receive the step's instant
(t, Δt, θ) through the composition, the one evaluation context the loads are evaluated at
too. An effect whose internal force depends on t gives the closed form at every step."""

import numpy as np
import pytest

from parsolve.effects import registry
from parsolve.effects.base import Effect, displacement_field
from parsolve.fem.integrals import cell_rule, integrate
from parsolve.loads.base import Instant

BAR = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 0.5
nx = 8
ny = 2
cell = "{cell}"
[model]
hypothesis = "plane_stress"
[[materials]]
E = 100.0
nu = 0.0
[drift]
b = [3.0, 0.0]
[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x", "y"]
[steps]
times = [0.5, 1.0, 1.5, 2.5]
"""


class Drift(Effect):
    """A force per unit volume g(t) b with g(t) = t², given as an internal force (−g ∫ N b)
    read from the instant: no load pattern, no evolution; nonlinear by declaration, so that
    the Newton loop (which evaluates it at every iteration) runs it."""

    name = "drift"
    linear = False
    seen: list = []   # the instants begin_step received (this process's effect)

    def __init__(self, b, ctx):
        self.b, self.mesh = np.asarray(b), ctx.mesh
        self.u = displacement_field(ctx.fields)
        Drift.seen = []

    def evaluate(self, cells, values, state, secant, at: Instant):
        rule = cell_rule(self.mesh.points[self.mesh.cells[cells]], self.mesh.cell_type)
        load = np.broadcast_to(at.t ** 2 * self.b, rule.weights.shape + self.b.shape)
        return {self.u: -integrate(rule, load)}, [], state, None

    def begin_step(self, q, active, at: Instant) -> bool:
        Drift.seen.append(at)
        return False

    def refresh(self, q, lam, active) -> bool:   # (so that the step's hooks call it)
        return False


def _parse(t, dim):
    b = t.floats("b", dim)
    t.done()
    return b


@pytest.fixture
def drift(monkeypatch):
    entry = registry.Entry("drift", False, _parse, lambda spec, ctx: Drift(spec, ctx),
                           coupling=True)
    monkeypatch.setitem(registry.EFFECTS, "drift", entry)


@pytest.mark.parametrize("cell", ["quad", "triangle6"])
def test_an_effect_reading_t_gives_the_closed_form_at_every_step(cell, drift, run):
    """A bar clamped at x = 0, free at x = L, under g(t) b along x (ν = 0: u_y = 0):
    u_x = g b (L x − x²/2) / E, exact at the nodes (1D linear and quadratic elements are);
    the clamp carries g b L h. Every step's begin_step had its instant (t, Δt, θ = 1)."""
    res = run(BAR.format(cell=cell))
    t = res["steps/time"]
    np.testing.assert_allclose(t, [0.5, 1.0, 1.5, 2.5])
    x = res["mesh/points"][:, 0]
    g = t[:, None] ** 2
    exact = g * 3.0 * (2.0 * x[None, :] - x[None, :] ** 2 / 2) / 100.0
    u = res["fields/displacement"]
    np.testing.assert_allclose(u[..., 0], exact, atol=1e-12 * exact.max())
    np.testing.assert_allclose(u[..., 1], 0.0, atol=1e-12 * exact.max())
    np.testing.assert_allclose(res["relations/clamp/resultant"][:, 0], -g[:, 0] * 3.0 * 2.0 * 0.5,
                               rtol=1e-10)
    assert Drift.seen == [Instant(0.5, 0.5, 1.0), Instant(1.0, 0.5, 1.0), Instant(1.5, 0.5, 1.0),
                          Instant(2.5, 1.0, 1.0)]
