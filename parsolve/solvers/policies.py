"""The relation policies of a nonlinear step, in one place: what decides which relation rows
the next solve enforces, and with which sense their reactions push.

- **active set** (``ActiveSet``): unilateral rows switched by their gaps and multipliers;
- **orientation**: o = -sign(A K⁻¹ D) of a unilateral non-associated row, from the first
  tangent (its reaction must push the row back whichever way its dual points);
- **dependent rows**: contact rows that depend on the other enforced rows (a held, tied or
  shared node) are left out of the solve, and checked after it;
- **contact closing**: a first solve that fails with contact rows open starts the body in
  contact;
- **maximum control**: at the start of a step, the row of each maximum group that reaches its
  value first under the group's control load, on the enforced cell's loading tangent;
- **effects' hooks**: the effects whose relations change between iterations (friction,
  finite sliding) update them, and their values are copied into the relation set.

The problem (``solvers.problem``) owns one ``RelationPolicies`` and hands it the state; the
policies' own solves (a unit response) go through the problem's ``respond`` callback.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np
from mpi4py import MPI

from parsolve.contact.dependent import dependent_rows
from parsolve.errors import SolverError
from parsolve.la.fetch import Fetch
from parsolve.mesh.blocks import exchange
from parsolve.solvers.active_set import GROUP_TOL, ActiveSet, _Seen

# an entry of a maximum group's enforced row on its way to its DOF's owner
_ENTRY = np.dtype([("group", np.int64), ("dof", np.int64), ("val", np.float64)])

#: (tangent, active rows, load) → δq = K⁻¹ f with those rows enforced at zero
Respond = Callable[[object, np.ndarray, np.ndarray], np.ndarray]


def _row_dots(r, ndof: int) -> np.ndarray:
    """A_k · D_k of every row of a relation (sparse: entries matched by (row, dof) key)."""
    dofs, drows, vals = r.dual_coo()
    keys, inv = np.unique(np.asarray(drows, dtype=np.int64) * ndof + dofs, return_inverse=True)
    d = np.bincount(inv, weights=vals)
    ka = r.a_rows * ndof + r.a_dofs
    if keys.size == 0:
        return np.zeros(r.nrows)
    pos = np.minimum(np.searchsorted(keys, ka), keys.size - 1)
    hit = keys[pos] == ka
    return np.bincount(r.a_rows[hit], weights=r.a_vals[hit] * d[pos[hit]], minlength=r.nrows)


class _CellReplaced:
    """Tangent blocks with the element matrices of a few cells taken from another evaluation
    (same effects, same terms): reduced like ``BlockMatrices`` plus the few cells' difference."""

    def __init__(self, base, other, cells: np.ndarray):
        self.base, self.other, self.cells = base, other, cells

    def reduce(self, pair_slot: np.ndarray, npairs: int) -> np.ndarray:
        return self.base.reduce_replaced(self.other, self.cells, pair_slot, npairs)


def _branch_reach(rate: np.ndarray, room: np.ndarray, current: float, largest: float
                  ) -> np.ndarray:
    """Control load at which each row of a maximum group reaches its value, along the branch
    the enforced row follows (rate: d(s A q)/dλ with the enforced row loading, ``current``
    the enforced row's, ``largest`` the largest |rate| of the group; room: s (b - A q)).
    Rising branch (the enforced row's rate > 0, before its peak): rows with r > 0 reach it
    at room / r. Past the enforced row's peak (rate < 0), its value grows only as the load
    falls, while the other rows unload: the rows with r < 0 reach it at room / -r. Rows that
    never reach it on that branch: +inf."""
    tol = 1e-9 * max(largest, 1e-300)
    side = -1.0 if current < -tol else 1.0
    r = side * rate
    return np.where(r > tol, room / np.where(r > tol, r, 1.0), np.inf)


class RelationPolicies:
    """Active set, orientation, dependent rows, contact closing, maximum-control predictor and
    the effects' refresh hooks of a system's multiplied relations. Every rank holds the same
    relations (or its own rows of those built per rank); the active set decides each row on
    the rank owning its multiplier, a maximum group's by reductions over the ranks holding its
    rows, and exchanges the changes (``ActiveSet``); the rest is decided alike on every rank."""

    def __init__(self, system, max_changes: int, respond: Respond):
        self.system = system   # its rate (a transient step) and its restructure
        self.ctx = ctx = system.context
        self.rset = ctx.relations
        self.respond = respond
        # each rank reads the multipliers it owns; the rows' owners keep after a restack
        self.active = ActiveSet(ctx.multiplied, max_changes, self.rset.owned_relrows, ctx.comm)
        # bound of the relations' DOF numbers (input numbering: the whole mesh's)
        self.ndof_keys = ctx.mesh.num_global_points * ctx.ncomp
        self.oriented = False
        # effects whose relations change between iterations (contact with friction): their
        # begin_step / refresh / end_step hooks; a new sparsity (finite sliding's spans made
        # again) has the system build its operator again
        self.hooks = [e for e in ctx.effects if e.refreshes]
        self._rows = self._dependence_rows()
        self.left_out = np.zeros(self.active.sign.size, dtype=bool)

    # ------------------------------------------------------------ dependent rows

    def _dependence_rows(self) -> tuple | None:
        """The multiplied rows as COO (row numbers of the active set) with the contact rows
        marked, and the eliminated DOFs: what ``enforceable`` needs (None without contact)."""
        mult = self.ctx.multiplied
        if not any(r.meta.get("type") == "contact" for r in mult):
            return None
        rset = self.rset
        # (a row over a region, spread over the ranks, ties no contact node: left out)
        keep = [k for k, r in enumerate(mult) if not r.collapsed and not r.spread]
        rows = np.concatenate([mult[k].a_rows + rset.rows_of(k).start for k in keep])
        dofs = np.concatenate([mult[k].a_dofs for k in keep])
        candidate = np.zeros(rset.nrelrows, dtype=bool)
        for k, r in enumerate(mult):
            candidate[rset.rows_of(k)] = r.meta.get("type") == "contact"
        fixed = self._fixed(np.unique(dofs))
        # each row's place in the fixed order over every rank: relation, then its global row
        first = np.concatenate([[0], np.cumsum([r.total for r in mult])])
        key = np.zeros(rset.nrelrows, dtype=np.int64)
        per_rank = np.zeros(rset.nrelrows, dtype=bool)
        for k, r in enumerate(mult):
            key[rset.rows_of(k)] = first[k] + r.row_ids()
            per_rank[rset.rows_of(k)] = not r.whole
        return rows, dofs, [mult[k] for k in keep], candidate, fixed, key, per_rank

    def _fixed(self, dofs: np.ndarray) -> np.ndarray:
        """The input DOFs of ``dofs`` (sorted, of nodes the DOF map knows) that an eliminated
        relation holds, each told by its owner (each rank holds the eliminated rows on its
        own DOFs: ``Relation.ids``). Collective."""
        dm = self.ctx.dofs
        held = np.zeros(dm.n_owned)
        for r in self.ctx.eliminated:
            held[dm.local_dofs(r.a_dofs, owned=f"relation {r.name!r} (eliminated)")] = 1.0
        return dofs[Fetch.of(dm, dm.input_new_dof(dofs))(held) > 0.5]

    def enforceable(self, active: np.ndarray) -> np.ndarray:
        """The active rows less the contact rows that depend on the others (a held, tied or
        shared contact node: ``parsolve.contact.dependent``), which the solve leaves out (their
        multipliers zero): the same displacements, and no null pivot."""
        if self._rows is None:
            return active
        rows, dofs, rels, candidate, fixed, key, per_rank = self._rows
        vals = np.concatenate([r.a_vals for r in rels])   # current (friction turns them)
        n = active.size
        f_rows, f_dofs, f_vals, f_key = self._foreign_rows(rows, dofs, vals, active, key,
                                                          per_rank, fixed)
        m = f_key.size
        out = dependent_rows(np.concatenate([rows, n + f_rows]), np.concatenate([dofs, f_dofs]),
                             np.concatenate([vals, f_vals]), n + m,
                             np.concatenate([active, np.ones(m, dtype=bool)]),
                             np.concatenate([candidate, np.ones(m, dtype=bool)]), fixed,
                             self.ctx.ncomp, np.concatenate([key, f_key]))
        self.left_out = out[:n]
        return active & ~self.left_out

    def _foreign_rows(self, rows, dofs, vals, hard, key, per_rank, fixed) -> tuple:
        """The enforced rows of relations built per rank that other ranks hold on nodes the
        whole relations or the rows across ranks touch (a periodic tie between contact nodes
        of two ranks, whole or built per rank): what a
        rank's analysis needs besides its own rows for every rank to decide alike. Rows on
        other nodes cannot depend on rows of another rank (they share no DOF with them).
        Returns their entries (rows numbered 0.. in key order), and each row's key."""
        empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64))
        comm, ncomp = self.ctx.comm, self.ctx.ncomp
        if comm.size == 1 or not comm.allreduce(bool(per_rank.any()), op=MPI.LOR):
            return empty
        live = hard[rows] & (vals != 0.0) & ~np.isin(dofs, fixed)
        mine = live & per_rank[rows]
        # and on the nodes of rows reaching other ranks' DOFs (a tie's u_b), every rank's
        away = np.ones(dofs.size, dtype=bool)
        away[self.ctx.dofs.owned_dof_entries(dofs)[0]] = False
        cross = np.zeros(hard.size, dtype=bool)
        cross[rows[mine & away]] = True
        whole_nodes = np.union1d(np.unique(dofs[live & ~per_rank[rows]] // ncomp), np.concatenate(
            comm.allgather(np.unique(dofs[mine & cross[rows]] // ncomp))))
        touch = np.zeros(hard.size, dtype=bool)
        touch[rows[mine & np.isin(dofs // ncomp, whole_nodes)]] = True
        send = mine & touch[rows]
        parts = comm.allgather((key[rows[send]], dofs[send], vals[send]))
        others = [p for rank, p in enumerate(parts) if rank != comm.rank]
        if not others or not sum(p[0].size for p in others):
            return empty
        f_entry_key = np.concatenate([p[0] for p in others])
        f_key, f_rows = np.unique(f_entry_key, return_inverse=True)
        return (f_rows.astype(np.int64), np.concatenate([p[1] for p in others]),
                np.concatenate([p[2] for p in others]), f_key)

    @property
    def enforced(self) -> np.ndarray:
        """The active rows the last solve enforced: less the contact rows it left out (a held
        or tied node's: multiplier zero, the rows it depends on carry its reaction), which a
        step's outputs report as carrying nothing (state open), not as stuck."""
        return self.active.active & ~self.left_out

    def _empty_rows(self) -> np.ndarray:
        """Per relation row of the active set: no A entry (a finite-sliding slave that no facet
        faces yet): never enforced, whatever its value."""
        rset = self.rset
        empty = np.ones(rset.nrelrows, dtype=bool)
        for k, r in enumerate(self.ctx.multiplied):
            empty[rset.rows_of(k)] = False if r.collapsed else self.rset.empty_rows(r)
        return empty

    def close_contact(self) -> bool:
        """Enforce every contact row that is not (True when there was one): the first solve of
        a step failed with rows open, which is a body held only by contact (nothing else, or
        soft supports, in the contact direction: a singular or ill-conditioned operator).
        Started in contact, the body is held; the active set then opens the rows that pull
        (a frictional node closing this way sticks or slides as any closing node). No
        tolerance to guess (``closed``) and the same answer: the set is decided as always.
        Every rank decides from the same active set."""
        if self._rows is None:
            return False
        closing = self._rows[3] & ~self.active.active & ~self._empty_rows()
        if not self.ctx.comm.allreduce(bool(closing.any()), op=MPI.LOR):   # (rows per rank)
            return False
        self.active.active[closing] = True
        self.active.held |= closing
        self.active.seen.add(self.active.active.tobytes())
        return True

    def check_left_out(self, t: float, q: np.ndarray) -> None:
        """A left-out row is decided by the rows it depends on: fail when they violate it (a
        node held inside the obstacle), rather than return a penetrating answer."""
        if not self.ctx.comm.allreduce(bool(self.left_out.any()), op=MPI.LOR):  # (rows per rank)
            return
        values = self.rset.primal_values(q)
        gap = values - self.rset.targets(t)
        # against the rows' values and the displacements (a row at rest on the plane has A q = 0)
        scale = max(self.ctx.max_abs(values), self.ctx.max_abs(q), 1e-300)
        bad = self.left_out & (self.active.sign * gap > 1e-9 * scale)
        if self.ctx.comm.allreduce(bool(bad.any()), op=MPI.LOR):
            said = None
            if bad.any():
                row = int(np.flatnonzero(bad)[0])
                k, local = self.rset.locate(row)
                rel = self.ctx.multiplied[k]
                node = int(rel.a_dofs[rel.a_rows == local][0]) // self.ctx.ncomp
                said = (f"contact row {int(rel.row_ids()[local])} of {rel.name!r} (node {node}) "
                        "depends on other relations (a held or tied node) that violate it by "
                        f"{abs(float(gap[row])):.3g}: they push it into the obstacle")
            raise SolverError(next(m for m in self.ctx.comm.allgather(said) if m))

    # ------------------------------------------------------------ active set

    def start_step(self) -> None:
        self.active.start_step()

    def update_active(self, t: float, q: np.ndarray, lam: np.ndarray) -> bool:
        """The active set after a solve (True when it changed; ``lam``: this rank's owned
        multipliers, unscaled); no change without unilateral rows. Collective."""
        if not self.active.unilateral:
            return False
        # each rank the rows whose multiplier it owns: their values and multipliers
        values = self.rset.owned_primal(q)
        gap = values - self.rset.targets(t)
        mine = self.active.owned
        # the largest |A q - b|, |A q| and |λ| over the ranks: one number each (a collapsed
        # group's multiplier is on its enforced row)
        scale_gap = max(self.ctx.max_abs(np.concatenate([gap[mine], values[mine]])), 1e-300)
        scale_lam = max(self.ctx.max_abs(lam), 1e-300)
        lam = self.rset.owned_row_values(lam)
        return self.active.update(gap, lam, 1e-9 * scale_gap, 1e-9 * scale_lam, scale_gap)

    # ------------------------------------------------------------ first tangent of a step

    def first_tangent(self, t: float, kmat, q: np.ndarray, states: list, t_prev: float,
                      secant: bool) -> tuple[object, int]:
        """The policies that need the step's first tangent: orientation (once per run) and
        the maximum-control predictor (every step). Returns the tangent the first solve uses
        and the predictor's solves (counted as iterations)."""
        if not self.oriented:
            self.orient(kmat)
            self.oriented = True
        if not self.active.groups:
            return kmat, 0
        if not secant:
            kmat = self.loading_tangent(kmat, q, states, t_prev)
        self.predict_maximum_rows(t, kmat, q)
        return kmat, 1

    def unit_response(self, kmat, released: np.ndarray, f: np.ndarray) -> np.ndarray:
        """δq = K⁻¹ f with the tangent, the rows ``released`` switched off and the other
        active rows enforced at zero (homogeneous): how the structure answers a unit load."""
        active = self.active.active.copy()
        active[released] = False
        return self.respond(kmat, self.enforceable(active), f)

    def dual_column(self, k: int, row: int | None = None) -> np.ndarray:
        """Column of D of relation k for its row numbered ``row`` (default 0; every row's
        when they share one vector). A relation built per rank: the row on the rank holding
        it, its entries on ghost DOFs added on their owners (collective)."""
        rel = self.ctx.multiplied[k]
        if rel.shared_dual is not None:
            return self.ctx.local_vector(*rel.shared_dual)
        dofs, rows, vals = rel.dual_coo()
        sel = rel.row_ids()[rows] == (0 if row is None else row)
        column = self.ctx.local_vector(dofs[sel], vals[sel])
        return column if rel.whole else self.ctx.dofs.owned_sum(column)

    def orient(self, kmat) -> None:
        """o = -sign(A K⁻¹ D) of every free unilateral non-associated row, from the first
        tangent: the reaction must push the row back whichever way its dual points. A relation
        whose rows share one dual vector (a load pattern) costs one solve; rows with their own
        local duals take the sign of -A_k·D_k."""
        for k, r in enumerate(self.ctx.multiplied):
            if r.sense == "=" or r.associated or r.maximum or r.groups is not None:
                continue  # a group's enforced row is chosen by value, whatever its sign
            span = self.rset.rows_of(k)
            rows = np.arange(span.start, span.stop)
            if r.meta.get("dual"):
                rate = self.ctx.relation_primal(r, self.unit_response(kmat, rows,
                                                                      self.dual_column(k)))
            else:
                rate = _row_dots(r, self.ndof_keys)
            # a row with no entry yet (a contact slave that no facet faces) is never enforced
            # until it has some: it takes the sense of the relation's other rows, for good (the
            # sense is decided once; a contact's normal rows all have the sense +1)
            empty = self.rset.empty_rows(r)
            if np.any(~empty & (np.abs(rate) <= 1e-12 * max(float(np.abs(rate).max(initial=0.0)), 1e-300))):
                raise SolverError(f"relation {r.name!r}: its dual does not move its primal value "
                                  "(A K⁻¹ D = 0), so the sense of its reaction is undefined")
            sense = -np.sign(rate)
            known = sense[~empty]
            sense[empty] = known[0] if known.size and np.all(known == known[0]) else 1.0
            self.active.orient[rows] = sense

    def enforced_rows(self) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
        """Per maximum group, its enforced row: (its place among the relation rows held here,
        -1 where another rank holds it; its relation; A's DOFs and coefficients on that row
        that this rank's owned DOFs carry: the holder sends each entry to its DOF's owner,
        no row gathered). Collective."""
        out, sent = [], []
        for j, (g, k) in enumerate(zip(self.active.groups, self.active.group_relations)):
            held = g[self.active.active[g]]
            row = int(held[0]) if held.size else -1
            r = self.ctx.multiplied[k]
            sel = np.flatnonzero(r.a_rows == row - self.rset.rows_of(k).start) if held.size \
                else np.zeros(0, dtype=np.int64)
            part = np.empty(sel.size, _ENTRY)
            part["group"], part["dof"], part["val"] = j, r.a_dofs[sel], r.a_vals[sel]
            sent.append(part)
            out.append((row, k))
        dm = self.ctx.dofs
        sent = np.concatenate(sent) if sent else np.zeros(0, _ENTRY)
        got, _ = exchange(self.ctx.comm, sent, dm.owner_of_dofs(dm.input_new_dof(sent["dof"])))
        return [(row, k, got["dof"][got["group"] == j], got["val"][got["group"] == j])
                for j, (row, k) in enumerate(out)]

    def enforced_cells(self, rows: list | None = None) -> np.ndarray:
        """Positions (in this rank's cells) of the cells measured by the enforced rows of the
        maximum groups (``rows``: ``enforced_rows()``, if already read): the cells all of whose
        nodes carry an entry of such a row (its owned nodes' marks sent to their ghosts).
        Collective."""
        ctx = self.ctx
        marked = np.zeros(ctx.ndof)
        for _, _, dofs, _ in self.enforced_rows() if rows is None else rows:
            marked += ctx.local_vector(dofs, np.ones(dofs.size))
        marked = ctx.dofs.forward(marked).reshape(-1, ctx.ncomp).any(axis=1)
        return np.flatnonzero(marked[ctx.mesh.cells[ctx.cells]].all(axis=1))

    def loading_tangent(self, kmat, q: np.ndarray, states: list, t_prev: float):
        """The first tangent of a step for a maximum control: the enforced rows' cells on
        their loading branch, every other cell as it is at the converged state (unloading).

        At a converged state no material point is loading (its history equals its current
        value), so the first tangent is the unloading one everywhere and the control load can
        only grow: past the peak, where the enforced cell softens and its neighbours must
        unload, the first iterate loaded every cell of the band, and the next tangent, softening
        in all of them, was nearly singular (the plate refined 8× ran into null pivots). The
        enforced cell's loading tangent is taken at q + δ, δ along its row with A δ = 1e-10 of
        the row's value; all other cells keep theirs. Not for a secant matrix: it does not tell
        loading from unloading (and a perturbed cell would break a symmetric tie)."""
        ctx = self.ctx
        delta = np.zeros(ctx.ndof)
        rows = self.enforced_rows()   # (each rank its owned DOFs' entries of the rows)
        for row, k, dofs, a in rows:
            rel = ctx.multiplied[k]
            value = ctx.relation_primal(rel, q)   # A q of its rows held here (collective)
            # the row's value and target, and |a|², from the ranks holding them
            here = np.array([0.0, 0.0, float(a @ a)])
            if row >= 0:
                local = row - self.rset.rows_of(k).start
                here[:2] = value[local], rel.rhs(t_prev)[local]
            if ctx.comm.size > 1:
                ctx.comm.Allreduce(MPI.IN_PLACE, here, op=MPI.SUM)
            value, b, norm2 = here
            size = 1e-10 * max(abs(float(value)), abs(float(b)), 1e-300)
            delta += ctx.local_vector(dofs, rel.sign * a * size / max(norm2, 1e-300))
        delta = ctx.dofs.forward(delta)   # (its ghosts from their owners)
        loading = ctx.composition.evaluate(q + delta, states, False, self.system.rate)[2]
        return _CellReplaced(kmat, loading, self.enforced_cells(rows))

    def predict_maximum_rows(self, t: float, kmat, q: np.ndarray) -> None:
        """For each maximum relation, enforce the row that reaches its value first under the
        relation's own control load: one solve with the tangent (``loading_tangent``) and a
        unit control load, rates r = A δq, then the smallest (b - A q) / |r| along the branch
        the enforced row follows (``_branch_reach``)."""
        active = self.active
        groups = np.concatenate(active.groups)
        f = np.zeros(self.ctx.ndof)
        for k in active.group_relations:  # the control load of each group at unit intensity
            f += self.dual_column(k)
        dq = self.unit_response(kmat, groups, f)
        rates = self.rset.primal_values(dq)
        gap = self.rset.targets(t) - self.rset.primal_values(q)
        # per group over the ranks: the enforced row's rate, the largest |rate| (one maximum)
        n = len(active.groups)
        top = np.full(2 * n, -np.inf)
        for j, g in enumerate(active.groups):
            s = active.sign[g] * rates[g]
            top[j] = s[active.active[g]].max(initial=-np.inf)
            top[n + j] = np.abs(s).max(initial=0.0)
        self._max(top)
        reach = [_branch_reach(active.sign[g] * rates[g], active.sign[g] * gap[g], top[j],
                               top[n + j]) for j, g in enumerate(active.groups)]
        # the nearest finite reach of each group (-inf: none), for its ties
        near = self._max(np.array([(-np.abs(x[np.isfinite(x)])).max(initial=-np.inf)
                                   for x in reach]))
        chosen = active.choose([-x for x in reach], GROUP_TOL * -near)
        for g, best, some in zip(active.groups, chosen, np.isfinite(near)):
            if some:   # (a group no row of which reaches its value keeps its row)
                active.active[g] = best
        active.start_step()

    def _max(self, values: np.ndarray) -> np.ndarray:
        """The largest of every rank's values, in place. Collective."""
        if self.ctx.comm.size > 1:
            self.ctx.comm.Allreduce(MPI.IN_PLACE, values, op=MPI.MAX)
        return values

    # ------------------------------------------------------------ effects' hooks

    def begin_hooks(self, q: np.ndarray) -> bool:
        """The hooks' effects at the start of a step (True when a relation changed)."""
        changed = False
        for e in self.hooks:
            changed = e.begin_step(q, self.rset.views(self.active.active),
                                   self.ctx.composition.now) or changed
        return changed

    def refresh_hooks(self, q: np.ndarray, lam: np.ndarray) -> bool:
        """The effects' updates between iterations (e.g. friction states and slip senses;
        ``lam``: this rank's owned multipliers, unscaled: an effect reads a relation's rows,
        fetched from their owners, only if it needs them — friction and geometric stiffness
        do, a frictionless contact does not); their relation values are then copied into the
        system (``sync_relations``). Collective."""
        lam = self.rset.by_relation(lam)
        active = self.rset.views(self.active.active)
        changed = False
        for e in self.hooks:
            changed = e.refresh(q, lam, active) or changed
        if any(getattr(e, "rows_moved", False) for e in self.hooks):
            # rows made again on the current geometry (finite sliding; every rank alike): the
            # sets seen so far were sets of other rows, so coming back to one is no cycle
            self.active.seen = _Seen(self.active.comm, self.active.active.tobytes())
        return changed

    def end_hooks(self) -> None:
        for e in self.hooks:
            e.end_step()

    @property
    def restructures(self) -> bool:
        """Whether a hook's effect may change its relations' sparsity (every step: one
        /timings/pattern dataset)."""
        return any(e.restructures for e in self.hooks)

    @property
    def restructured(self) -> bool:
        return any(e.restructured for e in self.hooks)

    def sync_relations(self) -> float | None:
        """Copy the current A and D values of the relations marked ``meta["refresh"]`` into
        the relation set (unscaled; the scales of the first assembly stay); when a hook
        changed their sparsity (``Effect.restructured``), the system's operator is built
        again on the new pattern and the rows of the dependence analysis made again. Returns
        the seconds of that restructure (/timings/pattern), None when there was none. Every
        rank decides alike (the same relations everywhere)."""
        if not self.restructured:
            self.rset.refresh()
            return None
        t0 = time.perf_counter()
        self.system.restructure()
        self._rows = self._dependence_rows()
        for e in self.hooks:
            e.restructured = False
        return time.perf_counter() - t0

    # ------------------------------------------------------------ restart

    def save_state(self) -> dict:
        return {"orient": self.active.orient.copy(), "oriented": self.oriented,
                "hooks": [e.restart_state() for e in self.hooks]}

    def load_state(self, state: dict) -> None:
        self.active.orient[:] = state["orient"]
        self.oriented = state["oriented"]
        for e, saved in zip(self.hooks, state["hooks"]):
            e.load_restart_state(saved)
