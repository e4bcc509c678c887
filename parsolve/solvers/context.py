"""The step context: what the nonlinear problem (``solvers.problem``), the outputs, the driver
and the effects' hooks see of a system, built once by the system.

It holds the values side of the problem: the DOF map (local/owned vectors, ghost exchange,
owned reductions), the relation set (stacked rows: A q, gaps, D λ, per-relation views), the
effects composed on this rank's cells (forces, tangents, states, field values) and the scene's
data the steps need (times, patterns, the initial state); the rows active now stay with the
active set (the problem's policies hand them to the hooks and the outputs as per-relation
views). Assembly, the right-hand side and unpacking stay with the system; nothing here reaches
into it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from parsolve.effects.compose import Composition
from parsolve.la.dofmap import DofMap
from parsolve.la.relation_set import RelationSet


@dataclass
class StepContext:
    comm: object
    dofs: DofMap                 # numbering, exchanges, owned reductions
    relations: RelationSet       # the multiplied relations, stacked
    eliminated: list             # relations eliminated from the operator
    all_relations: list          # every relation of the model, in its order
    composition: Composition     # the effects on this rank's local cells
    effects: list
    fields: object               # the model's FieldSet
    mesh: object                 # this rank's LocalMesh
    scene: object
    patterns: dict
    cells: np.ndarray            # this rank's local cells
    owned_cells: np.ndarray      # the cells this rank reports
    reported: np.ndarray         # which of its local cells they are
    initial_q: Callable[[], np.ndarray]   # the initial primal vector (a new array per call)
    symmetric: Callable[[bool], bool]     # whether the effects' tangents are symmetric
    nonlinear: bool = False
    transient: bool = False

    # ------------------------------------------------------------ relations

    @property
    def multiplied(self) -> list:
        """The relations with multipliers, in the stacked order."""
        return self.relations.relations

    @property
    def ncomp(self) -> int:
        return self.dofs.ncomp

    @property
    def ndof(self) -> int:
        """Local primal DOFs (owned then ghosts)."""
        return self.dofs.n_local

    def relation_primal(self, r, q: np.ndarray) -> np.ndarray:
        """A q of any relation's rows (one reduction). Collective."""
        return self.relations.relation_primal(r, q)

    def views(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Per multiplied relation, its rows of a per-relation-row array (writable views)."""
        return self.relations.views(x)

    def multipliers_by_relation(self, lam: np.ndarray) -> dict[str, np.ndarray]:
        """Per multiplied relation, the unscaled λ of its rows."""
        return self.relations.per_relation(lam)

    # ------------------------------------------------------------ values and reductions

    def values(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Nodal values of every field from a local primal vector."""
        return self.composition.values(q)

    def norm(self, v: np.ndarray) -> float:
        return self.dofs.norm(v)

    def dot(self, u: np.ndarray, v: np.ndarray) -> float:
        return self.dofs.dot(u, v)

    def max_abs(self, v: np.ndarray) -> float:
        return self.dofs.max_abs(v)

    def owned_rows(self, v: np.ndarray) -> np.ndarray:
        """A local primal vector → this rank's saddle rows."""
        return self.dofs.owned_rows(v)

    def local_vector(self, dofs: np.ndarray, values: np.ndarray) -> np.ndarray:
        """A local primal vector from (input DOFs, values) entries."""
        return self.dofs.local_vector(dofs, values)
