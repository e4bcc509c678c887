"""The effects of a model composed on one rank's local cells: the values of the terms they
declare (``Effect.terms``: stiffness and capacity alike), the internal forces they return,
their states, and the rate terms of a transient step.

A transient step from t_n to t = t_n + Δt (θ-scheme; θ = 1 is backward Euler) solves

    M (q - q_n) / Δt + θ f_int(q) + (1 - θ) f_int(q_n) = θ F(t) + (1 - θ) F(t_n) + D λ,
    A q = b(t),

whose tangent is M / Δt + θ K. The reaction D λ acts at t: λ is whatever it takes. θ weighs
only the equations of fields that have a capacity; the others (displacements next to a
transient field) are in equilibrium at t (their θ is 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.effects.base import TermValues, term_forces
from parsolve.fem.element_matrices import BlockMatrices, NodeForces
from parsolve.loads.base import Instant


@dataclass
class Rate:
    """The rate terms of one transient step."""

    dt: float
    theta: float
    q_prev: np.ndarray        # full primal vector at t_n (input numbering)
    f_int_prev: np.ndarray    # f_int(q_n)


class Composition:
    def __init__(self, model, cells: np.ndarray):
        self.model, self.cells = model, cells
        self.fields = model.fields
        self.nodes = model.mesh.cells[cells]                 # (nc, nen)
        self.npoints = model.mesh.num_points
        self._mass = None
        self.now = Instant(0.0)   # the step's instant: every effect's evaluation reads it
        for e in model.effects:
            e.couple(model.effects)

    @property
    def ndof(self) -> int:
        return self.npoints * self.fields.ncomp

    def values(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Node values of every field from a full primal vector: {field: (npoints, ncomp)}."""
        nodal = q.reshape(self.npoints, self.fields.ncomp)
        return {f.name: nodal[:, self.fields.columns(f.name)] for f in self.fields}

    def _parts(self, values: TermValues, factor) -> list:
        """The (row components, column components, matrices, factor) parts of a
        ``BlockMatrices`` from term values; ``factor``: a number, or a dict of the test
        field's factor."""
        for t, m in values:   # a cell term on a region, a facet term: their own slots
            if t.on_cells and t.cells is not None:
                m.positions, m.slots = t.positions(self.cells), t.slots
            elif t.on_facets:
                m.nodes, m.slots = t.facets, t.slots
        return [(self.fields.columns(t.test), self.fields.columns(t.trial), m,
                 factor[t.test] if isinstance(factor, dict) else factor) for t, m in values]

    def rate_fields(self) -> set[str]:
        """The fields with a capacity: the test fields of the declared rate terms."""
        return {t.test for e in self.model.effects for t in e.terms() if t.rate}

    def theta_of(self, theta: float) -> dict[str, float]:
        """θ of each field's equations: θ where the field has a capacity, 1 elsewhere."""
        rate = self.rate_fields()
        return {f.name: theta if f.name in rate else 1.0 for f in self.fields}

    def theta_dofs(self, theta: float) -> np.ndarray:
        """The same per DOF (input numbering); computed once per θ (every iteration asks)."""
        if getattr(self, "_theta", (None,))[0] != theta:
            cols = np.ones(self.fields.ncomp)
            for name, w in self.theta_of(theta).items():
                cols[self.fields.columns(name)] = w
            self._theta = (theta, np.tile(cols, self.npoints))
        return self._theta[1]

    def begin(self, t: float, t_prev: float, theta: float | None) -> Instant:
        """The instant of the step from t_prev to t (θ: the transient scheme's, None in a
        quasi-static run): the one evaluation context that the effects' ``evaluate`` and
        ``begin_step`` receive, as the loads do."""
        self.now = Instant(t, t - t_prev, 1.0 if theta is None else theta)
        return self.now

    def known_loads(self, t: float, t_prev: float, theta: float | None) -> np.ndarray:
        """The loads a step balances, the model's load patterns (every declared vector term:
        the scene's loads and the effects'): F(t), or in a θ-scheme step θ F(t) + (1 - θ)
        F(t_n) on the equations of fields with a capacity (F(t) elsewhere)."""
        scheme = 1.0 if theta is None else theta
        f = self.model.external_load(Instant(t, t - t_prev, scheme))
        if scheme != 1.0:
            w = self.theta_dofs(theta)
            f = w * f + (1.0 - w) * self.model.external_load(Instant(t_prev, t - t_prev, scheme))
        return f

    def _scatter(self, forces: dict, out: np.ndarray, factor: float = 1.0) -> None:
        """Add forces {field: element forces (nc, nen, ncomp) of the cells, ``NodeForces`` of
        a term, or a list of these} into a full vector."""
        for name, parts in forces.items():
            for fe in parts if isinstance(parts, list) else [parts]:
                nodes = fe.nodes if isinstance(fe, NodeForces) else self.nodes
                values = fe.values if isinstance(fe, NodeForces) else fe
                dofs = self.fields.dofs(name, nodes.ravel())
                out += factor * np.bincount(dofs.ravel(), weights=values.reshape(-1),
                                            minlength=out.size)

    def _linear(self, rate: bool = False) -> TermValues:
        """The values of the effects' stiffness terms (``rate``: capacity terms) on the cells."""
        return [v for e in self.model.effects for v in e.linear_values(self.cells, rate)]

    def mass_parts(self) -> TermValues:
        """The capacity terms' values (built once)."""
        if self._mass is None:
            self._mass = self._linear(rate=True)
        return self._mass

    def stiffness(self, rate: Rate | None = None) -> BlockMatrices:
        """θ K + M / Δt of the declared terms' linear values (K alone without a rate)."""
        theta = 1.0 if rate is None else self.theta_of(rate.theta)
        parts = self._parts(self._linear(), theta)
        if rate is not None:
            parts += self._parts(self.mass_parts(), 1.0 / rate.dt)
        return BlockMatrices(self.fields.ncomp, parts)

    def linear_step_loads(self, f_known: np.ndarray, q_prev: np.ndarray, dt: float,
                          theta: float) -> np.ndarray:
        """The right-hand side of a linear θ-step from q_n (see the module doc): the
        θ-weighted known loads, minus (1 - θ) K q_n on the equations of fields with a
        capacity, plus M q_n / Δt."""
        f_rhs = f_known
        if theta != 1.0:
            if getattr(self, "_linear_values", None) is None:   # K of the linear terms, once
                self._linear_values = self._linear()
            w = self.theta_dofs(theta)
            f_rhs = f_rhs - (1 - w) * self.product(self._linear_values, q_prev)
        return f_rhs + self.product(self.mass_parts(), q_prev) / dt

    def product(self, values: TermValues, q: np.ndarray) -> np.ndarray:
        """Σ K_e q_e of the given term values as a full vector (rows of this rank's cells)."""
        vals = self.values(q)
        out = np.zeros(self.ndof)
        forces: dict[str, list] = {}
        for t, m in values:
            forces.setdefault(t.test, []).append(term_forces(t, m, vals[t.trial], self.nodes))
        self._scatter(forces, out)
        return out

    def init_states(self) -> list:
        return [e.init_state(self.cells) for e in self.model.effects]

    def evaluate(self, q: np.ndarray, states: list, secant: bool, rate: Rate | None = None):
        """(f_int with the rate terms, f_int alone, tangent BlockMatrices, trial states, extras),
        forces as full vectors (rows of this rank's cells); the tangent from the term values
        each effect's ``evaluate`` returns."""
        vals = self.values(q)
        f_int = np.zeros(self.ndof)
        parts, trial, extras = [], [], []
        theta = 1.0 if rate is None else self.theta_of(rate.theta)
        for e, st in zip(self.model.effects, states):
            forces, tangent, new, extra = e.evaluate(self.cells, vals, st, secant, self.now)
            self._scatter(forces, f_int)
            parts += self._parts(tangent, theta)
            trial.append(new)
            extras.append(extra)
        total = f_int
        if rate is not None:
            w = self.theta_dofs(rate.theta)
            total = w * f_int + (1.0 - w) * rate.f_int_prev \
                + self.product(self.mass_parts(), q - rate.q_prev) / rate.dt
            parts += self._parts(self.mass_parts(), 1.0 / rate.dt)
        return total, f_int, BlockMatrices(self.fields.ncomp, parts), trial, extras
