"""Diffusion of a scalar field (heat, Darcy head, a dissolved or gaseous concentration):
conductivity per region (isotropic or a tensor), capacity (storage) for transient runs, the
flux -k ∇h as output. Sources and boundary fluxes are load patterns on the field
(``[[loads]] field = ..., source / flux``); relations on it are like those on displacements.

Scene schema (one table per scalar field)::

    [[diffusion]]
    field = "h"                      # the field's name (relations, loads, /fields/h)
    initial = 0.0                    # transient runs: the field at t = 0 (or an expression)
    [[diffusion.materials]]          # later entries override earlier ones on shared cells
    region = "all"
    conductivity = 1.0               # or a tensor [[kxx, kxy], [kxy, kyy]]; 0: immobile
    capacity = 1.0                   # storage per unit volume (transient runs)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.effects.base import Effect
from parsolve.errors import InputError
from parsolve.fem import diffusion as kern
from parsolve.fem.axisymmetric import is_axisymmetric
from parsolve.fem.element_matrices import ElementMatrices, Term
from parsolve.fields import Field
from parsolve.mesh import selectors


@dataclass
class DiffusionMaterial:
    region: str
    conductivity: np.ndarray   # (dim, dim)
    capacity: float
    key: str


@dataclass
class DiffusionSpec:
    field: str
    materials: list[DiffusionMaterial]
    key: str
    initial: float | str = 0.0   # the field at t = 0: a number or an expression of x, y, z


def parse(t, dim: int) -> DiffusionSpec:
    """A ``[[diffusion]]`` table (a scene Table) → spec; raises the scene's InputError."""
    field = t.get("field", str, "h")
    if not field.isidentifier():
        raise t.error("field", f"a field name is an identifier, not {field!r}")
    initial = t.get("initial", (float, str), 0.0)
    materials = []
    for sub in t.tables("materials"):
        region = sub.get("region", str, "all")
        raw = sub.get("conductivity", (float, list))
        if isinstance(raw, list) and not (  # ragged, strings, booleans: refused before numpy
                len(raw) == dim and all(isinstance(r, list) and len(r) == dim for r in raw)
                and all(isinstance(v, (int, float)) and not isinstance(v, bool) for r in raw for v in r)):
            raise sub.error("conductivity", f"expected a number or a {dim}×{dim} tensor of numbers, "
                            f"got {raw!r}"[:200])
        if isinstance(raw, list):  # finite, of sane magnitude, like every number of a scene
            from parsolve.schema import check_number

            for i, row in enumerate(raw):
                for j, v in enumerate(row):
                    check_number(v, sub.source, f"{sub.key('conductivity')}[{i}][{j}]")
        k = _tensor(sub, raw, dim)
        capacity = sub.get("capacity", float, 1.0)
        if capacity < 0:
            raise sub.error("capacity", "must not be negative")
        sub.done()
        materials.append(DiffusionMaterial(region, k, capacity, sub.path))
    if not materials:
        raise t.error("materials", "a diffusion field needs at least one [[diffusion.materials]]")
    t.done()
    return DiffusionSpec(field, materials, t.path, initial)


def _tensor(sub, raw, dim: int) -> np.ndarray:
    if isinstance(raw, float):
        if raw < 0:
            raise sub.error("conductivity", "must not be negative")
        return raw * np.eye(dim)
    k = np.asarray(raw, dtype=float) if all(isinstance(r, list) for r in raw) else None
    if k is None or k.shape != (dim, dim):
        raise sub.error("conductivity", f"expected a number or a {dim}×{dim} tensor")
    if not np.allclose(k, k.T) or np.linalg.eigvalsh(0.5 * (k + k.T)).min() < 0:
        raise sub.error("conductivity", "a tensor must be symmetric positive semi-definite")
    return k


class Diffusion(Effect):
    name = "diffusion"

    def __init__(self, spec: DiffusionSpec, mesh, regions, thickness: float, source: str,
                 lumped: bool = True):
        self.spec, self.mesh, self.lumped = spec, mesh, lumped
        # ∫ ∇v · k ∇h (conduction) and ∫ c v h (capacity: lumped or consistent)
        self.conduction = Term(spec.field, spec.field)
        self.capacity_term = Term(spec.field, spec.field, rate=True)
        self.thickness = thickness if mesh.dim == 2 else 1.0
        if is_axisymmetric(self.thickness):   # x = r: weights 2π r in conductivity and capacity
            self.thickness.check_mesh(mesh.points[:mesh.n_owned], regions.comm)
        self.cell_material = np.full(mesh.num_cells, -1, dtype=np.int64)
        for i, m in enumerate(spec.materials):
            region = regions(m.region, m.key + ".region")
            if regions.cell_count(region.cells) == 0:   # (over every rank)
                raise InputError(f"region {m.region!r} contains no cell", source, m.key + ".region")
            self.cell_material[region.cells] = i
        missing = np.flatnonzero(self.cell_material < 0)
        if missing.size:
            raise InputError(f"{missing.size} cells have no diffusion material (e.g. cell "
                             f"{missing[0]})", source, spec.key + ".materials")
        self.tensors = np.stack([m.conductivity for m in spec.materials])
        self.start = spec.initial
        if isinstance(spec.initial, str):  # checked finite on every node here, before a solve
            self.start = selectors.evaluate_value(spec.initial, mesh.points, source,
                                                  spec.key + ".initial")
        self.capacity = np.array([m.capacity for m in spec.materials])

    @property
    def field(self) -> str:
        return self.spec.field

    def fields(self) -> list[Field]:
        return [Field(self.field, ("",), self.field)]

    def output_names(self) -> list[str]:
        return [f"{self.field}_flux"]

    def initial(self) -> dict[str, np.ndarray]:
        return {self.field: np.broadcast_to(np.asarray(self.start, dtype=float),
                                            (self.mesh.num_points,))[:, None]}

    def _coords(self, cells: np.ndarray) -> np.ndarray:
        return self.mesh.points[self.mesh.cells[cells]]

    def terms(self) -> list[Term]:
        return [self.conduction, self.capacity_term]

    def term_values(self, term: Term, cells: np.ndarray) -> ElementMatrices:
        if term is self.conduction:
            return kern.conductivity_blocks(self.mesh.points, self.mesh.cells[cells],
                                            self.mesh.cell_type, self.tensors,
                                            self.cell_material[cells], self.thickness)
        c = self.capacity[self.cell_material[cells]]
        coords, ct = self._coords(cells), self.mesh.cell_type
        values = kern.lumped_as_matrices(kern.lumped_mass(coords, ct, c, self.thickness)) \
            if self.lumped else kern.mass(coords, ct, c, self.thickness)
        return ElementMatrices(values=values)

    def outputs(self, owned, values, extra, local_cells):
        """Flux -k ∇h: cell means and volume-weighted nodal averages."""
        k = self.tensors[self.cell_material[owned]]
        flux, sums = kern.flux_outputs(self.mesh.points, self.mesh.cells[owned],
                                       self.mesh.cell_type, k, values[self.field])
        name = f"{self.field}_flux"
        return {name: sums}, {name: flux}
