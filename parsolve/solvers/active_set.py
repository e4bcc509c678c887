"""The active set of unilateral relations: which rows are enforced as equalities.

Written once for every unilateral use (control by a maximum, contact, friction, solubility).
A row of sign s (+1 for "<=", -1 for ">=") is admissible when s (A q - b) <= 0. An inactive
row that is violated becomes active; an active row whose multiplier has the wrong sign
(s o λ < 0: the relation would pull instead of push) becomes inactive. The orientation o is +1
for associated rows (D = -Aᵀ: a positive s λ pushes back); a non-associated row's dual may
point either way, so o = -sign(A K⁻¹ D) from the row's own response. Rows of a *maximum*
relation work as a group: exactly one, the one with the largest s (A q - b), is enforced (the
paper's "maximum of several controlled quantities"). A maximum group never goes back, within
one step, to a row it has left: that is the most loaded element changing back and forth where
damage localizes, which a full Newton step cannot follow (its iterates wander from cell to cell
until whole cells are fully damaged and the tangent is singular); the step fails at once, with
that reason, and the stepper cuts it. Any other set that comes back after having been left is
cycling: the update then changes one row (or one group's row) at a time, the most violated,
and gives up after a bounded number of changes.

Across ranks, every rank holds the set's part on the rows it holds (a mask of the relation
rows) and decides the rows it owns (``owned``: those whose multiplier row it owns, and the
rows of a maximum group it holds). What a multiplier decides — a row whose reaction pulls —
is decided by the row's owner, and the rows so found (few: the changes) are exchanged, with
their scores; the rest (violated rows, cycling, the bound) is decided from the gaps, alike
on every rank. A relation built per rank (``Relation.ids``: solubility's nodes) has its
local groups on the rank building them, each whole there: that rank alone decides them. A
maximum group spans the ranks (a per-cell strain: each cell's row on the rank counting it):
it is decided by reductions of the groups' number (``choose``: each rank its rows' best
score, the largest over the ranks; the rows tied with it, the enforced one kept if among
them, else the lowest row number of them), no rank holding another's rows.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve.errors import SolverError
from parsolve.relations import Relation
from parsolve.solvers.diagnose import GoingBack


#: Relative tolerance within which rows of a maximum group are tied (see ``ActiveSet.choose``).
GROUP_TOL = 1e-7
#: The same for groups of a few local rows (solubility's two states of a node).
LOCAL_TIE = 1e-12
#: A contact zone forming closes the rows penetrating by at least this fraction of the deepest.
FORMING = 0.5


class _Seen:
    """The sets an update has been through (each rank its rows' part, added in the same
    order on every rank): a set was seen when every rank's part was, at one same time.
    Membership is collective."""

    def __init__(self, comm: MPI.Comm, first: bytes | None = None):
        self.comm, self.parts = comm, [] if first is None else [first]

    def add(self, part: bytes) -> None:
        self.parts.append(part)

    def __contains__(self, part: bytes) -> bool:
        here = np.array([p == part for p in self.parts], dtype=np.uint8)
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, here, op=MPI.MIN)
        return bool(here.any())


class ActiveSet:
    """The set of the rows of ``relations`` (concatenated) enforced now. ``owned``: the rows
    whose multipliers this rank reads (default every row: one process); ``comm``: the ranks
    deciding together (default this process alone)."""

    def __init__(self, relations: list[Relation], max_changes: int = 30,
                 owned: np.ndarray | None = None, comm: MPI.Comm | None = None):
        sizes = [r.nrows for r in relations]
        self.sign = np.concatenate([np.full(r.nrows, r.sign) for r in relations]) \
            if relations else np.zeros(0, dtype=np.int64)
        first = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        # local groups (a relation's ``groups``: contiguous runs of rows on one rank), with a
        # round-off wide tie (solubility: a node exactly at saturation)
        group = np.full(self.sign.size, -1, dtype=np.int64)
        count = 0
        for k, r in enumerate(relations):
            if r.groups is not None and not r.maximum:
                group[first[k]:first[k + 1]] = count + np.asarray(r.groups, dtype=np.int64)
                count += int(np.max(r.groups)) + 1 if r.nrows else 0
        self.group = group
        self.local_rows = np.flatnonzero(group >= 0)
        self.local_starts = np.flatnonzero(np.diff(np.concatenate([[-1], group[group >= 0]])))
        # whether some relation has local groups (on any rank: a relation built per rank may
        # have none here, and deciding them is collective)
        self._grouped = any(r.groups is not None and not r.maximum for r in relations)
        # the maximum groups (one per maximum relation, over the ranks): their relations, the
        # rows held here (for the per-step predictor), those rows' numbers in the relation
        self.group_relations = [k for k, r in enumerate(relations) if r.maximum]
        self.groups = [np.arange(first[k], first[k + 1]) for k in self.group_relations]
        self.group_ids = [relations[k].row_ids() for k in self.group_relations]
        self.maximum = np.concatenate([np.full(r.nrows, r.maximum) for r in relations]) \
            if relations else np.zeros(0, dtype=bool)
        self.names, self.first = [r.name for r in relations], first
        # rows of whole relations (every rank holds them, alike) and each row's place in the
        # relations' rows over every rank (relation, then global row): what ranks exchange
        self.shared = np.concatenate([np.full(r.nrows, r.whole) for r in relations]) \
            if relations else np.zeros(0, dtype=bool)
        totals = np.concatenate([[0], np.cumsum([r.total for r in relations])]).astype(np.int64)
        self.key = np.concatenate([totals[k] + r.row_ids() for k, r in enumerate(relations)]) \
            if relations else np.zeros(0, dtype=np.int64)
        self.totals = totals
        self.whole_relation = np.array([r.whole for r in relations], dtype=bool)
        self.free = (self.sign != 0) & (group < 0) & ~self.maximum   # rows decided one by one
        self.active = self.sign == 0              # equalities are always enforced
        # a group is always enforced somewhere: its first row
        self.active[self.local_rows[self.local_starts]] = True
        for g, ids in zip(self.groups, self.group_ids):
            self.active[g[ids == 0]] = True
        # +1 where a positive s·λ pushes the row back to its admissible side (associated rows);
        # non-associated rows get theirs from their own response (``RelationPolicies.orient``)
        self.orient = np.ones(self.sign.size)
        # rows that say a zone of them may form (contact): the most penetrating close first
        self.forming = np.concatenate([np.full(r.nrows, r.forming) for r in relations]) \
            if relations else np.zeros(0, dtype=bool)
        self.owned = np.ones(self.sign.size, dtype=bool) if owned is None else owned
        self.comm = MPI.COMM_SELF if comm is None else comm
        self.max_changes = max_changes
        self.changes = 0
        self.seen = _Seen(self.comm)
        self.held = self.active.copy()
        self._unilateral = any(r.sign != 0 for r in relations)
        self.forming_relations = [k for k, r in enumerate(relations) if r.forming]

    @property
    def unilateral(self) -> bool:
        """Whether some relation has unilateral rows (on any rank: a relation built per rank
        may have none here)."""
        return self._unilateral

    def start_step(self) -> None:
        self.changes = 0
        self.seen = _Seen(self.comm, self.active.tobytes())
        self.held = self.active.copy()  # rows enforced at some point of this step

    def update(self, gap: np.ndarray, lam: np.ndarray, tol_gap: float, tol_lam: float,
               scale: float | None = None) -> bool:
        """Update from the current A q - b (gap) and multipliers, both read on the ``owned``
        rows only; True when the set changed. ``scale``: the size of the rows' values (A q,
        b), for the ties of maximum groups. Collective."""
        scale = tol_gap / 1e-9 if scale is None else scale
        s = self.sign
        mine = self.owned
        new = self.active.copy()
        excess = s * gap
        violated = self._forming(mine & self.free & ~self.active & (excess > tol_gap), excess)
        violated, excess = self._everywhere(violated, excess)
        pull = -s * self.orient * lam
        wrong_sign, pull = self._everywhere(mine & self.free & self.active & (pull > tol_lam), pull)
        new[violated] = True
        new[wrong_sign] = False
        gain = np.full(self.sign.size, -np.inf)
        if self._grouped:
            rows = self.local_rows
            best, gain[rows] = self._groups(s[rows] * gap[rows], LOCAL_TIE * scale)
            new[rows] = best
        if self.groups:
            self._maxima(new, gain, s * gap, GROUP_TOL * scale)
        if self._same(new):
            return False
        if new.tobytes() in self.seen:  # cycling: change only the worst row
            new = self._one_change(excess, pull, gain)
        self.changes += 1
        if self.changes > self.max_changes:
            raise SolverError(f"active set did not settle after {self.max_changes} changes "
                              f"({int(self.active.sum())} active rows)")
        self.active = new
        self.held |= new
        self.seen.add(new.tobytes())
        return True

    def _same(self, new: np.ndarray) -> bool:
        """Whether no rank's rows change. Collective."""
        same = bool(np.array_equal(new, self.active))
        return same if self.comm.size == 1 else self.comm.allreduce(same, op=MPI.LAND)

    def _maxima(self, new: np.ndarray, gain: np.ndarray, value: np.ndarray, tol: float) -> None:
        """The maximum groups' rows to enforce (``choose`` on their values s (A q - b)) into
        ``new``, and, on the rows they move to, how far those exceed the row enforced now
        (``gain``), in place; a group going back to a row it left in this step fails it
        (``_no_way_back``). Collective."""
        mine = [self.owned[g] for g in self.groups]
        scores = [np.where(m, value[g], -np.inf) for g, m in zip(self.groups, mine)]
        current = np.array([s[self.active[g]].max(initial=-np.inf)
                            for g, s in zip(self.groups, scores)])
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, current, op=MPI.MAX)
        chosen = self.choose(scores, np.full(len(self.groups), tol))
        back = []
        for g, m, s, c, best in zip(self.groups, mine, scores, current, chosen):
            moved = m & best & ~self.active[g]
            gain[g[moved]] = s[moved] - c
            back.append(g[moved & self.held[g]])
            new[g] = best
        self._no_way_back(np.concatenate(back) if back else np.zeros(0, dtype=np.int64))

    def choose(self, scores: list[np.ndarray], tols: np.ndarray) -> list[np.ndarray]:
        """Per maximum group, the mask of its rows held here to enforce: the best (largest)
        finite score over every rank (``scores``: per group, its rows' here, -inf on the rows
        not decided here), rows within ``tols`` of it tied (tied rows of a symmetric problem
        differ by the solution's round-off, which grows with the tangent's conditioning past a
        peak and changes with the partition); among them the enforced row stays, otherwise
        the lowest row number is taken: a rule that round-off cannot change. Two reductions
        of the groups' number. Collective."""
        n = len(self.groups)
        top = np.array([s[np.isfinite(s)].max(initial=-np.inf) for s in scores])
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, top, op=MPI.MAX)
        tied = [np.isfinite(s) & (s >= t - tol) for s, t, tol in zip(scores, top, tols)]
        # (-1 where the enforced row is tied, then the lowest tied row's number: one minimum)
        keep_low = np.full(2 * n, np.iinfo(np.int64).max, dtype=np.int64)
        for j, (g, ids, t) in enumerate(zip(self.groups, self.group_ids, tied)):
            keep_low[j] = -1 if (t & self.active[g]).any() else 0
            keep_low[n + j] = ids[t].min(initial=np.iinfo(np.int64).max)
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, keep_low, op=MPI.MIN)
        return [self.active[g].copy() if keep_low[j] < 0 else ids == keep_low[n + j]
                for j, (g, ids) in enumerate(zip(self.groups, self.group_ids))]

    def _groups(self, value: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
        """Each local group's row to enforce (``pick_groups``, decided by the group's owner
        from its rows' values s (A q - b)) and, on the rows it moves to, how far they exceed
        the row enforced now (-inf elsewhere), over ``local_rows``, on every rank.
        Collective."""
        rows, starts = self.local_rows, self.local_starts
        mine = self.owned[rows]
        best = self.pick_groups(value, self.active[rows], tol)
        sizes = np.diff(np.concatenate([starts, [rows.size]]))
        enforced = np.where(self.active[rows], value, -np.inf)
        current = np.repeat(np.maximum.reduceat(enforced, starts), sizes)
        _, gain = self._everywhere(mine & best & ~self.active[rows], value - current)
        best, _ = self._everywhere(mine & best, value)
        return best, gain

    def _everywhere(self, mine: np.ndarray, score: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rows every rank found (``mine``: this rank's) and their scores (-inf on the
        other rows), on every rank: the rows found are exchanged (as many as there are),
        nothing else. Collective."""
        if self.comm.size == 1:
            return mine, np.where(mine, score, -np.inf)
        # a relation built per rank: its rows are this rank's alone, nothing to tell (the
        # arrays: over every row, or over ``local_rows``)
        shared = self.shared if mine.size == self.shared.size else self.shared[self.local_rows]
        shared_rows = np.flatnonzero(shared)
        found = mine & ~shared
        out = np.where(found, score, -np.inf)
        rows = np.searchsorted(shared_rows, np.flatnonzero(mine & shared)).astype(np.int64)
        counts = np.array(self.comm.allgather(rows.size), dtype=np.int64)
        every = np.empty(int(counts.sum()), dtype=np.int64)
        values = np.empty(every.size)
        self.comm.Allgatherv(rows, [every, counts])
        self.comm.Allgatherv(np.ascontiguousarray(score[shared_rows[rows]], dtype=float),
                             [values, counts])
        found[shared_rows[every]] = True
        out[shared_rows[every]] = values
        return found, out

    def _forming(self, violated: np.ndarray, excess: np.ndarray) -> np.ndarray:
        """The violated rows to close (``violated``: this rank's). A contact zone forming
        (more rows of a contact relation violated than enforced: a body meeting another, all
        its penetrating nodes found by a solve that did not know the contact) closes only the
        rows penetrating by at least FORMING × the deepest: closing every penetrating node
        makes a zone about 1.5× too wide (the first solve moves the body as if nothing were
        there), which the wrong-sign rule then shrinks by halving its excess per iteration (a
        number of iterations that grows with the surface's refinement). The zone then grows,
        if it must, by the plain rule (every violated row) from the next iteration on. Per
        forming relation, its violated rows' count and deepest excess are reduced over the
        ranks. Collective."""
        # (by relation: a relation built per rank may have no row here)
        spans = [slice(self.first[k], self.first[k + 1]) for k in self.forming_relations]
        if not spans:
            return violated
        count = np.array([float(violated[rows].sum()) for rows in spans])
        deepest = np.array([float(excess[rows][violated[rows]].max(initial=-np.inf))
                            for rows in spans])
        enforced = np.array([float(self.active[rows].sum()) for rows in spans])
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, count, op=MPI.SUM)
            self.comm.Allreduce(MPI.IN_PLACE, deepest, op=MPI.MAX)
            # a relation built per rank: its enforced rows on every rank
            whole = self.whole_relation[self.forming_relations]
            per_rank = np.where(whole, 0.0, enforced)
            self.comm.Allreduce(MPI.IN_PLACE, per_rank, op=MPI.SUM)
            enforced = np.where(whole, enforced, per_rank)
        out = violated.copy()
        for rows, n, depth, on in zip(spans, count, deepest, enforced):
            if n > on:
                out[rows] = violated[rows] & (excess[rows] >= FORMING * depth)
        return out

    def _no_way_back(self, back: np.ndarray) -> None:
        """Fail the step when a maximum group would return to a row it left in this step
        (``back``: such rows held here, of any group): the first group with one, its lowest
        such row and its enforced row, by row numbers over every rank. Collective."""
        n, big = len(self.groups), np.iinfo(np.int64).max
        found = np.full(2 * n, big, dtype=np.int64)   # per group: the row left, the enforced
        for j, (g, ids) in enumerate(zip(self.groups, self.group_ids)):
            found[j] = ids[np.isin(g, back)].min(initial=big)
            found[n + j] = -ids[self.active[g] & self.owned[g]].max(initial=-big)
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, found, op=MPI.MIN)
        hit = np.flatnonzero(found[:n] < big)
        if hit.size == 0:
            return
        j = int(hit[0])
        name, row, now = self.names[self.group_relations[j]], int(found[j]), int(-found[n + j])
        raise GoingBack(f"maximum relation {name!r}: the enforced row would go back "
                        f"from row {now} to row {row}, which it "
                        "left during this step (the most loaded element changes back and "
                        "forth where damage localizes: the step is too large to follow it)",
                        name, (now, row))

    def enforced_ids(self) -> np.ndarray:
        """Per maximum group, its enforced row's number in its relation (-1: none), from
        the rank holding it: one reduction of the groups' number. Collective."""
        out = np.array([ids[self.active[g] & self.owned[g]].max(initial=-1)
                        for g, ids in zip(self.groups, self.group_ids)], dtype=np.int64)
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.MAX)
        return out

    def pick_groups(self, score: np.ndarray, active: np.ndarray, tol) -> np.ndarray:
        """The row of each local group to enforce (score and active over ``local_rows``):
        the best score, rows within ``tol`` of it tied; among them the enforced row stays,
        otherwise the lowest is taken. The new active mask of those rows."""
        starts = self.local_starts
        n = score.size
        sizes = np.diff(np.concatenate([starts, [n]]))
        top = np.repeat(np.maximum.reduceat(score, starts), sizes)
        tied = score >= top - tol
        keep = np.repeat(np.logical_or.reduceat(active & tied, starts), sizes)
        index = np.where(tied, np.arange(n), n)
        lowest = np.repeat(np.minimum.reduceat(index, starts), sizes)
        return np.where(keep, active & tied, np.arange(n) == lowest)

    def _one_change(self, score: np.ndarray, score_l: np.ndarray,
                    gain: np.ndarray) -> np.ndarray:
        """The single most needed change: a violated row on (``score``: s (A q - b) of the
        violated rows, -inf elsewhere), a wrong-sign row off (``score_l``: -s o λ of those
        rows), or a group's enforced row moved to its best row (``gain``: how far the best
        row exceeds the enforced one, -inf elsewhere). Groups must be
        candidates: a fallback that cannot move them would report a change at every
        iteration without making one, until the bound of changes fails the step whatever its
        residual. Every rank the same (the scores are exchanged)."""
        new = self.active.copy()
        kind, row, key = self._best([score, score_l, gain])
        if kind == 2 and key is not None:   # a maximum group: its rows on every rank
            k = int(np.searchsorted(self.totals, key, side="right") - 1)
            if k in self.group_relations:
                new[self.groups[self.group_relations.index(k)]] = False
        if row < 0:
            return new
        if kind == 0:
            new[row] = True
        elif kind == 1:
            new[row] = False
        else:
            if self.group[row] >= 0:
                new[self.group == self.group[row]] = False
            new[row] = True
        return new

    def _best(self, scores: list[np.ndarray]) -> tuple[int, int, int | None]:
        """The kind with the largest score over every rank (the first of equal ones), its
        row held here with that score, first in the relations' rows over every rank (-1: not
        held here, or no finite score) and that row's ``key`` (None: no finite score).
        Collective."""
        tops = np.array([x.max(initial=-np.inf) for x in scores])
        firsts = np.array([self.key[x == top].min(initial=np.iinfo(np.int64).max)
                           for x, top in zip(scores, tops)])
        if self.comm.size > 1:
            every = self.comm.allgather((tops, firsts))
            top_all = np.max([t for t, _ in every], axis=0)
            kind = int(np.argmax(top_all))
            first = min(f[kind] for t, f in every if t[kind] == top_all[kind])
            top = top_all[kind]
        else:
            kind = int(np.argmax(tops))
            top, first = tops[kind], firsts[kind]
        if not np.isfinite(top):
            return kind, -1, None
        at = np.flatnonzero(self.key == first)
        return kind, int(at[0]) if at.size else -1, int(first)
