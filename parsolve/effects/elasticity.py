"""Elasticity (small strains, linear or nonlinear materials): the displacement field "u",
the stiffness or tangent of the cells, internal forces, and stresses and history variables as
outputs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsolve.effects.base import Effect
from parsolve.errors import InputError
from parsolve.fem import kernels
from parsolve.fem.axisymmetric import is_axisymmetric
from parsolve.fem.element_matrices import (CellKernel, ElementMatrices, Term, block_cells,
                                           cell_ranges)
from parsolve.fem.elements import element
from parsolve.fem.materials.base import REQUIRED, parameter_problem
from parsolve.fem.materials.elastic import Elastic
from parsolve.fem.materials.mazars import Mazars
from parsolve.fem.materials.von_mises import VonMises
from parsolve.fields import VECTOR_COMPONENTS, Field
from parsolve.mesh.mesh import Mesh

MODELS = {"elastic": Elastic, "mazars": Mazars, "von_mises": VonMises}


@dataclass
class MaterialSpec:
    """One [[materials]] entry: a model and its parameters on a region."""
    region: str
    model: str
    params: dict
    key: str
    density: float | None = None   # mass per unit volume (gravity loads)


def parse(t, dim: int) -> MaterialSpec:
    """[[materials]]: ``region`` (default all cells), ``model`` and the parameters the model
    declares (``Material.PARAMETERS``: the model's own rules, checked here so that the error
    names the key, and again by the model's constructor)."""
    region = t.get("region", str, "all")
    model = t.get("model", str, "elastic", choices=tuple(MODELS))
    declared = MODELS[model].PARAMETERS
    params = {p: t.get(p, float) if default is REQUIRED else t.get(p, float, default)
              for p, (default, _) in declared.items()}
    problem = parameter_problem(declared, params)
    if problem is not None:
        raise t.error(*problem)
    density = t.get("density", float, None)
    if density is not None and density <= 0:
        raise t.error("density", "must be positive")
    t.done()
    return MaterialSpec(region, model, params, t.path, density)


def declared_fields(spec: MaterialSpec, dim: int) -> dict[str, int]:
    """The displacement, one component per direction."""
    return {"u": dim}


def regions(spec: MaterialSpec) -> list[tuple[str, str]]:
    return [(spec.region, spec.key + ".region")]


def labels(specs: list[MaterialSpec]) -> list[str]:
    """What the scene's effect list says beyond "elasticity"."""
    return ["nonlinear material"] if any(s.model != "elastic" for s in specs) else []


def build(specs: list[MaterialSpec], ctx) -> "Elasticity":
    """One effect for every [[materials]] entry (later entries override earlier ones)."""
    scene = ctx.scene
    return Elasticity(ctx.mesh, scene.hypothesis, scene.thickness, specs, ctx.regions,
                      scene.source)


AFFINE = ("triangle", "tetra")
HISTORY = (("damage", "D"), ("plastic_strain", "p"))   # written cell means of the states   # constant gradients: one strain per cell
POST_BLOCK_BYTES = 8 << 20       # work arrays of one block of the stress post-processing

class Elasticity(Effect):
    """Materials per cell (later entries of the scene override earlier ones on shared cells)."""

    name = "elasticity"

    def __init__(self, mesh: Mesh, hypothesis: str, thickness: float, materials: list, regions,
                 source: str):
        self.mesh, self.hypothesis = mesh, hypothesis
        self.thickness = thickness if mesh.dim == 2 else 1.0
        self.axisymmetric = is_axisymmetric(self.thickness)   # x = r, y = z; weights 2π r
        if self.axisymmetric:
            self.thickness.check_mesh(mesh.points[:mesh.n_owned], regions.comm)
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
        self.nv = self.C.shape[1]     # Voigt components: 3 (plane), 4 (axisymmetric), 6 (3D)
        self.nonlinear = any(not isinstance(m, Elastic) for m in self.models)
        self.linear = not self.nonlinear
        # Mazars' consistent tangent is not symmetric (its secant (1 - D) C is)
        self.symmetric_secant = True
        self.symmetric = not any(isinstance(m, Mazars) for m in self.models)
        # effects imposing a strain on the material (thermal expansion): the stresses are
        # C (ε − Σ ε*), each giving ``eigenstrain(cells, values)`` = (cell means, at nodes)
        self.eigenstrains: list = []
        # ∫ ε(v) : C ε(u) over every cell: the stiffness, or a nonlinear material's tangent
        self.term = Term("u", "u", symmetric=self.symmetric, linear=self.linear)

    def fields(self) -> list[Field]:
        return [Field("u", VECTOR_COMPONENTS[:self.mesh.dim], "displacement", displacement=True)]

    def output_names(self) -> list[str]:
        """The stress, and the history variables its materials have (``internal_variables``)."""
        keys = set().union(*(m.init_state(1) for m in self.models))
        return ["stress"] + [name for name, key in HISTORY if key in keys]

    def increment_size(self, cells: np.ndarray, values: dict[str, np.ndarray]) -> float:
        """The largest strain component of the increment ``values`` on these cells (a block of
        cells at a time: the strain operator B of a block, never every cell's)."""
        if not len(cells):
            return 0.0
        u = values["u"]
        ndof = self.mesh.cells.shape[1] * self.ncomp
        one = self.geometry(cells[:1]).strain_operator()   # sizes (nq, nv) from one cell
        largest = 0.0
        for sl in cell_ranges(len(cells), block_cells(one.shape[1] * one.shape[2] * ndof * 8)):
            eps = kernels.strains(self.geometry(cells[sl]).strain_operator(),
                                  u[self.mesh.cells[cells[sl]]].reshape(-1, ndof))
            largest = max(largest, float(np.abs(eps).max()))
        return largest

    def terms(self) -> list[Term]:
        return [self.term]

    def term_values(self, term: Term, cells: np.ndarray) -> ElementMatrices:
        """The elastic stiffness (a nonlinear material's initial tangent)."""
        return self.stiffness(cells)

    def init_state(self, cells: np.ndarray):
        return self.init_state_qp(cells)

    def evaluate(self, cells, values, state, secant: bool, at):
        """Internal forces, tangent, trial state and stresses at the quadrature points."""
        fe, tangent, trial, sig = self.evaluate_u(cells, values["u"], state, secant)
        nen = self.mesh.cells.shape[1]
        return {"u": fe.reshape(len(cells), nen, self.ncomp)}, [(self.term, tangent)], trial, sig

    def outputs(self, owned, values, extra, local_cells):
        """Nodal stress (volume-weighted average) and cell stress; with a nonlinear run
        (``extra`` = (stress at the quadrature points of the local cells, states)), the
        stress and history variables of the material state."""
        u = values["u"]
        npts = self.mesh.num_points
        nodes = self.mesh.cells[owned]
        if extra is None:
            sums, cell = self._stress_outputs(owned, u, values)
            return {"stress": sums}, {"stress": cell}
        stress_qp, states = extra
        pos = np.searchsorted(local_cells, owned)
        wq = kernels.weights_cell_last(self.mesh.points[nodes], self.mesh.cell_type,
                                       self.thickness)                 # (nq, nc)
        vol = wq.sum(axis=0)
        sig = np.einsum("cqv,qc->vc", stress_qp[pos], wq) / vol         # (nv, nc)
        if self.eigenstrains:   # the material saw ε alone
            sig -= self._hooke(owned, self._eigenstrain(owned, values)[0])
        cells = {name: value[pos] for name, value in
                 self.internal_variables(local_cells, states).items()}
        cells["stress"] = np.ascontiguousarray(sig.T)
        return {"stress": kernels.nodal_sums(nodes, sig, vol, npts)}, cells

    def geometry(self, cells: np.ndarray, at_nodes: bool = False) -> kernels.CellGeometry:
        coords = self.mesh.points[self.mesh.cells[cells]]
        points = element(self.mesh.cell_type).nodes if at_nodes else None
        return kernels.CellGeometry(coords, self.mesh.cell_type, thickness=self.thickness,
                                    points=points)

    def stiffness(self, cells: np.ndarray) -> ElementMatrices:
        """Element stiffness of the given cells, factored (geometry × constant Hooke tensor)
        and blocked: the geometric part (d², nen, nen, nc) is computed a block of cells at a
        time when the assembly reduces it (``CellKernel``), never for every cell at once."""
        mesh, d = self.mesh, self.mesh.dim

        # axisymmetric: a third gradient direction N_a / r carries the hoop strain (P is 9 rows)
        gradients = kernels.axisymmetric_gradients if self.axisymmetric else \
            (lambda x, ct, thickness: kernels.gradients_cell_last(x, ct, thickness=thickness))

        def geometric(sel, out):
            coords = mesh.points[mesh.cells[cells[sel]]]
            G, wdet = gradients(coords, mesh.cell_type, thickness=self.thickness)
            return kernels.geometric_part(G, wdet, out=out)

        tensors = np.stack([kernels.axisymmetric_tensor(C) if self.axisymmetric
                            else kernels.voigt_to_tensor(C, d) for C in self.C])
        kernel = CellKernel(geometric, len(cells), tensors.shape[1], mesh.cells.shape[1])
        return ElementMatrices(tensors=tensors, cell_material=self.cell_model[cells], kernel=kernel)

    def _stresses(self, cells: np.ndarray, u: np.ndarray, values: dict | None = None):
        """(stress at the cells' nodes (nv, nen, nc), or (nv, nc) where it is constant over the
        cell; cell-mean stress (nv, nc); cell measures (nc,)), cell-last, from the full
        displacement array u (npoints, ncomp). σ is linear in ε: the cell mean of σ is C times
        the cell mean of ε. On affine cells (P1 triangles and tetrahedra) the strain is
        constant: the stress at the nodes is the cell's (less the eigenstrains there)."""
        mesh = self.mesh
        if self.axisymmetric:
            return self._stresses_axisymmetric(cells, u, values)
        rows = kernels.cell_rows(mesh.points, u, mesh.cells[cells])        # (nen, 2d, nc)
        g, vol = kernels.mean_gradient(rows, mesh.cell_type, thickness=self.thickness)
        eps = kernels.voigt_of_gradient(g)
        mean, at_nodes = self._eigenstrain(cells, values)
        sig = self._hooke(cells, eps - mean)
        if mesh.cell_type in AFFINE:
            at = self._hooke(cells, eps[:, None] - at_nodes) if self.eigenstrains else sig
            return at, sig, vol
        g = kernels.gradient_at_nodes(rows, mesh.cell_type)
        return self._hooke(cells, kernels.voigt_of_gradient(g) - at_nodes), sig, vol

    def _eigenstrain(self, cells: np.ndarray, values: dict | None):
        """Σ of the ``eigenstrains`` (cell means, at the cells' nodes); 0 without any (or
        without the fields' values: ``cell_stress`` of a displacement alone)."""
        parts = [e.eigenstrain(cells, values) for e in self.eigenstrains if values is not None]
        return (sum(p[0] for p in parts), sum(p[1] for p in parts)) if parts else (0.0, 0.0)

    def _stresses_axisymmetric(self, cells: np.ndarray, u: np.ndarray, values: dict | None):
        """``_stresses`` of an axisymmetric model: the hoop strain u_r / r varies over every
        cell (no constant-strain cell), and the cell mean is weighted by 2π r, the volume. At
        a node on the axis the hoop strain is its limit ε_rr (u_r vanishes there). The
        eigenstrains (thermal expansion: its hoop component too) are subtracted."""
        mesh, d = self.mesh, self.mesh.dim
        rows = kernels.cell_rows(mesh.points, u, mesh.cells[cells])        # (nen, 2d, nc)
        g = kernels.gradient_at_nodes(rows, mesh.cell_type)                # (2, 2, nen, nc)
        r, ur = rows[:, 0], rows[:, d]
        hoop = np.where(r > 0.0, ur / np.where(r > 0.0, r, 1.0), g[0, 0])
        at_nodes = np.concatenate([kernels.voigt_of_gradient(g), hoop[None]])
        geo = self.geometry(cells)                                        # quadrature points
        ue = u[mesh.cells[cells]]                                          # (nc, nen, 2)
        vol = geo.wdet.sum(axis=1)
        mean = np.empty((4, len(cells)))
        mean[:3] = np.einsum("cqv,cq->vc", kernels.voigt_strain(geo.dNdx, ue), geo.wdet)
        mean[3] = np.einsum("cq,cq->c", (ue[:, :, 0] @ geo.N.T) / geo.r, geo.wdet)
        mean /= vol
        e_mean, e_nodes = self._eigenstrain(cells, values)
        return self._hooke(cells, at_nodes - e_nodes), self._hooke(cells, mean - e_mean), vol

    def _hooke(self, cells: np.ndarray, eps: np.ndarray) -> np.ndarray:
        """σ = C ε with each cell's own Hooke matrix, cell-last: eps (nv, ..., nc)."""
        nv = eps.shape[0]
        if len(self.models) == 1:
            return (self.C[0] @ eps.reshape(nv, -1)).reshape(eps.shape)
        sig = np.empty_like(eps)
        material = self.cell_model[cells]
        for k, C in enumerate(self.C):  # one product per material, on its cells
            idx = np.flatnonzero(material == k)
            part = eps[..., idx]
            sig[..., idx] = (C @ part.reshape(nv, -1)).reshape(part.shape)
        return sig

    def _stress_outputs(self, cells: np.ndarray, u: np.ndarray, values: dict | None = None
                        ) -> tuple[tuple, np.ndarray]:
        """((nodal stress sums (npoints, nv), weights (npoints,)), cell-mean stress (nc, nv))
        of the given cells, computed a block of cells at a time (``POST_BLOCK_BYTES`` of work
        arrays): nothing of the cells' size is formed but the cell stress itself."""
        mesh = self.mesh
        nen, d = mesh.cells.shape[1], mesh.dim
        nv = self.nv
        # per cell: the rows (nen, 2d), gradients and strains at the nodes, their stresses
        # (axisymmetric: also the shape gradients and strains at the quadrature points)
        per_cell = 8 * nen * (2 * d + 3 * d * d + 2 * nv)
        if self.axisymmetric:
            per_cell += 8 * 9 * (nen * d + nv + 2)
        size = block_cells(per_cell, POST_BLOCK_BYTES)
        cell = np.empty((len(cells), nv))
        sums, weights = np.zeros((mesh.num_points, nv)), np.zeros(mesh.num_points)
        for sl in cell_ranges(len(cells), size):
            at_nodes, sig, vol = self._stresses(cells[sl], u, values)
            cell[sl] = sig.T
            kernels.add_nodal_sums(sums, weights, mesh.cells[cells[sl]], at_nodes, vol)
        return (sums, weights), cell

    def cell_stress(self, cells: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Mean stress over each cell (nc, nv) (Voigt), from the full displacement array u
        (npoints, ncomp)."""
        return self._stress_outputs(cells, u)[1]

    def nodal_stress_sums(self, cells: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stress evaluated at each cell's nodes, summed per node with cell-volume weights.

        Returns (weighted sums (npoints, nvoigt), weights (npoints,)); the caller adds the
        ranks' sums and divides (a volume-weighted nodal average, as post-processors do)."""
        return self._stress_outputs(cells, u)[0]

    # ------------------------------------------------------------ nonlinear materials

    def init_state_qp(self, cells: np.ndarray) -> list[dict]:
        """History of every quadrature point of the given cells, per material model."""
        nq = self.geometry(cells[:1]).nq if cells.size else 1
        return [m.init_state(int((self.cell_model[cells] == k).sum()) * nq)
                for k, m in enumerate(self.models)]

    def evaluate_u(self, cells: np.ndarray, u: np.ndarray, states: list[dict], secant: bool = False):
        """Internal forces (nc, ndof), tangent ElementMatrices, trial states and the stress at
        the quadrature points (nc, nq, nv), at the displacement u (npoints, ncomp). Strains
        and forces go over cell blocks (the strain operator B of a block at a time); the
        tangent is blocked (``CellKernel``: B and K_e of a block when the assembly reduces
        it), so no array of every cell's B or K_e is held."""
        nen, d = self.mesh.cells.shape[1], self.ncomp
        ndof = nen * d
        one = self.geometry(cells[:1]).strain_operator()   # sizes (nq, nv) from one cell
        nq, nv = one.shape[1], one.shape[2]
        # cells a block: B, its products with C and w|J|, K_e and its cell-last copy
        blk = block_cells(nq * nv * ndof * 8 * 3 + ndof * ndof * 8 * 2)
        eps = np.empty((len(cells), nq, nv))
        for sl in cell_ranges(len(cells), blk):
            B = self.geometry(cells[sl]).strain_operator()
            eps[sl] = kernels.strains(B, u[self.mesh.cells[cells[sl]]].reshape(-1, ndof))
        sig = np.empty_like(eps)
        tangent = None
        trial = []
        for k, model in enumerate(self.models):
            idx = np.flatnonzero(self.cell_model[cells] == k)
            s, c, st = model.update(eps[idx].reshape(-1, nv), states[k])
            if secant and "D" in st:  # damage: the secant (1 - D) C stays positive definite
                c = (1.0 - st["D"])[:, None, None] * model.C[None]
            sig[idx] = s.reshape(len(idx), nq, nv)
            tangent = _tangent(tangent, idx, c, len(cells), nq, nv)
            trial.append(st)
        if tangent is None:   # (no cells)
            tangent = np.empty((0, nq, nv, nv))
        fe = np.empty((len(cells), ndof))
        for sl in cell_ranges(len(cells), blk):
            geo = self.geometry(cells[sl])
            fe[sl] = kernels.internal_forces(geo.strain_operator(), geo.wdet, sig[sl])

        def values(sel, out):
            geo = self.geometry(cells[sel])
            ke = kernels.stiffness(geo.strain_operator(), geo.wdet, tangent[sel])
            n = len(ke)
            v = ke.reshape(n, nen, d, nen, d).transpose(2, 4, 1, 3, 0).reshape(d * d, nen, nen, n)
            if out is None:
                return np.ascontiguousarray(v)
            out[...] = v
            return out

        kernel = CellKernel(values, len(cells), d * d, nen, block=blk)
        return fe, ElementMatrices(kernel=kernel), trial, sig

    def internal_variables(self, cells: np.ndarray, states: list[dict]) -> dict[str, np.ndarray]:
        """Cell means of the scalar history variables worth plotting (damage, plastic strain)."""
        nq = self.geometry(cells[:1]).nq if cells.size else 1
        out = {}
        for name, key in HISTORY:
            if not any(key in st for st in states):
                continue
            field = np.zeros(len(cells))
            for k, st in enumerate(states):
                if key in st:
                    idx = np.flatnonzero(self.cell_model[cells] == k)
                    field[idx] = st[key].reshape(len(idx), nq).mean(axis=1)
            out[name] = field
        return out


def _tangent(tangent: np.ndarray | None, idx: np.ndarray, c: np.ndarray, ncells: int, nq: int,
             nv: int) -> np.ndarray:
    """The tangent (ncells, nq, nv, nv) with the cells ``idx``'s points' c (idx.size · nq, nv,
    nv) placed. One model's constant tangent on every cell (an elastic material's, the same
    matrix at every point) stays that one matrix seen at every point, not copied: the copy was
    about 0.8 KB per DOF in every Newton iteration of a 3D run."""
    if idx.size == 0:
        return tangent
    if idx.size == ncells and c.ndim == 3 and c.strides[0] == 0:
        return np.broadcast_to(c[0], (ncells, nq, nv, nv))
    if tangent is None:
        tangent = np.empty((ncells, nq, nv, nv))
    tangent[idx] = c.reshape(idx.size, nq, nv, nv)
    return tangent
