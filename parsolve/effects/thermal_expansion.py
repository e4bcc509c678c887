"""Thermal expansion: the temperature T of a scalar diffusion field acts on the elasticity as
an eigenstrain ε_th = α (T − T_ref) I, so that σ = C (ε − ε_th).

Coupled monolithically: the internal force of the displacement equations gains
−∫ Bᵀ C α (T − T_ref) m dΩ (m = (1, 1, 0) in 2D, (1, 1, 1, 0, 0, 0) in 3D, Voigt), i.e. an
off-diagonal operator block (u rows, T columns)

    B_uT[i a, b] = −∫ α ∂_j N_a S_ij N_b dΩ      (S = C m: the stress of a unit ε_th)

and a constant load B_uT T_ref (the reference state: a vector term), while the heat equations see nothing of
the displacements: the operator is block triangular in (u, T), hence unsymmetric
(``symmetric = False``: the solver set-up then picks LU, not Cholesky).

In 2D the elasticity's hypothesis decides what m and S are (isotropic material, E, ν):

- plane stress (σ_zz = 0, ε_zz free): the in-plane eigenstrain is α ΔT (1, 1, 0) and the 2D
  Hooke matrix applies as it is: S = C (1, 1, 0) = E / (1 − ν) (1, 1, 0).
- plane strain (ε_zz = 0 although the material would expand by α ΔT along z): in 3D
  σ_xx = λ (ε_xx + ε_yy − 3 α ΔT) + 2 μ (ε_xx − α ΔT), and the 2D plane-strain matrix
  gives λ (ε_xx + ε_yy) + 2 μ ε_xx − (2 λ + 2 μ) a for an in-plane eigenstrain a (1, 1, 0):
  the two agree for a = α ΔT (3 λ + 2 μ) / (2 λ + 2 μ) = (1 + ν) α ΔT. So the effective
  in-plane eigenstrain is (1 + ν) α ΔT (1, 1, 0) and S = E / (1 − 2 ν) (1, 1, 0); the
  out-of-plane stress (not an output) would be σ_zz = ν (σ_xx + σ_yy) − E α ΔT.
- 3D: m = (1, 1, 1, 0, 0, 0), S = E / (1 − 2 ν) m.

The stress output of the elasticity subtracts the same effective eigenstrain (its
``eigenstrains`` hook): a free body heated uniformly is stress free, a clamped one is not.

Only linear elastic materials: a nonlinear material would have to see ε − ε_th in its own
update, which the off-diagonal block does not give; such scenes are refused. Arc-length runs
balance the composition's known loads (these loads included) plus μ P.

Scene schema::

    [[thermal_expansion]]
    field = "T"            # a scalar diffusion field: the temperature
    alpha = 1.2e-5         # expansion coefficient (1 / unit of T), on ``region``
    reference = 20.0       # T_ref: no thermal strain at this temperature (default 0)
    region = "all"         # where the body expands (elsewhere α = 0)
    [[thermal_expansion.regions]]   # optional: α per region (later entries override)
    region = "insert"
    alpha = 0.5e-5
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.effects.base import Effect, displacement_field
from parsolve.effects.elasticity import Elasticity
from parsolve.errors import InputError
from parsolve.fem import kernels
from parsolve.fem.element_matrices import CellKernel, ElementMatrices, Term, apply
from parsolve.fem.elements import default_degree, element, quadrature


@dataclass
class ThermalExpansionSpec:
    field: str
    alpha: list[tuple[str, float, str]]   # (region, α, key of α): the first is ``region``'s
    reference: float
    key: str


def parse(t, dim: int) -> ThermalExpansionSpec:
    """A ``[[thermal_expansion]]`` table (a scene Table) → spec (numbers checked finite)."""
    field = t.get("field", str, "T")
    levels = [(t.get("region", str, "all"), t.get("alpha", float), t.key("alpha"))]
    reference = t.get("reference", float, 0.0)
    for sub in t.tables("regions"):
        levels.append((sub.get("region", str), sub.get("alpha", float), sub.key("alpha")))
        sub.done()
    t.done()
    return ThermalExpansionSpec(field, levels, reference, t.path)


def regions(spec: ThermalExpansionSpec) -> list[tuple[str, str]]:
    """The regions a spec names, with their keys (checked by the scene before the mesh)."""
    return [(name, key.rsplit(".", 1)[0] + ".region") for name, _, key in spec.alpha]


def build(spec: ThermalExpansionSpec, ctx) -> "ThermalExpansion":
    return ThermalExpansion(spec, ctx.mesh, ctx.regions, ctx.fields, ctx.scene)


def _stress_of_unit_strain(model, hypothesis: str) -> np.ndarray:
    """S = C m_eff (Voigt) of an isotropic material: the stress of a unit α ΔT held at zero
    total strain (module docstring: plane strain's (1 + ν))."""
    E, nu = model.E, model.nu
    if hypothesis == "3d":
        return E / (1 - 2 * nu) * np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    if hypothesis == "axisymmetric":   # (rr, zz, rz, θθ): the hoop strain held too
        return E / (1 - 2 * nu) * np.array([1.0, 1.0, 0.0, 1.0])
    scale = E / (1 - 2 * nu) if hypothesis == "plane_strain" else E / (1 - nu)
    return scale * np.array([1.0, 1.0, 0.0])


class ThermalExpansion(Effect):
    name = "thermal_expansion"
    symmetric = False   # the (u, T) block has no (T, u) counterpart

    def __init__(self, spec: ThermalExpansionSpec, mesh, regions, fields, scene):
        self.spec, self.mesh, self.source = spec, mesh, scene.source
        key = spec.key + ".field"
        if spec.field not in fields or not fields[spec.field].scalar:
            raise InputError(f"names no scalar diffusion field: {spec.field!r} (fields: "
                             f"{', '.join(fields.names())})", self.source, key)
        first = next(s for s in scene.effect_specs.get("thermal_expansion", [spec])
                     if s.field == spec.field)
        if first.key != spec.key:   # (their eigenstrains would add: σ doubled)
            raise InputError(f"a second thermal expansion of field {spec.field!r} (the first is "
                             f"{first.key}): their eigenstrains would add; give one entry, with "
                             "[[thermal_expansion.regions]] for α per region", self.source, key)
        if not scene.materials:
            raise InputError("thermal expansion acts on elasticity: give [[materials]]",
                             self.source, spec.key)
        for m in scene.materials:
            if m.model != "elastic":
                raise InputError(f"thermal expansion needs linear elastic materials, not "
                                 f"{m.model!r}", self.source, m.key + ".model")
        self.axisymmetric = scene.hypothesis == "axisymmetric"
        self.thickness = scene.thickness if mesh.dim == 2 else 1.0
        self.alpha = np.zeros(mesh.num_cells)
        for name, value, akey in spec.alpha:
            region = regions(name, akey.rsplit(".", 1)[0] + ".region")
            if regions.cell_count(region.cells) == 0:   # (over every rank)
                raise InputError(f"region {name!r} contains no cell", self.source,
                                 akey.rsplit(".", 1)[0] + ".region")
            self.alpha[region.cells] = value
        self.elasticity: Elasticity | None = None
        # −∫ ε(v) : C α m N T over every cell: the displacement's equations on the temperature
        self.u = displacement_field(fields)
        self.term = Term(self.u, spec.field, symmetric=False)
        # B_uT T_ref: the reference state's load on the displacement (no thermal strain there)
        self.reference = Term(self.u, None)

    @property
    def field(self) -> str:
        return self.spec.field

    # ------------------------------------------------------------ coupling with elasticity

    def couple(self, effects: list[Effect]) -> None:
        """Finds the elasticity (the composition calls this before any block is asked for):
        its Hooke matrices make the block, its stresses subtract this eigenstrain. Per cell
        one (material, α) pair: the factored block's tensors."""
        self.elasticity = el = next(e for e in effects if isinstance(e, Elasticity))
        if self not in el.eigenstrains:
            el.eigenstrains.append(self)
        d = self.mesh.dim
        pairs = np.column_stack([el.cell_model.astype(float), self.alpha])
        combos, self.cell_combo = np.unique(pairs, axis=0, return_inverse=True)
        self.cell_combo = self.cell_combo.ravel()
        if not len(combos):   # a rank without cells: one (zero) tensor all the same
            combos = np.zeros((1, 2))
        S = [_stress_of_unit_strain(el.models[int(k)], el.hypothesis) for k, _ in combos]
        # M[j, i] = −α S_ij: the block's rows i from the geometric part's rows j
        tensor = _axisymmetric_tensor if self.axisymmetric else (lambda s: _voigt_tensor(s, d).T)
        self.tensors = np.stack([-a * tensor(s) for (_, a), s in zip(combos, S)])
        # the effective eigenstrain per unit α ΔT (Voigt), S = C m_eff: (1 + ν) in plane strain
        self.m_eff = np.stack([np.linalg.solve(el.C[int(k)], s) for (k, _), s in zip(combos, S)])

    def _rule(self) -> tuple[np.ndarray, int]:
        """The load rule (degree 2p: exact for ∫ ∂N_a N_b on affine cells): N (nq, nen) at
        its points, and its degree."""
        ct = self.mesh.cell_type
        degree = default_degree(ct, "load")
        return element(ct).shape(quadrature(ct, degree)[0]), degree

    def coupling(self, cells: np.ndarray) -> ElementMatrices:
        """B_uT of the given cells, factored (P[j, a, b] = ∫ ∂_j N_a N_b, one tensor per
        (material, α) pair) and blocked (``CellKernel``: a block of cells at a time)."""
        mesh = self.mesh
        N, degree = self._rule()
        if self.axisymmetric:   # the stiffness rule, with N_a / r as a third direction
            ct = mesh.cell_type
            N = element(ct).shape(quadrature(ct, kernels.stiffness_degree(ct, self.thickness))[0])

        def gradients(coords):
            if self.axisymmetric:
                return kernels.axisymmetric_gradients(coords, mesh.cell_type, self.thickness)
            return kernels.gradients_cell_last(coords, mesh.cell_type, degree, self.thickness)

        def geometric(sel, out):
            coords = mesh.points[mesh.cells[cells[sel]]]
            G, wdet = gradients(coords)
            d, nq, nen, nc = G.shape
            if out is None or out.shape != (d, nen, nen, nc):
                out = np.empty((d, nen, nen, nc))
            out[...] = 0.0
            for q in range(nq):   # Σ_q (w G_j)_a N_b: d·nq products of (nen, nen, nc)
                for j in range(d):
                    out[j] += (G[j, q] * wdet[q])[:, None, :] * N[q][None, :, None]
            return out

        rows = 3 if self.axisymmetric else mesh.dim
        kernel = CellKernel(geometric, len(cells), rows, mesh.cells.shape[1])
        return ElementMatrices(tensors=self.tensors, cell_material=self.cell_combo[cells],
                               kernel=kernel)

    def terms(self) -> list[Term]:
        return [self.term, self.reference]

    def term_values(self, term: Term, cells: np.ndarray) -> ElementMatrices | np.ndarray:
        """B_uT of the cells; for the reference state's vector term its load B_uT T_ref."""
        if term is self.reference:
            ref = np.full((len(cells), self.mesh.cells.shape[1], 1), self.spec.reference)
            return apply(self.coupling(cells), ref)
        return self.coupling(cells)

    # ------------------------------------------------------------ the eigenstrain (outputs)

    def eigenstrain(self, cells: np.ndarray, values: dict[str, np.ndarray]):
        """(cell means (nv, nc), values at the cells' nodes (nv, nen, nc)) of the effective
        eigenstrain α (T − T_ref) m_eff that the elasticity's stresses subtract."""
        mesh = self.mesh
        te = values[self.field][mesh.cells[cells], 0] - self.spec.reference   # (nc, nen)
        N, degree = self._rule()
        _, wdet = kernels.gradients_cell_last(mesh.points[mesh.cells[cells]], mesh.cell_type,
                                              degree, self.thickness)
        mean = ((N @ te.T) * wdet).sum(axis=0) / wdet.sum(axis=0)                # (nc,)
        m = self.m_eff[self.cell_combo[cells]].T * self.alpha[cells]            # (nv, nc)
        return m * mean, m[:, None, :] * te.T[None]


def _axisymmetric_tensor(s: np.ndarray) -> np.ndarray:
    """Stress (rr, zz, rz, θθ) → M[j, i] over the directions j = ∂r, ∂z, 1/r (the hoop
    strain u_r / r) and the components i = r, z."""
    return np.array([[s[0], s[2]], [s[2], s[1]], [s[3], 0.0]])


def _voigt_tensor(s: np.ndarray, d: int) -> np.ndarray:
    """Voigt stress (xx, yy, xy) or (xx, yy, zz, yz, xz, xy) → the symmetric d × d tensor."""
    if d == 2:
        return np.array([[s[0], s[2]], [s[2], s[1]]])
    return np.array([[s[0], s[5], s[4]], [s[5], s[1], s[3]], [s[4], s[3], s[2]]])
