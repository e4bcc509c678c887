"""Rows that tie a slave node to master nodes (node-to-face contact, dual mortar, periodic
ties), condensed on their slave node (``solvers.condensed``): the pieces the nodal
condensation lacks.

A hard row i of slave node s reads A_s u_s + A_m u_m = r_i (A_s: its entries on s, A_m: on its
masters). The slave's rows A_s = Rᵀ Q_cᵀ (the QR of ``condensed``) fix u_s along Q_c:
u_s = Q_f y_s + Q_c R⁻ᵀ (r_h − A_m u_m). With no master holding hard rows of its own (refused:
a chain), u = H y + (I + X) c, H = H_n + X, X = −Q_c R⁻ᵀ A_m (rows: the slave's DOFs, columns:
its masters'), H_n the nodal frames, c the nodal lifts Q_c R⁻ᵀ r_h. The multipliers of s act
on s through B_s and on its masters through B_m; s's constrained equations give
λ_s = E_c⁻¹ Q_cᵀ (r̂ − K_eff u)_s, and a master's equation, less B_m times that, holds no
multiplier: G = G_n + Y, Y = −B_m E_c⁻¹ Q_cᵀ (rows: the masters' DOFs, columns: the slave's).
For an associated relation (B = −Aᵀ) Y = Xᵀ and G = Hᵀ. S = G K_eff H is no longer in K's
pattern: PETSc's triple product of the sparse G, K_eff, H (``MatMatMatMult``), reused while
the active rows (G's and H's patterns) stay.

The slave of a row is, of its nodes on this rank, that of the largest block of A (a
node-to-face row: the slave's coefficient is the normal, a master's the normal times a shape
function ≤ 1; of blocks within TIE of the largest, the node in the fewest of the rank's rows:
a slave lies in its own rows only, a master in those of every slave near it); where that node
lies in another row too (a master there: dual mortar's weights M_ia / w_i exceed 1 where a
slave's facets are barely covered), the row's node in the fewest rows, then of the largest
block. Any node whose block has full rank would do: the elimination is exact whichever it is
(the choice only shapes S). A row spread over several slave nodes (standard mortar) makes
another row's slave its master: a chain, refused with its reason.

Measured on the mortar sphere (configs/contact_mortar_sphere_3d.toml) at 1x and 8x (16,659
and 118,830 DOFs, 1 rank): the condensation is exact (LU on S: GMRES on M takes 1 iteration
per solve at both sizes, against 20-24 and 30-38 with the V-cycle); X's weights stay <= 1
(its rows' |.|-sums <= 1.23; the larger weights are the coarsened test meshes'), and the
V-cycle on the tied S needs the Krylov iterations of the same V-cycle on K alone (GMRES to
2.5e-14 on a random right-hand side: 28 and 28 at 1x, 48 and 48 at 8x). What grows with the
mesh is the V-cycle on this graded, stretched grid's stiffness, not the tied rows
(docs/performance.md, the mortar paragraph).
"""

from __future__ import annotations

import hashlib

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc


def tied_rows(pre, mat: PETSc.Mat):
    """(code, rows): the multiplier rows of ``mat`` read for the condensation of tied rows.
    rows = (slave node of each row (local) or -1, C's diagonal, A's and B's entries on the
    slave (``condensed._node_blocks``' arguments)); the master parts are kept on ``pre``
    (``tie_a``, ``tie_b``: (row, global primal DOF, value)). Codes: those of
    ``condensed.REASONS``."""
    nc = pre.nc
    sub = mat.createSubMatrix(pre.is_l, pre.is_all)   # [A, C]
    indptr, cols, vals = sub.getValuesCSR()
    sub.destroy()
    rows = np.repeat(np.arange(pre.nl), np.diff(indptr))
    glob, on_l = _primal(pre, cols)
    c = on_l
    # (a C off its diagonal is refused after the second submatrix: both are collective, and
    # only the rank holding such an entry sees it)
    coupled = bool(np.any(cols[c] != pre.start + pre.nq + rows[c]))
    diag = np.zeros(pre.nl)
    diag[rows[c]] = vals[c]
    ar, ag, av = rows[~on_l], glob[~on_l], _clean(pre.nl, rows[~on_l], vals[~on_l])
    sub = mat.createSubMatrix(pre.is_all, pre.is_l)   # [B; C], its transpose: by multiplier
    bt = sub.transpose(PETSc.Mat())
    sub.destroy()
    indptr, cols, vals = bt.getValuesCSR()
    bt.destroy()
    if coupled:
        return 2, None
    brow = np.repeat(np.arange(pre.nl), np.diff(indptr))
    bglob, b_on_l = _primal(pre, cols)
    br, bg, bv = brow[~b_on_l], bglob[~b_on_l], _clean(pre.nl, brow[~b_on_l], vals[~b_on_l])
    slave = _slaves(pre, ar, ag // nc, av)
    hard = diag == 0.0
    some = slave >= 0
    lo, hi = pre.q_start // nc, (pre.q_start + pre.nq) // nc
    if np.any(hard & ~some):
        return 5, None
    if np.any((slave[some] < lo) | (slave[some] >= hi)):
        return 1, None
    on_slave = ag // nc == slave[ar]
    tied = (av != 0.0) & ~on_slave
    if np.any(~hard[ar[tied]]):
        return 8, None
    # each row's dual on its own nodes (the pattern of its A row)
    width = np.int64(int(pre.nqs.sum()) // nc + 1)
    if not np.all(np.isin(br * width + bg // nc, ar * width + ag // nc)):
        return 3, None
    b_on_slave = bg // nc == slave[br]
    pre.tie_a = (ar[tied], ag[tied], av[tied])
    b_tied = ~b_on_slave & (bv != 0.0)
    if np.any(~hard[br[b_tied]]):
        return 8, None
    pre.tie_b = (br[b_tied], bg[b_tied], bv[b_tied])
    node = np.where(some, slave - lo, -1)
    arows = (ar[on_slave], ag[on_slave] - pre.q_start, av[on_slave])
    bcols = (bg[b_on_slave] - pre.q_start, br[b_on_slave], bv[b_on_slave])
    return 0, (node, diag, arows, bcols)


def _clean(n: int, rows: np.ndarray, vals: np.ndarray) -> np.ndarray:
    """The values with those below NEGLIGIBLE times their row's largest set to 0: round-off
    entries (a mortar row's 1e-13 on a neighbouring slave node) would make a master of a
    slave node (a chain); left out, the condensation is M⁻¹ to that relative accuracy."""
    top = np.zeros(n)
    np.maximum.at(top, rows, np.abs(vals))
    return np.where(np.abs(vals) > NEGLIGIBLE * top[rows], vals, 0.0)


def _primal(pre, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Saddle columns → (their global primal DOF (where primal), whether a multiplier)."""
    owner = np.searchsorted(pre.starts, cols, side="right") - 1
    inside = cols - pre.starts[owner]
    q_first = np.concatenate([[0], np.cumsum(pre.nqs)])
    return q_first[owner] + inside, inside >= pre.nqs[owner]


#: blocks of a row within this of its largest are tied for its slave
TIE = 1e-9
#: an entry of a tied row below this times the row's largest is taken as round-off (0)
NEGLIGIBLE = 1e-10


def _slaves(pre, rows: np.ndarray, nodes: np.ndarray, vals: np.ndarray) -> np.ndarray:
    """Each multiplier row's slave node (global; -1: a row with no nonzero entry): of its
    nodes on this rank, that of the largest block of A (of tied ones, the one in the fewest of
    this rank's rows); where that node lies in another row too (a master there), the one in
    the fewest rows, then of the largest block."""
    nc = pre.nc
    slave = np.full(pre.nl, -1, dtype=np.int64)
    nz = vals != 0.0
    if not nz.any():
        return slave
    width = np.int64(nodes.max() + 1)
    key, inv = np.unique(rows[nz] * width + nodes[nz], return_inverse=True)
    norm = np.zeros(key.size)
    np.add.at(norm, inv, vals[nz] ** 2)
    row, node = key // width, key % width
    lo, hi = pre.q_start // nc, (pre.q_start + pre.nq) // nc
    remote = (node < lo) | (node >= hi)
    _, which = np.unique(node, return_inverse=True)
    count = np.bincount(which)[which]   # (the rows of this rank each node lies in)
    top = np.zeros(pre.nl)
    np.maximum.at(top, row, norm)
    tied = norm >= (1.0 - TIE) ** 2 * top[row]

    def first(*keys) -> np.ndarray:   # (each row's first entry in the order of the keys)
        order = np.lexsort(keys + (remote, row))
        return order[np.r_[True, row[order][1:] != row[order][:-1]]]

    largest, fewest = first(-norm, count, ~tied), first(-norm, count)
    slave[row[largest]] = node[largest]
    clash = node[slave[row] != node]                 # nodes that are another row's master
    moved = np.isin(slave[row[fewest]], clash)
    slave[row[fewest[moved]]] = node[fewest[moved]]
    return slave


def chain(pre) -> bool:
    """Whether a master node of a hard tied row holds hard rows of its own (on any rank):
    its frame H would enter the slave's (not done). Collective."""
    nc = pre.nc
    masters = np.unique(pre.tie_a[1] // nc)
    held = PETSc.Vec().createMPI((pre.nq // nc, None), comm=pre.comm)
    held.array[:] = 0.0
    held.array[pre.nodes[pre.keep.any(axis=1)]] = 1.0
    out = gather_nodes(pre.comm, held, masters)
    held.destroy()
    return bool(pre.comm.allreduce(int(np.any(out != 0.0)), op=MPI.MAX))


def gather_nodes(comm, vec: PETSc.Vec, index: np.ndarray) -> np.ndarray:
    """The entries ``index`` (global) of a distributed vector, on this rank."""
    is_ = PETSc.IS().createGeneral(index.astype(PETSc.IntType), comm=comm)
    out = PETSc.Vec().createSeq(index.size, comm=PETSc.COMM_SELF)
    scatter = PETSc.Scatter().create(vec, is_, out, None)
    scatter.scatter(vec, out, addv=PETSc.InsertMode.INSERT_VALUES,
                    mode=PETSc.ScatterMode.FORWARD)
    values = out.array.copy()
    for obj in (scatter, out, is_):
        obj.destroy()
    return values


def frames(pre) -> tuple[PETSc.Mat, PETSc.Mat, PETSc.Mat]:
    """(G, H, X) of the module docstring, distributed AIJ on the primal layout: the nodal
    frames (the identity off the condensed nodes) plus the tied rows' Y and X. Their values
    put in place into ``pre``'s (pre.G, pre.H, pre.X, returned) when their pattern is the last
    call's on every rank (the same active rows: S's product is then reused, solvers.condensed);
    else new matrices (pre.G is None: made anew). Collective."""
    triplets = [_sorted(*t) for t in _triplets(pre)]
    pattern = _digest(triplets)
    same = pre.G is not None and pre.frame_pattern == pattern
    same = bool(pre.comm.allreduce(int(same), op=MPI.MIN))
    pre.frame_pattern = pattern
    if not same:
        return tuple(_aij(pre, *t) for t in triplets)
    mats = (pre.G, pre.H, pre.X)
    for mat, (rows, cols, vals) in zip(mats, triplets):
        mat.zeroEntries()
        _set(mat, rows, cols, vals)
    return mats


def _digest(triplets) -> bytes:
    """The pattern of the triplets (their rows and columns) as a digest: kept between calls
    instead of the arrays themselves (two int64 per entry beside the matrices)."""
    h = hashlib.blake2b(digest_size=32)
    for rows, cols, _ in triplets:
        h.update(np.int64(rows.size).tobytes())
        h.update(np.ascontiguousarray(rows, dtype=np.int64).tobytes())
        h.update(np.ascontiguousarray(cols, dtype=np.int64).tobytes())
    return h.digest()


def _triplets(pre):
    """G's, H's and X's entries (global (row, column, value), unsorted, duplicates to sum)."""
    nc, q0 = pre.nc, pre.q_start
    at, pos = np.full(pre.nl, -1), np.full(pre.nl, -1)
    at[pre.hard], pos[pre.hard] = pre.hard_at, pre.hard_pos
    dofs = q0 + pre.nodes[:, None] * nc + np.arange(nc)             # (m, nc) global
    i, j, v = pre.tie_a                                              # X: slave DOFs × masters
    x = (dofs[at[i]].reshape(-1), np.repeat(j, nc),
         -(pre.lift[at[i], :, pos[i]] * v[:, None]).reshape(-1))
    i, j, v = pre.tie_b                                              # Y: masters × slave DOFs
    y = (np.repeat(j, nc), dofs[at[i]].reshape(-1),
         -(pre.dual[at[i], pos[i], :] * v[:, None]).reshape(-1))
    out = []
    for blocks, extra in ((pre.g, y), (pre.h, x)):
        nodal = _nodal_entries(pre, blocks)
        out.append(tuple(np.concatenate([a, b]) for a, b in zip(nodal, extra)))
    out.append(x)
    return out


def _nodal_entries(pre, blocks: np.ndarray):
    """The block-diagonal frame: ``blocks`` on the condensed nodes, 1 on the other DOFs'
    diagonal (global (row, column, value))."""
    nc, q0 = pre.nc, pre.q_start
    other = np.ones(pre.nq, dtype=bool)
    own = (pre.nodes[:, None] * nc + np.arange(nc)).reshape(-1)
    other[own] = False
    rows = np.repeat(pre.nodes[:, None] * nc + np.arange(nc), nc, axis=1).reshape(-1)
    cols = np.tile(pre.nodes[:, None] * nc + np.arange(nc), (1, nc)).reshape(-1)
    free = np.flatnonzero(other)
    return (q0 + np.concatenate([rows, free]), q0 + np.concatenate([cols, free]),
            np.concatenate([blocks.reshape(-1), np.ones(free.size)]))


def _sorted(rows: np.ndarray, cols: np.ndarray, vals: np.ndarray):
    order = np.lexsort((cols, rows))
    return rows[order], cols[order], vals[order]


def _aij(pre, rows: np.ndarray, cols: np.ndarray, vals: np.ndarray) -> PETSc.Mat:
    """A distributed AIJ matrix (primal × primal) of the triplets (sorted by row, then column;
    duplicates summed; rows of other ranks sent to them at assembly)."""
    n = int(pre.nqs.sum())
    mine = (rows >= pre.q_start) & (rows < pre.q_start + pre.nq)
    count = np.bincount(rows[mine] - pre.q_start, minlength=pre.nq)
    inside = (cols[mine] >= pre.q_start) & (cols[mine] < pre.q_start + pre.nq)
    diag = np.bincount(rows[mine][inside] - pre.q_start, minlength=pre.nq)
    mat = PETSc.Mat().createAIJ(size=((pre.nq, n), (pre.nq, n)),
                                nnz=(np.minimum(diag, pre.nq).astype(PETSc.IntType),
                                     (count - diag).astype(PETSc.IntType)), comm=pre.comm)
    mat.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    _set(mat, rows, cols, vals)
    return mat


def _set(mat: PETSc.Mat, rows: np.ndarray, cols: np.ndarray, vals: np.ndarray) -> None:
    """The sorted triplets added into ``mat``, then assembled."""
    starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])[:rows.size]
    indptr = np.append(starts, rows.size).astype(PETSc.IntType)
    mat.setValuesIJV(indptr, cols.astype(PETSc.IntType), vals,
                     rowmap=rows[starts].astype(PETSc.IntType),
                     addv=PETSc.InsertMode.ADD_VALUES)
    mat.assemble()
