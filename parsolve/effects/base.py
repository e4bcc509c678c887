"""What an effect is: the fields it declares, the operators, forces, relations and outputs it
contributes, and its nature (linear, symmetric, transient). The driver composes the effects a
scene lists and nothing else (see ``compose``); adding an effect is a class and a registry
line (``registry``), nothing in the core.

What an effect puts into the operator and the loads is one kind of thing: the terms it declares
(``terms``: test field, trial field, domain -- cells of a region, facets of a boundary region
or tuples of nodes -- and nature), whose values it gives as ``ElementMatrices`` over the
domain's cells or facets, cell-last, in bounded blocks, or ``TermMatrices`` on the node tuples:
``term_values`` for a linear term (and a rate term's capacity), ``evaluate`` for the tangent of
a nonlinear one. A term without a trial field is a vector term: a load on its test field, on
cells, facets or nodes, whose forces ``vector_values`` gives at the step's instant (constant
ones: ``term_values``, element forces (nc, nen, d) of the domain's cells, or ``NodeForces``);
its pattern and evolution are declared with it, and the scene's ``[[loads]]`` are vector terms
declared the same way (``loads``).
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from parsolve.fem.element_matrices import (ElementMatrices, NodeForces, Term, TermMatrices,
                                           apply)
from parsolve.fields import Field
from parsolve.loads.base import Instant

Matrices = ElementMatrices | TermMatrices
#: the values of declared terms: (term, its element arrays)
TermValues = list[tuple[Term, Matrices]]


def displacement_field(fields) -> str | None:
    """The name of the displacement among a model's fields (the field an effect acting on the
    displacement addresses: springs, contact); None without one."""
    return next((f.name for f in fields if f.displacement), None)


class Effect:
    name = ""
    linear = True        # its internal forces are K q: no Newton loop needed for it
    symmetric = True     # its tangent is symmetric (with associated relations: Cholesky)

    def fields(self) -> list[Field]:
        return []

    def terms(self) -> list[Term]:
        """Every term it contributes to the operator, declared once (the same objects at every
        call): stiffness terms on cells (elasticity, conduction, a coupling), capacity terms
        (``rate``), terms on boundary facets (an exchange's h ∫ N Nᵀ), terms on tuples of nodes
        (springs, a contact pair's penalty block) and vector terms (loads: thermal expansion's
        reference state, an exchange's h ∫ N T∞). The system derives its pattern from the
        matrix terms and gives each its slots; the model makes load patterns of the vector
        terms (``loads.base.load_patterns``), applied at every step. None by default."""
        return []

    def term_values(self, term: Term, cells: np.ndarray) -> Matrices | None:
        """The values of one of its declared terms on ``cells`` (the local cells of a cell
        term's domain): a linear term's, a nonlinear one's initial tangent, a rate term's
        capacity (a vector term's constant forces: see ``vector_values``). None: nothing
        until ``evaluate`` gives its tangent."""
        return None

    def couple(self, effects: list["Effect"]) -> None:
        """Called once the model's effects are composed: a coupling effect finds the effects
        it acts on (thermal expansion: the elasticity). Nothing by default."""

    def output_names(self) -> list[str]:
        """The /fields and /cell_fields names its outputs take (besides its fields')."""
        return []

    def initial(self) -> dict[str, np.ndarray]:
        """Initial values of its fields {field: (npoints, ncomp)} (absent: zero)."""
        return {}

    def init_state(self, cells: np.ndarray):
        return None

    def increment_size(self, cells: np.ndarray, values: dict[str, np.ndarray]) -> float:
        """How large a step's increment ``values`` {field: (npoints, ncomp)} is on these cells,
        for the adaptive steps (elasticity: the largest strain increment). 0: no limit."""
        return 0.0

    def evaluate(self, cells: np.ndarray, values: dict[str, np.ndarray], state, secant: bool,
                 at: Instant):
        """Internal forces per field {field: (nc, nen, ncomp) element forces of the cells,
        ``NodeForces`` of a node term or a region's cells, or a list of these}, the tangent's
        ``TermValues`` (its stiffness terms; rate terms are the composition's), trial state
        and extras (e.g. stresses at quadrature points) at the node values ``values``
        {field: (npoints, ncomp)} and the step's instant ``at`` (t, Δt, θ: what an effect
        that depends on time reads, as the loads do). A linear effect: K q and K."""
        tangent = self.linear_values(cells)
        forces: dict[str, list] = {}
        for term, m in tangent:
            forces.setdefault(term.test, []).append(
                term_forces(term, m, values[term.trial], self.cells_nodes(cells)))
        return forces, tangent, state, None

    def linear_values(self, cells: np.ndarray, rate: bool = False) -> TermValues:
        """The values of its stiffness terms (``rate``: its capacity terms) on these cells,
        where it has any."""
        out = []
        for term in self.terms():
            if term.rate != rate or term.vector:
                continue
            at = term.positions(cells) if term.on_cells else None
            m = self.term_values(term, cells if at is None else cells[at])
            if m is not None:
                if at is not None:
                    m.positions = at
                if term.on_facets:
                    m.nodes = term.facets
                out.append((term, m))
        return out

    def vector_values(self, term: Term, cells: np.ndarray, at: Instant) -> Iterable[NodeForces]:
        """The forces of one of its vector terms at the step's instant ``at``, as
        ``NodeForces`` block after block (a list, or a generator: one block at a time). By
        default constant: ``term_values`` of the term's cells among ``cells`` (the
        composition's: element forces (nc, nen, d)) or the ``NodeForces`` it gives; an effect
        whose loads vary in time overrides this."""
        where = term.positions(cells) if term.on_cells else None
        chosen = cells if where is None else cells[where]
        f = self.term_values(term, chosen)
        if term.on_cells:
            f = NodeForces(self.cells_nodes(chosen), f)
        return f if isinstance(f, list) else [f]

    def cells_nodes(self, cells: np.ndarray) -> np.ndarray:
        return self.mesh.cells[cells]

    def relations(self) -> list:
        """Relations the effect itself contributes (e.g. solubility's switched ones)."""
        return []

    def outputs(self, owned: np.ndarray, values: dict[str, np.ndarray], extra,
                local_cells: np.ndarray) -> tuple[dict, dict]:
        """({name: (nodal sums (npoints, k), weights (npoints,))}, {name: (owned, nc, k) cell
        values}) of this rank's owned cells; the driver adds the ranks' sums and divides."""
        return {}, {}

    # ------------------------------------------------ relations that change within a step
    def attach(self, ctx) -> None:
        """Called once by the system when it is built, with its step context
        (``parsolve.solvers.context.StepContext``: the DOF map's owned reductions, the relation
        set): what the value hooks below need beyond their arguments. Default: nothing."""

    # An effect whose relations change between Newton iterations (contact: friction states
    # and slip senses) overrides these three; Newton calls them only for such effects. Values
    # change in place (``meta["refresh"]`` marks the relations to copy); when a hook changed
    # their sparsity (``Relation.set_entries``: finite sliding's spans made again) or the
    # domain of a term it declares (``Term.nodes`` given anew: node tuples that moved, e.g. a
    # pairing's) it sets ``restructured`` -- on every rank alike, whether or not the rank
    # holds what moved: the restructure is collective -- and Newton has the system build its
    # operator again (its stiffness pattern derived again from the declared terms,
    # preallocated).
    restructured = False
    # whether its hooks may ever do so (the result file then has /timings/pattern)
    restructures = False

    def begin_step(self, q: np.ndarray, active: dict, at: Instant) -> bool:
        """Start a step from the committed state, toward the instant ``at`` (t, Δt, θ of the
        step); True when relation values changed."""
        return False

    def refresh(self, q: np.ndarray, lam: dict, active: dict) -> bool:
        """Update between iterations (``active``: rows by relation name, writable); True when
        a relation value or a switch changed (the step has not converged then)."""
        return False

    def end_step(self) -> None:
        """Commit the converged step's state."""

    def restart_state(self) -> dict:
        """What a restart needs of the effect's own state between steps (the hooks' committed
        state): none by default."""
        return {}

    def load_restart_state(self, state: dict) -> None:
        """The state ``restart_state`` gave, in a new effect of the same model and ranks."""

    def failure_hints(self) -> list[str]:
        """Sentences on what, in this effect, likely made the last step fail (the driver adds
        them to a solver failure's message): none by default. Every rank says the same."""
        return []

    @property
    def refreshes(self) -> bool:
        """Whether the effect overrides the within-step hooks (``refresh``)."""
        return type(self).refresh is not Effect.refresh

    def step_outputs(self, q: np.ndarray, lam: dict, active: dict) -> tuple[dict, dict]:
        """Outputs of its switched relations at a converged step, from the primal vector and
        the multipliers and active rows of every relation by name: ({field name: (npoints,
        k)}, {relation name: {dataset: value}})."""
        return {}, {}


def term_forces(term: Term, m: Matrices, x: np.ndarray, nodes: np.ndarray):
    """K x of a term's values from node values x (npoints, d_trial): ``NodeForces`` at the
    term's nodes (or a region's cells', or a facet term's facets'), or (nc, nen, d_test)
    element forces of every cell (``nodes``: those cells' nodes)."""
    if isinstance(m, TermMatrices):
        return m.forces(x)
    if m.nodes is not None:   # a facet term: its facets' nodes
        return NodeForces(m.nodes, apply(m, x[m.nodes]))
    if m.positions is None:
        return apply(m, x[nodes])
    return NodeForces(nodes[m.positions], apply(m, x[nodes[m.positions]]))
