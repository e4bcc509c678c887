"""Numbering of the saddle system [[K, -D], [A, 0]] across ranks.

Rank r owns a contiguous block of the global vector: first its primal DOFs (its nodes × ncomp,
node-major), then its share of the multipliers. Primal DOFs are numbered ``new_node * ncomp + c``
with the partition's contiguous node numbering; multipliers are split in near-equal blocks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.mesh.partition import Partition


@dataclass
class Layout:
    ncomp: int
    part: Partition
    q_ranges: np.ndarray   # (nranks + 1,) primal DOF block of each rank (new numbering)
    l_ranges: np.ndarray   # (nranks + 1,) multiplier block of each rank
    offsets: np.ndarray    # (nranks + 1,) start of each rank's block in the saddle numbering

    @property
    def nq(self) -> int:
        return int(self.q_ranges[-1])

    @property
    def nl(self) -> int:
        return int(self.l_ranges[-1])

    @property
    def size(self) -> int:
        return int(self.offsets[-1])

    def owned(self, rank: int) -> tuple[int, int, int, int]:
        """(q_start, q_end, l_start, l_end) of a rank."""
        return (int(self.q_ranges[rank]), int(self.q_ranges[rank + 1]),
                int(self.l_ranges[rank]), int(self.l_ranges[rank + 1]))

    def new_dof(self, dofs: np.ndarray) -> np.ndarray:
        """Input DOF numbers (node * ncomp + c) to the partition's numbering."""
        dofs = np.asarray(dofs, dtype=np.int64)
        return self.part.new_of_old[dofs // self.ncomp].astype(np.int64) * self.ncomp + dofs % self.ncomp

    def q_index(self, new_dofs: np.ndarray) -> np.ndarray:
        """Saddle index of primal DOFs given in the new numbering."""
        owner = np.searchsorted(self.q_ranges, new_dofs, side="right") - 1
        return new_dofs - self.q_ranges[owner] + self.offsets[owner]

    def l_index(self, rows: np.ndarray) -> np.ndarray:
        """Saddle index of multipliers (global multiplier numbers)."""
        owner = np.searchsorted(self.l_ranges, rows, side="right") - 1
        nq_owner = self.q_ranges[owner + 1] - self.q_ranges[owner]
        return rows - self.l_ranges[owner] + self.offsets[owner] + nq_owner


def make_layout(part: Partition, ncomp: int, nmult: int) -> Layout:
    """Primal blocks from the node partition, multipliers split evenly."""
    q_ranges = part.node_ranges * ncomp
    nranks = part.nparts
    l_ranges = np.array([(nmult * r) // nranks for r in range(nranks + 1)], dtype=np.int64)
    sizes = np.diff(q_ranges) + np.diff(l_ranges)
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    return Layout(ncomp, part, q_ranges, l_ranges, offsets)
