"""Named fields on the mesh nodes and the DOF numbering they share.

Every field lives on every node (the mesh's own interpolation: P1/Q1, or P2 on quadratic
cells). A node carries the components of all fields one after the other, so the DOF of
(node, field, component) is ``node * ncomp + offset[field] + component``: the node-pair
block assembly of ``la/`` works unchanged for any set of fields (the DMPlex default, point by
point), and each field is still addressable on its own (``dofs``, per-field index sets).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

VECTOR_COMPONENTS = ("x", "y", "z")


@dataclass(frozen=True)
class Field:
    name: str                      # name in the scene (relations, loads): "u", "h", "c_s"
    components: tuple[str, ...]    # ("x", "y") for a 2D vector, ("",) for a scalar
    output: str                    # name of /fields/<output> in the result file
    # a displacement: rigid-body modes are its null space, and no capacity holds it in time
    displacement: bool = False

    @property
    def ncomp(self) -> int:
        return len(self.components)

    @property
    def scalar(self) -> bool:
        return self.ncomp == 1


class FieldSet:
    """The fields of a model, in declaration order, and their place in a node's DOFs."""

    def __init__(self, fields: list[Field]):
        self.fields = list(fields)
        self.by_name = {f.name: f for f in self.fields}
        self.offset, start = {}, 0
        for f in self.fields:
            self.offset[f.name] = start
            start += f.ncomp
        self.ncomp = start

    def __contains__(self, name: str) -> bool:
        return name in self.by_name

    def __getitem__(self, name: str) -> Field:
        return self.by_name[name]

    def __iter__(self):
        return iter(self.fields)

    def names(self) -> list[str]:
        return [f.name for f in self.fields]

    def component(self, field: str, comp: int) -> int:
        """Place of (field, component) among a node's DOFs."""
        return self.offset[field] + comp

    def columns(self, field: str) -> np.ndarray:
        """The node-DOF columns of a field: view a (npoints, ncomp) array's part with them."""
        return np.arange(self.offset[field], self.offset[field] + self.by_name[field].ncomp)

    def dofs(self, field: str, nodes: np.ndarray) -> np.ndarray:
        """(len(nodes), field.ncomp) DOF numbers of a field at the given nodes."""
        nodes = np.asarray(nodes, dtype=np.int64)
        return nodes[:, None] * self.ncomp + self.columns(field)[None, :]
