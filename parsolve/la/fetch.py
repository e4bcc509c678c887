"""The values of a primal vector at DOFs any rank owns, fetched from their owners: one plan
(``GhostExchange`` on those DOFs alone), two ``Alltoallv`` a call. What a rank reads beyond its
own nodes and ghosts: a tie's other end, a contact row's master nodes, an eliminated DOF a
relation row names."""

from __future__ import annotations

import numpy as np

from parsolve.la.dofmap import GhostExchange


class Fetch:
    """A primal vector's values at DOFs given by their global numbers (``new_dofs``: new node
    · ncomp + component, any rank's) from their owners (``node_ranges``: each rank's first new
    node); ``width`` values per DOF (columns of a table (n, width): all in one exchange).
    Planning is collective, and so is each call."""

    def __init__(self, comm, new_dofs: np.ndarray, node_ranges: np.ndarray, ncomp: int,
                 width: int = 1):
        ranges = np.asarray(node_ranges, dtype=np.int64) * ncomp
        new_dofs = np.asarray(new_dofs, dtype=np.int64)
        owner = np.searchsorted(ranges, new_dofs, side="right") - 1
        self.n_owned = int(ranges[comm.rank + 1] - ranges[comm.rank])
        # (a table's row-major entries: DOF d's column c at d · width + c)
        wanted = (new_dofs[:, None] * width + np.arange(width)).ravel()
        self.plan = GhostExchange(comm, wanted, np.repeat(owner, width),
                                  int(ranges[comm.rank]) * width)

    @classmethod
    def of(cls, dofmap, new_dofs: np.ndarray, width: int = 1) -> "Fetch":
        """The plan of a DOF map's ranks (``DofMap``). Collective."""
        return cls(dofmap.comm, new_dofs, dofmap.node_ranges, dofmap.ncomp, width)

    def __call__(self, q: np.ndarray) -> np.ndarray:
        """The values from this rank's vector q (its owned DOFs first), or its table
        (n, width): (len(new_dofs),) or (len(new_dofs), width). Collective."""
        q = np.asarray(q[:self.n_owned], dtype=float)
        return self.plan.forward(q.ravel()).reshape((-1,) + q.shape[1:])
