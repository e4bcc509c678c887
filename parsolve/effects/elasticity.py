"""Elasticity (small strains, linear or nonlinear materials): the displacement field "u",
the stiffness or tangent of the cells, internal forces, and stresses and history variables as
outputs."""

from __future__ import annotations

import numpy as np

from parsolve.effects.base import Effect
from parsolve.errors import InputError
from parsolve.fem import kernels
from parsolve.fem.element_matrices import ElementMatrices
from parsolve.fem.elements import element
from parsolve.fem.materials.elastic import Elastic
from parsolve.fem.materials.mazars import Mazars
from parsolve.fem.materials.von_mises import VonMises
from parsolve.fields import VECTOR_COMPONENTS, Field
from parsolve.mesh.mesh import Mesh

MODELS = {"elastic": Elastic, "mazars": Mazars, "von_mises": VonMises}


AFFINE = ("triangle", "tetra")   # constant gradients: one strain per cell

class Elasticity(Effect):
    """Materials per cell (later entries of the scene override earlier ones on shared cells)."""

    name = "elasticity"

    def __init__(self, mesh: Mesh, hypothesis: str, thickness: float, materials: list, regions,
                 source: str):
        self.mesh, self.hypothesis = mesh, hypothesis
        self.thickness = thickness if mesh.dim == 2 else 1.0
        self.ncomp = mesh.dim
        self.models = []
        self.cell_model = np.full(mesh.num_cells, -1, dtype=np.int64)
        for spec in materials:
            region = regions(spec.region, spec.key + ".region")
            if regions.cell_count(region.cells) == 0:   # (over every rank)
                raise InputError(f"region {spec.region!r} contains no cell", source, spec.key + ".region")
            self.cell_model[region.cells] = len(self.models)
            try:
                self.models.append(MODELS[spec.model](hypothesis=hypothesis, **spec.params))
            except ValueError as exc:  # e.g. von Mises in plane stress
                raise InputError(str(exc), source, spec.key + ".model") from None
        missing = np.flatnonzero(self.cell_model < 0)
        if missing.size:
            raise InputError(f"{missing.size} cells have no material (e.g. cell {missing[0]})",
                             source, "materials")
        self.C = np.stack([m.C for m in self.models])
        self.nonlinear = any(not isinstance(m, Elastic) for m in self.models)
        self.linear = not self.nonlinear
        # Mazars' consistent tangent is not symmetric (its secant (1 - D) C is)
        self.symmetric_secant = True
        self.symmetric = not any(isinstance(m, Mazars) for m in self.models)

    def fields(self) -> list[Field]:
        return [Field("u", VECTOR_COMPONENTS[:self.mesh.dim], "displacement")]

    def output_names(self) -> list[str]:
        return ["stress", "damage", "plastic_strain"]

    def stiffness_blocks(self, cells: np.ndarray):
        return [("u", "u", self.stiffness(cells))]

    def init_state(self, cells: np.ndarray):
        return self.init_state_qp(cells)

    def evaluate(self, cells, values, state, secant: bool):
        """Internal forces, tangent, trial state and stresses at the quadrature points."""
        fe, tangent, trial, sig = self.evaluate_u(cells, values["u"], state, secant)
        nen = self.mesh.cells.shape[1]
        return {"u": fe.reshape(len(cells), nen, self.ncomp)}, [("u", "u", tangent)], trial, sig

    def outputs(self, owned, values, extra, local_cells):
        """Nodal stress (volume-weighted average) and cell stress; with a nonlinear run
        (``extra`` = (stress at the quadrature points of the local cells, states)), the
        stress and history variables of the material state."""
        u = values["u"]
        if extra is None:  # one geometry for both (the cell mean and the volume weights)
            geo = self.geometry(owned)
            sig = self.cell_stress(owned, u, geo)
            return {"stress": self.nodal_stress_sums(owned, u, geo, sig)}, {"stress": sig}
        stress_qp, states = extra
        pos = np.searchsorted(local_cells, owned)
        wq = self.geometry(owned).wdet
        sig = (stress_qp[pos] * wq[:, :, None]).sum(axis=1) / wq.sum(axis=1)[:, None]
        vol = wq.sum(axis=1)
        nodes = self.mesh.cells[owned].ravel()
        nen, npts = self.mesh.cells.shape[1], self.mesh.num_points
        sums = np.stack([np.bincount(nodes, weights=np.repeat(sig[:, k] * vol, nen), minlength=npts)
                         for k in range(sig.shape[1])], 1)
        weights = np.bincount(nodes, weights=np.repeat(vol, nen), minlength=npts)
        cells = {name: value[pos] for name, value in
                 self.internal_variables(local_cells, states).items()}
        cells["stress"] = sig
        return {"stress": (sums, weights)}, cells

    def geometry(self, cells: np.ndarray, at_nodes: bool = False) -> kernels.CellGeometry:
        coords = self.mesh.points[self.mesh.cells[cells]]
        points = element(self.mesh.cell_type).nodes if at_nodes else None
        return kernels.CellGeometry(coords, self.mesh.cell_type, thickness=self.thickness,
                                    points=points)

    def stiffness(self, cells: np.ndarray) -> ElementMatrices:
        """Element stiffness of the given cells, factored (geometry × constant Hooke tensor)."""
        coords = self.mesh.points[self.mesh.cells[cells]]
        G, wdet = kernels.gradients_cell_last(coords, self.mesh.cell_type, thickness=self.thickness)
        self._work = kernels.geometric_part(G, wdet, out=getattr(self, "_work", None))
        tensors = np.stack([kernels.voigt_to_tensor(C, self.mesh.dim) for C in self.C])
        return ElementMatrices(geometric=self._work, tensors=tensors,
                               cell_material=self.cell_model[cells])

    def cell_stress(self, cells: np.ndarray, u: np.ndarray,
                    geo: kernels.CellGeometry | None = None) -> np.ndarray:
        """Mean stress over each cell (Voigt), from the full displacement array u (npoints, ncomp);
        ``geo``: the cells' geometry at the quadrature points, if already computed."""
        geo = self.geometry(cells) if geo is None else geo
        eps = kernels.voigt_strain(geo.dNdx, u[self.mesh.cells[cells]])
        w = geo.wdet / geo.wdet.sum(axis=1, keepdims=True)
        # σ is linear in ε: the cell mean of σ is C times the cell mean of ε
        return self._hooke(cells, (eps * w[:, :, None]).sum(axis=1))

    def _hooke(self, cells: np.ndarray, eps: np.ndarray) -> np.ndarray:
        """σ = C ε with each cell's own Hooke matrix; eps (nc, ..., nv)."""
        C = self.C[self.cell_model[cells]]
        return np.einsum("cvw,c...w->c...v", C, eps)

    def nodal_stress_sums(self, cells: np.ndarray, u: np.ndarray,
                          geo: kernels.CellGeometry | None = None,
                          cell_sig: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Stress evaluated at each cell's nodes, summed per node with cell-volume weights.

        Returns (weighted sums (npoints, nvoigt), weights (npoints,)); the caller adds the
        ranks' sums and divides (a volume-weighted nodal average, as post-processors do).
        ``geo`` / ``cell_sig``: the geometry at the quadrature points and the cell stresses,
        if already computed. On affine cells (P1 triangles and tetrahedra) the strain is
        constant: the stress at the nodes is the cell's, and no geometry at the nodes is needed.
        """
        mesh = self.mesh
        vol = (self.geometry(cells) if geo is None else geo).wdet.sum(axis=1)
        if mesh.cell_type in AFFINE:
            cell_sig = self.cell_stress(cells, u, geo) if cell_sig is None else cell_sig
            sig = cell_sig[:, None, :]                                     # (nc, 1, nv)
        else:
            at_nodes = self.geometry(cells, at_nodes=True)
            sig = self._hooke(cells, kernels.voigt_strain(at_nodes.dNdx, u[mesh.cells[cells]]))
        sig = np.broadcast_to(sig, (cells.size, mesh.cells.shape[1], sig.shape[2]))
        nodes = mesh.cells[cells].ravel()
        nv = sig.shape[2]
        sums = np.stack([np.bincount(nodes, weights=(sig[..., k] * vol[:, None]).ravel(),
                                     minlength=mesh.num_points) for k in range(nv)], axis=1)
        weights = np.bincount(nodes, weights=np.repeat(vol, mesh.cells.shape[1]),
                              minlength=mesh.num_points)
        return sums, weights

    # ------------------------------------------------------------ nonlinear materials

    def init_state_qp(self, cells: np.ndarray) -> list[dict]:
        """History of every quadrature point of the given cells, per material model."""
        nq = self.geometry(cells[:1]).nq if cells.size else 1
        return [m.init_state(int((self.cell_model[cells] == k).sum()) * nq)
                for k, m in enumerate(self.models)]

    def evaluate_u(self, cells: np.ndarray, u: np.ndarray, states: list[dict], secant: bool = False):
        """Internal forces (nc, ndof), tangent ElementMatrices, trial states and the stress at
        the quadrature points (nc, nq, nv), at the displacement u (npoints, ncomp)."""
        geo = self.geometry(cells)
        B = geo.strain_operator()
        nc, nq, nv, ndof = B.shape
        eps = kernels.strains(B, u[self.mesh.cells[cells]].reshape(nc, ndof))
        sig = np.empty_like(eps)
        tangent = np.empty((nc, nq, nv, nv))
        trial = []
        for k, model in enumerate(self.models):
            idx = np.flatnonzero(self.cell_model[cells] == k)
            s, c, st = model.update(eps[idx].reshape(-1, nv), states[k])
            if secant and "D" in st:  # damage: the secant (1 - D) C stays positive definite
                c = (1.0 - st["D"])[:, None, None] * model.C[None]
            sig[idx] = s.reshape(len(idx), nq, nv)
            tangent[idx] = c.reshape(len(idx), nq, nv, nv)
            trial.append(st)
        fe = kernels.internal_forces(B, geo.wdet, sig)
        ke = kernels.stiffness(B, geo.wdet, tangent)           # (nc, ndof, ndof) node-major
        d, nen = self.ncomp, ndof // self.ncomp
        values = ke.reshape(nc, nen, d, nen, d).transpose(2, 4, 1, 3, 0).reshape(d * d, nen, nen, nc)
        return fe, ElementMatrices(values=np.ascontiguousarray(values)), trial, sig

    def internal_variables(self, cells: np.ndarray, states: list[dict]) -> dict[str, np.ndarray]:
        """Cell means of the scalar history variables worth plotting (damage, plastic strain)."""
        nq = self.geometry(cells[:1]).nq if cells.size else 1
        out = {}
        for name, key in (("damage", "D"), ("plastic_strain", "p")):
            if not any(key in st for st in states):
                continue
            field = np.zeros(len(cells))
            for k, st in enumerate(states):
                if key in st:
                    idx = np.flatnonzero(self.cell_model[cells] == k)
                    field[idx] = st[key].reshape(len(idx), nq).mean(axis=1)
            out[name] = field
        return out
