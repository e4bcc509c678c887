"""The DOF map of a rank, in the manner of dolfinx's ``IndexMap``: the one owner of how the
saddle vector [q, λ] is numbered and split across ranks.

- **Saddle numbering.** Rank r owns a contiguous block of the global vector: first its primal
  DOFs (its owned nodes × ncomp, node-major, in the partition's contiguous node numbering
  ``new_node * ncomp + c``), then its multipliers: the rows the relation set gives it, those
  whose first DOF it owns (``set_multipliers``; ``la.relation_set``), so that a row of A and
  its column of D live with the nodes they act on.
- **Local DOFs.** A rank holds its owned nodes then its ghost nodes (``LocalMesh``); local DOF
  ``local_node * ncomp + c``. Ghosts' owners follow from the node ranges. On 1 rank there are
  no ghosts and every number below is the input's: the same code.
- **Input ids.** Relations and contact rows name input DOFs (``input_node * ncomp + c``): the
  map finds their local DOFs by a sorted lookup, and (``index_inputs``) their global numbers
  and coordinates: this rank's nodes from its mesh, the others' (a whole relation's nodes
  elsewhere) from their owners in one reduction.
- **Held multipliers.** Like its primal DOFs, a rank holds its owned multiplier rows then
  ghost rows: the other ranks' rows whose multipliers its own rows read (``set_multipliers``;
  the relation set gives those whose D column has an entry on one of its owned DOFs, so a
  global row such as a control column is held by every rank its load touches, owned by one).
  Held order: owned rows, then ghosts by global number.
- **Exchanges.** Forward: owned values → ghosts, of primal DOFs and of multipliers alike
  (``gather``: the values a rank holds of a saddle vector, ``HeldValues``; two plans, made
  once). No reverse exchange: the cells through an owned node are all local, so sums over
  them (nodal averages, loads, the operator's owned rows) are complete on the owner.
- **Owned reductions.** Norms, dots, max |v|, and A q of rows given as COO entries over input
  DOFs: each entry taken on the rank owning its DOF, summed over the ranks in one reduction of
  the rows' size (every rank then holds the same values, so decisions made from them agree).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve.io.slabs import OwnedRows
from parsolve.relation_kinds.spread import NodeOwners, ask


def _displacements(counts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)


class HeldValues:
    """What a rank holds of a saddle vector: its local primal DOFs (``q``, local order: owned
    then ghosts) and its held multipliers (``lam``, scaled, held order: owned rows then
    ghosts, ``DofMap.l_held``); ``x[saddle indices]`` answers for those indices as the whole
    vector would, without being as long as it."""

    def __init__(self, keys: tuple[np.ndarray, np.ndarray], q: np.ndarray, lam: np.ndarray):
        self.q, self.lam = q, lam
        self._keys = keys   # (order, sorted keys), shared by the copies

    def _where(self, idx) -> np.ndarray:
        order, sorted_keys = self._keys
        idx = np.asarray(idx, dtype=np.int64)
        if idx.size == 0:   # (a rank with no cell asks for nothing)
            return np.zeros(idx.shape, dtype=np.int64)
        pos = np.minimum(np.searchsorted(sorted_keys, idx), max(sorted_keys.size - 1, 0))
        if sorted_keys.size == 0 or not np.array_equal(sorted_keys[pos], idx):
            miss = idx[sorted_keys[pos] != idx] if sorted_keys.size else idx
            raise IndexError(f"saddle indices not held by this rank: {miss[:5]} "
                             f"({miss.size} of {idx.size})")
        return order[pos]

    def __getitem__(self, idx) -> np.ndarray:
        # each value from q or lam directly: no concatenation of both at every lookup
        where = self._where(idx)
        nq = self.q.size
        in_q = where < nq
        out = np.empty(where.shape)
        out[in_q] = self.q[where[in_q]]
        out[~in_q] = self.lam[where[~in_q] - nq]
        return out

    def copy(self) -> "HeldValues":
        return HeldValues(self._keys, self.q.copy(), self.lam.copy())

    def with_q(self, q: np.ndarray) -> "HeldValues":
        """A copy with its primal part replaced by q."""
        return HeldValues(self._keys, q.copy(), self.lam.copy())


def held_keys(saddle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(order, sorted keys) of saddle indices, for ``HeldValues``."""
    keys = np.asarray(saddle, dtype=np.int64)
    order = np.argsort(keys, kind="stable")
    return order, keys[order]


class GhostExchange:
    """The plan of the ghost exchange: who sends this rank its ghost DOFs' values (two
    ``Alltoallv`` of buffers per exchange, no pickling)."""

    def __init__(self, comm, wanted: np.ndarray, owner: np.ndarray, first: int):
        self.comm = comm
        self.order = np.argsort(owner, kind="stable")
        self.recv_counts = np.bincount(owner, minlength=comm.size).astype(np.int64)
        self.send_counts = np.empty_like(self.recv_counts)
        comm.Alltoall(self.recv_counts, self.send_counts)
        asked = np.ascontiguousarray(wanted[self.order], dtype=np.int64)
        self.asked_of_me = np.empty(int(self.send_counts.sum()), dtype=np.int64)
        comm.Alltoallv([asked, self.recv_counts, _displacements(self.recv_counts), MPI.INT64_T],
                       [self.asked_of_me, self.send_counts, _displacements(self.send_counts),
                        MPI.INT64_T])
        self.asked_of_me -= first   # owned rows of this rank

    def _move(self, send: np.ndarray, counts_out: np.ndarray, counts_in: np.ndarray) -> np.ndarray:
        got = np.empty(int(counts_in.sum()), dtype=np.float64)
        self.comm.Alltoallv([np.ascontiguousarray(send, dtype=np.float64), counts_out,
                             _displacements(counts_out), MPI.DOUBLE],
                            [got, counts_in, _displacements(counts_in), MPI.DOUBLE])
        return got

    def forward(self, x_owned: np.ndarray) -> np.ndarray:
        """Values of the ghost DOFs (in their local order) from the owners' rows."""
        got = self._move(x_owned[self.asked_of_me], self.send_counts, self.recv_counts)
        out = np.empty_like(got)
        out[self.order] = got
        return out

    def reverse(self, ghosts: np.ndarray, n_owned: int) -> np.ndarray:
        """Values on the ghost DOFs (their local order) added up on their owners' rows: the
        transpose of ``forward``."""
        got = self._move(ghosts[self.order], self.recv_counts, self.send_counts)
        return np.bincount(self.asked_of_me, weights=got, minlength=n_owned)


class DofMap:
    """The saddle numbering of a rank and everything that depends on it (see the module doc).

    ``mesh``: this rank's ``LocalMesh`` (owned nodes first, then ghosts); no multiplier rows
    until ``set_multipliers`` (a primal map, e.g. for an effect built before the system);
    ``comm`` None: this process alone."""

    def __init__(self, comm, mesh, ncomp: int):
        comm = MPI.COMM_SELF if comm is None else comm
        self.comm, self.mesh, self.ncomp = comm, mesh, int(ncomp)
        self.rank = comm.rank
        n = mesh.num_points
        self.node_ranges = np.asarray(getattr(mesh, "node_ranges", [0, n]), dtype=np.int64)
        self.n_owned_nodes = int(mesh.n_owned)
        self.n_owned = self.n_owned_nodes * self.ncomp      # owned primal DOFs
        self.n_local = n * self.ncomp                       # local primal DOFs (with ghosts)
        order = np.argsort(mesh.global_nodes, kind="stable")
        self._order, self._sorted = order, np.asarray(mesh.global_nodes)[order]
        self._exchange: GhostExchange | None = None
        self._inputs: tuple | None = None
        self._node_owners: NodeOwners | None = None   # (made at the first ask)
        self.set_multipliers(np.zeros(self.node_ranges.size - 1, dtype=np.int64))

    def set_multipliers(self, counts: np.ndarray, ghosts: np.ndarray | None = None) -> None:
        """Give rank r ``counts[r]`` multiplier rows, numbered after those of the ranks
        before it (the same counts on every rank); ``ghosts``: the other ranks' rows this
        rank holds besides its own (global multiplier numbers; its own are dropped)."""
        counts = np.asarray(counts, dtype=np.int64)
        if counts.size != self.node_ranges.size - 1:
            raise ValueError(f"{counts.size} multiplier counts for {self.node_ranges.size - 1} ranks")
        self.q_ranges = self.node_ranges * self.ncomp
        self.l_ranges = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        sizes = np.diff(self.q_ranges) + np.diff(self.l_ranges)
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        l0, l1 = self.l_ranges[self.rank], self.l_ranges[self.rank + 1]
        ghosts = np.unique(np.zeros(0, dtype=np.int64) if ghosts is None
                           else np.asarray(ghosts, dtype=np.int64))
        self.l_ghosts = ghosts[(ghosts < l0) | (ghosts >= l1)]
        self.l_held = np.concatenate([np.arange(l0, l1), self.l_ghosts])
        self._saddle = None
        self._held_keys = None
        self._mult_exchange: GhostExchange | None = None

    # ------------------------------------------------------------ sizes and ranges

    @property
    def nq(self) -> int:
        """Primal DOFs of all ranks."""
        return int(self.q_ranges[-1])

    @property
    def nl(self) -> int:
        """Multiplier rows of all ranks."""
        return int(self.l_ranges[-1])

    @property
    def size(self) -> int:
        """Length of the global saddle vector."""
        return int(self.offsets[-1])

    @property
    def offset(self) -> int:
        """First saddle row of this rank."""
        return int(self.offsets[self.rank])

    @property
    def nrows(self) -> int:
        """Saddle rows this rank owns (primal then multipliers)."""
        return int(self.offsets[self.rank + 1] - self.offsets[self.rank])

    def owned(self, rank: int | None = None) -> tuple[int, int, int, int]:
        """(q_start, q_end, l_start, l_end) of a rank (default: this one)."""
        r = self.rank if rank is None else rank
        return (int(self.q_ranges[r]), int(self.q_ranges[r + 1]),
                int(self.l_ranges[r]), int(self.l_ranges[r + 1]))

    # ------------------------------------------------------------ numberings

    def new_dof(self, local_dofs: np.ndarray) -> np.ndarray:
        """Local DOFs → the partition's primal numbering."""
        node, comp = np.divmod(np.asarray(local_dofs, dtype=np.int64), self.ncomp)
        return self.mesh.node_new[node].astype(np.int64) * self.ncomp + comp

    def q_index(self, new_dofs: np.ndarray) -> np.ndarray:
        """Saddle index of primal DOFs given in the new numbering."""
        new_dofs = np.asarray(new_dofs, dtype=np.int64)
        owner = self.owner_of_dofs(new_dofs)
        return new_dofs - self.q_ranges[owner] + self.offsets[owner]

    def l_index(self, rows: np.ndarray) -> np.ndarray:
        """Saddle index of multipliers (global multiplier numbers)."""
        rows = np.asarray(rows, dtype=np.int64)
        owner = np.searchsorted(self.l_ranges, rows, side="right") - 1
        nq_owner = self.q_ranges[owner + 1] - self.q_ranges[owner]
        return rows - self.l_ranges[owner] + self.offsets[owner] + nq_owner

    def saddle_to_new(self, saddle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(new primal DOF, mask of the indices that are primal) of saddle indices."""
        saddle = np.asarray(saddle, dtype=np.int64)
        owner = np.searchsorted(self.offsets, saddle, side="right") - 1
        new = saddle - self.offsets[owner] + self.q_ranges[owner]
        return new, new < self.q_ranges[owner + 1]

    @property
    def saddle_of_local(self) -> np.ndarray:
        """Saddle index of every local primal DOF (owned then ghosts)."""
        if self._saddle is None:
            self._saddle = self.q_index(self.new_dof(np.arange(self.n_local)))
        return self._saddle

    @property
    def saddle_of_mult(self) -> np.ndarray:
        """Saddle index of every multiplier row (the relations' size; built on demand, for
        dense checks of small systems)."""
        return self.l_index(np.arange(self.nl))

    @property
    def n_held(self) -> int:
        """Multiplier rows this rank holds (owned and ghosts)."""
        return int(self.l_held.size)

    def held_index(self, rows: np.ndarray) -> np.ndarray:
        """Place among the held multipliers (``l_held``) of global multiplier rows this rank
        holds."""
        rows = np.asarray(rows, dtype=np.int64)
        l0, l1 = self.l_ranges[self.rank], self.l_ranges[self.rank + 1]
        own = (rows >= l0) & (rows < l1)
        ghost = np.searchsorted(self.l_ghosts, rows)
        found = self.l_ghosts[np.minimum(ghost, max(self.l_ghosts.size - 1, 0))] == rows \
            if self.l_ghosts.size else np.zeros(rows.shape, dtype=bool)
        if not np.all(own | found):
            raise IndexError(f"multiplier rows not held by this rank: {rows[~(own | found)][:5]}")
        return np.where(own, rows - l0, l1 - l0 + ghost)

    def owner_of_dofs(self, new_dofs: np.ndarray) -> np.ndarray:
        """The rank owning each primal DOF given in the new numbering."""
        return np.searchsorted(self.q_ranges, np.asarray(new_dofs, dtype=np.int64),
                               side="right") - 1

    @property
    def owned_dofs(self) -> np.ndarray:
        """Local DOFs this rank owns (the first ``n_owned``: owned nodes come first)."""
        return np.arange(self.n_owned)

    def ghost_owners(self) -> np.ndarray:
        """Owner of each ghost node (local order)."""
        return self.mesh.owner_of(np.arange(self.n_owned_nodes, self.mesh.num_points))

    # ------------------------------------------------------------ per-field sets

    def field_dofs(self, columns: np.ndarray) -> np.ndarray:
        """Owned local DOFs of a field (its columns among the node's ncomp)."""
        own = self.owned_dofs
        return own[np.isin(own % self.ncomp, columns)]

    def field_rows(self, columns: np.ndarray) -> np.ndarray:
        """Saddle indices of a field's owned rows (node-major), for its index set."""
        q0, q1, _, _ = self.owned()
        nodes = np.arange(q0, q1, self.ncomp) - q0
        return (nodes[:, None] + np.asarray(columns)[None, :]).ravel() + self.offset

    # ------------------------------------------------------------ input ids

    def local_nodes(self, nodes: np.ndarray) -> np.ndarray:
        """Local node of each input node id, -1 where the node is not on this rank."""
        nodes = np.asarray(nodes, dtype=np.int64)
        if self._sorted.size == 0:
            return np.full(nodes.shape, -1, dtype=np.int64)
        pos = np.minimum(np.searchsorted(self._sorted, nodes), self._sorted.size - 1)
        return np.where(self._sorted[pos] == nodes, self._order[pos], -1)

    def owned_nodes(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(mask of the input node ids owned here, their local nodes)."""
        local = self.local_nodes(nodes)
        own = (local >= 0) & (local < self.n_owned_nodes)
        return own, local[own]

    def local_dofs(self, dofs: np.ndarray, owned: str | None = None) -> np.ndarray:
        """Local DOF of each input DOF, -1 where its node is not on this rank (mask it before
        indexing: a -1 reads or writes the last entry silently). ``owned``: what the DOFs are,
        each owned here, else a RuntimeError naming it."""
        dofs = np.asarray(dofs, dtype=np.int64)
        node, comp = np.divmod(dofs, self.ncomp)
        ln = self.local_nodes(node)
        local = np.where(ln >= 0, ln * self.ncomp + comp, -1)
        if owned is not None:
            away = (local < 0) | (local >= self.n_owned)
            if away.any():
                raise RuntimeError(f"{owned}: {np.count_nonzero(away)} input DOFs not owned "
                                   f"by rank {self.rank} (the first: {dofs[away][0]})")
        return local

    def owned_dof_entries(self, dofs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions of the input DOFs owned here, their local DOFs)."""
        local = self.local_dofs(dofs)
        own = (local >= 0) & (local < self.n_owned)
        return np.flatnonzero(own), local[own]

    def index_inputs(self, dofs: list[np.ndarray]) -> None:
        """Global numbers and coordinates of the nodes of these input DOFs: this rank's nodes
        (owned and ghosts) from its mesh; the others (a tie's other end, a master node on
        another rank) asked of their owners (found through a directory of the owned ids by
        blocks, made once: ``NodeOwners``), no rank holding another's asked nodes. Each rank
        may ask for different nodes (relations built per rank). Collective."""
        nc = self.ncomp
        nodes = np.unique(np.concatenate([np.asarray(d, dtype=np.int64) // nc for d in dofs])
                          if dofs else np.zeros(0, dtype=np.int64))
        mesh = self.mesh
        dim = mesh.points.shape[1]
        packed = np.zeros((nodes.size, 1 + dim))
        local = self.local_nodes(nodes)
        here = local >= 0
        packed[here, 0] = mesh.node_new[local[here]]
        packed[here, 1:] = mesh.points[local[here]]
        asked = nodes[~here]
        packed[~here, 0] = -1   # (a node no rank owns)
        if self.comm.size > 1:
            if self._node_owners is None:
                owned = np.asarray(mesh.global_nodes[:self.n_owned_nodes], dtype=np.int64)
                space = self.comm.allreduce(int(owned.max(initial=-1)) + 1, op=MPI.MAX)
                self._node_owners = NodeOwners(self.comm, owned, space)

            def answer(got: np.ndarray) -> np.ndarray:
                own, at = self.owned_nodes(got)
                out = np.zeros((got.size, 1 + dim))
                out[:, 0] = -1
                out[own, 0], out[own, 1:] = mesh.node_new[at], mesh.points[at]
                return out

            packed[~here] = ask(self.comm, asked, self._node_owners(asked), answer)
        self._inputs = (nodes, packed[:, 0].astype(np.int64), packed[:, 1:])

    def input_new_dof(self, dofs: np.ndarray) -> np.ndarray:
        """Input DOFs (of nodes given to ``index_inputs``) → the new primal numbering."""
        nodes, new_node, _ = self._inputs
        node, comp = np.divmod(np.asarray(dofs, dtype=np.int64), self.ncomp)
        return new_node[np.searchsorted(nodes, node)] * self.ncomp + comp

    def input_saddle(self, dofs: np.ndarray) -> np.ndarray:
        """Saddle index of input DOFs (of nodes given to ``index_inputs``)."""
        return self.q_index(self.input_new_dof(dofs))

    def input_points(self, nodes: np.ndarray) -> np.ndarray:
        """Coordinates of input nodes (given to ``index_inputs``)."""
        known, _, coords = self._inputs
        return coords[np.searchsorted(known, np.asarray(nodes, dtype=np.int64))]

    # ------------------------------------------------------------ local ↔ owned vectors

    def owned_rows(self, full: np.ndarray) -> np.ndarray:
        """A local primal vector → this rank's saddle rows (multiplier rows zero)."""
        out = np.zeros(self.nrows)
        own = self.owned_dofs
        out[self.saddle_of_local[own] - self.offset] = full[own]
        return out

    def local_vector(self, dofs: np.ndarray, values: np.ndarray) -> np.ndarray:
        """A local primal vector from (input DOFs, values) entries (duplicates add; entries of
        nodes not on this rank dropped)."""
        local = self.local_dofs(dofs)
        on = local >= 0
        return np.bincount(local[on], weights=np.asarray(values, dtype=float)[on],
                           minlength=self.n_local).astype(float, copy=False)

    def owned_sum(self, full: np.ndarray) -> np.ndarray:
        """A local primal vector whose ghost entries are parts of their owners' (a row built
        on this rank's cells) → the same with each ghost part added on its owner, ghosts 0.
        Collective."""
        out = np.zeros(self.n_local)
        out[:self.n_owned] = full[:self.n_owned]
        if self.comm is not None and self.comm.size > 1:
            out[:self.n_owned] += self._plan().reverse(full[self.n_owned:], self.n_owned)
        return out

    # ------------------------------------------------------------ exchanges

    def _plan(self) -> GhostExchange:
        if self._exchange is None:   # planned once, on first use (collective)
            nc, n0 = self.ncomp, self.n_owned
            ghosts = np.arange(n0, self.n_local)
            owner = np.repeat(self.ghost_owners(), nc)
            self._exchange = GhostExchange(self.comm, self.new_dof(ghosts), owner,
                                       int(self.q_ranges[self.rank]))
        return self._exchange

    def forward(self, x_owned: np.ndarray) -> np.ndarray:
        """The local primal vector (owned then ghosts) from this rank's saddle rows: owned
        values copied, ghosts' fetched from their owners. Collective."""
        q = np.empty(self.n_local)
        q[:self.n_owned] = x_owned[:self.n_owned]   # owned DOFs first in both numberings
        q[self.n_owned:] = self._plan().forward(x_owned)
        return q

    def _keys(self) -> tuple[np.ndarray, np.ndarray]:
        if self._held_keys is None:
            self._held_keys = held_keys(np.concatenate([self.saddle_of_local,
                                                        self.l_index(self.l_held)]))
        return self._held_keys

    def forward_multipliers(self, owned: np.ndarray) -> np.ndarray:
        """The held multipliers (owned then ghosts) from this rank's owned ones: ghosts'
        values fetched from their owners. Collective."""
        if self._mult_exchange is None:   # planned once, on first use (collective)
            owner = np.searchsorted(self.l_ranges, self.l_ghosts, side="right") - 1
            self._mult_exchange = GhostExchange(self.comm, self.l_ghosts, owner,
                                            int(self.l_ranges[self.rank]))
        owned = np.asarray(owned, dtype=float)
        return np.concatenate([owned, self._mult_exchange.forward(owned)])

    def gather(self, x_owned: np.ndarray) -> HeldValues:
        """What this rank holds of a saddle vector from its owned rows: its local primal DOFs
        and its held multipliers, ghosts of both fetched from their owners. Collective."""
        q = self.forward(x_owned)
        return HeldValues(self._keys(), q, self.forward_multipliers(x_owned[self.n_owned:]))

    def zeros(self) -> HeldValues:
        """A zero saddle vector as ``gather`` returns them."""
        return HeldValues(self._keys(), np.zeros(self.n_local), np.zeros(self.n_held))

    # ------------------------------------------------------------ owned reductions

    def sum_ranks(self, values: np.ndarray) -> np.ndarray:
        """Σ over the ranks, in place (one reduction of the array's size). Collective."""
        self.comm.Allreduce(MPI.IN_PLACE, values, op=MPI.SUM)
        return values

    def norm(self, v: np.ndarray) -> float:
        """2-norm of a local primal vector, each DOF once (owned rows). Collective."""
        own = v[self.owned_dofs]
        return float(np.sqrt(self.comm.allreduce(float(own @ own))))

    def dot(self, u: np.ndarray, v: np.ndarray) -> float:
        """u · v of two local primal vectors, each DOF once (owned rows). Collective."""
        own = self.owned_dofs
        return float(self.comm.allreduce(float(u[own] @ v[own])))

    def max_abs(self, v: np.ndarray) -> float:
        """max |v| over every rank's values (the same number on all). Collective."""
        return self.comm.allreduce(float(np.abs(v).max()) if v.size else 0.0, op=MPI.MAX)

    def owned_part(self, sel: np.ndarray, local: np.ndarray, rows: np.ndarray,
                   coefs: np.ndarray, nrows: int, q: np.ndarray) -> np.ndarray:
        """This rank's part of A q: the entries ``sel`` on its owned DOFs ``local`` (from
        ``owned_dof_entries``)."""
        # (float even with no entry here: numpy's bincount of nothing is int64)
        return np.bincount(rows[sel], weights=coefs[sel] * q[local],
                           minlength=nrows).astype(float, copy=False)

    def rows(self, dofs: np.ndarray, rows: np.ndarray, coefs: np.ndarray, nrows: int,
             q: np.ndarray) -> np.ndarray:
        """A q of rows given as COO entries over input DOFs (the same on every rank).
        Collective."""
        sel, local = self.owned_dof_entries(dofs)
        return self.sum_ranks(self.owned_part(sel, local, rows, coefs, nrows, q))

    def rows_here(self, dofs: np.ndarray, rows: np.ndarray, coefs: np.ndarray, nrows: int,
                  q: np.ndarray) -> np.ndarray:
        """A q of rows whose entries are all on this rank's owned DOFs (a relation built per
        rank): no reduction."""
        sel, local = self.owned_dof_entries(dofs)
        return self.owned_part(sel, local, rows, coefs, nrows, q)

    def relation(self, r, q: np.ndarray) -> np.ndarray:
        """A q of a relation's rows held here. Collective for a whole relation."""
        rows = self.rows if r.whole else self.rows_here
        return rows(r.a_dofs, r.a_rows, r.a_vals, r.nrows, q)

    def nodal(self, nodes: np.ndarray, values: np.ndarray, fill: float = 0.0) -> OwnedRows:
        """A nodal output (k columns) with ``values`` at input ``nodes`` and ``fill``
        elsewhere: this rank's owned rows (owned nodes come first, in increasing input id)."""
        values = np.asarray(values, dtype=float)
        k = values.shape[1] if values.ndim == 2 else values.size // max(len(nodes), 1) or 1
        values = values.reshape(len(nodes), k)   # (no node here: the columns as given)
        own, local = self.owned_nodes(nodes)
        out = np.full((self.n_owned_nodes, values.shape[1]), fill)
        out[local] = values[own]
        return OwnedRows(out)
