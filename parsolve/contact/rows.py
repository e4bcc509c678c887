"""Relation rows of contact and friction, as COO triplets over (row, node, component).

Every row of a pairing entry i couples the slave node s_i and the master nodes a of its facet
through one vector v_i (dim,) at the contact point:

    row_i . q = v_i . u(s_i) - sum_a N_a(xi_i) v_i . u(a)

(for an obstacle there are no master nodes). The vector is

    normal row        Dn:           v = n
    tangential rows   Dt_j:         v = t_j                 (one per tangent, j < dim-1)
    slip-direction    Dt.s:         v = sum_j s_j t_j       (s unit in the tangent plane)
    frictional dual   Dn - mu Dt.s: v = n - mu sum_j s_j t_j

so every kind of row has the same layout: ``(1 + k) * dim`` entries per row, slave components
first, then each master node's components, row-major. A dual shares its primal row's
(node, component) positions: refreshing a direction or a pairing on the same facets is a
value update.

For a displacement u: ``Dn . q = n . (u_s - u_m)``, and the current gap is
``g = g0 + Dn . q``. The unilateral normal relation is therefore

    Dn . q >= -g0       (values returned by :func:`normal_values`)

Sign conventions of the reactions: see docs/contact.md and friction.py.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.contact.pairing import Pairing


@dataclass
class Rows:
    """``nrows`` rows as COO entries: entry e adds ``coef[e] * u[node[e], comp[e]]`` to row[e].

    row, node, comp: (nnz,) int64; coef: (nnz,) float64. Entries of one row are contiguous,
    ``width`` per row (rows built from one pairing); duplicates are not merged.
    """

    nrows: int
    row: np.ndarray
    node: np.ndarray
    comp: np.ndarray
    coef: np.ndarray
    width: int

    def apply(self, u: np.ndarray) -> np.ndarray:
        """Row values for a nodal field u (npts, dim): (nrows,)."""
        return np.bincount(self.row, weights=self.coef * u[self.node, self.comp],
                           minlength=self.nrows)

    def dofs(self, ncomp: int) -> np.ndarray:
        """Global DOF numbers under the numbering ``node * ncomp + comp`` (for convenience)."""
        return self.node * ncomp + self.comp


def rows_differ(a: Rows, b: Rows, tol: float) -> bool:
    """Whether the rows a and b (the same rows, any entry layout: spans made again) differ by
    more than tol in some coefficient, entries of the same (row, node, component) summed."""
    if a.row.size == b.row.size and np.array_equal(a.row, b.row) \
            and np.array_equal(a.node, b.node) and np.array_equal(a.comp, b.comp):
        return not np.allclose(a.coef, b.coef, rtol=0, atol=tol)
    keys = np.column_stack([np.concatenate([a.row, b.row]), np.concatenate([a.node, b.node]),
                            np.concatenate([a.comp, b.comp])])
    _, at = np.unique(keys, axis=0, return_inverse=True)
    diff = np.bincount(at.ravel(), weights=np.concatenate([a.coef, -b.coef]))
    return bool(np.any(np.abs(diff) > tol))


def _check(pairing: Pairing) -> None:
    if not np.all(pairing.paired):
        raise ValueError("contact rows need paired entries only: use pairing.only_paired()")


def node_rows(pairing: Pairing, vectors: np.ndarray) -> Rows:
    """One row per pairing entry: v_i . u(s_i) - sum_a N_a v_i . u(a); vectors (n, dim)."""
    _check(pairing)
    n, dim = vectors.shape
    k = pairing.master.shape[1]
    nodes = np.concatenate([pairing.slave[:, None], pairing.master], axis=1)  # (n, 1+k)
    weights = np.concatenate([np.ones((n, 1)), -pairing.weights], axis=1)
    coef = weights[:, :, None] * vectors[:, None, :]  # (n, 1+k, dim)
    width = (1 + k) * dim
    return Rows(
        nrows=n,
        row=np.repeat(np.arange(n, dtype=np.int64), width),
        node=np.repeat(nodes, dim, axis=1).ravel(),
        comp=np.tile(np.arange(dim, dtype=np.int64), n * (1 + k)),
        coef=coef.ravel(),
        width=width,
    )


def normal_rows(pairing: Pairing) -> Rows:
    """Dn: the normal rows (n rows)."""
    return node_rows(pairing, pairing.normal)


def normal_values(pairing: Pairing, obstacle_displacement: np.ndarray | None = None) -> np.ndarray:
    """Right-hand side of ``Dn . q >= b``: b = -g0 (+ n . d for an obstacle moved by d (dim,)
    or (n, dim))."""
    b = -pairing.gap.copy()
    if obstacle_displacement is not None:
        d = np.broadcast_to(np.asarray(obstacle_displacement, dtype=float), pairing.normal.shape)
        b += np.einsum("mx,mx->m", pairing.normal, d)
    return b


def tangent_rows(pairing: Pairing) -> Rows:
    """Dt_j: (dim-1) rows per entry, row ``i * (dim-1) + j`` along tangent j of entry i."""
    n, dm1, dim = pairing.tangents.shape
    rows = node_rows(repeated(pairing, dm1), pairing.tangents.reshape(n * dm1, dim))
    return rows


def repeated(pairing: Pairing, times: int) -> Pairing:
    """Each entry ``times`` times in a row (the rows of one slave: 3D tangential, geometric)."""
    return pairing.subset(np.repeat(np.arange(len(pairing)), times))


def slip_vectors(pairing: Pairing, direction: np.ndarray) -> np.ndarray:
    """Physical slip vectors sum_j s_j t_j (n, dim) of directions s (n, dim-1) or (n,) in 2D."""
    s = np.asarray(direction, dtype=float)
    s = s.reshape(len(pairing), 1) if s.ndim <= 1 else s
    return np.einsum("mj,mjx->mx", s, pairing.tangents)


def direction_rows(pairing: Pairing, direction: np.ndarray) -> Rows:
    """Dt.s: one tangential row per entry along the unit tangent-plane direction s (n, dim-1).

    In 2D s is the slip sense +-1 (shape (n,) or (n, 1)); in 3D a unit 2-vector in (t1, t2).
    """
    return node_rows(pairing, slip_vectors(pairing, direction))


def friction_dual(pairing: Pairing, mu: float | np.ndarray, direction: np.ndarray) -> Rows:
    """The paper's frictional dual of the normal rows, Dn - mu Dt.s, as rows (n rows).

    Same layout as :func:`normal_rows` (same node/comp arrays): only ``coef`` differs. In
    parsolve's convention (reaction ``D lambda``, associated ``D = -A^T``) the relation's dual
    columns are the *negated* coefficients: ``D = -(Dn - mu Dt.s)``, which reduces to ``-A^T``
    for mu = 0. See docs/contact.md for the signs.
    """
    mu = np.broadcast_to(np.asarray(mu, dtype=float), (len(pairing),))
    v = pairing.normal - mu[:, None] * slip_vectors(pairing, direction)
    return node_rows(pairing, v)


def tangential_components(pairing: Pairing, u: np.ndarray) -> np.ndarray:
    """Relative tangential displacement (slave minus master) in the tangent basis: (n, dim-1)."""
    n, dm1, _ = pairing.tangents.shape
    return tangent_rows(pairing).apply(u).reshape(n, dm1)


def span_rows(pairing: Pairing, vectors: np.ndarray, ptr: np.ndarray, nodes: np.ndarray) -> Rows:
    """Rows like :func:`node_rows` over a superset of master nodes per entry (finite sliding):
    entry i spans the slave node and the master nodes ``nodes[ptr[i]:ptr[i+1]]`` (increasing
    ids: every facet the slave may visit), the nodes of its current facet carry -N_a v_i, the
    others 0. The layout depends on the span alone, so a slave moving to another facet of its
    span is a value update of the same entries (no new sparsity until the spans change).
    ValueError when a current facet node is outside its entry's span."""
    _check(pairing)
    if pairing.master.shape[1] == 0:   # a rigid obstacle: the slave alone, spans empty
        return node_rows(pairing, vectors)
    return span_combination(pairing, vectors, -pairing.weights[:, :, None] * vectors[:, None, :],
                            ptr, nodes)


def span_combination(pairing: Pairing, slave: np.ndarray, master: np.ndarray, ptr: np.ndarray,
                     nodes: np.ndarray) -> Rows:
    """Rows in :func:`span_rows`' layout whose entry i holds the vector ``slave[i]`` (dim,) on
    its slave node and ``master[i, a]`` on node a of its current facet (the span's other
    nodes 0): any combination of the slave's and its facet's displacements."""
    n, dim = slave.shape
    if pairing.master.shape[1] == 0:   # a rigid obstacle: the slave alone
        return node_rows(pairing, slave)
    counts = np.diff(ptr)
    owner = np.repeat(np.arange(n, dtype=np.int64), counts)
    big = int(max(nodes.max(initial=0), pairing.master.max(initial=0))) + 1
    key = owner * big + nodes                        # increasing: owners, then node ids
    cur = (np.arange(n, dtype=np.int64)[:, None] * big + pairing.master).ravel()
    pos = np.minimum(np.searchsorted(key, cur), max(key.size - 1, 0))
    if cur.size and (key.size == 0 or np.any(key[pos] != cur)):   # (a rank may hold none)
        raise ValueError("a current master facet lies outside the entry's span")
    on_span = np.zeros((nodes.size, dim))
    np.add.at(on_span, pos, master.reshape(-1, dim))   # distinct nodes of one facet: no overlap
    # per entry: the slave node first, then its span (entry i starts at ptr[i] + i)
    total = n + nodes.size
    first = ptr[:-1] + np.arange(n)
    is_slave = np.zeros(total, dtype=bool)
    is_slave[first] = True
    node_all = np.empty(total, dtype=np.int64)
    node_all[first] = pairing.slave
    node_all[~is_slave] = nodes
    coef = np.empty((total, dim))
    coef[first] = slave
    coef[~is_slave] = on_span
    row_of = np.repeat(np.arange(n, dtype=np.int64), counts + 1)
    return Rows(nrows=n, row=np.repeat(row_of, dim), node=np.repeat(node_all, dim),
                comp=np.tile(np.arange(dim, dtype=np.int64), total), coef=coef.ravel(), width=0)
