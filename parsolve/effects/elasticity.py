"""Linear elasticity: stiffness of the cells, and stresses from a displacement field."""

from __future__ import annotations

import numpy as np

from parsolve.errors import InputError
from parsolve.fem import kernels
from parsolve.fem.element_matrices import ElementMatrices
from parsolve.fem.elements import element
from parsolve.fem.materials.elastic import Elastic
from parsolve.mesh.mesh import Mesh

MODELS = {"elastic": Elastic}


class Elasticity:
    """Materials per cell (later entries of the scene override earlier ones on shared cells)."""

    def __init__(self, mesh: Mesh, hypothesis: str, thickness: float, materials: list, regions,
                 source: str):
        self.mesh, self.hypothesis = mesh, hypothesis
        self.thickness = thickness if mesh.dim == 2 else 1.0
        self.ncomp = mesh.dim
        self.models = []
        self.cell_model = np.full(mesh.num_cells, -1, dtype=np.int64)
        for spec in materials:
            region = regions(spec.region, spec.key + ".region")
            if region.cells.size == 0:
                raise InputError(f"region {spec.region!r} contains no cell", source, spec.key + ".region")
            self.cell_model[region.cells] = len(self.models)
            self.models.append(MODELS[spec.model](hypothesis=hypothesis, **spec.params))
        missing = np.flatnonzero(self.cell_model < 0)
        if missing.size:
            raise InputError(f"{missing.size} cells have no material (e.g. cell {missing[0]})",
                             source, "materials")
        self.C = np.stack([m.C for m in self.models])

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

    def cell_stress(self, cells: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Mean stress over each cell (Voigt), from the full displacement array u (npoints, ncomp)."""
        geo = self.geometry(cells)
        B = geo.strain_operator()
        ue = u[self.mesh.cells[cells]].reshape(len(cells), -1)
        eps = kernels.strains(B, ue)
        sig = np.matmul(self.C[self.cell_model[cells]][:, None], eps[..., None])[..., 0]
        w = geo.wdet / geo.wdet.sum(axis=1, keepdims=True)
        return (sig * w[:, :, None]).sum(axis=1)

    def nodal_stress_sums(self, cells: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stress evaluated at each cell's nodes, summed per node with cell-volume weights.

        Returns (weighted sums (npoints, nvoigt), weights (npoints,)); the caller adds the
        ranks' sums and divides (a volume-weighted nodal average, as post-processors do).
        """
        mesh = self.mesh
        geo = self.geometry(cells, at_nodes=True)
        ue = u[mesh.cells[cells]].reshape(len(cells), -1)
        eps = kernels.strains(geo.strain_operator(), ue)               # (nc, nen, nv)
        sig = np.matmul(self.C[self.cell_model[cells]][:, None], eps[..., None])[..., 0]
        vol = self.geometry(cells).wdet.sum(axis=1)
        nodes = mesh.cells[cells].ravel()
        nv = sig.shape[2]
        sums = np.stack([np.bincount(nodes, weights=(sig[..., k] * vol[:, None]).ravel(),
                                     minlength=mesh.num_points) for k in range(nv)], axis=1)
        weights = np.bincount(nodes, weights=np.repeat(vol, mesh.cells.shape[1]),
                              minlength=mesh.num_points)
        return sums, weights
