"""Relation rows spread over the ranks, numbered and checked without an array of the whole set
on any rank: a key (a DOF, a node, a row number) is looked after by the rank of its block of
the key space (``blocks``), which answers for it (``Directory``, ``ask``), and a row's place
among every rank's rows is its key's place among every rank's keys (``places``). A spread
relation's entries go to the ranks owning their DOFs (``to_owners``; an input node's owner
found where its id is looked after, ``node_owners``)."""

from __future__ import annotations

from typing import Callable

import numpy as np

from parsolve.mesh.blocks import exchange, rank_order


def blocks(keys: np.ndarray, space: int, size: int) -> np.ndarray:
    """The rank looking after each key of ``[0, space)``: near-equal blocks of the space."""
    return (np.asarray(keys, dtype=np.int64) * size // max(int(space), 1)).clip(0, size - 1)


class Directory:
    """Rows sent to the ranks ``dest`` (one ``exchange``): ``got`` is what this rank was sent
    (in (source rank, row order)); ``reply`` sends an answer per row got back to its sender,
    in the order the sender gave its rows."""

    def __init__(self, comm, rows: np.ndarray, dest: np.ndarray):
        self.comm, self.order = comm, rank_order(dest, comm.size)
        self.got, self.counts = exchange(comm, rows, dest)

    def reply(self, answers: np.ndarray) -> np.ndarray:
        senders = np.repeat(np.arange(self.comm.size), self.counts)
        back, _ = exchange(self.comm, np.asarray(answers), senders)
        out = np.empty_like(back)
        out[self.order] = back
        return out


def ask(comm, rows: np.ndarray, dest: np.ndarray,
        answer: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """``answer`` (run on every rank, on the rows it was sent; collective calls allowed) of
    each row, back where the row was asked, in its order."""
    directory = Directory(comm, rows, dest)
    return directory.reply(answer(directory.got))


def places(comm, keys: np.ndarray, space: int) -> np.ndarray:
    """Each key's place (from 0) among every rank's keys sorted (keys of ``[0, space)``; a
    repeated key takes places in rank order). Collective; two exchanges and a scan."""
    keys = np.asarray(keys, dtype=np.int64)

    def answer(got: np.ndarray) -> np.ndarray:
        start = comm.exscan(int(got.size)) if comm.size > 1 else 0
        out = np.empty(got.size, dtype=np.int64)
        out[np.argsort(got, kind="stable")] = (start or 0) + np.arange(got.size)
        return out

    return ask(comm, keys, blocks(keys, space, comm.size), answer)


#: a sum of entries at most this fraction of its terms' size is round-off of a cancellation
CANCELLED = 1e-12

# a relation entry on its way to the rank owning its DOF: its row, its input DOF, its
# coefficient
ENTRY = np.dtype([("row", np.int64), ("dof", np.int64), ("coef", np.float64)])


def to_owners(comm, rows: np.ndarray, dofs: np.ndarray, coefs: np.ndarray,
              owners: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Entries (row, input DOF, coefficient) sent to the ranks ``owners`` (each DOF's owner),
    where those of one (row, DOF) add up: this rank's entries, by row then DOF (a spread
    relation's entries, ``Relation.spread``). A sum that cancels to round-off of its terms (a
    region's inner node in its mean strain) is dropped: whatever order the ranks add the
    terms in, the same entries. Collective; one exchange."""
    sent = np.empty(np.asarray(rows).size, dtype=ENTRY)
    sent["row"], sent["dof"], sent["coef"] = rows, dofs, coefs
    got, _ = exchange(comm, sent, np.asarray(owners, dtype=np.int64))
    order = np.lexsort((got["dof"], got["row"]))
    got = got[order]
    start = np.flatnonzero(np.concatenate([[True], (got["row"][1:] != got["row"][:-1])
                                           | (got["dof"][1:] != got["dof"][:-1])])) \
        if got.size else np.zeros(0, dtype=np.int64)
    coef = np.add.reduceat(got["coef"], start) if got.size else np.zeros(0)
    size = np.add.reduceat(np.abs(got["coef"]), start) if got.size else np.zeros(0)
    keep = np.abs(coef) > CANCELLED * size
    return got["row"][start][keep], got["dof"][start][keep], coef[keep]


class NodeOwners:
    """The rank owning each input node, found where its block of ids is looked after: every
    rank's owned ids registered there once (its own ids' size, not the mesh's), each lookup
    one ``ask``. Collective to make and to use."""

    def __init__(self, comm, owned: np.ndarray, space: int):
        owned = np.asarray(owned, dtype=np.int64)
        directory = Directory(comm, owned, blocks(owned, space, comm.size))
        rank = np.repeat(np.arange(comm.size, dtype=np.int64), directory.counts)
        order = np.argsort(directory.got, kind="stable")
        self.ids, self.rank = directory.got[order], rank[order]
        self.comm, self.space = comm, int(space)

    def __call__(self, nodes: np.ndarray) -> np.ndarray:
        nodes = np.asarray(nodes, dtype=np.int64)
        return ask(self.comm, nodes, blocks(nodes, self.space, self.comm.size), self._answer)

    def _answer(self, got: np.ndarray) -> np.ndarray:
        pos = np.minimum(np.searchsorted(self.ids, got), max(self.ids.size - 1, 0))
        return self.rank[pos] if self.ids.size else np.zeros(got.size, dtype=np.int64)


def node_owners(comm, nodes: np.ndarray, owned: np.ndarray, space: int) -> np.ndarray:
    """The rank owning each input node of ``nodes`` (``owned``: this rank's owned input ids,
    ``space``: the mesh's nodes). Collective."""
    return NodeOwners(comm, owned, space)(nodes)
