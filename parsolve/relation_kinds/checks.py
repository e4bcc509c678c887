"""The scene's relations checked as a set (a DOF fixed twice, a tie given twice or held at both
ends, a control pattern acting only on held DOFs), collective over rows spread on the ranks: a
row held per rank is looked at where it is held, a spread relation's entries where they are
held (its rows' entry counts summed), a whole relation's rows (the same on every rank) on
rank 0 alone, and the rows meet at the rank looking after their DOF
(``spread.blocks``). Every decision is summed or gathered over the ranks before it raises (the
same error on every rank) or drops rows (a per-rank relation's rows then numbered again)."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsolve import relations as rel
from parsolve.errors import InputError
from parsolve.relation_kinds.registry import RELATIONS
from parsolve.relation_kinds.spread import Directory, ask, blocks, places

# a single-DOF equality row as sent to its DOF's rank: its DOF, its value (over its
# coefficient), its relation, its evolution (numbered by first appearance), whether it is
# associated and of a kind that holds DOFs
SINGLE = np.dtype([("dof", np.int64), ("value", np.float64), ("rel", np.int32),
                   ("evol", np.int32), ("assoc", np.bool_), ("holds", np.bool_)])


def check_set(relations: list[rel.Relation], specs: list, fields, source: str, comm,
              space: int) -> list[rel.Relation]:
    """The relations with the rows the checks drop (a DOF fixed twice to one value, a tie
    between two DOFs held at one value), or the checks' InputError on every rank; ``space``:
    the whole mesh's DOFs. Collective."""
    singles = Singles(comm, relations, space)
    relations = _drop(comm, relations, singles.repeated())
    _check_repeated_ties(comm, relations, fields, source, space)
    relations = _drop_held_ties(comm, relations, singles, source)
    _check_duals(comm, relations, specs, singles, source)
    singles.raise_duplicates(fields, source)
    return relations


def _kind(r: rel.Relation, flag: str) -> bool:
    """Whether a relation of the scene is of a kind with that flag (``RelationEntry``)."""
    entry = RELATIONS.get(r.meta.get("type"))
    return entry is not None and getattr(entry, flag)


def _here(comm, r: rel.Relation) -> bool:
    """Whether this rank looks at the relation's rows: its own, a spread relation's entries
    held here, or a whole relation's on rank 0."""
    return not r.whole or r.spread or comm.rank == 0


def _floats(column: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(column).view(np.float64)


class Singles:
    """The single-DOF equality rows of the relations, each at the rank looking after its DOF
    (in ``got``, by DOF then relation): a DOF fixed twice is found there, and a DOF is asked
    there whether it is held."""

    def __init__(self, comm, relations: list, space: int):
        self.comm, self.space, self.relations = comm, space, relations
        evolutions, parts, self.rel, self.row = [], [], [], []
        for k, r in enumerate(relations):
            if r.evolution not in evolutions:
                evolutions.append(r.evolution)
            if r.sense != "=" or not _here(comm, r):
                continue
            counts = np.bincount(r.a_rows, minlength=r.nrows)
            if r.spread:   # (its rows' entries over every rank: the same relations on each)
                comm.Allreduce(MPI.IN_PLACE, counts)
            at = np.flatnonzero(counts[r.a_rows] == 1)
            rows = np.empty(at.size, dtype=SINGLE)
            rows["dof"], rows["rel"], rows["evol"] = r.a_dofs[at], k, evolutions.index(r.evolution)
            with np.errstate(divide="ignore", invalid="ignore"):
                rows["value"] = r.values[r.a_rows[at]] / r.a_vals[at]
            rows["assoc"], rows["holds"] = r.associated, _kind(r, "holds")
            parts.append(rows)
            self.rel.append(k)
            self.row.append(r.a_rows[at])   # (where the answers about them go)
        sent = np.concatenate(parts) if parts else np.zeros(0, dtype=SINGLE)
        self.directory = Directory(comm, sent, blocks(sent["dof"], space, comm.size))
        del sent
        got, self.directory.got = self.directory.got, None
        self.order = np.lexsort((got["rel"], got["dof"]))   # stable: then the rows' order
        self.got = got[self.order]
        del got
        self.alive = np.ones(len(self.got), dtype=bool)

    def repeated(self) -> dict[int, np.ndarray]:
        """A DOF fixed twice to the same value (two Dirichlet conditions meeting at a corner,
        the same value and evolution) keeps the first relation's row only: per relation, the
        rows it loses (a mask on its rows looked at here)."""
        at = np.flatnonzero(self.got["assoc"])
        dof, value, evol, k = (self.got[f][at] for f in ("dof", "value", "evol", "rel"))
        same = (dof[1:] == dof[:-1]) & (value[1:] == value[:-1]) & (evol[1:] == evol[:-1]) \
            & (k[1:] != k[:-1])
        self.alive[at[1:][same]] = False
        answers = np.empty(len(self.got), dtype=bool)
        answers[self.order] = ~self.alive
        lost = self.directory.reply(answers)
        out, start = {}, 0
        for k, row in zip(self.rel, self.row):   # a loop over relations, not rows
            gone = lost[start:start + row.size]
            start += row.size
            if gone.any():
                mask = np.zeros(self.relations[k].nrows, dtype=bool)
                mask[row[gone]] = True
                out[k] = mask
        return out

    def _held(self, flag: str) -> np.ndarray:
        return self.got[self.alive & self.got[flag]]

    def held(self, dofs: np.ndarray) -> np.ndarray:
        """Per DOF: (held by an associated row, its value's bits, its evolution), the first
        relation's row where several hold it. Collective."""
        held = self._held("assoc")

        def answer(got: np.ndarray) -> np.ndarray:
            pos = np.minimum(np.searchsorted(held["dof"], got), max(len(held) - 1, 0))
            out = np.zeros((got.size, 3), dtype=np.int64)
            if len(held):
                out[:, 0] = held["dof"][pos] == got
                out[:, 1] = held["value"][pos].view(np.int64)
                out[:, 2] = held["evol"][pos]
            return out

        return ask(self.comm, dofs, blocks(dofs, self.space, self.comm.size), answer)

    def holders(self, dofs: np.ndarray) -> tuple[int, list[int]]:
        """(how many of ``dofs`` no Dirichlet row holds, the relations holding any of them),
        over every rank. Collective."""
        held = self._held("holds")
        got = Directory(self.comm, dofs, blocks(dofs, self.space, self.comm.size)).got
        on = np.isin(got, held["dof"])
        free = self.comm.allreduce(int(np.count_nonzero(~on)))
        mine = np.unique(held["rel"][np.isin(held["dof"], got)]).tolist()
        return free, sorted(set().union(*self.comm.allgather(mine)))

    def raise_duplicates(self, fields, source: str) -> None:
        """Two single-DOF equality rows left on one DOF (different values, or one relation
        fixing it twice) would make the system singular: refused, naming both relations."""
        dof, k = self.got["dof"][self.alive], self.got["rel"][self.alive]
        dup = np.flatnonzero(dof[1:] == dof[:-1])
        first = (int(dof[dup[0]]), int(k[dup[0]]), int(k[dup[0] + 1])) if dup.size else None
        count = self.comm.allreduce(int(dup.size))
        if not count:
            return
        dof, a, b = min(f for f in self.comm.allgather(first) if f is not None)
        a, b = self.relations[a].name, self.relations[b].name
        node, comp = divmod(dof, fields.ncomp)
        what = f"relations {a!r} and {b!r} both fix" if a != b else f"relation {a!r} fixes twice"
        raise InputError(f"redundant relations: {what} {_label(fields, comp)} at node {node} "
                         f"({count} such DOFs); the system would be singular", source,
                         "relations")


def _label(fields, comp: int) -> str:
    """The field and component name of a DOF's component number (``displacement.x``)."""
    field = next(f for f in fields if comp in fields.columns(f.name))
    return f"{field.name}.{field.components[comp - fields.offset[field.name]]}".rstrip(".")


def _drop(comm, relations: list, drop: dict[int, np.ndarray]) -> list:
    """The relations without the rows ``drop`` names (per relation, a mask on the rows looked
    at here: a whole relation's on rank 0, sent to every rank); a per-rank relation's rows
    numbered again in the same order. Collective."""
    counts = np.zeros(len(relations), dtype=np.int64)
    for k, mask in drop.items():
        counts[k] = np.count_nonzero(mask)
    comm.Allreduce(MPI.IN_PLACE, counts)
    whole = comm.bcast({k: m for k, m in drop.items()
                        if relations[k].whole and not relations[k].spread}
                       if comm.rank == 0 else None, root=0)
    out = list(relations)
    for k in np.flatnonzero(counts):   # a loop over relations, not rows
        r = relations[k]
        if r.spread:   # (each rank's mask on the rows of the entries it holds)
            mask = drop.get(k, np.zeros(r.nrows, dtype=bool)).astype(np.uint8)
            comm.Allreduce(MPI.IN_PLACE, mask, op=MPI.MAX)
            out[k] = rel.keep_rows(r, mask == 0)
            continue
        if r.whole:
            out[k] = rel.keep_rows(r, ~whole[k])
            continue
        keep = ~drop.get(k, np.zeros(r.nrows, dtype=bool))
        ids = r.ids[keep]
        out[k] = rel.rows_here(rel.keep_rows(r, keep), places(comm, ids, r.size),
                               r.size - int(counts[k]))
    return out


def _tie_ends(r: rel.Relation) -> tuple[np.ndarray, np.ndarray]:
    """Per row of a tie u_a − u_b: (u_a's DOF, u_b's DOF)."""
    ends = []
    for side in (r.a_vals > 0, r.a_vals < 0):
        d = np.full(r.nrows, -1, dtype=np.int64)
        d[r.a_rows[side]] = r.a_dofs[side]
        ends.append(d)
    return ends[0], ends[1]


def _check_repeated_ties(comm, relations: list, fields, source: str, space: int) -> None:
    """The same pair of DOFs tied twice (one periodic relation given twice, or both ways:
    region and target swapped) makes the system singular: refused, naming both relations.
    The pairs meet at the rank looking after their lower DOF."""
    ties = [k for k, r in enumerate(relations) if _kind(r, "ties") and not r.spread]
    if not ties:
        return
    parts = [np.zeros((0, 3), dtype=np.int64)]
    for k in ties:
        r = relations[k]
        if _here(comm, r):
            pairs = np.sort(np.stack(_tie_ends(r), axis=1), axis=1)
            parts.append(np.column_stack([pairs, np.full(r.nrows, k)]))
    table = np.concatenate(parts)
    got = Directory(comm, table, blocks(table[:, 0], space, comm.size)).got
    got = got[np.lexsort((got[:, 2], got[:, 1], got[:, 0]))]
    again = np.flatnonzero((got[1:, :2] == got[:-1, :2]).all(axis=1))
    first = tuple(int(v) for v in got[again[0], :3]) + (int(got[again[0] + 1, 2]),) \
        if again.size else None
    count = comm.allreduce(int(again.size))
    if not count:
        return
    dof_a, dof_b, k1, k2 = min(f for f in comm.allgather(first) if f is not None)
    first, second = relations[k1], relations[k2]
    node_a, comp = divmod(dof_a, fields.ncomp)
    both = f"relations {first.name!r} and {second.name!r} both tie" if k1 != k2 \
        else f"relation {first.name!r} ties twice"
    raise InputError(f"repeated periodic tie: {both} {_label(fields, comp)} of nodes {node_a} "
                     f"and {dof_b // fields.ncomp} ({count} such pairs; a tie given twice, or "
                     "both ways); the system would be singular: give each tie once", source,
                     second.meta["key"])


def _drop_held_ties(comm, relations: list, singles: Singles, source: str) -> list:
    """A periodic row between two DOFs that Dirichlet rows both hold (the corners of a cell
    whose top and bottom are held) would constrain nothing and make the system singular: it
    is dropped when the two held values agree (same value and evolution: the tie holds by
    itself), an input error when they do not. Each end asked where its DOF is looked after."""
    ties = [k for k, r in enumerate(relations) if _kind(r, "ties") and not r.spread]
    if not ties:
        return relations
    ends = {k: _tie_ends(relations[k]) if _here(comm, relations[k])
            else (np.zeros(0, np.int64),) * 2 for k in ties}
    asked = np.concatenate([np.concatenate(ends[k]) for k in ties])
    answers = singles.held(asked)
    drop, at = {}, 0
    for k in ties:   # a loop over relations, not rows
        r, n = relations[k], ends[k][0].size
        a, b = answers[at:at + n], answers[at + n:at + 2 * n]
        at += 2 * n
        both = (a[:, 0] == 1) & (b[:, 0] == 1)
        clash = both & ((_floats(a[:, 1]) != _floats(b[:, 1])) | (a[:, 2] != b[:, 2]))
        count = comm.allreduce(int(np.count_nonzero(clash)))
        if count:
            row = int(np.argmax(clash)) if clash.any() else None
            first = None if row is None else (int(r.row_ids()[row]), int(ends[k][0][row]))
            dof = min(f for f in comm.allgather(first) if f is not None)[1]
            raise InputError(f"a tied pair is held by conditions of different values (DOF "
                             f"{dof} and its partner, {count} such rows): the tie contradicts "
                             "them", source, r.meta["key"] + ".region")
        if comm.allreduce(int(np.count_nonzero(both))) == r.total:
            raise InputError("every tied DOF is held by other conditions: the tie constrains "
                             "nothing", source, r.meta["key"] + ".region")
        if both.any():
            drop[k] = both
    return _drop(comm, relations, drop)


def _check_duals(comm, relations: list, specs: list, singles: Singles, source: str) -> None:
    """A control relation's multiplier drives its load pattern; a pattern acting only on DOFs
    that Dirichlet relations hold is taken by their reactions, leaves the multiplier nothing
    to drive, and the system is singular (MUMPS null pivot): refuse it before any solve."""
    keys = {spec.name: spec.key for spec in specs}
    for r in relations:   # a loop over relations, not rows
        if r.shared_dual is None:
            continue
        dofs, vals = r.shared_dual   # (this rank's part of the pattern: its owned DOFs)
        acting = dofs[vals != 0]
        free, holders = singles.holders(acting)
        if comm.allreduce(int(acting.size)) and free == 0:
            names = sorted(relations[k].name for k in holders)
            raise InputError(f"load pattern {r.meta['dual']!r} acts only on DOFs that "
                             f"{', '.join(map(repr, names))} already hold: the control "
                             "multiplier would drive nothing (singular system)",
                             source, keys.get(r.name, "relations") + ".dual")
