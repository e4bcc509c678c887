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

import numpy as np

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


def global_tuples(values, mesh, ids: np.ndarray, whole: bool = True
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tuples of input node ids (n, m) in the partition's global node numbers, with the mask
    of the nodes this rank owns and their local nodes (−1 off this rank). ``whole``: every
    rank gives the same tuples, and each node's number comes from its owner (one reduction of
    the tuples' size: collective); else each rank's own tuples, every node owned here."""
    local = values.local_nodes(ids)
    here = local >= 0
    new = np.where(here, mesh.node_new[np.where(here, local, 0)], 0)
    if whole:
        new = values.node_sum(ids.ravel(), new.ravel().astype(float)).astype(np.int64)
    tuples = new.reshape(ids.shape).astype(np.int64)
    lo, hi = values.node_ranges[values.rank], values.node_ranges[values.rank + 1]
    return tuples, (tuples >= lo) & (tuples < hi), local


class RowTerm:
    """A term on the tuples of rows (``RowTuples``) in the partition's global node numbers,
    declared where this rank owns one of a tuple's nodes (each rank adds its owned rows: a
    tuple split over ranks is whole, no entry crosses ranks at assembly). Its values come
    with the effect's tangent (``evaluate``), set by its hooks between iterations as its
    relations' are; it is ``linear`` in the model's sense (no internal force: the model is as
    nonlinear as its forces, and the hooks run the Newton loop)."""

    def __init__(self, field: str, symmetric: bool):
        self.term = Term(field, field, np.zeros((0, 1), dtype=np.int64), symmetric=symmetric,
                         global_ids=True)
        self.layout: RowTuples | None = None
        self.declared = np.zeros(0, dtype=np.int64)

    def lay(self, rows: Rows, per: int, dim: int, values, mesh, whole: bool) -> None:
        """Its tuples from the rows' layout (``whole``: every rank the same rows, collective)."""
        self.layout = RowTuples(rows, per, dim)
        tuples, owned, _ = global_tuples(values, mesh, self.layout.nodes, whole)
        self.declared = np.flatnonzero(owned.any(axis=1))
        self.term.nodes = tuples[self.declared]

    def matrices(self, u: np.ndarray, w: np.ndarray) -> tuple[Term, TermMatrices]:
        """(the term, Σ_r u_r w_rᵀ on its declared tuples) from (k, r, m, d) arrays over every
        tuple."""
        return self.term, TermMatrices(self.term, outer_blocks(u[self.declared],
                                                               w[self.declared]))
