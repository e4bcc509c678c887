"""Element matrices as the assembly receives them, cell-last.

Either *factored*: ``K_e[ij] = Σ_kl M[material][kl, ij] P[kl]`` with a geometric part
``P`` (d², nen, nen, nc) and constant material tensors ``M`` (nmat, d², d²) -- then the
material contraction can be done after summing over cells, on far fewer numbers -- or *full*:
the values (d², nen, nen, nc) themselves (a tangent that varies from point to point).

Either held (the arrays themselves) or *blocked*: a ``CellKernel`` that computes them for a
range of cells into a reused work array, so that a reduction or a product goes over cell
blocks of a bounded size (``BLOCK_BYTES`` of element values) and never holds every cell's
element matrices at once: the memory beside the matrix stays bounded whatever the mesh size,
and the first assembly does not pay page faults on a mesh-sized array.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np

BLOCK_BYTES = 4 << 20   # element values of one block of cells (a few MB: stays in cache-ish
#                         memory, small beside any matrix worth blocking for)


def block_cells(bytes_per_cell: int, budget: int | None = None) -> int:
    """Cells per block for element arrays of ``bytes_per_cell`` bytes a cell."""
    return max(1, int(BLOCK_BYTES if budget is None else budget) // max(int(bytes_per_cell), 1))


def cell_ranges(ncells: int, size: int) -> Iterator[slice]:
    """Consecutive blocks of at most ``size`` cells."""
    for start in range(0, ncells, size):
        yield slice(start, min(start + size, ncells))


class CellKernel:
    """Element arrays of a range of cells on demand: ``compute(cells, out)`` returns the
    (rows, nen, nen, len(cells)) values of the cells ``cells`` (a slice or an index array of
    the kernel's cells), written into ``out`` when it has that shape (the reused work array)."""

    def __init__(self, compute: Callable, ncells: int, rows: int, nen: int,
                 block: int | None = None):
        self.compute, self.ncells, self.rows, self.nen = compute, ncells, rows, nen
        self.block = block_cells(rows * nen * nen * 8) if block is None else max(int(block), 1)

    def blocks(self) -> Iterator[tuple[slice, np.ndarray]]:
        """(cells, values) block after block, the values in one work array reused."""
        work = None
        for sl in cell_ranges(self.ncells, self.block):
            n = sl.stop - sl.start
            if work is None or work.shape[-1] != n:
                work = np.empty((self.rows, self.nen, self.nen, n))
            yield sl, self.compute(sl, work)

    def all(self) -> np.ndarray:
        """Every cell's values at once (for callers that need them whole: small sets)."""
        return self.compute(slice(0, self.ncells), None)


SPAN_FACTOR = 8   # a block's slots are bincounted over their range when it is at most this
#                   many times their number (numbering that follows the mesh), else compressed


class ElementMatrices:
    """Element matrices of a set of cells, factored or full, held or blocked (see above)."""

    def __init__(self, values: np.ndarray | None = None, geometric: np.ndarray | None = None,
                 tensors: np.ndarray | None = None, cell_material: np.ndarray | None = None,
                 kernel: CellKernel | None = None):
        """``kernel``: computes the geometric part (with ``tensors``) or the full values
        (without) block by block, instead of ``geometric`` / ``values``."""
        self._values, self._geometric, self.kernel = values, geometric, kernel
        self.tensors, self.cell_material = tensors, cell_material
        # a term on a region's cells: which of the composition's cells these are, and their
        # slots (``Term.slots``); None: every cell, whose slots the reductions are given
        self.positions: np.ndarray | None = None
        self.slots: np.ndarray | None = None
        # a term on facets: its facets' nodes (k, nfn), its "cells" (None: cells)
        self.nodes: np.ndarray | None = None

    @property
    def factored(self) -> bool:
        return self.tensors is not None

    @property
    def values(self) -> np.ndarray | None:
        """Full values (d², nen, nen, nc); a blocked full form computes them all here."""
        if self._values is None and self.kernel is not None and not self.factored:
            return self.kernel.all()
        return self._values

    @property
    def geometric(self) -> np.ndarray | None:
        """Geometric part P; a blocked factored form computes it for every cell here."""
        if self._geometric is None and self.kernel is not None and self.factored:
            return self.kernel.all()
        return self._geometric

    def reduce(self, pair_slot: np.ndarray, npairs: int) -> np.ndarray:
        """Sum over cells into node-pair blocks: (d², npairs)."""
        if self.kernel is not None:
            return self._reduce_blocks(pair_slot, npairs)
        slots = _slots(pair_slot)
        if not self.factored:
            return _bincount_rows(slots, self._values.reshape(len(self._values), -1), npairs)
        P = self._geometric.reshape(len(self._geometric), -1)
        nmat = len(self.tensors)
        if nmat == 1:
            return self.tensors[0].T @ _bincount_rows(slots, P, npairs)
        out = np.zeros((self.tensors.shape[2], npairs))
        nen2 = P.shape[1] // len(self.cell_material)
        for m in range(nmat):  # weights zero outside the material keep one pass per material
            mask = np.tile(self.cell_material == m, nen2).astype(float)
            out += self.tensors[m].T @ _bincount_rows(slots, P * mask, npairs)
        return out

    def _reduce_blocks(self, pair_slot: np.ndarray, npairs: int) -> np.ndarray:
        """Block after block: element values of a block, summed into the node pairs its slots
        reach. One material: the geometric parts are summed and contracted once at the end
        (on the node pairs, fewer numbers than the cells'); several: each block contracted."""
        k = self.kernel
        one = self.factored and len(self.tensors) == 1
        rows = self.tensors.shape[2] if self.factored and not one else k.rows
        acc = np.zeros((rows, npairs))
        for sl, V in k.blocks():
            if self.factored and not one:
                V = contract(self.tensors, self.cell_material[sl], V)
            _accumulate(acc, pair_slot[:, :, sl], V.reshape(len(V), -1), npairs)
        return _left_multiply(self.tensors[0].T, acc) if one else acc

    def reduce_into(self, pair_slot: np.ndarray, npairs: int, target: "StiffnessTarget",
                    ci: np.ndarray, cj: np.ndarray, fac: float = 1.0,
                    first: np.ndarray | None = None) -> None:
        """Add ``fac`` × the node-pair sums of rows (ci[a], cj[b]) into the target's values,
        with no (d², npairs) array beside them: block sums go into a window over the pairs
        the blocks reach (a numbering that follows the mesh: a block's worth), flushed into
        the target as the blocks move on. One material: geometric parts summed, contracted
        when flushed (few numbers: the node pairs', not the cells'). ``first`` (per row): no
        value written there yet (assigned rather than added: nothing to zero first)."""
        one = self.factored and len(self.tensors) == 1
        M = fac * self.tensors[0].T if one else None
        ci, cj = np.asarray(ci), np.asarray(cj)
        if first is None:
            first = np.zeros(len(ci) * len(cj), dtype=bool)
        rows = _Rows(target, ci, cj, first)
        win = _Window(rows, npairs, M, 1.0 if one else fac)
        for sl, V in self._raw_blocks():
            if self.factored and not one:
                V = contract(self.tensors, self.cell_material[sl], V)
            win.add(pair_slot[:, :, sl], V.reshape(len(V), -1))
        win.flush_all()
        rows.finish(npairs)

    def _raw_blocks(self) -> Iterator[tuple[slice, np.ndarray]]:
        """(cells, geometric parts or full values) block after block (held: cut in blocks)."""
        if self.kernel is not None:
            yield from self.kernel.blocks()
            return
        held = self._geometric if self.factored else self._values
        for sl in cell_ranges(held.shape[-1], block_cells(held[..., :1].nbytes)):
            yield sl, held[..., sl]

    def block_values(self) -> Iterator[tuple[slice, np.ndarray]]:
        """(cells, full values of those cells) block after block (held: one block)."""
        if self.kernel is None:
            yield slice(0, None), full_values(self)
            return
        for sl, V in self.kernel.blocks():
            yield sl, (contract(self.tensors, self.cell_material[sl], V) if self.factored else V)

    @property
    def ncells(self) -> int:
        if self.kernel is not None:
            return self.kernel.ncells
        return (self._values if self._values is not None else self._geometric).shape[-1]


def contract(tensors: np.ndarray, cell_material: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Full values Σ_k M[material][k, m] P[k] (m, nen, nen, nc) of geometric parts P."""
    nmat, _, rows = tensors.shape
    if nmat == 1:
        return np.tensordot(tensors[0].T, P, axes=1)
    out = np.empty((rows,) + P.shape[1:])
    for m in np.unique(cell_material):  # one product per material present
        idx = np.flatnonzero(cell_material == m)
        out[..., idx] = np.tensordot(tensors[m].T, P[..., idx], axes=1)
    return out


def _left_multiply(M: np.ndarray, acc: np.ndarray, chunk: int = 1 << 16) -> np.ndarray:
    """M @ acc column chunk by column chunk, in place when M is square (no second array of
    the node pairs' size)."""
    out = acc if M.shape[0] == acc.shape[0] else np.empty((M.shape[0], acc.shape[1]))
    for s in range(0, acc.shape[1], chunk):
        out[:, s:s + chunk] = M @ acc[:, s:s + chunk]
    return out


class StiffnessTarget:
    """Where node-pair sums go: the operator's value array ``data``, entry (i, j) of pair p
    at ``starts[i, p] + j`` (the layout of ``la.petsc``'s stiffness slots)."""

    def __init__(self, data: np.ndarray, starts: np.ndarray):
        self.data, self.starts = data, starts


class _Rows:
    """Row k = (ci[k // len(cj)], cj[k % len(cj)]) of a part, as positions in the target.

    Rows ``first`` (no earlier part wrote their component pair) are not zeroed beforehand:
    pairs at and past ``done`` have not been written yet, so they are assigned (the gaps
    zeroed); the others are added to."""

    def __init__(self, target: StiffnessTarget, ci: np.ndarray, cj: np.ndarray,
                 first: np.ndarray):
        self.target, self.ci, self.cj, self.first = target, ci, cj, first
        self.done = 0

    def _pos(self, k: int, pairs) -> np.ndarray:
        a, b = divmod(k, len(self.cj))
        return self.target.starts[self.ci[a], pairs] + self.cj[b]

    def add(self, pairs, values: np.ndarray) -> None:
        """target[row k, pairs] += values[k] for every row k (pairs: a slice or sorted keys)."""
        data = self.target.data
        if isinstance(pairs, slice):
            s, e = pairs.start, pairs.stop
            old = slice(s, min(max(self.done, s), e))   # already written: add
            new = slice(old.stop, e)                    # not yet: assign
            gap = slice(self.done, s) if s > self.done else None
        else:
            old, new = pairs, None
            e = int(pairs[-1]) + 1 if pairs.size else 0
            gap = slice(self.done, e) if e > self.done else None
        n_old = old.stop - old.start if isinstance(old, slice) else len(old)
        for k, v in enumerate(values):
            if not self.first[k]:
                data[self._pos(k, pairs)] += v
                continue
            if gap is not None:
                data[self._pos(k, gap)] = 0.0
            if n_old:
                data[self._pos(k, old)] += v[:n_old] if new is not None else v
            if new is not None and new.stop > new.start:
                data[self._pos(k, new)] = v[n_old:]
        self.done = max(self.done, e)

    def finish(self, npairs: int) -> None:
        """Zero the first rows' pairs past the last one written."""
        if self.done < npairs:
            for k in np.flatnonzero(self.first):
                self.target.data[self._pos(int(k), slice(self.done, npairs))] = 0.0
            self.done = npairs


class _Window:
    """Node-pair sums of pairs [lo, lo + n) in a buffer of a few blocks' range, added into the
    target (after ``M`` @ or × ``fac``) when the blocks have moved past them. A pair reached
    again after its flush is added again: correct for any numbering, each pair flushed once
    (the sums of ``reduce`` exactly) when the blocks' slots move forward."""

    def __init__(self, rows: _Rows, npairs: int, M: np.ndarray | None, fac: float):
        self.rows, self.npairs, self.M, self.fac = rows, npairs, M, fac
        self.buf, self.lo, self.n = None, 0, 0

    def add(self, pair_slot: np.ndarray, values: np.ndarray) -> None:
        slots = pair_slot.astype(np.intp).ravel()
        if slots.size == 0:
            return
        lo, hi = int(slots.min()), int(slots.max()) + 1
        if hi - lo > SPAN_FACTOR * slots.size:   # wide: the slots present, straight in
            keys, inv = np.unique(slots, return_inverse=True)
            keep = keys < self.npairs
            sums = np.stack([np.bincount(inv, weights=v, minlength=keys.size)[keep]
                             for v in values])
            self._put(keys[keep], sums)
            return
        top = min(hi, self.npairs)
        self._move_to(lo, top, len(values))
        slots -= lo
        off = lo - self.lo
        for k, v in enumerate(values):
            self.buf[k, off:off + top - lo] += np.bincount(slots, weights=v,
                                                           minlength=hi - lo)[:top - lo]
        self.n = max(self.n, top - self.lo)

    def _move_to(self, lo: int, top: int, nrows: int) -> None:
        """Window starting at ``lo`` with room up to ``top``: pairs before ``lo`` flushed."""
        if self.buf is not None and lo >= self.lo and top - self.lo <= self.buf.shape[1]:
            return   # room left: pairs before ``lo`` flushed later, several blocks at once
        if self.buf is not None and lo >= self.lo:
            k = min(lo - self.lo, self.n)
            if k:
                self._flush(k)
                self.buf[:, :self.n - k] = self.buf[:, k:self.n]
                self.buf[:, self.n - k:self.n] = 0.0
                self.n -= k
            self.lo = lo   # k = lo - lo_old, or the window emptied
            if top - lo <= self.buf.shape[1]:
                return
        self.flush_all()
        if self.buf is None or self.buf.shape[1] < top - lo:
            self.buf = np.zeros((nrows, 2 * (top - lo)))
        self.lo, self.n = lo, 0

    def _flush(self, k: int) -> None:
        self._put(slice(self.lo, self.lo + k), self.buf[:, :k])

    def flush_all(self) -> None:
        if self.buf is not None and self.n:
            self._flush(self.n)
            self.buf[:, :self.n] = 0.0
            self.lo += self.n
            self.n = 0

    def _put(self, pairs, sums: np.ndarray) -> None:
        if self.M is not None:
            sums = self.M @ sums
        elif self.fac != 1.0:
            sums = self.fac * sums
        self.rows.add(pairs, sums)


def _accumulate(acc: np.ndarray, pair_slot: np.ndarray, values: np.ndarray, npairs: int) -> None:
    """acc[:, slot] += values summed by slot, for one block's slots (nen, nen, nb) and values
    (rows, nen·nen·nb) in the same order; slot ``npairs`` (rows owned elsewhere) dropped. The
    counts go over the slots' range (contiguous in a numbering that follows the mesh), or over
    the slots present when that range is wide."""
    slots = pair_slot.astype(np.intp).ravel()
    if slots.size == 0:
        return
    lo, hi = int(slots.min()), int(slots.max()) + 1
    if hi - lo <= SPAN_FACTOR * slots.size:
        slots -= lo
        top = min(hi, npairs) - lo
        for k, v in enumerate(values):
            acc[k, lo:lo + top] += np.bincount(slots, weights=v, minlength=hi - lo)[:top]
        return
    keys, inv = np.unique(slots, return_inverse=True)
    keep = keys < npairs
    dest = keys[keep]
    for k, v in enumerate(values):
        acc[k, dest] += np.bincount(inv, weights=v, minlength=keys.size)[keep]


def _slots(pair_slot: np.ndarray) -> np.ndarray:
    """The pair slots flat, as np.bincount takes them (intp): the pattern keeps them int32 to
    halve their memory, so they are widened once per reduction, not once per row."""
    return pair_slot.astype(np.intp, copy=False).ravel()


def _bincount_rows(slots: np.ndarray, values: np.ndarray, npairs: int) -> np.ndarray:
    """Row-wise bincount, dropping the dump slot ``npairs`` (rows owned by another rank)."""
    out = np.empty((len(values), npairs))
    for k, v in enumerate(values):  # one row's counts alive at a time, not all of them
        out[k] = np.bincount(slots, weights=v, minlength=npairs + 1)[:npairs]
    return out


def full_values(m: ElementMatrices) -> np.ndarray:
    """The element matrices (d², nen, nen, nc) whatever their form (a blocked one: all)."""
    if not m.factored:
        return m.values
    return contract(m.tensors, m.cell_material, m.geometric)


def apply(m: ElementMatrices, ue: np.ndarray) -> np.ndarray:
    """Element products K_e u_e: ue (nc, nen, dj) → (nc, nen, di), d² = di·dj; block by
    block for a blocked form."""
    nc, nen, dj = ue.shape
    rows = m.tensors.shape[2] if m.factored else \
        (m.kernel.rows if m.kernel is not None else len(m.values))
    out = np.empty((nc, nen, rows // dj))
    for sl, V in m.block_values():
        n = V.shape[-1]
        out[sl] = np.einsum("ijabc,cbj->cai", V.reshape(rows // dj, dj, nen, nen, n), ue[sl])
    return out


def place_rows(values: np.ndarray, target: "StiffnessTarget", ci, cj, fac: float,
                first: np.ndarray) -> None:
    """Rows k = (ci[k // len(cj)], cj[k % len(cj)]) of (rows, npairs) node-pair sums into the
    target: assigned where ``first``, added elsewhere."""
    for k, (i, j) in enumerate((i, j) for i in ci for j in cj):
        pos = target.starts[i] + j
        if first[k]:
            target.data[pos] = fac * values[k]
        else:
            target.data[pos] += fac * values[k]


@dataclass
class BlockMatrices:
    """Element matrices of several effects, each on its own (row, column) components of the
    node DOFs, scaled: reduced into the full (ncomp², npairs) node-pair blocks."""

    ncomp: int
    parts: list  # (row components, column components, ElementMatrices, factor)

    def reduce_into(self, pair_slot: np.ndarray, npairs: int, target: StiffnessTarget) -> None:
        """Node-pair blocks straight into the operator's stiffness slots, with no (ncomp²,
        npairs) array beside them: the parts in turn, each component pair assigned by the
        first part on it and added to by the next; those no part reaches zeroed."""
        nc = self.ncomp
        # (not widened whole: each form widens the block of slots it reads, a cell's 64
        # int32 slots as intp being another 0.5 KB per cell beside the assembly)
        written = np.zeros((nc, nc), dtype=bool)
        for ci, cj, m, fac in self.parts:
            ci, cj = np.asarray(ci), np.asarray(cj)
            first = ~written[np.ix_(ci, cj)].ravel()
            if hasattr(m, "reduce_into"):
                m.reduce_into(_own_slots(m, pair_slot), npairs, target, ci, cj, fac, first=first)
            else:   # small forms with only ``reduce`` (node blocks, springs: few pairs)
                place_rows(m.reduce(pair_slot, npairs), target, ci, cj, fac, first)
            written[np.ix_(ci, cj)] = True
        for i, j in zip(*np.nonzero(~written)):
            target.data[target.starts[i] + j] = 0.0

    def reduce(self, pair_slot: np.ndarray, npairs: int) -> np.ndarray:
        nc = self.ncomp
        pair_slot = pair_slot.astype(np.intp, copy=False)   # widened once for every part
        if len(self.parts) == 1:
            ci, cj, m, fac = self.parts[0]
            if len(ci) == len(cj) == nc and np.all(ci == np.arange(nc)) \
                    and np.all(cj == np.arange(nc)) and fac == 1.0:
                return m.reduce(_own_slots(m, pair_slot), npairs)
        out = np.zeros((nc * nc, npairs))
        for ci, cj, m, fac in self.parts:
            idx = (np.asarray(ci)[:, None] * nc + np.asarray(cj)[None, :]).ravel()
            out[idx] += fac * m.reduce(_own_slots(m, pair_slot), npairs)
        return out

    def reduce_replaced(self, other: "BlockMatrices", cells: np.ndarray, pair_slot: np.ndarray,
                        npairs: int) -> np.ndarray:
        """``reduce`` with the element matrices of a few of the composition's cells ``cells``
        taken from ``other`` (the same terms evaluated otherwise: a loading tangent): the
        reduction plus those cells' difference. Node terms have no cells: left as they are."""
        out = self.reduce(pair_slot, npairs)
        nc = self.ncomp
        for (ci, cj, m0, fac), (_, _, m1, _) in zip(self.parts, other.parts):
            if not isinstance(m0, ElementMatrices) or m0.nodes is not None or cells.size == 0:
                continue
            at = cells if m0.positions is None else np.flatnonzero(np.isin(m0.positions, cells))
            if at.size == 0:
                continue
            slots = _own_slots(m0, pair_slot)[:, :, at].astype(np.intp).ravel()
            diff = cell_values(m1, at) - cell_values(m0, at)
            idx = (np.asarray(ci)[:, None] * nc + np.asarray(cj)[None, :]).ravel()
            out[idx] += fac * _bincount_rows(slots, diff.reshape(len(diff), -1), npairs)
        return out


def _own_slots(m, pair_slot: np.ndarray) -> np.ndarray:
    """The slots a part reduces into: its own (a term on a region's cells) or the cells'."""
    slots = getattr(m, "slots", None)
    return pair_slot if slots is None or isinstance(m, TermMatrices) else slots


def cell_values(m: ElementMatrices, cells: np.ndarray) -> np.ndarray:
    """Element matrices (d², nen, nen, len(cells)) of some of its cells, whatever the form."""
    if m.kernel is not None and not m.factored:   # blocked full values: just these cells
        return m.kernel.compute(cells, None)
    if m.values is not None:
        return m.values[..., cells]
    return np.einsum("ckm,kabc->mabc", m.tensors[m.cell_material[cells]], m.geometric[..., cells])


# ------------------------------------------------ declared terms


@dataclass(eq=False)   # a term is itself (hashable): equal values do not make two terms one
class Term:
    """A term an effect declares once, at set-up: its test and trial fields, its domain and
    its nature. The domain is one of

    - cells (the default): every cell (``cells`` None) or the cells of a region (``cells``:
      their mesh cell numbers);
    - facets (``facets``: (k, nfn) local nodes of boundary facets of a region, outward as the
      region gives them): a boundary integral, its element arrays (d², nfn, nfn, k) given in
      facet blocks (``fem.integrals.facet_matrices``), its pattern the cells' own (a boundary
      facet lies in one of this rank's cells);
    - tuples of nodes (``nodes``: k tuples of m local nodes, a node to the ground, a pair of
      nodes, whether or not a cell holds them together).

    ``rate``: a capacity term (M, weighed by 1/Δt in a transient step) rather than a
    stiffness. ``trial`` None: a vector term, a load on the test field: its values are forces
    (``NodeForces`` at its domain's nodes, from its declarer's ``vector_values`` at the step's
    instant), it has no slots, and it belongs to a load pattern (``loads.base``).

    The system derives the stiffness pattern from the cells and the declared terms, and gives
    each term its slots there (``slots`` (m, m, k): node pair (i, j) of tuple, facet or cell
    k; the pattern's ``nnzb`` where another rank owns the row, which drops it; None for a term
    on every cell, whose slots are the cells' own): each rank declares the terms on its local
    nodes, and a row's entries are its owner's. Its values come as ``ElementMatrices`` (cell
    and facet terms, in bounded blocks) or ``TermMatrices`` (node tuples), paired with the
    term."""

    test: str
    trial: str | None                 # None: a vector term (a load)
    nodes: np.ndarray | None = None   # (k, m) local nodes; None: a cell or facet term
    symmetric: bool = True
    linear: bool = True
    rate: bool = False
    cells: np.ndarray | None = None   # a cell term's region (mesh cells); None: every cell
    slots: np.ndarray | None = None   # (m, m, k), set by the system
    # ``nodes`` are the partition's global node numbers, not local ones: tuples whose nodes
    # need not be on this rank's part (a contact pair: a slave node and its master facet's),
    # each declared by one rank (the entries of rows another rank owns are sent there:
    # ``la.tuple_rows``), which gives their forces itself
    global_ids: bool = False
    facets: np.ndarray | None = None  # (k, nfn) local nodes of boundary facets: a facet term
    # a vector term (a load): the pattern it belongs to (None: its declarer's), its factor in
    # time (None: constant), and whether its values depend on t (assembled at every instant)
    pattern: str | None = None
    evolution: Callable | None = None
    timed: bool = False

    def __post_init__(self) -> None:
        if self.facets is not None:
            self.facets = np.asarray(self.facets, dtype=np.int64)
        if self.nodes is None:
            return
        nodes = np.asarray(self.nodes, dtype=np.int64)
        self.nodes = nodes if nodes.ndim == 2 else nodes.reshape(-1, 1)   # (k,): single nodes

    @property
    def on_cells(self) -> bool:
        return self.nodes is None and self.facets is None

    @property
    def on_facets(self) -> bool:
        return self.facets is not None

    @property
    def on_nodes(self) -> bool:
        return self.nodes is not None

    @property
    def vector(self) -> bool:
        """A load on the test field, not an operator block: the pattern has nothing of it."""
        return self.trial is None

    def positions(self, cells: np.ndarray) -> np.ndarray | None:
        """Which of ``cells`` (a composition's local cells) the cell term covers: their
        positions, or None for every one (a term on every cell)."""
        if self.cells is None:
            return None
        return np.flatnonzero(np.isin(cells, self.cells))


@dataclass
class TermMatrices:
    """The values of a declared term, (d_test·d_trial, m, m, k): reduced into the term's own
    slots (the cells' ``pair_slot`` does not hold them), and applied to node values."""

    term: Term
    values: np.ndarray

    def reduce(self, pair_slot: np.ndarray, npairs: int) -> np.ndarray:
        slots = self.term.slots
        if slots is None or self.values.shape[-1] == 0:   # (no system: no slots; none here)
            return np.zeros((len(self.values), npairs))
        return _bincount_rows(slots.astype(np.intp).ravel(),
                              self.values.reshape(len(self.values), -1), npairs)

    def reduce_into(self, pair_slot: np.ndarray, npairs: int, target: StiffnessTarget,
                    ci: np.ndarray, cj: np.ndarray, fac: float = 1.0,
                    first: np.ndarray | None = None) -> None:
        """``reduce`` added into the target's values (``ElementMatrices.reduce_into``) at the
        pairs the term's slots reach only: a term on a few nodes (contact rows' blocks) made a
        (rows, npairs) array as large as the stiffness at every assembly (0.6 KB per DOF)."""
        ci, cj = np.asarray(ci), np.asarray(cj)
        rows = _Rows(target, ci, cj, np.zeros(len(ci) * len(cj), dtype=bool)
                     if first is None else first)
        slots = self.term.slots
        if slots is not None and self.values.shape[-1]:
            keys, inv = np.unique(slots.astype(np.intp).ravel(), return_inverse=True)
            keep = keys < npairs   # (the dump slot: rows owned by another rank)
            values = self.values.reshape(len(self.values), -1)
            sums = np.stack([np.bincount(inv, weights=v, minlength=keys.size)[keep]
                             for v in values])
            rows.add(keys[keep], fac * sums)
        rows.finish(npairs)

    def forces(self, x: np.ndarray) -> "NodeForces":
        """K x at the term's nodes from node values x (npoints, d_trial)."""
        if self.term.global_ids:
            raise ValueError("a term on global node numbers gives its forces itself")
        nodes = self.term.nodes
        k, m = nodes.shape
        dj = x.shape[1]
        V = self.values.reshape(len(self.values) // dj, dj, m, m, k)
        return NodeForces(nodes, np.einsum("ijabk,kbj->kai", V, x[nodes]))


@dataclass
class NodeForces:
    """Forces at tuples of local nodes, (k, m, d) at ``nodes`` (k, m): what a term's effect
    returns where a cell effect returns (nc, nen, d) element forces."""

    nodes: np.ndarray
    values: np.ndarray
