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
        self.part = partition(mesh, comm.size)
        self.eliminated = [r for r in model.relations if r.eliminable()]
        self.multiplied = [r for r in model.relations if not r.eliminable()]
        nmult = sum(r.nrows for r in self.multiplied)
        self.layout = lay = make_layout(self.part, ncomp, nmult)
        self.local_cells = self.part.local_cells(rank, mesh.cells)
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

    def _elimination_setup(self) -> None:
        dofs, coefs, owners = [], [], []
        for r in self.eliminated:
            order = np.argsort(r.a_rows)
            dofs.append(r.a_dofs[order])
            coefs.append(r.a_vals[order])
        self.elim_dofs = np.concatenate(dofs) if dofs else np.zeros(0, dtype=np.int64)
        self.elim_coefs = np.concatenate(coefs) if coefs else np.zeros(0)
        sad = self.saddle_of_input[self.elim_dofs]
        n = self.op.nrows
        own = (sad >= self.offset) & (sad < self.offset + n)
        self.elim_own = own
        self.op.set_eliminated(sad)

    def elim_values(self, t: float) -> np.ndarray:
        """Prescribed values of the eliminated DOFs at t (A q = b with one coefficient per row)."""
        if not self.eliminated:
            return np.zeros(0)
        # each row holds one entry and dofs were sorted by row: values line up with rhs rows
        return np.concatenate([r.rhs(t) for r in self.eliminated]) / self.elim_coefs

    # ------------------------------------------------------------ assembly

    def assemble(self) -> PETSc.Mat:
        t0 = time.perf_counter()
        ke = self.model.elasticity.stiffness(self.local_cells)
        self.op.set_stiffness(ke.reduce(self.pattern.pair_slot, self.pattern.nnzb))
        if self.block.row_scale is None:
            self.kscale = self.op.diagonal_scale()
            self.block.set_scales(self.kscale)
        self.op.relation_values()
        self.op.eliminate(self.kscale)
        mat = self.op.petsc_matrix()
        self.assembled = True
        self.timings["assembly"] = time.perf_counter() - t0
        return mat

    def rhs(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(owned right-hand side with lifting, full saddle vector of prescribed values)."""
        n = self.op.nrows
        f_full = self.model.external_load(t)
        b = np.zeros(n)
        own = self.owned_input_dofs
        b[self.saddle_of_input[own] - self.offset] = f_full[own]
        q0, q1, l0, l1 = self.layout.owned(self.comm.rank)
        b[q1 - q0:] = self.block.rhs(t)[l0:l1]
        x_e = np.zeros(self.layout.size)
        if self.eliminated:
            x_e[self.saddle_of_input[self.elim_dofs]] = self.elim_values(t)
            b -= self.op.lifting(x_e)
            b[self.op.elim_rows - self.offset] = self.kscale * x_e[self.op.elim_rows]
        return b, x_e

    # ------------------------------------------------------------ back to fields

    def gather(self, x_owned: np.ndarray) -> np.ndarray:
        return np.concatenate(self.comm.allgather(x_owned))

    def unpack(self, x_full: np.ndarray, t: float) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Primal vector (input numbering) and unscaled multipliers of every relation."""
        q = x_full[self.saddle_of_input]
        lam = x_full[self.saddle_of_mult] * self.block.col_scale if self.block.nrows else np.zeros(0)
        out = {}
        for k, r in enumerate(self.multiplied):
            out[r.name] = lam[self.block.first_row[k]:self.block.first_row[k + 1]]
        if self.eliminated:
            out.update(self._eliminated_multipliers(x_full, t))
        return q, out

    def _eliminated_multipliers(self, x_full: np.ndarray, t: float) -> dict[str, np.ndarray]:
        """λ = (F - row of [K, -D] x) / a on each eliminated row (the row before zeroing)."""
        f_full = self.model.external_load(t)
        row_vals = self.op.eliminated_rows(x_full)
        sad = self.saddle_of_input[self.elim_dofs]
        lam = np.zeros(self.elim_dofs.size)
        own = self.elim_own
        lam[own] = (f_full[self.elim_dofs[own]] - row_vals[sad[own] - self.offset]) / self.elim_coefs[own]
        lam = self.comm.allreduce(lam, op=MPI.SUM)
        out, start = {}, 0
        for r in self.eliminated:
            out[r.name] = lam[start:start + r.nrows]
            start += r.nrows
        return out
