"""Contact rows that depend on the other enforced rows: found exactly, then not enforced.

A contact row on a node that a Dirichlet relation also holds (a held corner), a periodic tie
between two contact nodes, a node in two contact surfaces along the same normal: the enforced
rows are then linearly dependent and the saddle operator is singular (MUMPS: null pivots).
Such a row adds no constraint that the others do not already impose, so leaving it out of the
solve (its multiplier zero) gives the same displacements; the reaction goes to the rows it
depends on (the Dirichlet condition, the other surface). Only contact rows are ever left out,
and only when they depend on rows that come before them in a fixed order (every other
relation first, then the contact rows in their order): the same rows on every rank and
partition, whatever the round-off.

The test is exact linear algebra on a small block, not a regularisation:

1. the columns of eliminated DOFs (single-DOF Dirichlet conditions) are dropped: a row left
   with no entry is fixed by them alone (a contact row on a fully held obstacle node);
2. a row with an entry on a DOF that no other row touches is independent of all others, and
   so are the rows that alone touch a node on which they are independent (the rows of one
   contact node); so are the rows left so once those are set aside (peeling, vectorised);
3. the few rows that remain (those of held, tied or shared nodes) form a dense block whose
   Householder QR in the fixed order gives each row's distance to the span of the rows before
   it: a distance below ``TOL`` of the row's norm is a dependent row.

Whether the left-out row is satisfied is decided by the rows it depends on: ``violated``
tells the solver when it is not (a held node pushed into the obstacle), which is an error,
not a silently wrong answer.
"""

from __future__ import annotations

import numpy as np

#: Relative distance below which a row is in the span of the rows before it. Dependent rows
#: of the cases above are exactly dependent (distance at round-off, ~1e-16); independent ones
#: are at distances of order one of their coefficients.
TOL = 1e-9
#: The dense block's largest size (rows): beyond it the check is skipped (never reached by
#: held, tied or shared nodes alone; a whole surface tied to another would be).
MAX_CORE = 4000


def dependent_rows(rows: np.ndarray, dofs: np.ndarray, vals: np.ndarray, nrows: int,
                   enforced: np.ndarray, candidate: np.ndarray,
                   fixed_dofs: np.ndarray, ncomp: int = 1,
                   key: np.ndarray | None = None) -> np.ndarray:
    """Mask (nrows,) of the ``candidate`` rows among the ``enforced`` ones that depend on the
    enforced rows before them (non-candidates first, then candidates in row order).

    rows, dofs, vals: COO entries of every row (DOFs ``node * ncomp + component``); fixed_dofs:
    DOFs whose columns are eliminated (their values known); key: each row's place in the
    order (default: its number), the same on every rank for rows held on several."""
    out = np.zeros(nrows, dtype=bool)
    keep = enforced[rows] & (vals != 0.0) & ~np.isin(dofs, fixed_dofs)
    norm = np.sqrt(np.bincount(rows, weights=vals ** 2, minlength=nrows))
    left = np.sqrt(np.bincount(rows[keep], weights=vals[keep] ** 2, minlength=nrows))
    empty = enforced & (left <= TOL * np.maximum(norm, 1e-300))
    out[empty & candidate] = True
    r, d, v = _merged(rows[keep], dofs[keep], vals[keep])
    alive = enforced & ~empty
    while True:   # peel the rows with a DOF of their own, or a node of their own
        on = alive[r]
        _, inv, count = np.unique(d[on], return_inverse=True, return_counts=True)
        own = np.zeros(nrows, dtype=bool)
        own[r[on][count[inv] == 1]] = True
        own |= _own_node(r[on], d[on], v[on], nrows, ncomp)
        if not own.any():
            break
        alive &= ~own
    core = np.flatnonzero(alive)
    if core.size == 0 or core.size > MAX_CORE:
        return out
    if key is not None:
        core = core[np.argsort(key[core], kind="stable")]
    order = np.concatenate([core[~candidate[core]], core[candidate[core]]])
    on = alive[r]
    cols, col = np.unique(d[on], return_inverse=True)
    pos = np.empty(nrows, dtype=np.int64)
    pos[order] = np.arange(order.size)
    block = np.zeros((cols.size, order.size))
    np.add.at(block, (col, pos[r[on]]), v[on])
    dep = order[_dependent_columns(block)]
    out[dep[candidate[dep]]] = True
    return out


def _own_node(r: np.ndarray, d: np.ndarray, v: np.ndarray, nrows: int, ncomp: int) -> np.ndarray:
    """Rows independent of all others through a node: where the rows touching a node's DOFs
    are independent on those DOFs alone (at most ncomp of them, a full-rank block), no
    combination of all rows can vanish unless theirs do (the normal and tangential rows of a
    contact node on an inclined surface share its DOFs: no DOF of their own, but their node).
    Every node's block at once (batched singular values)."""
    out = np.zeros(nrows, dtype=bool)
    if r.size == 0:
        return out
    node, comp = np.divmod(d, ncomp)
    keys = np.unique(node * nrows + r)               # (node, row) pairs, by node
    knode, krow = np.divmod(keys, nrows)
    nodes, first, count = np.unique(knode, return_index=True, return_counts=True)
    slot = np.arange(keys.size) - np.repeat(first, count)
    small = count <= ncomp
    if not small.any():
        return out
    at = np.searchsorted(nodes, node)
    pick = small[at]
    blocks = np.zeros((nodes.size, ncomp, ncomp))
    np.add.at(blocks, (at[pick], slot[np.searchsorted(keys, node[pick] * nrows + r[pick])],
                       comp[pick]), v[pick])
    sv = np.linalg.svd(blocks[small], compute_uv=False)
    k = count[small]
    full = sv[np.arange(k.size), k - 1] > TOL * np.maximum(sv[:, 0], 1e-300)
    good = np.zeros(nodes.size, dtype=bool)
    good[np.flatnonzero(small)[full]] = True
    out[krow[good[np.searchsorted(nodes, knode)]]] = True
    return out


def _dependent_columns(block: np.ndarray) -> np.ndarray:
    """Positions of the columns in the span of the columns before them. Householder QR gives
    each column's distance to the span of the previous ones (|R_kk|) up to the first dependent
    column only (past it the diagonal no longer measures distances): that column is set aside
    and the rest factored again, once per dependent column (few: one per held, tied or shared
    node direction)."""
    index = np.arange(block.shape[1])
    out, start = [], 0
    size = np.maximum(np.linalg.norm(block, axis=0), 1e-300)
    while index.size > start:
        sub = block[:, index]
        if sub.shape[0] < sub.shape[1]:   # more rows than DOFs: pad (distances unchanged)
            sub = np.vstack([sub, np.zeros((sub.shape[1] - sub.shape[0], sub.shape[1]))])
        dist = np.abs(np.diag(np.linalg.qr(sub, mode="r")))
        bad = np.flatnonzero(dist[start:] <= TOL * size[index[start:]])
        if bad.size == 0:
            break
        k = start + int(bad[0])
        out.append(index[k])
        index, start = np.delete(index, k), k
    return np.array(out, dtype=np.int64)


def _merged(rows: np.ndarray, dofs: np.ndarray, vals: np.ndarray):
    """The entries with repeated (row, DOF) pairs summed (a row's DOF counted once)."""
    span = int(dofs.max()) + 1 if dofs.size else 1
    keys, inv = np.unique(rows.astype(np.int64) * span + dofs, return_inverse=True)
    return keys // span, keys % span, np.bincount(inv, weights=vals, minlength=keys.size)
