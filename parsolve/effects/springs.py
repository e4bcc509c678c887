"""Discrete springs on the displacement: each node of a region to the ground, or each node of
a region to a partner node (of a target region), with a stiffness per global component.

A spring of stiffness K = diag(k_x, k_y(, k_z)) (force per unit displacement: N/m in 3D; in
2D the same, not per unit thickness) adds to the internal forces

    to ground        f_a = K u_a
    node to node     f_a = K (u_a - u_b),  f_b = K (u_b - u_a)

and its (constant, symmetric) blocks to the stiffness: the effect is linear and symmetric,
so an associated-only scene keeps its symmetric factorization.

The blocks go into the stiffness pattern the cells already made, through one of the rank's
cells holding the spring's nodes (a node's diagonal block; for a pair, the four blocks of a
cell holding both): re-assembly stays a value update. A pair whose nodes share no cell (two
bodies joined by springs) asks the system for slots of its own (``node_pairs``: the system
pads it into a pseudo-cell of its pattern); its forces go to a cell of each node. On parts,
the rank owning either node of such a pair must hold the other one too (owned or ghost: the
nodes of its cells); a pair split otherwise is an input error (exit 2; e.g. run on fewer
ranks). Each rank adds each block once; the rows it does not own fall out of its pattern, so
the ranks' sum is each spring once.

Pairing (``target``): a target of one node takes every node of the region (a star, e.g. a
region hung from one point); otherwise each region node is paired with the target node at its
position + ``translation`` (default zero: coincident nodes), within the regions' tolerance.

Scene schema (one table per set of springs)::

    [[springs]]
    name = "support"             # optional (default springs0, springs1, ...): the output
    #                              /fields/<name>_force, the force the springs exert on
    #                              each node (zero elsewhere)
    region = "base"              # its nodes, each with its own spring
    stiffness = [0.0, 1e3]       # per component (x, y(, z)), >= 0, not all zero
    target = "pin"               # optional: node to node instead of to the ground
    translation = [0.0, 0.0]     # optional, with target: partner at x + translation
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.effects.base import Effect
from parsolve.effects.compose import node_places
from parsolve.relation_kinds.periodic import partners
from parsolve.errors import InputError
from parsolve.fem.element_matrices import CellKernel, ElementMatrices, place_rows


@dataclass
class SpringSpec:
    name: str
    region: str
    stiffness: list[float]
    key: str
    target: str | None = None
    translation: list[float] | None = None


def parse(t, dim: int) -> SpringSpec:
    """A ``[[springs]]`` table (a scene Table) → spec; raises the scene's InputError."""
    name = t.get("name", str, t.path.replace("[", "").replace("]", ""))   # springs0, ...
    if not name.isidentifier():
        raise t.error("name", f"a plain name (letters, digits, '_'), not {name!r}")
    region = t.get("region", str)
    stiffness = t.floats("stiffness", dim)
    if any(k < 0 for k in stiffness) or not any(k > 0 for k in stiffness):
        raise t.error("stiffness", "every component must be >= 0 and one at least > 0")
    target = t.get("target", str, None)
    translation = t.floats("translation", dim, None)
    if translation is not None and target is None:
        raise t.error("translation", "a translation pairs nodes with a 'target' region")
    t.done()
    return SpringSpec(name, region, stiffness, t.path, target, translation)


def regions(spec: SpringSpec) -> list[tuple[str, str]]:
    out = [(spec.region, spec.key + ".region")]
    return out + ([(spec.target, spec.key + ".target")] if spec.target is not None else [])


class SpringMatrices(ElementMatrices):
    """The springs' blocks as element matrices of the rank's cells: entries (d² values, row
    local node, column local node, cell). Reduced straight into their pattern slots (a few
    numbers); anything that wants every cell's matrices (an element product) gets them block
    by block from a kernel that writes zeros but for the entries."""

    def __init__(self, values: np.ndarray, row: np.ndarray, col: np.ndarray, cell: np.ndarray,
                 ncells: int, nen: int):
        self.entries = (values, row, col, cell)
        super().__init__(kernel=CellKernel(self._compute, ncells, len(values), nen))

    def _compute(self, sel, out):
        values, row, col, cell = self.entries
        k = self.kernel
        idx = np.arange(k.ncells)[sel]
        shape = (k.rows, k.nen, k.nen, idx.size)
        out = out if out is not None and out.shape == shape else np.empty(shape)
        out[...] = 0.0
        pos = np.full(k.ncells, -1)
        pos[idx] = np.arange(idx.size)
        at = pos[cell] >= 0
        np.add.at(out, (slice(None), row[at], col[at], pos[cell[at]]), values[:, at])
        return out

    # the blocks of pairs that share no cell: (d², m) values and their own pattern slots
    loose = (np.zeros((0, 0)), np.zeros(0, dtype=np.intp))

    def reduce_into(self, pair_slot: np.ndarray, npairs: int, target, ci, cj, fac: float = 1.0,
                    first: np.ndarray | None = None) -> None:
        """Into the operator's slots through ``reduce`` (a few numbers: the cells' kernel would
        miss the pairs that share no cell)."""
        first = np.zeros(len(ci) * len(cj), dtype=bool) if first is None else first
        place_rows(self.reduce(pair_slot, npairs), target, ci, cj, fac, first)

    def reduce(self, pair_slot: np.ndarray, npairs: int) -> np.ndarray:
        values, row, col, cell = self.entries
        slots = pair_slot[row, col, cell].astype(np.intp)
        if self.loose[1].size:
            values = np.concatenate([values, self.loose[0]], axis=1)
            slots = np.concatenate([slots, self.loose[1].astype(np.intp)])
        return np.stack([np.bincount(slots, weights=v, minlength=npairs + 1)[:npairs]
                         for v in values]) if len(values) else np.zeros((0, npairs))


class Springs(Effect):
    name = "springs"
    linear = True
    symmetric = True

    def __init__(self, spec: SpringSpec, mesh, regions, scene):
        if not scene.materials:
            raise InputError("springs act on the displacement: the scene needs [[materials]]",
                             scene.source, spec.key)
        self.spec, self.mesh, self.source = spec, mesh, scene.source
        self.u = scene.primary   # the displacement (the field springs act on)
        self.k = np.asarray(spec.stiffness, dtype=float)
        self.pairs = self._pairs(regions)   # (n, 2) local nodes (-1: not on this part; b to
        #                                     the ground: -1 throughout)
        self.loose = self._check_cells(regions)   # (n,) pairs that share no cell
        self.slots = np.zeros((2, 2, 0), dtype=np.intp)
        self._cache = (None, None)

    # ------------------------------------------------------------------ pairing

    def _pairs(self, regions) -> np.ndarray:
        spec = self.spec
        a = regions.relation_nodes(spec.region, spec.key + ".region")   # input ids, whole
        if spec.target is None:
            return np.stack([self._local(a), np.full(a.size, -1)], axis=1)
        b_all = regions.relation_nodes(spec.target, spec.key + ".target")
        if b_all.size == 1:
            b = np.repeat(b_all, a.size)
        else:
            b = partners(regions.points_of(a), b_all, regions.points_of(b_all),
                         spec.translation or [0.0] * self.mesh.dim, regions.tol)
            if np.any(b < 0):
                lost = int(a[np.flatnonzero(b < 0)[0]])
                raise InputError(f"node {lost} of region {spec.region!r} has no node of region "
                                 f"{spec.target!r} at its position + translation (within "
                                 f"{regions.tol:.3g})", self.source, spec.key + ".target")
        if np.any(a == b):
            raise InputError("a spring would tie a node to itself", self.source,
                             spec.key + ".target")
        # a pair of which this rank holds a node but not the other cannot be in its cells
        return np.stack([self._local(a), self._local(b)], axis=1)

    def _local(self, ids: np.ndarray) -> np.ndarray:
        """Local node of each input id (-1: not on this rank's part)."""
        glob = getattr(self.mesh, "global_nodes", None)
        if glob is None:
            return np.asarray(ids, dtype=np.int64)
        order = np.argsort(glob)
        pos = np.minimum(np.searchsorted(glob[order], ids), max(glob.size - 1, 0))
        hit = glob[order][pos] == ids if glob.size else np.zeros(ids.size, dtype=bool)
        return np.where(hit, order[pos] if glob.size else -1, -1)

    def _check_cells(self, regions) -> np.ndarray:
        """Which pairs share no cell (the ranks' cells together); such a pair must have both
        nodes on the rank owning either."""
        if self.spec.target is None:
            return np.zeros(len(self.pairs), dtype=bool)
        cell = self._places(np.arange(self.mesh.num_cells))[0]
        found = cell >= 0
        comm = getattr(regions, "comm", None)
        if comm is not None:
            found = comm.allreduce(found.astype(np.int64)) > 0   # the pairs' size
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        owned = getattr(self.mesh, "n_owned", self.mesh.num_points)
        split = ~found & (((a >= 0) & (a < owned) & (b < 0)) | ((b >= 0) & (b < owned) & (a < 0)))
        nsplit = int(split.sum()) if comm is None else comm.allreduce(int(split.sum()))
        if nsplit:
            raise InputError(f"{nsplit} spring pairs join nodes that share no cell and lie on "
                             "different ranks' parts (the rank owning one node must hold the "
                             "other; run on fewer ranks)", self.source, self.spec.key + ".target")
        return ~found

    # ------------------------------------------------------------ pairs with slots of their own

    def _own_pairs(self) -> np.ndarray:
        """The pairs sharing no cell whose two nodes are both on this rank (it adds them)."""
        return self.loose & (self.pairs[:, 0] >= 0) & (self.pairs[:, 1] >= 0)

    def node_pairs(self) -> np.ndarray:
        return self.pairs[self._own_pairs()]

    def set_pair_slots(self, slots: np.ndarray) -> None:
        self.slots = slots
        self._cache = (None, None)

    def _places(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position in ``cells``, local node of a, of b) of the first cell holding each
        spring's nodes (-1 where none does; b's is -1 for a spring to the ground)."""
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        # only the cells holding a spring's first node (a few): no array of the mesh's size
        near = np.flatnonzero(np.isin(self.mesh.cells[cells], a[a >= 0]).any(axis=1))
        nodes = self.mesh.cells[cells[near]]
        nen = nodes.shape[1]
        n = max(self.mesh.num_points, 1)
        ground = np.full(len(a), self.spec.target is None)   # (b = -1 also: not on this part)
        # keys (node, partner) of the ordered node pairs of every cell, and (node, node) for
        # the diagonal: the first cell of each key by a stable sort (lowest position wins)
        i, j = np.meshgrid(np.arange(nen), np.arange(nen), indexing="ij")
        i, j = i.ravel(), j.ravel()
        keys = (nodes[:, i].astype(np.int64) * n + nodes[:, j]).ravel()     # (nc·nen²)
        order = np.argsort(keys, kind="stable")
        skeys = keys[order]
        none = np.full(len(a), -1, dtype=np.int64)
        if keys.size == 0:   # this rank's cells hold none of the springs
            return none, none, none.copy()
        want = np.where(ground, a * n + a, a * n + np.maximum(b, 0)).astype(np.int64)
        pos = np.minimum(np.searchsorted(skeys, want), skeys.size - 1)
        hit = (skeys[pos] == want) & (a >= 0) & (ground | (b >= 0))
        flat = order[pos]
        cell = np.where(hit, near[flat // (nen * nen)], -1)
        la = np.where(hit, i[flat % (nen * nen)], -1)
        lb = np.where(hit & ~ground, j[flat % (nen * nen)], -1)
        return cell, la, lb

    # ------------------------------------------------------------------ the Effect interface

    def _matrices(self, cells: np.ndarray) -> SpringMatrices:
        if self._cache[0] is not cells:
            cell, la, lb = self._places(cells)
            K = np.diag(self.k).ravel()[:, None]                # (d², 1), row-major (i, j)
            ground = self.spec.target is None
            g = (cell >= 0) & ground
            p = (cell >= 0) & (not ground)
            rows = [la[g], la[p], lb[p], la[p], lb[p]]
            cols = [la[g], la[p], lb[p], lb[p], la[p]]
            sign = [1.0, 1.0, 1.0, -1.0, -1.0]
            values = np.concatenate([s * np.repeat(K, r.size, axis=1)
                                     for s, r in zip(sign, rows)], axis=1)
            hosts = np.concatenate([cell[g]] + [cell[p]] * 4)
            m = SpringMatrices(values, np.concatenate(rows), np.concatenate(cols), hosts,
                               len(cells), self.mesh.cells.shape[1])
            m.loose = self._loose_blocks(K)
            self._cache = (cells, m)
        return self._cache[1]

    def _loose_blocks(self, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(values, slots) of the pairs sharing no cell: +K on (a, a), (b, b), −K on (a, b),
        (b, a), each in the pseudo-cell slots the system gave (none: the element form alone,
        e.g. a model not assembled by a system)."""
        s = self.slots
        n = s.shape[2]
        if n == 0:
            return SpringMatrices.loose
        sign = np.repeat([1.0, 1.0, -1.0, -1.0], n)
        slots = np.concatenate([s[0, 0], s[1, 1], s[0, 1], s[1, 0]])
        return K * sign[None, :], slots

    def _loose_forces(self, cells: np.ndarray, u: np.ndarray, fe: np.ndarray) -> None:
        """K (u_a − u_b) on a, its opposite on b, for the pairs sharing no cell this rank adds,
        each on a cell of the node (a nodal force: no common cell needed)."""
        pairs = self.pairs[self._own_pairs()]
        if len(pairs) == 0:
            return
        f = (u[pairs[:, 0]] - u[pairs[:, 1]]) * self.k
        nodes = np.concatenate([pairs[:, 0], pairs[:, 1]])
        cell, local = node_places(self.mesh.cells[cells], nodes)
        np.add.at(fe, (cell, local), np.concatenate([f, -f]))

    def stiffness_blocks(self, cells: np.ndarray):
        return [(self.u, self.u, self._matrices(cells))]

    def evaluate(self, cells: np.ndarray, values: dict, state, secant: bool, at):
        """K u of the springs on their host cells' nodes (a few entries, not a cell pass)."""
        m = self._matrices(cells)
        vals, row, col, cell = m.entries
        d = self.mesh.dim
        u = values[self.u][self.mesh.cells[cells][cell, col]]          # (n, d) column node's
        force = np.einsum("ijn,nj->ni", vals.reshape(d, d, -1), u)
        fe = np.zeros((len(cells), self.mesh.cells.shape[1], d))
        np.add.at(fe, (cell, row), force)
        self._loose_forces(cells, values[self.u], fe)
        return {self.u: fe}, [(self.u, self.u, m)], state, None

    def output_names(self) -> list[str]:
        return [f"{self.spec.name}_force"]

    def outputs(self, owned, values, extra, local_cells):
        """The force the springs exert on each node, -K (u_a - u_b) on a and its opposite on
        b, complete on every node this rank holds with its partner (all the owned ones);
        weight 1 there, so that the ranks' contributions average to it."""
        npts, d = self.mesh.num_points, self.mesh.dim
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        u = values[self.u]
        ground = self.spec.target is None
        on = (a >= 0) if ground else (a >= 0) & (b >= 0)
        a, b = a[on], b[on]
        f = -self.k * (u[a] - (0.0 if ground else u[b]))
        force, weight = np.zeros((npts, d)), np.zeros(npts)
        np.add.at(force, a, f)
        weight[a] = 1.0
        if not ground:
            np.add.at(force, b, -f)
            weight[b] = 1.0
        return {f"{self.spec.name}_force": (force * weight[:, None], weight)}, {}
