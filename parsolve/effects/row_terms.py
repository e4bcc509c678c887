"""Rows that are a stiffness: terms on the node tuples of contact rows.

A row a with dual column d, enforced on the Newton increment with compliance c and a zero
right-hand side, its multiplier discarded after the solve (``a Δq − c λ = 0``), adds −d aᵀ / c
to the primal block once λ = a Δq / c is eliminated (associated, d = −aᵀ: aᵀa / c ≥ 0), and
nothing else: it has no force, and its λ is no result. It is then the same thing as a term on
the tuple of the row's nodes, with that block as its values and no force: friction's cross
stiffness κ (s⊥)(s⊥)ᵀ, finite sliding's geometric stiffness −G = −Σ u wᵀ. The term is exact
(no compliance in the operator's multiplier block), keeps the saddle system to the rows that
constrain, and its pattern is derived with the others' (a new one when spans are made again).

A row whose multiplier is a result, whose right-hand side is a target (a soft support held
at a value), or whose compliance may vanish (the same row hard at one iterate and soft at the
next) is not the same thing: its multiplier must stay. None is left in parsolve: friction's
row across s is a relation row while the node is held or sticks (hard, its multiplier the
friction force) and a term while it slides free.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from mpi4py import MPI

from parsolve.contact.rows import Rows
from parsolve.fem.element_matrices import Term, TermMatrices


class RowTuples:
    """The node tuples of rows grouped ``per`` consecutive rows a tuple (the rows of one slave:
    row i in tuple i // per, place i % per): each tuple the rows' distinct nodes (input ids),
    padded to the widest with its first node (a repeated node adds nothing to the pattern)."""

    def __init__(self, rows: Rows, per: int, dim: int):
        self.per, self.dim = per, dim
        group = rows.row // per
        k = rows.nrows // per
        big = int(rows.node.max(initial=0)) + 1
        keys, inverse = np.unique(group * big + rows.node, return_inverse=True)
        owner, node = np.divmod(keys, big)
        first = np.searchsorted(owner, np.arange(k))
        place = np.arange(keys.size) - first[owner]
        width = int(place.max(initial=0)) + 1
        self.nodes = np.repeat(node[np.minimum(first, max(keys.size - 1, 0))][:, None], width,
                               axis=1) if keys.size else np.zeros((k, 1), dtype=np.int64)
        self.nodes[owner, place] = node
        self._at = (group, rows.row % per, place[inverse.ravel()], rows.comp)

    def dense(self, coef: np.ndarray) -> np.ndarray:
        """The rows' coefficients (in the layout's entry order) as (k, per, m, dim)."""
        k, m = self.nodes.shape
        out = np.zeros((k, self.per, m, self.dim))
        np.add.at(out, self._at, coef)
        return out


def outer_blocks(u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Σ_r u_r w_rᵀ per tuple, from (k, r, m, d) arrays, as a term's values (d·d, m, m, k):
    entry (i, j) of node pair (a, b) at [i d + j, a, b]."""
    k, _, m, d = u.shape
    return np.einsum("krai,krbj->ijabk", u, w).reshape(d * d, m, m, k)


class RowTerm:
    """A term on the tuples of this rank's own rows (``RowTuples``; a slave's rows live on its
    owner, their master nodes on any rank) in the partition's global node numbers, declared
    by this rank alone (the system sends the entries of the rows another rank owns there:
    ``la.tuple_rows``). Its values come
    with the effect's tangent (``evaluate``), set by its hooks between iterations as its
    relations' are; it is ``linear`` in the model's sense (no internal force: the model is as
    nonlinear as its forces, and the hooks run the Newton loop). ``new_of`` gives input node
    ids' global numbers (this rank's rows' nodes)."""

    def __init__(self, field: str, symmetric: bool, new_of: Callable[[np.ndarray], np.ndarray]):
        self.term = Term(field, field, np.zeros((0, 1), dtype=np.int64), symmetric=symmetric,
                         global_ids=True)
        self.new_of = new_of
        self.layout: RowTuples | None = None

    def lay(self, rows: Rows, per: int, dim: int, values) -> None:
        """Its tuples from the rows' layout (this rank's rows). Collective."""
        self.layout = RowTuples(rows, per, dim)
        nodes = self.layout.nodes
        width = values.comm.allreduce(nodes.shape[1], op=MPI.MAX)
        if width > nodes.shape[1]:   # (the same width everywhere: first nodes repeated)
            pad = np.repeat(nodes[:, :1], width - nodes.shape[1], axis=1)
            self.layout.nodes = nodes = np.concatenate([nodes, pad], axis=1)
        self.term.nodes = self.new_of(nodes).reshape(nodes.shape).astype(np.int64)

    def matrices(self, u: np.ndarray, w: np.ndarray) -> tuple[Term, TermMatrices]:
        """(the term, Σ_r u_r w_rᵀ) from (k, r, m, d) arrays over this rank's tuples."""
        return self.term, TermMatrices(self.term, outer_blocks(u, w))
