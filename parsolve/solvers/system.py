"""The distributed saddle system of a model: partition, numbering, operator, right-hand side,
and the way back from the solution to named fields and multipliers.

Single-DOF associated equalities are eliminated (zeroed rows and columns, scaled unit
diagonal, lifting in the right-hand side) unless the scene asks otherwise; every other relation
gets multipliers. Their reactions are recovered from the unmodified rows, so both ways report
the same multipliers.
"""

from __future__ import annotations

import time
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from parsolve import progress
from parsolve.effects.compose import Composition, Rate
from parsolve.fem.element_matrices import BlockMatrices, ElementMatrices, StiffnessTarget
from parsolve.la.dofmap import DofMap, HeldValues, held_keys
from parsolve.la.fetch import Fetch
from parsolve.la.pattern import node_pattern
from parsolve.la.petsc import SaddleOperator
from parsolve.la.relation_set import RelationSet
from parsolve.la.tuple_rows import TupleRows
from parsolve.mesh.topology import match_facets
from parsolve.model import Model
from parsolve.solvers.augmented import AugmentedMatrix
from parsolve.solvers.context import StepContext


class SaddleSystem:
    """Everything a rank needs to assemble, solve and read back the saddle system."""

    def __init__(self, comm: MPI.Comm, model: Model):
        self.comm, self.model = comm, model
        mesh, ncomp = model.mesh, model.ncomp
        rank = comm.rank
        self.timings = {}
        t0 = time.perf_counter()
        if model.comm.size != comm.size:
            raise ValueError(f"the model's mesh is split over {model.comm.size} ranks, not "
                             f"{comm.size}: build it with this communicator")
        self.part = mesh.partition()
        self.eliminated = [r for r in model.relations if r.eliminable()]
        self.multiplied = [r for r in model.relations if not r.eliminable()]
        # the multiplier rows are given their owners by the relation set (below)
        self.dofmap = dm = progress.timed("numbering", DofMap, comm, mesh, ncomp)
        # relations name input DOFs: the map finds their numbers (one reduction)
        self.unused = self.unused_dofs()
        dm.index_inputs(self._relation_dofs())
        self.local_cells = self.part.local_cells(rank, mesh.cells)
        # the cells this rank reports, and which of its local cells they are (every output step)
        self.owned_cells = self.part.owned_cells(rank, mesh.cells)
        self.reported = np.isin(self.local_cells, self.owned_cells, assume_unique=True)
        self.composition = Composition(model, self.local_cells)
        self.rate: Rate | None = None  # the rate terms of a transient step (set by the stepper)
        lo, hi = self.part.node_ranges[rank], self.part.node_ranges[rank + 1]
        self.pattern = pattern = progress.timed("pattern", self._pattern, lo, hi)
        self.relation_set = RelationSet(self.multiplied, dm)
        self.op = progress.timed("operator", SaddleOperator, comm, dm, pattern, self.relation_set)
        self.offset = dm.offset
        self._elimination_setup()
        self.context = StepContext(
            comm, dm, self.relation_set, self.eliminated, model.relations, self.composition,
            model.effects, model.fields, mesh, model.scene, model.patterns, self.local_cells,
            self.owned_cells, self.reported, model.initial_q, model.symmetric,
            model.nonlinear, model.transient)
        for e in model.effects:   # once: the reductions their hooks need (Effect.attach)
            e.attach(self.context)
        self.timings["setup"] = time.perf_counter() - t0
        self.assembled = False   # the operator as it is now assembled (its lifting known)
        self._augmented: AugmentedMatrix | None = None

    def _pattern(self, lo: int, hi: int):
        """The stiffness pattern of the effects' declared terms (``Effect.terms``): the local
        cells (the domain of the cell terms), then the node terms' tuples of m nodes, each
        padded into a pseudo-cell [a, b, b, ...] after the cells (a repeated node a diagonal
        entry), or covered by several when wider than a cell (``_Cover``), then the entries
        other ranks' terms in global numbers send to this rank's rows (``la.tuple_rows``:
        [row, column, column, ...]). The cells' reductions get the cells' slots; a node term,
        and a cell term on a region, its own (``Term.slots``); the received entries theirs."""
        model = self.model
        cells = model.mesh.cells[self.local_cells]
        terms = [term for e in model.effects for term in e.terms() if not term.vector]
        tuples = [t for t in terms if t.on_nodes]
        nnodes = int(self.part.node_ranges[-1])
        nen = cells.shape[1]
        self._check_owners([t for t in tuples if not t.global_ids])
        covers = [_Cover(t.nodes.shape[1], nen) for t in tuples]
        pseudo = [c.cells(g) for c, g in zip(covers, map(self._global_nodes, tuples))]
        # a term in global numbers is declared by one rank: its rows owned elsewhere travel
        self._away = [(t, TupleRows(self.comm, t.nodes, self.part.node_ranges))
                      for t in tuples if t.global_ids]
        received = [rows.cells(nen) for _, rows in self._away]
        pattern = node_pattern(np.concatenate([self.part.new_of_old[cells]] + pseudo + received),
                               lo, hi, model.ncomp, nnodes)
        start = len(cells)
        for t, c, g in zip(tuples, covers, pseudo):
            t.slots = c.slots(pattern.pair_slot, start, len(t.nodes))
            start += len(g)
        self._away_slots = []   # (the received entries' slots: (row, column), a diagonal's)
        for _, rows in self._away:
            at = slice(start, start + len(rows.received))
            diagonal = rows.received[:, 0] == rows.received[:, 1]
            self._away_slots.append(np.where(diagonal, pattern.pair_slot[0, 0, at],
                                             pattern.pair_slot[0, 1, at]).astype(np.intp))
            start = at.stop
        # the node tuples the pattern holds (``restructure``: a term whose domain moved)
        self._domains = [(t, t.nodes.copy()) for t in tuples]
        if tuples:
            pattern.pair_slot = np.ascontiguousarray(pattern.pair_slot[:, :, :len(cells)])
        for t in terms:
            at = t.positions(self.local_cells) if t.on_cells else None
            if at is not None:
                t.slots = pattern.pair_slot[:, :, at].astype(np.intp)
            if t.on_facets:
                t.slots = facet_slots(model.mesh, self.local_cells, pattern.pair_slot, t.facets)
        return pattern

    def _received(self, ke) -> list:
        """The entries of this rank's rows in the global-number terms other ranks declared
        (``la.tuple_rows``): (row components, column components, slots, values (n, width)),
        the slots unique. Collective (an exchange a term)."""
        parts = getattr(ke, "parts", None) or getattr(getattr(ke, "base", None), "parts", [])
        fields, out = self.model.fields, []
        for (t, rows), slots in zip(self._away, self._away_slots):
            ci, cj = fields.columns(t.test), fields.columns(t.trial)
            part = next(((m, fac) for _, _, m, fac in parts if getattr(m, "term", None) is t),
                        None)
            got = rows.send(None, len(ci) * len(cj)) if part is None else \
                rows.send(part[0].values, len(ci) * len(cj), part[1])
            keys, inv = np.unique(slots, return_inverse=True)
            sums = np.stack([np.bincount(inv.ravel(), weights=v, minlength=keys.size)
                             for v in got.T], axis=1) if keys.size else got[:0]
            out.append((ci, cj, keys, sums))
        return out

    def _global_nodes(self, term) -> np.ndarray:
        """A node term's tuples in the partition's global node numbers (``Term.global_ids``:
        given so, nodes that may lie on no part of this rank's)."""
        return term.nodes if term.global_ids else self.part.new_of_old[term.nodes]

    def _check_owners(self, tuples: list) -> None:
        """Tuples in local numbers: each rank adds the rows it owns of those it declares, so
        a tuple is whole only if the owner of each of its nodes declares it too (one some
        owner does not declare: its nodes share no cell and lie on different ranks' parts)
        would lose that node's rows silently, and leave the operator's pattern unsymmetric:
        refused on every rank alike. Collective (one exchange of the tuples with their nodes'
        owners)."""
        comm, ranges = self.comm, self.part.node_ranges
        mine, out = [], [[] for _ in range(comm.size)]
        for i, t in enumerate(tuples):   # (every rank declares the same terms, in one order)
            nodes = np.sort(self._global_nodes(t), axis=1)   # global, order-free
            mine.append(_rows(nodes))
            owners = np.searchsorted(ranges, nodes, side="right") - 1
            for r in np.unique(owners[owners != comm.rank]):
                out[r].append((i, nodes[np.any(owners == r, axis=1)]))
        lost = sum(int(np.count_nonzero(~np.isin(_rows(nodes), mine[i])))
                   for got in comm.alltoall(out) for i, nodes in got)
        lost = comm.allreduce(lost)
        if lost:
            raise RuntimeError(f"{lost} node tuples of declared terms join nodes whose owners do "
                               "not all declare them (the rank owning a tuple's node must hold "
                               "its other nodes and declare it too)")

    def restructure(self) -> None:
        """Build the operator again after a sparsity changed: a multiplied relation's
        (``Relation.set_entries``: finite sliding's spans made again) or a declared term's
        domain (``Term.nodes`` given anew: node tuples that moved). The DOF map learns the
        relations' DOFs (one reduction), the relation set is stacked again (the same rows,
        multiplier layout and scales); the stiffness pattern is derived again from the cells
        and the declared terms when a term moved on any rank, and the operator's CSR is built
        anew on it, exactly preallocated as at the start. The next assembly makes a new PETSc
        matrix (the solver must be given it). Collective: every rank holds the same
        relations."""
        self.dofmap.index_inputs(self._relation_dofs())
        self.relation_set.restack()
        if self.comm.allreduce(self._terms_moved(), op=MPI.LOR):
            rank = self.comm.rank
            lo, hi = self.part.node_ranges[rank], self.part.node_ranges[rank + 1]
            self.pattern = self._pattern(lo, hi)
        self._operator_anew(self.op.active)

    def _operator_anew(self, active: np.ndarray) -> None:
        """The operator's CSR built anew on the relations as stacked now, enforcing the owned
        multiplier rows of ``active`` (per held row before the stacking: the ghosts may
        change). The next assembly makes a new PETSc matrix. Collective."""
        owned = active[:self.relation_set.n_owned]
        self.op = SaddleOperator(self.comm, self.dofmap, self.pattern, self.relation_set)
        self.op.active = self.relation_set.from_owned(owned.astype(float)) > 0.5
        self._elimination_setup()   # (the relation rows' columns may have changed)
        self.assembled = False   # (no lifting before its first assembly: ``rhs_from``)

    def _terms_moved(self) -> bool:
        """Whether this rank's node terms are not those the pattern was derived from (a term
        added or gone, or its node tuples changed)."""
        terms = [t for e in self.model.effects for t in e.terms()
                 if t.on_nodes and not t.vector]
        if len(terms) != len(self._domains) or \
                any(t is not held for t, (held, _) in zip(terms, self._domains)):
            return True
        return any(not np.array_equal(t.nodes, nodes) for t, nodes in self._domains)

    # ------------------------------------------------------------ elimination

    def unused_dofs(self) -> np.ndarray:
        """DOFs of the points no cell uses (Gmsh writes such points): held at zero, out of
        the system's way, instead of making it singular. Input DOFs of those this rank owns
        (a point of no cell is no rank's ghost)."""
        mesh = self.model.mesh
        used = np.zeros(mesh.num_points, dtype=bool)
        used[mesh.cells.ravel()] = True
        nodes = np.flatnonzero(~used)
        nodes = np.sort(mesh.global_nodes[nodes[nodes < mesh.n_owned]].astype(np.int64))
        return (nodes[:, None] * self.model.ncomp + np.arange(self.model.ncomp)).ravel()

    def _relation_dofs(self) -> list[np.ndarray]:
        """Every input DOF a relation names (A and D entries), and the unused points'."""
        out = [self.unused]
        for r in self.model.relations:
            out.append(r.a_dofs)
            if r.shared_dual is not None:
                out.append(r.shared_dual[0])
            elif r.dual is not None:
                out.append(np.asarray(r.dual[0]))
        return out

    def _elimination_setup(self) -> None:
        """The eliminated DOFs this rank reads: first its own (the rows of the eliminated
        relations it holds, each on a DOF it owns, relation by relation in row order, then its
        unused points'), then the others' its operator rows name (its ghosts', its node
        terms' and the columns of the relation rows it owns), each found at its owner with its
        value, its coefficient and its relation (one plan, made again with the operator; q
        there fetched by ``eliminated_values``). Collective."""
        dm = self.dofmap
        dofs, coefs, refs, which = [np.zeros(0, np.int64)], [np.zeros(0)], [np.zeros(0)], []
        for k, r in enumerate(self.eliminated):
            order = np.argsort(r.a_rows)   # (one entry per row)
            dofs.append(r.a_dofs[order])
            coefs.append(r.a_vals[order])
            refs.append(r.values)
            which.append(np.full(r.nrows, k, dtype=np.int64))
        unused = np.setdiff1d(self.unused, np.concatenate(dofs))
        own = np.concatenate(dofs + [unused])
        n_own = own.size
        coefs = np.concatenate(coefs + [np.ones(unused.size)])
        refs = np.concatenate(refs + [np.zeros(unused.size)])
        which = np.concatenate(which + [np.full(unused.size, -1, dtype=np.int64)])
        # per owned DOF: its coefficient (0: not eliminated), value, relation and input id
        at = dm.local_dofs(own, owned="the eliminated and unused DOFs of this rank")
        table = np.zeros((dm.n_owned, 4))
        table[at, 0], table[at, 1], table[at, 2] = coefs, refs, which
        table[:, 3] = (dm.mesh.global_nodes[:dm.n_owned_nodes].astype(np.int64)[:, None]
                       * dm.ncomp + np.arange(dm.ncomp)).ravel()
        # the other ranks' DOFs its operator rows name: its ghosts', its node terms' and its
        # relation rows' columns (the off-process block's primal columns)
        op = self.op
        new, primal = dm.saddle_to_new(op.global_columns(np.arange(op.nnz_d, op.data.size)))
        q0, q1, _, _ = dm.owned()
        seen = np.union1d(dm.new_dof(np.arange(dm.n_owned, dm.n_local)), new[primal])
        seen = seen[(seen < q0) | (seen >= q1)]
        got = Fetch.of(dm, seen, width=4)(table).T   # (the four columns: one exchange)
        on = got[0] != 0.0
        self._elim_fetch = Fetch.of(dm, seen[on])   # (q at the others, at each use)
        self.elim_dofs = np.concatenate([own, got[3, on].astype(np.int64)])
        self.elim_coefs = np.concatenate([coefs, got[0, on]])
        self._elim_refs = np.concatenate([refs, got[1, on]])
        self._elim_which = np.concatenate([which, got[2, on].astype(np.int64)])
        # (the others': -1 where not on this rank; only the own part, elim_own, indexes)
        self.elim_local = np.concatenate([at, dm.local_dofs(self.elim_dofs[n_own:])])
        self.elim_saddle = np.concatenate([dm.input_saddle(own), dm.q_index(seen[on])])
        self.elim_own = np.arange(self.elim_dofs.size) < n_own
        self._n_eliminated = self.comm.allreduce(n_own)
        self.op.set_eliminated(self.elim_saddle)

    @property
    def n_eliminated(self) -> int:
        """Eliminated DOFs (every rank's: the same number on all)."""
        return self._n_eliminated

    def index_sets(self):
        """The PETSc index sets of the primal and multiplier fields."""
        return self.op.index_sets()

    def elim_values(self, t: float) -> np.ndarray:
        """Prescribed values of the eliminated DOFs this rank reads (``elim_dofs``) at t
        (A q = b with one coefficient per row)."""
        evolution = np.array([r.evolution(t) for r in self.eliminated] + [0.0])
        return self._elim_refs * evolution[self._elim_which] / self.elim_coefs

    # ------------------------------------------------------------ assembly

    def assemble(self, elements=None) -> PETSc.Mat:
        """Assemble [[K, -D], [A, 0]]; K from ``elements`` (ElementMatrices of the local cells,
        e.g. a tangent) or the elastic stiffness."""
        t0 = time.perf_counter()
        ke = self.composition.stiffness(self.rate) if elements is None else elements
        self._place_stiffness(ke)
        if not self.relation_set.scaled:
            self.kscale = self.op.diagonal_scale()
            self.relation_set.set_scales(self.kscale)
        self.op.relation_values(self.kscale)
        self.op.eliminate(self.kscale)
        mat = self.op.petsc_matrix()
        self.assembled = True
        # summed over a step's assemblies (one per Newton iteration); the driver takes it per step
        self.timings["assembly"] = self.timings.get("assembly", 0.0) + time.perf_counter() - t0
        return mat

    def preconditioner(self, mat: PETSc.Mat, gamma: float) -> AugmentedMatrix:
        """The iterative preset's augmented Lagrangian form of the operator as last assembled
        (its operator T M, preconditioning matrix and right-hand side transform): γ/k Aᵀ A of
        its enforced rows added to the stiffness block (``solvers.augmented``)."""
        if self._augmented is None:
            self._augmented = AugmentedMatrix(self.comm, self.dofmap)
        _, _, l0, l1 = self.dofmap.owned()
        own = slice(0, l1 - l0)   # (owned rows first among the held)
        return self._augmented.update(mat, self.op.active[own].astype(bool), self.kscale, gamma)

    def _place_stiffness(self, ke) -> None:
        """Node-pair sums of the element matrices into the operator's stiffness slots: summed
        there directly (no node-pair array beside the matrix) when the form can, else reduced
        and copied (a tangent with a few cells replaced)."""
        slot, npairs = self.pattern.pair_slot, self.pattern.nnzb
        received = self._received(ke)
        nc = self.dofmap.ncomp
        if isinstance(ke, ElementMatrices):
            ke = BlockMatrices(nc, [(np.arange(nc), np.arange(nc), ke, 1.0)])
        if isinstance(ke, BlockMatrices):
            target = StiffnessTarget(self.op.data, self.op.block_start)
            ke.reduce_into(slot, npairs, target)
            for ci, cj, keys, sums in received:
                for k, (i, j) in enumerate((i, j) for i in ci for j in cj):
                    target.data[target.starts[i, keys] + j] += sums[:, k]
        else:
            blocks = ke.reduce(slot, npairs)
            for ci, cj, keys, sums in received:
                for k, (i, j) in enumerate((i, j) for i in ci for j in cj):
                    blocks[i * nc + j, keys] += sums[:, k]
            self.op.set_stiffness(blocks)

    def to_owned(self, full: np.ndarray) -> np.ndarray:
        """A primal vector of this mesh's DOFs → this rank's rows (multiplier rows zero)."""
        return self.dofmap.owned_rows(full)

    def rhs(self, t: float, f_int: np.ndarray | None = None, q: np.ndarray | None = None,
            f_ext: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(owned right-hand side with lifting, full saddle vector of prescribed values).

        Linear: K q - D λ = F, A q = b. Newton (``f_int`` and ``q`` given, unknowns the
        increment Δq and the total λ): K Δq - D λ = F - f_int, A Δq = b - A q.
        """
        f_full = self.composition.known_loads(t, t, None) if f_ext is None else f_ext
        if f_int is not None:
            f_full = f_full - f_int
        target = self.relation_set.scaled_residual(t, q)
        values = self.elim_values(t)
        if q is not None and self.n_eliminated:
            values = values - self.eliminated_values(q)
        return self.rhs_from(f_full, target, values)

    def eliminated_values(self, q: np.ndarray) -> np.ndarray:
        """q at the eliminated DOFs this rank reads (``elim_dofs``): its own from q, the
        others' from their owners (a relation row owned here may name an eliminated DOF of
        a node this rank does not hold, whose value its lifting needs). Collective."""
        n = int(self.elim_own.sum())
        return np.concatenate([q[self.elim_local[:n]], self._elim_fetch(q)])

    def rhs_from(self, f_full: np.ndarray, target: np.ndarray, elim_values: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Right-hand side from a force vector (this mesh's DOFs), scaled relation values of
        every multiplied row, and values of the eliminated DOFs."""
        if not self.assembled and self._n_eliminated:   # (every rank alike: both collective)
            raise RuntimeError("a right-hand side of an operator built anew and not yet "
                               "assembled (its lifting of the eliminated DOFs is not known)")
        b = self.to_owned(f_full)
        q0, q1, l0, l1 = self.dofmap.owned()
        b[q1 - q0:] = target * self.op.active[:l1 - l0]   # (owned rows first among the held)
        # the eliminated DOFs' values only, not a whole saddle vector
        x_e = HeldValues(held_keys(self.elim_saddle), np.asarray(elim_values, dtype=float),
                         np.zeros(0))
        if self.elim_dofs.size:
            b -= self.op.lifting(x_e)
            b[self.op.elim_rows - self.offset] = self.kscale * x_e[self.op.elim_rows]
        return b, x_e

    def set_active(self, active_rows: np.ndarray) -> None:
        """Enforce these relation rows (a collapsed group carries its enforced row). A
        per-rank maximum group enforcing another row than its operator row holds: the
        relations were stacked again with that row's entries (``RelationSet.select``), and
        the operator is built anew (the next assembly makes a new PETSc matrix). Collective."""
        rset = self.relation_set
        active = rset.select(active_rows)
        if rset.restacked:   # (the same on every rank: the groups' rows are reduced)
            rset.restacked = False
            self._operator_anew(active)
        else:
            self.op.active = active

    def carry(self, rows: np.ndarray) -> None:
        """The maximum groups' operator rows hold these rows' entries (``RelationSet.carried``
        of the run a restart continues), the operator built anew when that changes them.
        Collective."""
        if self.relation_set.carry(rows):   # (the same on every rank)
            self._operator_anew(self.op.active)

    def free_rows(self) -> np.ndarray:
        """Mask of this rank's primal rows that are not eliminated."""
        q0, q1, _, _ = self.dofmap.owned()
        mask = np.zeros(self.op.nrows, dtype=bool)
        mask[:q1 - q0] = True
        mask[self.op.elim_rows - self.offset] = False
        return mask

    # ------------------------------------------------------------ back to fields

    def gather(self, x_owned: np.ndarray) -> HeldValues:
        """What this rank holds of the saddle vector (its DOFs and multipliers, ghosts
        included) from its owned rows (the DOF map's forward exchanges)."""
        return self.dofmap.gather(x_owned)

    def with_primal(self, x_full: HeldValues, q: np.ndarray) -> HeldValues:
        """A copy of ``x_full`` with its primal part replaced by q."""
        return x_full.with_q(q)

    def multipliers(self, x_full) -> np.ndarray:
        """Unscaled λ of this rank's owned multiplier rows from a held saddle vector."""
        return self.relation_set.multipliers(x_full.lam)

    def unpack(self, x_full: np.ndarray, t: float, f_int: np.ndarray | None = None,
               f_ext: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Primal vector (this mesh's DOFs, owned then ghosts) and unscaled multipliers of
        every relation. Collective."""
        q = x_full.q
        lam = self.multipliers(x_full)
        out = self.relation_set.per_relation(lam)
        if self.eliminated:
            out.update(self._eliminated_multipliers(x_full, t, f_int, f_ext))
        return q, out

    def _eliminated_multipliers(self, x_full: np.ndarray, t: float, f_int: np.ndarray | None,
                                f_ext: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """λ = (F - row of [K, -D] x) / a on each eliminated row (the row before zeroing); with
        ``f_int`` (nonlinear) the stiffness part of the row is f_int instead of K q."""
        f_full = self.composition.known_loads(t, t, None) if f_ext is None else f_ext
        if f_int is None:
            row_vals = self.op.eliminated_rows(x_full)
        else:  # x_full holds λ; the primal part of the row is the internal force
            row_vals = self.to_owned(f_int) - self.relation_set.reactions(self.multipliers(x_full))
        own = self.elim_own
        sad, local = self.elim_saddle[own], self.elim_local[own]
        lam = (f_full[local] - row_vals[sad - self.offset]) / self.elim_coefs[own]
        out, start = {}, 0
        for r in self.eliminated:   # (each rank its own rows: ``Relation.ids``)
            out[r.name] = lam[start:start + r.nrows]
            start += r.nrows
        return out


def _rows(a: np.ndarray) -> np.ndarray:
    """The rows of a 2D integer array as single comparable items (for ``np.isin``)."""
    a = np.ascontiguousarray(a, dtype=np.int64)
    return a.view(np.dtype((np.void, a.dtype.itemsize * a.shape[1]))).ravel()


class _Cover:
    """Pseudo-cells of ``nen`` nodes that hold every node pair of tuples of m nodes: the tuple
    itself padded (m ≤ nen: [a, b, b, ...]), or, wider, cut into chunks of h = nen // 2 nodes
    (the last padded) and one pseudo-cell per pair of chunks i ≤ j, [chunk i, chunk j]: the
    pattern of a tuple wider than a cell (a contact row's span) without widening the cells."""

    def __init__(self, m: int, nen: int):
        self.m, self.nen = m, nen
        self.h = m if m <= nen else max(nen // 2, 1)
        self.nch = -(-m // self.h)
        self.i, self.j = np.triu_indices(self.nch)           # the chunk pairs, i ≤ j
        self.per = self.i.size                               # pseudo-cells per tuple

    def cells(self, g: np.ndarray) -> np.ndarray:
        """(k · per, nen) pseudo-cells of the tuples g (k, m)."""
        k, h = len(g), self.h
        g = np.concatenate([g, np.repeat(g[:, -1:], self.nch * h - self.m, axis=1)], axis=1)
        if self.per == 1:
            out = g
        else:
            ch = g.reshape(k, self.nch, h)
            out = np.concatenate([ch[:, self.i], ch[:, self.j]], axis=2).reshape(-1, 2 * h)
        return np.concatenate([out, np.repeat(out[:, -1:], self.nen - out.shape[1], axis=1)],
                              axis=1)

    def slots(self, pair_slot: np.ndarray, start: int, k: int) -> np.ndarray:
        """The (m, m, k) slots of the tuples' node pairs, their pseudo-cells from ``start``."""
        m, h = self.m, self.h
        if self.per == 1:
            return np.ascontiguousarray(pair_slot[:m, :m, start:start + k])
        a = np.arange(m)
        ca, cb = np.meshgrid(a // h, a // h, indexing="ij")
        pa, pb = np.meshgrid(a % h, a % h, indexing="ij")
        lower = ca > cb                       # (a, b) in the pseudo-cell of chunks (cb, ca)
        lo_c, hi_c = np.minimum(ca, cb), np.maximum(ca, cb)
        # the pair's pseudo-cell among the tuple's: index of (lo_c, hi_c) in triu order
        cell = lo_c * self.nch - lo_c * (lo_c - 1) // 2 + (hi_c - lo_c)
        pa = np.where(lower, h + pa, pa)
        pb = np.where(lower, pb, h + pb)
        which = start + np.arange(k)[None, None, :] * self.per + cell[:, :, None]
        return np.ascontiguousarray(pair_slot[pa[:, :, None], pb[:, :, None], which])


def facet_slots(mesh, local_cells: np.ndarray, pair_slot: np.ndarray,
                facets: np.ndarray) -> np.ndarray:
    """A facet term's slots (nfn, nfn, k), derived like a cell term's: each boundary facet's
    node pairs are those of the local cell holding it (``pair_slot``'s, over ``local_cells``;
    a region keeps the facets with a node this rank owns, whose cell is local here)."""
    if facets.shape[0] == 0:
        return np.zeros((facets.shape[1], facets.shape[1], 0), dtype=np.intp)
    owner = match_facets(mesh, facets)[0]
    at = np.searchsorted(local_cells, owner)
    if np.any(at >= local_cells.size) or np.any(local_cells[np.minimum(at, local_cells.size - 1)]
                                                 != owner):
        raise RuntimeError("a facet term's facet lies in no cell this rank assembles")
    # where each facet node sits in its cell (the facet's own node order kept)
    place = np.argmax(mesh.cells[owner][:, None, :] == facets[:, :, None], axis=2)
    slots = pair_slot[place[:, :, None], place[:, None, :], at[:, None, None]]
    return np.ascontiguousarray(slots.transpose(1, 2, 0)).astype(np.intp)
