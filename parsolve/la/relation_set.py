"""The relation set: every multiplied (not eliminated) relation stacked into global multiplier
rows, in the DOF map's numbering, scaled — the one owner of the stacked layout.

Relations are rescaled so that their rows and columns are commensurate with the stiffness
(E = 2e11 next to unit coefficients would otherwise wreck pivoting): row k of A is multiplied by
``row_scale[k]`` and column k of D by ``col_scale[k]``, so the solved multiplier is
``λ / col_scale`` and the primal equation's right-hand side ``b · row_scale``. An associated
relation gets equal scales, which keeps the operator symmetric.

A relation is whole (every row on every rank) or built per rank (``Relation.ids``: a rigid
obstacle's contact rows, each built by the rank owning its slave node; multiplied Dirichlet,
equal and periodic rows, by the rank owning the DOF or node each constrains; solubility's two
rows of a node, by the node's owner; a per-cell strain row, by the rank counting the cell, under
a maximum too; numbered by their place in the whole relation). A whole relation may be
spread (``Relation.spread``: a mean, linear or strain row, each rank holding the entries on its
owned DOFs): its rows' A entries are sent to their multiplier row's owner (``_foreign_a``),
whose operator row adds them, and its rows' owners are counted from every rank's entries
(``_loose_owners``). A tie's entries on another rank's DOF: its D entries go to that DOF's
owner (``_foreign_d``), its A q reads the DOF's value from there (``la.fetch.Fetch``).
The relation rows a rank holds are its per-rank relations' rows and every whole relation's;
the vectors per relation row (``mult_of_row``, ``position``, the active set's masks, targets,
gaps) run over those, ``rep_row`` over the multiplier rows those rows have (``mults_here``),
and the ones per multiplier row over the rank's held multiplier rows (owned, then ghosts:
``DofMap.l_held``): the row and column scales, the operator's enforced rows; the right-hand
side and gaps over its owned rows.

Multiplier rows are numbered by owner: a per-rank relation's rows belong to the rank that built
them; a whole relation's row to the rank owning most of the DOFs its A
row and D column name (ties: the lowest rank; a row with no entry: ranks in turn), so that the
row of A and the column of D live, as far as they can, with the nodes they act on. A contact
row on a rigid obstacle goes with its slave node; a row tying a slave node to a span of master
nodes (finite sliding, mortar) with the master nodes, which are most of its entries; the
rows of a whole relation's ``groups``, which the active set decides together, with the owner
of the group's first row; a maximum relation's rows stay with the ranks building them (the
group decided by reductions), its one multiplier row owned by one rank. Rank r's rows come after those of the ranks before it, in stacking order (relation by
relation; the per-rank relations' counts gathered); the DOF map is given each rank's count
(``DofMap.set_multipliers``). On one rank
this is the stacking order itself. Each rank keeps the entries of its own operator rows only
(the A entries of the multiplier rows it owns, the D entries on the primal DOFs it owns) and
holds, besides its own multipliers, the ghost rows whose D column has an entry on one of its
owned DOFs: what its reactions D λ and its eliminated rows read (given to the DOF map at every
stacking).

A relation's rows ("relation rows", what the active set decides) map to multiplier rows one to
one, except for a collapsed maximum group (``Relation.collapsed``): all its rows share one
multiplier row and one dual column, which carries the coefficients of the enforced row
(``select``). Its rows are built per rank, its one multiplier row numbered alike on every
rank (owned by the rank owning most of its rows' entries, as a spread row's): each rank holds
its own rows; the operator's row holds the A entries of one row of the group alone, the one it
carries (``_carried``: its first, then the last enforced), sent by the row's holder to the
multiplier row's owner (known there by the row's number, ``a_gid``), and when the group
enforces another row the relations are stacked again with that row's entries (``select``
says so: ``restacked``; the system builds its operator anew), so no rank holds the group's
other rows' entries. The enforced row's number, its value and its multiplier pass between the
row's holder and the multiplier row's owner by one reduction of the groups' number
(``select``, ``_per_mult``, ``_group_multipliers``).

Relations refreshed between iterations (``meta["refresh"]``: friction turning its rows,
contact pairings) keep their sparsity: ``refresh`` copies their current A and D values into the stacked
arrays in place. When a relation's
sparsity changes (finite sliding's spans made again) ``restack`` stacks them again, with the
same rows, owners and scales.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from mpi4py import MPI

from parsolve.la.dofmap import DofMap, GhostExchange
from parsolve.la.fetch import Fetch
from parsolve.mesh.blocks import exchange
from parsolve.relations import Relation


# a spread relation's A entry sent to its multiplier row's owner: the row, the column (new
# primal DOF), the value, the relation and its row there
_A_ENTRY = np.dtype([("row", np.int64), ("col", np.int64), ("val", np.float64),
                     ("rel", np.int64), ("relrow", np.int64), ("gid", np.int64)])


def _per_rank_group(r: Relation) -> bool:
    """A maximum group built per rank with one multiplier row (``Relation.collapsed``): its
    rows on the ranks building them, the row numbered alike on every rank and owned by one."""
    return r.collapsed and not r.whole


def _cat(parts, dtype) -> np.ndarray:
    return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype)


def _segments(keep: np.ndarray, sizes: list[int], wanted: list[bool]) -> dict:
    """Per wanted relation k, (its run among the kept entries, their places in its own
    entries): ``keep`` sorted indices into the relations' entries stacked in order."""
    bounds = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    at = np.searchsorted(keep, bounds)
    return {k: (slice(int(at[k]), int(at[k + 1])), keep[at[k]:at[k + 1]] - bounds[k])
            for k in range(len(sizes)) if wanted[k]}


class RelationSet:
    """The stacked relations of a system (see the module doc). The COO arrays (``a_rows``,
    ``a_cols``, ``a_vals``, ``d_rows``, ``d_cols``, ``d_vals``; rows/columns in global
    multiplier rows and new primal DOFs, values unscaled, D itself: the matrix holds -D) hold
    this rank's operator rows only: the A entries of the multiplier rows it owns and the D
    entries on the primal DOFs it owns. They are read by the operator (``la.petsc``)."""

    def __init__(self, relations: list[Relation], dofmap: DofMap):
        self.relations, self.dofmap = relations, dofmap
        self.position: np.ndarray | None = None   # multiplier row of each stacked row
        for r in relations:   # (the same relations on every rank: raised on all alike)
            if r.meta.get("refresh") and (r.spread or _per_rank_group(r)):
                # ``refresh`` copies the entries kept here, not those sent to a row's owner
                raise ValueError(f"relation '{r.name}': values refreshed between iterations "
                                 "are not supported on a row whose entries are sent to its "
                                 "owner (a spread row, a maximum group)")
        # per maximum group built per rank (``_groups``): the number of its enforced row
        # (its first until ``select`` says, -1: none), told by the row's holder, and of the
        # row whose A entries its operator row holds (the last enforced)
        ngroups = sum(_per_rank_group(r) for r in relations)
        self._enforced = np.zeros(ngroups, dtype=np.int64)
        self._carried = np.zeros(ngroups, dtype=np.int64)
        self.restacked = False   # ``select`` stacked the relations again (a group moved)
        self._stack()
        self.row_scale: np.ndarray | None = None
        self.col_scale: np.ndarray | None = None

    def restack(self) -> None:
        """Stack the relations again after their sparsity changed (``Relation.set_entries``):
        the same rows, so the multiplier layout, the scales and the row each collapsed group
        enforces (``set_active``'s choice) stay, and so do their owners (a slave node's
        row stays with its rank while its masters change); the DOF map must know their DOFs
        (``DofMap.index_inputs``)."""
        rep_row = self.rep_row
        self._stack()
        self.rep_row = rep_row
        if self.scaled:   # (the ghost rows may have changed: their scales from the owners)
            n = self.n_owned
            self.row_scale = self.from_owned(self.row_scale[:n])
            self.col_scale = self.from_owned(self.col_scale[:n])

    def _stack(self) -> None:
        relations, dofmap = self.relations, self.dofmap
        new_dof = dofmap.input_new_dof
        sizes = [r.nrows for r in relations]        # the rows held here (``Relation.ids``)
        mult_sizes = [1 if r.collapsed else r.nrows for r in relations]
        self.row_first = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        first = np.concatenate([[0], np.cumsum(mult_sizes)]).astype(np.int64)
        ar, ac, av, dr, dc, dv, arel, mult, gid = [], [], [], [], [], [], [], [], []
        # maximum groups built per rank with one multiplier row (their A entries found by
        # their rows' numbers, ``a_gid``: the enforced one's on, ``a_on``)
        self._groups = [k for k, r in enumerate(relations) if _per_rank_group(r)]
        for k, rel in enumerate(relations):
            local = np.zeros(rel.nrows, dtype=np.int64) if rel.collapsed else np.arange(rel.nrows)
            mult.append(local + first[k])
            ar.append(local[rel.a_rows] + first[k])
            grouped = _per_rank_group(rel)
            arel.append(np.full(rel.a_rows.size, -1, dtype=np.int64) if grouped
                        else rel.a_rows + self.row_first[k])
            gid.append(rel.ids[rel.a_rows] if grouped
                       else np.full(rel.a_rows.size, -1, dtype=np.int64))
            ac.append(new_dof(rel.a_dofs))
            av.append(rel.a_vals)
            if rel.collapsed:  # one copy of the shared vector
                dofs, vals = rel.shared_dual
                rows = np.zeros(dofs.size, dtype=np.int64)
            else:
                dofs, rows, vals = rel.dual_coo()
            dr.append(new_dof(dofs))
            dc.append(np.asarray(rows, dtype=np.int64) + first[k])
            dv.append(np.asarray(vals, dtype=float))
        stacked_d = _cat(dc, np.int64)
        self.d_rows, self.d_vals = _cat(dr, np.int64), _cat(dv, float)
        if self.position is None:   # the owners, once (from every row's entries): restacking
            self.a_cols = _cat(ac, np.int64)   # keeps them
            self.position, self._counts = self._by_owner(_cat(ar, np.int64), stacked_d, first)
        for j, k in enumerate(self._groups):   # a group's carried row's entries alone
            keep = gid[k] == self._carried[j]
            ar[k], ac[k], av[k], arel[k], gid[k] = (x[keep] for x in
                                                    (ar[k], ac[k], av[k], arel[k], gid[k]))
        stacked_a = _cat(ar, np.int64)
        self._d_per_rank = np.repeat([not r.whole for r in relations],
                                     [len(d) for d in dv]).astype(bool)
        self._a_sent = np.repeat([r.spread or _per_rank_group(r) for r in relations],
                                 [len(a) for a in av]).astype(bool)
        self.a_cols, self.a_vals = _cat(ac, np.int64), _cat(av, float)
        pos = self.position
        self.a_rows, self.d_cols = pos[stacked_a], pos[stacked_d]
        self.a_relrow = _cat(arel, np.int64)            # relation row of each A entry
        self.a_gid = _cat(gid, np.int64)   # its row's number in a per-rank group, else -1
        self._keep_own([len(a) for a in av], [len(d) for d in dv])
        self.mult_rows = [pos[first[k]:first[k + 1]] for k in range(len(relations))]
        self._group_mult = np.array([pos[first[k]] for k in self._groups], dtype=np.int64)
        self.mult_of_row = pos[_cat(mult, np.int64)]    # multiplier row of each relation row
        # the relation rows of whole relations (the same on every rank) and the others
        whole = np.concatenate([np.full(r.nrows, r.whole) for r in relations]) \
            if relations else np.zeros(0, dtype=bool)
        self.whole_rows, self.own_rows = np.flatnonzero(whole), np.flatnonzero(~whole)
        self.mults_here = np.unique(self.mult_of_row)  # multiplier rows with a row held here
        # per multiplier row held here (``mults_here``), the relation row it enforces
        self.rep_row = np.zeros(self.mults_here.size, dtype=np.int64)
        self.rep_row[self._here(self.mult_of_row[::-1])] = \
            np.arange(self.mult_of_row.size)[::-1]    # (its first)
        # where the multiplier rows of the relation rows held here are held (a whole
        # relation's rows on other ranks are not)
        self._mult_held = self._held_places(self.mult_of_row)
        self._owned_entries: dict[int, tuple] = {}      # per relation: its owned A entries
        self._fetch: dict[int, _Fetched | None] = {}      # and the plan of its others'
        self._sums: _RowSums | None = None              # owned_primal's plan

    def _held_places(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(mask of the global multiplier rows this rank holds, their places among the held
        ones: owned rows first, then ghosts; ``DofMap.l_held``)."""
        dm = self.dofmap
        _, _, l0, l1 = dm.owned()
        rows = np.asarray(rows, dtype=np.int64)
        own = (rows >= l0) & (rows < l1)
        at = np.searchsorted(dm.l_ghosts, rows)
        ghost = ~own & (dm.l_ghosts[np.minimum(at, dm.l_ghosts.size - 1)] == rows) \
            if dm.l_ghosts.size else np.zeros(rows.shape, dtype=bool)
        return own | ghost, np.where(own, rows - l0, l1 - l0 + at)

    @property
    def n_owned(self) -> int:
        """Multiplier rows this rank owns (the first of those it holds)."""
        _, _, l0, l1 = self.dofmap.owned()
        return l1 - l0

    @property
    def d_places(self) -> np.ndarray:
        """Place among the held multiplier rows of each kept D entry's column."""
        return self._d_held

    def from_owned(self, owned: np.ndarray) -> np.ndarray:
        """A per held multiplier row vector from its owned rows' values, the ghosts' fetched
        from their owners. Collective."""
        return self.dofmap.forward_multipliers(owned)

    def _here(self, mults: np.ndarray) -> np.ndarray:
        """Places in ``mults_here`` of multiplier rows held here."""
        return np.searchsorted(self.mults_here, mults)

    def _by_owner(self, stacked_a: np.ndarray, stacked_d: np.ndarray, first: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
        """The multiplier row of each stacked row held here, rows grouped by owner (see the
        module doc), and each rank's count. A whole relation's rows: every rank computes the
        same owners; a relation built per rank: its rows are this rank's. Rank r's rows are
        numbered relation by relation, each relation's in row order, after the ranks before
        it (one gather of the per-rank relations' counts)."""
        dofmap = self.dofmap
        nranks, me = dofmap.q_ranges.size - 1, dofmap.rank
        n, nrel = int(first[-1]), len(self.relations)
        relation = np.repeat(np.arange(nrel), np.diff(first))
        # rows numbered alike on every rank: a whole relation's, a per-rank group's one row
        whole = np.array([r.whole or r.collapsed for r in self.relations], dtype=bool)
        is_whole = whole[relation] if nrel else np.zeros(0, dtype=bool)
        wid = np.cumsum(is_whole) - 1                           # whole rows' common numbers
        owner = np.full(n, me, dtype=np.int64)
        owner[is_whole] = np.arange(int(is_whole.sum()), dtype=np.int64) % nranks  # no entry
        rows = np.concatenate([stacked_a, stacked_d])
        dof_owner = dofmap.owner_of_dofs(np.concatenate([self.a_cols, self.d_rows]))
        loose = whole & np.array([not r.complete for r in self.relations], dtype=bool)
        is_loose = loose[relation] if nrel else np.zeros(0, dtype=bool)
        on = is_whole[rows] & ~is_loose[rows]
        keys, count = np.unique(wid[rows[on]] * nranks + dof_owner[on], return_counts=True)
        row, rank = np.divmod(keys, nranks)
        best = np.lexsort((rank, -count, row))                  # most entries, then lowest rank
        lead = np.flatnonzero(np.diff(np.concatenate([[-1], row[best]])) != 0)
        at = np.flatnonzero(is_whole)
        owner[at[row[best[lead]]]] = rank[best[lead]]
        if loose.any():   # (the same relations on every rank)
            self._loose_owners(owner, rows, dof_owner, is_loose)
        self._groups_together(owner, first)
        # per relation and rank, its rows: whole relations' from the owners, the others'
        # gathered
        counts = np.zeros((nrel, nranks), dtype=np.int64)
        np.add.at(counts, (relation, owner), 1)
        mine = np.where(whole, 0, np.diff(first)).astype(np.int64)
        if nranks > 1:
            theirs = np.empty((nranks, nrel), dtype=np.int64)
            dofmap.comm.Allgather(mine, theirs)
            counts[~whole] = theirs.T[~whole]
        starts = np.concatenate([[0], np.cumsum(counts.sum(axis=0))])[:-1]
        before = np.cumsum(counts, axis=0) - counts              # rows of earlier relations
        key = relation * nranks + owner
        order = np.argsort(key, kind="stable")
        group_start = np.searchsorted(key[order], key[order])
        within = np.empty(n, dtype=np.int64)
        within[order] = np.arange(n) - group_start
        position = starts[owner] + before[relation, owner] + within
        return position, counts.sum(axis=0)

    def _loose_owners(self, owner: np.ndarray, rows: np.ndarray, dof_owner: np.ndarray,
                      is_loose: np.ndarray) -> None:
        """The owners of the rows of whole relations whose entries are spread over the ranks
        (``Relation.complete`` false: a spread relation, a load pattern), in place: the rank
        owning most of their entries (then the lowest), from each rank's count of the entries
        on its owned DOFs (one reduction of the rows' size: the largest count, with the rank
        in its low digits). Collective."""
        dofmap = self.dofmap
        nranks = dofmap.q_ranges.size - 1
        at = np.flatnonzero(is_loose)
        mine = is_loose[rows] & (dof_owner == dofmap.rank)
        count = np.bincount(np.searchsorted(at, rows[mine]), minlength=at.size).astype(np.int64)
        best = np.where(count > 0, count * nranks + (nranks - 1 - dofmap.rank), -1)
        if nranks > 1:
            dofmap.comm.Allreduce(MPI.IN_PLACE, best, op=MPI.MAX)
        some = best >= 0
        owner[at[some]] = nranks - 1 - best[some] % nranks

    def _groups_together(self, owner: np.ndarray, first: np.ndarray) -> None:
        """The rows of a whole relation's ``groups`` (decided together by the active set) go
        with the group's first row's owner, in place (a relation built per rank: its groups
        are this rank's; a maximum group's rows are decided by reductions, wherever they
        are)."""
        for k, r in enumerate(self.relations):
            ids = r.groups
            if ids is not None and r.nrows and r.whole:
                _, lead, inverse = np.unique(ids, return_index=True, return_inverse=True)
                rows = first[k] + np.arange(r.nrows)
                owner[rows] = owner[rows[lead[inverse]]]

    def _keep_own(self, a_sizes: list[int], d_sizes: list[int]) -> None:
        """Keep the entries of this rank's operator rows only: A entries of the multiplier
        rows it owns (whole rows), D entries on the primal DOFs it owns; per refreshed
        relation, where its kept entries come from (``refresh`` copies them). The DOF map is
        told each rank's rows and this rank's ghost rows: those whose D column has an entry on
        one of its owned DOFs, the multipliers its reactions and eliminated rows read."""
        dofmap = self.dofmap
        dofmap.set_multipliers(self._counts)
        q0, q1, l0, l1 = dofmap.owned()
        owned = (self.a_rows >= l0) & (self.a_rows < l1)
        keep_a = np.flatnonzero(owned)
        mine = (self.d_rows >= q0) & (self.d_rows < q1)
        keep_d = np.flatnonzero(mine)
        sent = self._foreign_d(self._d_per_rank & ~mine)
        got_a = self._foreign_a(self._a_sent & ~owned)
        for name, got in zip(("a_rows", "a_cols", "a_vals", "a_relrow", "a_gid"), got_a):
            setattr(self, name, np.concatenate([getattr(self, name)[keep_a], got]))
        for name, got in zip(("d_rows", "d_cols", "d_vals"), sent):
            setattr(self, name, np.concatenate([getattr(self, name)[keep_d], got]))
        refreshed = [bool(r.meta.get("refresh")) for r in self.relations]
        # a refreshed relation's D entries sent to other ranks: sent again by ``refresh``
        # (received after the kept ones)
        self._resend = self._crossing and self.dofmap.comm.allreduce(bool(np.any(
            np.repeat(refreshed, d_sizes).astype(bool)[self._sent[0]])), op=MPI.LOR)
        self._got_from = keep_d.size
        self._a_from = _segments(keep_a, a_sizes, refreshed)
        self._d_from = _segments(keep_d, d_sizes, refreshed)
        dofmap.set_multipliers(self._counts, self.d_cols)
        self._d_held = dofmap.held_index(self.d_cols)

    def _foreign_a(self, out: np.ndarray) -> tuple:
        """The A entries this rank holds of spread relations' rows owned elsewhere (``out``:
        on its owned DOFs, ``Relation.spread``) and of per-rank maximum groups' rows whose
        one multiplier row another rank owns, sent to those rows' owners, who add them to
        their operator rows; returns the entries received (multiplier rows, columns, values,
        relation rows here, group row numbers). Collective (nothing moves on one rank or
        without such a relation anywhere: the same relations on every rank)."""
        comm = self.dofmap.comm
        if comm.size == 1 or not any(r.spread or _per_rank_group(r) for r in self.relations):
            return (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0),
                    np.zeros(0, np.int64), np.zeros(0, np.int64))
        at = np.flatnonzero(out)
        owner = np.searchsorted(self.dofmap.l_ranges, self.a_rows[at], side="right") - 1
        k = np.searchsorted(self.row_first, np.maximum(self.a_relrow[at], 0), side="right") - 1
        sent = np.empty(at.size, dtype=_A_ENTRY)
        sent["row"], sent["col"], sent["val"] = self.a_rows[at], self.a_cols[at], self.a_vals[at]
        sent["rel"], sent["relrow"] = k, self.a_relrow[at] - self.row_first[k]
        sent["gid"] = self.a_gid[at]
        got, _ = exchange(comm, sent, owner)
        # (a whole relation's row j is relation row row_first[k] + j on every rank; a
        # group's entries are known by their row's number alone)
        relrow = np.where(got["gid"] >= 0, -1, self.row_first[got["rel"]] + got["relrow"])
        return got["row"], got["col"], got["val"], relrow, got["gid"]

    def _foreign_d(self, out: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The D entries of this rank's rows built per rank on other ranks' DOFs (``out``: a
        tie's u_b) sent to those DOFs' owners, who add them to their operator rows; returns
        the entries received (rows, columns, values). Collective (nothing moves on one rank or
        without such rows anywhere). A refreshed relation's are sent again by ``refresh``."""
        comm, dofmap = self.dofmap.comm, self.dofmap
        none = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
        self._crossing = comm.size > 1 and comm.allreduce(bool(out.any()), op=MPI.LOR)
        self._sent = (np.zeros(0, np.int64), None, None)
        if not self._crossing:
            return none
        at = np.flatnonzero(out)
        owner = dofmap.owner_of_dofs(self.d_rows[at])
        order = np.argsort(owner, kind="stable")
        at = at[order]
        counts = np.bincount(owner, minlength=comm.size).astype(np.int64)
        got_counts = np.empty_like(counts)
        comm.Alltoall(counts, got_counts)
        self._sent = (at, counts, got_counts)   # (what ``refresh`` sends again)
        got = []
        for values, kind in ((self.d_rows, MPI.INT64_T), (self.d_cols, MPI.INT64_T),
                             (self.d_vals, MPI.DOUBLE)):
            buf = np.empty(int(got_counts.sum()), dtype=values.dtype)
            comm.Alltoallv([np.ascontiguousarray(values[at]), counts, _displ(counts), kind],
                           [buf, got_counts, _displ(got_counts), kind])
            got.append(buf)
        return tuple(got)

    # ------------------------------------------------------------ sizes and views

    @property
    def nrows(self) -> int:
        """Multiplier rows."""
        return int(self.dofmap.nl)

    @property
    def nrelrows(self) -> int:
        """Relation rows (what the active set decides)."""
        return int(self.row_first[-1])

    def __len__(self) -> int:
        return len(self.relations)

    def rows_of(self, k: int) -> slice:
        """The relation rows of relation k."""
        return slice(int(self.row_first[k]), int(self.row_first[k + 1]))

    def views(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Per relation, its rows of a per-relation-row array x (writable views)."""
        return {r.name: x[self.rows_of(k)] for k, r in enumerate(self.relations)}

    def locate(self, row: int) -> tuple[int, int]:
        """(relation, its local row) of a relation row."""
        k = int(np.searchsorted(self.row_first, row, side="right") - 1)
        return k, int(row - self.row_first[k])

    @property
    def a_on(self) -> np.ndarray:
        """A entries of the rows enforced now (all but a collapsed group's other rows; a
        per-rank group's: those of its enforced row's number)."""
        grouped = self.a_gid >= 0
        on = np.zeros(self.a_rows.size, dtype=bool)
        if self.rep_row.size:
            at = np.minimum(self._here(self.a_rows[~grouped]), self.rep_row.size - 1)
            on[~grouped] = self.rep_row[at] == self.a_relrow[~grouped]
        for j, mult in enumerate(self._group_mult):   # (a loop over groups, not rows)
            at = grouped & (self.a_rows == mult)
            on[at] = self.a_gid[at] == self._enforced[j]
        return on

    # ------------------------------------------------------------ values

    def targets(self, t: float) -> np.ndarray:
        """Unscaled b(t) of every relation row."""
        return np.concatenate([r.rhs(t) for r in self.relations]) if self.relations else np.zeros(0)

    def _per_mult(self, per_row: np.ndarray) -> np.ndarray:
        """Per multiplier row this rank owns, the value of the relation row it enforces."""
        _, _, l0, l1 = self.dofmap.owned()
        out = np.zeros(l1 - l0)
        own = (self.mults_here >= l0) & (self.mults_here < l1)
        out[self.mults_here[own] - l0] = per_row[self.rep_row[own]]
        if self._groups:   # (collective) a per-rank group's: its enforced row's holder's
            mine = (self._group_mult >= l0) & (self._group_mult < l1)
            out[self._group_mult[mine] - l0] = self._group_values(per_row)[mine]
        return out

    def _group_values(self, per_row: np.ndarray) -> np.ndarray:
        """Per per-rank maximum group, the value (of ``per_row``, per relation row held here)
        of its enforced row, from the rank holding it: one reduction of the groups' number.
        Collective."""
        out = np.zeros(len(self._groups))
        for j, k in enumerate(self._groups):
            at = np.flatnonzero(self.relations[k].ids == self._enforced[j])
            out[j] = per_row[self.row_first[k] + at[0]] if at.size else 0.0
        return self.dofmap.sum_ranks(out)

    def _group_multipliers(self, lam: np.ndarray, out: np.ndarray, start: int) -> None:
        """A per-rank group's λ (``lam``: this rank's owned multipliers) on its enforced row
        where held, 0 on its other rows, in ``out`` (per relation row from ``start``), in
        place: one reduction of the groups' number. Collective."""
        _, _, l0, l1 = self.dofmap.owned()
        mine = (self._group_mult >= l0) & (self._group_mult < l1)
        values = np.zeros(len(self._groups))
        values[mine] = lam[self._group_mult[mine] - l0]
        self.dofmap.sum_ranks(values)
        for j, k in enumerate(self._groups):
            span = self.rows_of(k)
            if span.start < start or span.stop > start + out.size:
                continue
            rows = out[span.start - start:span.stop - start]
            rows[:] = np.where(self.relations[k].ids == self._enforced[j], values[j], 0.0)

    def rhs(self, t: float) -> np.ndarray:
        """Scaled b(t) of the multiplier rows this rank owns."""
        return self._per_mult(self.targets(t)) * self.row_scale[:self.n_owned]

    def _owned_part(self, r: Relation, q: np.ndarray) -> np.ndarray:
        """This rank's part of A q of a relation's rows held here: its entries on owned DOFs;
        a relation built per rank, its entries on other ranks' DOFs too (a tie's u_b,
        fetched from their owners: ``la.fetch.Fetch``). Collective for a relation built per rank."""
        key = id(r)
        if key not in self._owned_entries:
            self._owned_entries[key] = self.dofmap.owned_dof_entries(r.a_dofs)
            self._fetch[key] = None if r.whole else _Fetched.plan(self.dofmap, r)
        sel, local = self._owned_entries[key]
        part = self.dofmap.owned_part(sel, local, r.a_rows, r.a_vals, r.nrows, q)
        fetch = self._fetch[key]
        return part if fetch is None else fetch.add(part, r, q)

    def _parts(self, q: np.ndarray) -> np.ndarray:
        return np.concatenate([self._owned_part(r, q) for r in self.relations])

    def primal_values(self, q: np.ndarray) -> np.ndarray:
        """A q of every relation row held here (unscaled), q a local primal vector: a
        relation built per rank on its own entries (on owned DOFs), the whole ones' in one
        reduction. Collective."""
        if not self.relations:
            return np.zeros(0)
        parts = self._parts(q)
        parts[self.whole_rows] = self.dofmap.sum_ranks(parts[self.whole_rows])
        return parts

    def owned_primal(self, q: np.ndarray) -> np.ndarray:
        """A q of the relation rows whose multiplier this rank owns (``owned_relrows``; 0 on
        the others), q a local primal vector: a relation built per rank on its own entries;
        a whole relation's entries each taken on the rank owning its DOF and its row's part
        sent to the row's owner (an exchange of the rows that cross the ranks, planned once
        per stacking). Collective."""
        if not self.relations:
            return np.zeros(0)
        parts = self._parts(q)
        if self.dofmap.comm.size == 1:
            return parts
        if self._sums is None:
            self._sums = _RowSums(self)
        parts[self.whole_rows] = self._sums.add(parts[self.whole_rows])
        return parts

    def relation_primal(self, r: Relation, q: np.ndarray) -> np.ndarray:
        """A q of one relation's rows held here (any relation of the model). Collective."""
        part = self._owned_part(r, q)
        return self.dofmap.sum_ranks(part) if r.whole else part

    def empty_rows(self, r: Relation) -> np.ndarray:
        """A relation's rows with no A entry. A spread relation's entries are over the ranks
        (each holds those on its DOFs): a row is empty only when it is so on every rank.
        Collective for a spread relation."""
        empty = r.empty_rows()
        if r.spread and self.dofmap.comm.size > 1:
            self.dofmap.comm.Allreduce(MPI.IN_PLACE, empty, op=MPI.LAND)
        return empty

    def gap(self, t: float, q: np.ndarray) -> np.ndarray:
        """b(t) - A q of the multiplier rows this rank owns, unscaled. Collective
        (``owned_primal``)."""
        if not self.relations:
            return np.zeros(0)
        return self._per_mult(self.targets(t) - self.owned_primal(q))

    def scaled_residual(self, t: float, q: np.ndarray | None) -> np.ndarray:
        """Scaled b(t) - A q of the multiplier rows this rank owns (b(t) alone without q).
        Collective (``owned_primal``)."""
        target = self.rhs(t)
        if q is not None and self.nrows:
            target = target - self._per_mult(self.owned_primal(q)) * self.row_scale[:target.size]
        return target

    def reactions(self, lam: np.ndarray) -> np.ndarray:
        """Owned saddle rows of D λ (unscaled λ of this rank's owned multiplier rows; the
        ghost rows' fetched from their owners; multiplier rows 0). Collective."""
        q0, q1, _, _ = self.dofmap.owned()
        held = self.dofmap.forward_multipliers(lam)
        out = np.zeros(self.dofmap.nrows)
        out[:q1 - q0] = np.bincount(self.d_rows - q0, weights=self.d_vals * held[self._d_held],
                                    minlength=q1 - q0)
        return out

    def multipliers(self, lam_scaled: np.ndarray) -> np.ndarray:
        """Unscaled λ of this rank's owned multiplier rows from the solved (scaled) held ones
        (owned rows first)."""
        n = self.n_owned
        return lam_scaled[:n] * self.col_scale[:n] if self.nrows else np.zeros(0)

    @property
    def owned_relrows(self) -> np.ndarray:
        """Mask of the relation rows this rank decides: those whose multiplier row it owns,
        and a per-rank maximum group's rows it holds (the group decided by reductions, its
        one multiplier row owned by one rank)."""
        _, _, l0, l1 = self.dofmap.owned()
        out = (self.mult_of_row >= l0) & (self.mult_of_row < l1)
        for k in self._groups:
            out[self.rows_of(k)] = True
        return out

    def _owned_values(self, lam: np.ndarray, span: slice) -> np.ndarray:
        """Per relation row of ``span``, unscaled λ of its multiplier row (this rank's owned
        ones) on the row it enforces, 0 on the others and on the rows whose multiplier another
        rank owns."""
        _, _, l0, l1 = self.dofmap.owned()
        mult = self.mult_of_row[span]
        rows = np.arange(span.start, span.start + mult.size)
        sel = (mult >= l0) & (mult < l1) & (self.rep_row[self._here(mult)] == rows)
        out = np.zeros(mult.size)
        out[sel] = lam[mult[sel] - l0]
        return out

    def owned_row_values(self, lam: np.ndarray) -> np.ndarray:
        """Per relation row, unscaled λ (``_owned_values``) of the rows whose multiplier this
        rank owns (``owned_relrows``), 0 on the others: what it decides on. No exchange."""
        return self._owned_values(lam, slice(0, self.nrelrows))

    def relation_values(self, k: int, lam: np.ndarray) -> np.ndarray:
        """Unscaled λ of relation k's rows held here (``_owned_values``) from this rank's owned
        multipliers, each row's from its owner: one reduction of a whole relation's size
        (a relation built per rank: its own). Collective."""
        span = self.rows_of(k)
        part = self._owned_values(lam, span)
        if self._groups:   # (the same relations on every rank)
            self._group_multipliers(lam, part, span.start)
        return self.dofmap.sum_ranks(part) if self.relations[k].whole else part

    def every_row(self, lam: np.ndarray) -> np.ndarray:
        """Per relation row held here, unscaled λ from this rank's owned multipliers, the
        whole relations' rows' from their owners: one reduction of their size. Collective.
        Not on the Newton iteration's path (the failure analysis and the written steps'
        outputs)."""
        if not self.nrows:
            return np.zeros(0)
        out = self.owned_row_values(lam)
        out[self.whole_rows] = self.dofmap.sum_ranks(out[self.whole_rows])
        if self._groups:
            self._group_multipliers(lam, out, 0)
        return out

    def per_relation(self, lam: np.ndarray) -> dict[str, np.ndarray]:
        """Unscaled λ of every relation row held here, by relation (a collapsed group: on
        its enforced row, 0 on the others), from this rank's owned multipliers. Collective."""
        per_row = self.every_row(lam)
        return {r.name: per_row[self.rows_of(k)] for k, r in enumerate(self.relations)}

    def by_relation(self, lam: np.ndarray) -> "RelationMultipliers":
        """Per relation name, unscaled λ of its rows, each relation's fetched from the owners
        when first read (``relation_values``)."""
        return RelationMultipliers(self, lam)

    # ------------------------------------------------------------ updates in place

    def select(self, active_rows: np.ndarray) -> np.ndarray:
        """The enforced relation rows → which row each collapsed group carries, and the mask of
        the held multiplier rows enforced (``DofMap.l_held``). A per-rank group enforcing a
        row other than the one its operator row holds: the relations are stacked again with
        that row's entries (``restacked`` set: the operator must be built anew)."""
        active_rows = np.asarray(active_rows, dtype=bool)
        if self._groups and self._select_groups(active_rows):   # (collective)
            self.restack()
            self.restacked = True
        on = np.zeros(self.dofmap.n_held, dtype=bool)
        held, at = self._mult_held
        np.logical_or.at(on, at[held], active_rows[held])
        rows = np.flatnonzero(active_rows)
        self.rep_row[self._here(self.mult_of_row[rows])] = rows
        if self._groups:   # a per-rank group's multiplier row: on when it enforces a row
            held, at = self._held_places(self._group_mult)
            on[at[held]] = self._enforced[held] >= 0
        if self._crossing:   # ghost rows built per rank elsewhere: their owners' say
            # (collective: a tie's D column on another rank's DOF, ``_foreign_d``)
            on = self.from_owned(on[:self.n_owned].astype(float)) > 0.5
        return on

    def _select_groups(self, active_rows: np.ndarray) -> bool:
        """Each per-rank maximum group's enforced row (its number, -1: none) from the rank
        holding it: one reduction of the groups' number. Returns whether a group enforces a
        row other than the one its operator row holds (then carried from now on)."""
        none = np.iinfo(np.int64).max   # (the lowest enforced row over the ranks, as on one)
        found = np.full(len(self._groups), none, dtype=np.int64)
        for j, k in enumerate(self._groups):
            at = np.flatnonzero(active_rows[self.rows_of(k)])
            if at.size:
                found[j] = self.relations[k].ids[at].min()
        if self.dofmap.comm.size > 1:
            self.dofmap.comm.Allreduce(MPI.IN_PLACE, found, op=MPI.MIN)
        found[found == none] = -1
        self._enforced = found
        moved = (found >= 0) & (found != self._carried)
        self._carried[moved] = found[moved]
        return bool(moved.any())

    @property
    def carried(self) -> np.ndarray:
        """Per maximum group built per rank, the number of the row whose A entries its
        operator row holds (the same on every rank): state a restart carries over."""
        return self._carried.copy()

    def carry(self, rows: np.ndarray) -> bool:
        """Hold these rows' entries in the groups' operator rows (``carried`` of a run
        continued here); stacked again when that changes them. Returns whether it did (the
        operator must then be built anew)."""
        rows = np.asarray(rows, dtype=np.int64)
        if np.array_equal(rows, self._carried):
            return False
        self._carried[:] = rows
        self.restack()
        return True

    def refresh(self) -> None:
        """Copy the current A and D values of the relations marked ``meta["refresh"]`` into
        the stacked arrays (unscaled; the scales of the first assembly stay; same sparsity)."""
        for k, r in enumerate(self.relations):
            if r.meta.get("refresh"):
                at, src = self._d_from[k]
                self.d_vals[at] = np.asarray(r.dual_coo()[2])[src]
                at, src = self._a_from[k]
                self.a_vals[at] = r.a_vals[src]
        if self._resend:   # (collective) the entries on other ranks' DOFs to their owners
            at, counts, got_counts = self._sent
            vals = _cat([r.shared_dual[1] if r.collapsed else r.dual_coo()[2]
                         for r in self.relations], float)[at]
            comm = self.dofmap.comm
            comm.Alltoallv([np.ascontiguousarray(vals), counts, _displ(counts), MPI.DOUBLE],
                           [self.d_vals[self._got_from:], got_counts, _displ(got_counts),
                            MPI.DOUBLE])

    def set_scales(self, kscale: float) -> None:
        """Scale each row of A and column of D to the size of the stiffness diagonal (the
        largest |entry| of a row or column over the ranks holding its entries; a per-rank
        group's row: of all its rows, whichever it carries), per held
        multiplier row: a row of A is whole on its owner; a column of D's entries on the ranks
        owning their DOFs, whose largest go to the row's owner; the owners' scales then go to
        the ghosts. Collective."""
        _, _, l0, l1 = self.dofmap.owned()
        amax = np.zeros(l1 - l0)
        np.maximum.at(amax, self.a_rows - l0, np.abs(self.a_vals))
        if self._groups:   # (the same relations on every rank) a group's over all its rows
            amax_groups = np.array([np.abs(self.relations[k].a_vals).max(initial=0.0)
                                    for k in self._groups])
            self.dofmap.comm.Allreduce(MPI.IN_PLACE, amax_groups, op=MPI.MAX)
            mine = (self._group_mult >= l0) & (self._group_mult < l1)
            amax[self._group_mult[mine] - l0] = amax_groups[mine]
        dmax = np.zeros(self.dofmap.n_held)
        np.maximum.at(dmax, self._d_held, np.abs(self.d_vals))
        dmax = self._owners_max(dmax)
        amax[amax == 0] = 1.0
        dmax[dmax == 0] = 1.0
        row, col = kscale / amax, kscale / dmax
        held, at = self._mult_held
        for k, rel in enumerate(self.relations):
            if rel.associated:  # same scale on both sides keeps the operator symmetric
                mine = at[self.rows_of(k)][held[self.rows_of(k)]]
                mine = mine[mine < l1 - l0]
                col[mine] = row[mine]
        self.row_scale, self.col_scale = self.from_owned(row), self.from_owned(col)

    def _owners_max(self, held: np.ndarray) -> np.ndarray:
        """Per owned multiplier row, the largest of every rank's values of it (``held``: this
        rank's, per held row; the ghosts' sent to their owners). Collective."""
        dm = self.dofmap
        _, _, l0, l1 = dm.owned()
        out = held[:l1 - l0].copy()
        if dm.comm.size == 1:
            return out
        owner = np.searchsorted(dm.l_ranges, dm.l_ghosts, side="right") - 1
        plan = GhostExchange(dm.comm, dm.l_ghosts, owner, l0)
        got = plan._move(held[l1 - l0:][plan.order], plan.recv_counts, plan.send_counts)
        np.maximum.at(out, plan.asked_of_me, got)
        return out

    @property
    def scaled(self) -> bool:
        return self.row_scale is not None


class _RowSums:
    """The plan of ``owned_primal`` for the whole relations' rows (numbered alike on every
    rank: ``RelationSet.whole_rows``): those this rank has entries of (on its owned DOFs),
    sent to their rows' owners, who add them (two ``Alltoallv`` to plan, one of values per
    use)."""

    def __init__(self, rset: RelationSet):
        dofmap = rset.dofmap
        comm = self.comm = dofmap.comm
        touched = []
        for k, r in enumerate(rset.relations):
            if not r.whole:
                continue
            rset._owned_part(r, np.zeros(dofmap.n_local))   # (its owned entries, cached)
            sel, _ = rset._owned_entries[id(r)]
            touched.append(np.unique(r.a_rows[sel]) + rset.row_first[k])
        held = _cat(touched, np.int64)
        rows = np.searchsorted(rset.whole_rows, held)            # the common numbers
        owner = np.searchsorted(dofmap.l_ranges, rset.mult_of_row[held], side="right") - 1
        order = np.argsort(owner, kind="stable")
        self.send_rows = rows[order]
        self.send_counts = np.bincount(owner, minlength=comm.size).astype(np.int64)
        self.recv_counts = np.empty_like(self.send_counts)
        comm.Alltoall(self.send_counts, self.recv_counts)
        self.recv_rows = np.empty(int(self.recv_counts.sum()), dtype=np.int64)
        comm.Alltoallv([self.send_rows, self.send_counts, _displ(self.send_counts), MPI.INT64_T],
                       [self.recv_rows, self.recv_counts, _displ(self.recv_counts), MPI.INT64_T])
        self.nrows = int(rset.whole_rows.size)

    def add(self, parts: np.ndarray) -> np.ndarray:
        """The owned rows' sums of every rank's parts (``parts``: this rank's, per whole
        relation row)."""
        got = np.empty(self.recv_rows.size)
        self.comm.Alltoallv([np.ascontiguousarray(parts[self.send_rows]), self.send_counts,
                             _displ(self.send_counts), MPI.DOUBLE],
                            [got, self.recv_counts, _displ(self.recv_counts), MPI.DOUBLE])
        return np.bincount(self.recv_rows, weights=got, minlength=self.nrows)


class _Fetched:
    """The A entries of a relation built per rank on DOFs this rank does not own (a tie's
    u_b): their places and the plan of their values (``Fetch``)."""

    def __init__(self, at: np.ndarray, fetch: Fetch):
        self.at, self.fetch = at, fetch

    @classmethod
    def plan(cls, dofmap: DofMap, r: Relation) -> "_Fetched | None":
        """None when no rank has such entries. Collective."""
        sel, _ = dofmap.owned_dof_entries(r.a_dofs)
        at = np.setdiff1d(np.arange(r.a_dofs.size), sel)
        if dofmap.comm.size == 1 or not dofmap.comm.allreduce(bool(at.size), op=MPI.LOR):
            return None
        return cls(at, Fetch.of(dofmap, dofmap.input_new_dof(r.a_dofs[at])))

    def add(self, part: np.ndarray, r: Relation, q: np.ndarray) -> np.ndarray:
        part += np.bincount(r.a_rows[self.at], weights=r.a_vals[self.at] * self.fetch(q),
                            minlength=r.nrows)
        return part


def _displ(counts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)


class RelationMultipliers(Mapping):
    """Unscaled λ of a relation's rows by its name, fetched from the rows' owners (one
    reduction of the relation's size) the first time it is read: only the relations a reader
    reads cross the ranks. Reading is collective: every rank reads the same names in the
    same order (the readers decide alike on every rank)."""

    def __init__(self, rset: RelationSet, lam: np.ndarray):
        self._rset, self._lam = rset, lam
        self._index = {r.name: k for k, r in enumerate(rset.relations)}
        self._read: dict[str, np.ndarray] = {}

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._read:
            self._read[name] = self._rset.relation_values(self._index[name], self._lam)
        return self._read[name]

    def __iter__(self):
        return iter(self._index)

    def __len__(self) -> int:
        return len(self._index)
