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
                    fresh: bool = False) -> None:
        """Add ``fac`` × the node-pair sums of rows (ci[a], cj[b]) into the target's values,
        with no (d², npairs) array beside them. ``fresh``: those positions hold zeros and
        no other part's values, so a single material's geometric parts can be summed there
        and contracted in place (pair chunk by pair chunk)."""
        ci, cj = np.asarray(ci), np.asarray(cj)
        one = self.factored and len(self.tensors) == 1
        in_place = one and fresh and self.tensors.shape[1] == self.tensors.shape[2]
        rows = _Rows(target, ci, cj)
        for sl, V in self._raw_blocks():
            if self.factored and not in_place:
                V = contract(self.tensors, self.cell_material[sl], V)
            _accumulate(rows, pair_slot[:, :, sl], V.reshape(len(V), -1), npairs,
                        1.0 if in_place else fac)
        if in_place:
            rows.contract(fac * self.tensors[0].T, npairs)

    def _raw_blocks(self) -> Iterator[tuple[slice, np.ndarray]]:
        """(cells, geometric parts or full values) block after block (held: one block)."""
        if self.kernel is not None:
            yield from self.kernel.blocks()
            return
        held = self._geometric if self.factored else self._values
        yield slice(0, held.shape[-1]), held

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

    def zero(self) -> None:
        """Zero every stiffness slot (before parts are added into them)."""
        nc = self.starts.shape[0]
        for i in range(nc):
            for j in range(nc):
                self.data[j:][self.starts[i]] = 0.0


class _Rows:
    """Row k = (ci[k // len(cj)], cj[k % len(cj)]) of a part, as positions in the target."""

    def __init__(self, target: StiffnessTarget, ci: np.ndarray, cj: np.ndarray):
        self.target, self.ci, self.cj = target, ci, cj

    def positions(self, k: int, pairs) -> np.ndarray:
        a, b = divmod(k, len(self.cj))
        return self.target.starts[self.ci[a], pairs] + self.cj[b]

    def __setitem__(self, key, value) -> None:   # rows[k, pairs] += v: read, add, write back
        k, pairs = key
        self.target.data[self.positions(k, pairs)] = value

    def __getitem__(self, key) -> np.ndarray:
        k, pairs = key
        return self.target.data[self.positions(k, pairs)]

    def contract(self, M: np.ndarray, npairs: int, chunk: int = 1 << 14) -> None:
        """Values ← M @ values on every pair, chunk by chunk (the rows hold geometric sums)."""
        nrow = len(self.ci) * len(self.cj)
        data = self.target.data
        for s in range(0, npairs, chunk):
            pairs = slice(s, min(s + chunk, npairs))
            pos = np.stack([self.positions(k, pairs) for k in range(nrow)])
            data[pos] = M @ data[pos]


def _accumulate(acc, pair_slot: np.ndarray, values: np.ndarray, npairs: int,
                fac: float = 1.0) -> None:
    """acc[:, slot] += fac × values summed by slot, for one block's slots (nen, nen, nb) and
    values (rows, nen·nen·nb) in the same order; slot ``npairs`` (rows owned elsewhere)
    dropped. ``acc``: an array (rows, npairs) or a part's rows in the operator (``_Rows``).
    The counts go over the slots' range (contiguous in a numbering that follows the mesh), or
    over the slots present when that range is wide."""
    slots = pair_slot.astype(np.intp).ravel()
    if slots.size == 0:
        return
    lo, hi = int(slots.min()), int(slots.max()) + 1
    if hi - lo <= SPAN_FACTOR * slots.size:
        slots -= lo
        top = min(hi, npairs) - lo
        dest = slice(lo, lo + top)
        for k, v in enumerate(values):
            c = np.bincount(slots, weights=v, minlength=hi - lo)[:top]
            acc[k, dest] += c if fac == 1.0 else fac * c
        return
    keys, inv = np.unique(slots, return_inverse=True)
    keep = keys < npairs
    dest = keys[keep]
    for k, v in enumerate(values):
        c = np.bincount(inv, weights=v, minlength=keys.size)[keep]
        acc[k, dest] += c if fac == 1.0 else fac * c


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


@dataclass
class BlockMatrices:
    """Element matrices of several effects, each on its own (row, column) components of the
    node DOFs, scaled: reduced into the full (ncomp², npairs) node-pair blocks."""

    ncomp: int
    parts: list  # (row components, column components, ElementMatrices, factor)

    def reduce_into(self, pair_slot: np.ndarray, npairs: int, target: StiffnessTarget) -> None:
        """Node-pair blocks straight into the operator's stiffness slots (zeroed first), with
        no (ncomp², npairs) array beside them; a part on components already written by an
        earlier part is added, contracted before (it cannot be contracted in place)."""
        target.zero()
        nc = self.ncomp
        pair_slot = pair_slot.astype(np.intp, copy=False)
        written = np.zeros((nc, nc), dtype=bool)
        for ci, cj, m, fac in self.parts:
            ci, cj = np.asarray(ci), np.asarray(cj)
            fresh = not written[np.ix_(ci, cj)].any()
            m.reduce_into(pair_slot, npairs, target, ci, cj, fac, fresh=fresh)
            written[np.ix_(ci, cj)] = True

    def reduce(self, pair_slot: np.ndarray, npairs: int) -> np.ndarray:
        nc = self.ncomp
        pair_slot = pair_slot.astype(np.intp, copy=False)   # widened once for every part
        if len(self.parts) == 1:
            ci, cj, m, fac = self.parts[0]
            if len(ci) == len(cj) == nc and np.all(ci == np.arange(nc)) \
                    and np.all(cj == np.arange(nc)) and fac == 1.0:
                return m.reduce(pair_slot, npairs)
        out = np.zeros((nc * nc, npairs))
        for ci, cj, m, fac in self.parts:
            idx = (np.asarray(ci)[:, None] * nc + np.asarray(cj)[None, :]).ravel()
            out[idx] += fac * m.reduce(pair_slot, npairs)
        return out
