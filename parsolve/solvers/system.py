"""The distributed saddle system of a model: partition, numbering, operator, right-hand side,
and the way back from the solution to named fields and multipliers.

Single-DOF associated equalities are eliminated (zeroed rows and columns, scaled unit
diagonal, lifting in the right-hand side) unless the scene asks otherwise; every other relation
gets multipliers. Their reactions are recovered from the unmodified rows, so both ways report
the same multipliers.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from parsolve.effects.compose import Composition, Rate
from parsolve.la.layout import make_layout
from parsolve.la.pattern import node_pattern
from parsolve.la.petsc import SaddleOperator
from parsolve.la.saddle import stack_relations
from parsolve.mesh.partition import partition
from parsolve.model import Model


@dataclass
class Solution:
    q: np.ndarray                       # full primal vector, input numbering
    multipliers: dict[str, np.ndarray]  # relation name -> λ (unscaled, per row)
    residual: float                     # relative residual of the linear system
    iterations: int


class SaddleSystem:
    """Everything a rank needs to assemble, solve and read back the saddle system."""

    def __init__(self, comm: MPI.Comm, model: Model):
        self.comm, self.model = comm, model
        mesh, ncomp = model.mesh, model.ncomp
        rank = comm.rank
        self.timings = {}
        t0 = time.perf_counter()
        self.part = partition(mesh, comm.size, model.scene.solver.partitioner, comm)
        self.eliminated = [r for r in model.relations if r.eliminable()]
        self.multiplied = [r for r in model.relations if not r.eliminable()]
        nmult = sum(1 if r.collapsed else r.nrows for r in self.multiplied)
        self.layout = lay = make_layout(self.part, ncomp, nmult)
        self.local_cells = self.part.local_cells(rank, mesh.cells)
        lumped = model.scene.time is None or model.scene.time.mass == "lumped"
        self.composition = Composition(model, self.local_cells, lumped)
        self.rate: Rate | None = None  # the rate terms of a transient step (set by the stepper)
        new_cells = self.part.new_of_old[mesh.cells[self.local_cells]]
        lo, hi = self.part.node_ranges[rank], self.part.node_ranges[rank + 1]
        self.pattern = pattern = node_pattern(new_cells, lo, hi, ncomp, mesh.num_points)
        self.block = stack_relations(self.multiplied, lay)
        self.op = SaddleOperator(comm, lay, pattern, self.block)
        ndof = mesh.num_points * ncomp
        self.saddle_of_input = lay.q_index(lay.new_dof(np.arange(ndof)))
        self.saddle_of_mult = lay.l_index(np.arange(nmult))
        q0, q1, l0, l1 = lay.owned(rank)
        self.owned_input_dofs = np.flatnonzero((lay.new_dof(np.arange(ndof)) >= q0)
                                               & (lay.new_dof(np.arange(ndof)) < q1))
        self.offset = int(lay.offsets[rank])
        self._elimination_setup()
        self.timings["setup"] = time.perf_counter() - t0
        self.assembled = False

    # ------------------------------------------------------------ elimination

    def unused_dofs(self) -> np.ndarray:
        """DOFs of the points no cell uses (Gmsh writes such points): held at zero, out of
        the system's way, instead of making it singular."""
        mesh = self.model.mesh
        used = np.zeros(mesh.num_points, dtype=bool)
        used[mesh.cells.ravel()] = True
        nodes = np.flatnonzero(~used)
        return (nodes[:, None] * self.model.ncomp + np.arange(self.model.ncomp)).ravel()

    def _elimination_setup(self) -> None:
        dofs, coefs = [], []
        for r in self.eliminated:
            order = np.argsort(r.a_rows)
            dofs.append(r.a_dofs[order])
            coefs.append(r.a_vals[order])
        self.n_unused = 0
        unused = self.unused_dofs()
        if unused.size:
            taken = np.concatenate(dofs) if dofs else np.zeros(0, dtype=np.int64)
            unused = np.setdiff1d(unused, taken)
            self.n_unused = unused.size
            dofs.append(unused)
            coefs.append(np.ones(unused.size))
        self.elim_dofs = np.concatenate(dofs) if dofs else np.zeros(0, dtype=np.int64)
        self.elim_coefs = np.concatenate(coefs) if coefs else np.zeros(0)
        sad = self.saddle_of_input[self.elim_dofs]
        n = self.op.nrows
        own = (sad >= self.offset) & (sad < self.offset + n)
        self.elim_own = own
        self.op.set_eliminated(sad)

    def elim_values(self, t: float) -> np.ndarray:
        """Prescribed values of the eliminated DOFs at t (A q = b with one coefficient per row)."""
        if self.elim_dofs.size == 0:
            return np.zeros(0)
        # each row holds one entry and dofs were sorted by row: values line up with rhs rows
        values = [r.rhs(t) for r in self.eliminated] + [np.zeros(self.n_unused)]
        return np.concatenate(values) / self.elim_coefs

    # ------------------------------------------------------------ assembly

    def assemble(self, elements=None) -> PETSc.Mat:
        """Assemble [[K, -D], [A, 0]]; K from ``elements`` (ElementMatrices of the local cells,
        e.g. a tangent) or the elastic stiffness."""
        t0 = time.perf_counter()
        ke = self.composition.stiffness(self.rate) if elements is None else elements
        self.op.set_stiffness(ke.reduce(self.pattern.pair_slot, self.pattern.nnzb))
        if self.block.row_scale is None:
            self.kscale = self.op.diagonal_scale()
            self.block.set_scales(self.kscale)
        self.op.relation_values(self.kscale)
        self.op.eliminate(self.kscale)
        mat = self.op.petsc_matrix()
        self.assembled = True
        self.timings["assembly"] = time.perf_counter() - t0
        return mat

    def to_owned(self, full: np.ndarray) -> np.ndarray:
        """A full primal vector (input numbering) → this rank's rows (multiplier rows zero)."""
        out = np.zeros(self.op.nrows)
        own = self.owned_input_dofs
        out[self.saddle_of_input[own] - self.offset] = full[own]
        return out

    def rhs(self, t: float, f_int: np.ndarray | None = None, q: np.ndarray | None = None,
            f_ext: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(owned right-hand side with lifting, full saddle vector of prescribed values).

        Linear: K q - D λ = F, A q = b. Newton (``f_int`` and ``q`` given, unknowns the
        increment Δq and the total λ): K Δq - D λ = F - f_int, A Δq = b - A q.
        """
        f_full = self.model.external_load(t) if f_ext is None else f_ext
        if f_int is not None:
            f_full = f_full - f_int
        target = self.block.rhs(t)
        if q is not None and self.block.nrows:
            target = target - self.primal_values(q)[self.block.rep_row] * self.block.row_scale
        values = self.elim_values(t)
        if q is not None and self.elim_dofs.size:
            values = values - q[self.elim_dofs]
        return self.rhs_from(f_full, target, values)

    def rhs_from(self, f_full: np.ndarray, target: np.ndarray, elim_values: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Right-hand side from a force vector (input numbering), scaled relation values of
        every multiplied row, and values of the eliminated DOFs."""
        b = self.to_owned(f_full)
        q0, q1, l0, l1 = self.layout.owned(self.comm.rank)
        b[q1 - q0:] = (target * self.op.active)[l0:l1]
        x_e = np.zeros(self.layout.size)
        if self.elim_dofs.size:
            x_e[self.saddle_of_input[self.elim_dofs]] = elim_values
            b -= self.op.lifting(x_e)
            b[self.op.elim_rows - self.offset] = self.kscale * x_e[self.op.elim_rows]
        return b, x_e

    def set_active(self, active_rows: np.ndarray) -> None:
        """Enforce these relation rows (a collapsed group carries its enforced row)."""
        self.op.active = self.block.select(active_rows)

    def gap(self, t: float, q: np.ndarray) -> np.ndarray:
        """b(t) - A q of every multiplier row, unscaled."""
        if not self.multiplied:
            return np.zeros(0)
        b = np.concatenate([r.rhs(t) for r in self.multiplied])
        return (b - self.primal_values(q))[self.block.rep_row]

    def primal_values(self, q: np.ndarray) -> np.ndarray:
        """A q of every multiplied row (unscaled), q a full primal vector (input numbering)."""
        return np.concatenate([r.primal(q) for r in self.multiplied]) if self.multiplied \
            else np.zeros(0)

    def reactions(self, lam: np.ndarray) -> np.ndarray:
        """Owned rows of D λ (unscaled λ of all multiplied rows)."""
        blk = self.block
        q0, q1, _, _ = self.layout.owned(self.comm.rank)
        own = (blk.d_rows >= q0) & (blk.d_rows < q1)
        out = np.zeros(self.op.nrows)
        out[:q1 - q0] = np.bincount(blk.d_rows[own] - q0, weights=blk.d_vals[own] * lam[blk.d_cols[own]],
                                    minlength=q1 - q0)
        return out

    def free_rows(self) -> np.ndarray:
        """Mask of this rank's primal rows that are not eliminated."""
        q0, q1, _, _ = self.layout.owned(self.comm.rank)
        mask = np.zeros(self.op.nrows, dtype=bool)
        mask[:q1 - q0] = True
        mask[self.op.elim_rows - self.offset] = False
        return mask

    # ------------------------------------------------------------ back to fields

    def gather(self, x_owned: np.ndarray) -> np.ndarray:
        """The whole saddle vector on every rank (buffer collective: no pickling)."""
        if not hasattr(self, "_gather_counts"):
            self._gather_counts = np.array(self.comm.allgather(int(x_owned.size)))
        out = np.empty(int(self._gather_counts.sum()))
        self.comm.Allgatherv(np.ascontiguousarray(x_owned, dtype=float), [out, self._gather_counts])
        return out

    def multipliers(self, x_full: np.ndarray) -> np.ndarray:
        """Unscaled λ of every multiplied row from a full saddle vector."""
        return x_full[self.saddle_of_mult] * self.block.col_scale if self.block.nrows else np.zeros(0)

    def unpack(self, x_full: np.ndarray, t: float, f_int: np.ndarray | None = None,
               f_ext: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Primal vector (input numbering) and unscaled multipliers of every relation."""
        q = x_full[self.saddle_of_input]
        lam = self.multipliers(x_full)
        out = {}
        per_row = self.block.row_values(lam) if self.block.nrows else lam
        for k, r in enumerate(self.multiplied):
            out[r.name] = per_row[self.block.row_first[k]:self.block.row_first[k + 1]]
        if self.eliminated:
            out.update(self._eliminated_multipliers(x_full, t, f_int, f_ext))
        return q, out

    def _eliminated_multipliers(self, x_full: np.ndarray, t: float, f_int: np.ndarray | None,
                                f_ext: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """λ = (F - row of [K, -D] x) / a on each eliminated row (the row before zeroing); with
        ``f_int`` (nonlinear) the stiffness part of the row is f_int instead of K q."""
        f_full = self.model.external_load(t) if f_ext is None else f_ext
        if f_int is None:
            row_vals = self.op.eliminated_rows(x_full)
        else:  # x_full holds λ; the primal part of the row is the internal force
            row_vals = self.to_owned(f_int) - self.reactions(self.multipliers(x_full))
        sad = self.saddle_of_input[self.elim_dofs]
        lam = np.zeros(self.elim_dofs.size)
        own = self.elim_own
        lam[own] = (f_full[self.elim_dofs[own]] - row_vals[sad[own] - self.offset]) / self.elim_coefs[own]
        self.comm.Allreduce(MPI.IN_PLACE, lam, op=MPI.SUM)
        out, start = {}, 0
        for r in self.eliminated:
            out[r.name] = lam[start:start + r.nrows]
            start += r.nrows
        return out
