"""Derived fields for ParaView: strain, von Mises stress, principal stresses, and nodal stress
averaged per material region (not smeared across interfaces).

Written into a copy of the result file (the input is never modified):

    /cell_fields/strain            cell mean of ε (Voigt: 2D xx yy xy, 3D xx yy zz yz xz xy),
                                   shear components ENGINEERING (γ = 2 ε_ij), as the B operator
    /cell_fields/von_mises         from the stored cell stress; 2D: σzz = 0 in plane stress,
                                   ν (σxx + σyy) in plane strain
    /cell_fields/principal_stress  the three principal values, largest first (2D: the in-plane
                                   pair and σzz, sorted together)
    /fields/stress_<region>        nodal stress averaged over the cells of one material entry
                                   (its ``region`` name); NaN at nodes outside that region, so a
                                   node on an interface carries one value per side
    /fields/<cell field>           every cell field (stored and derived: von_mises,
                                   principal_stress, strain, damage, ...) projected onto the
                                   nodes (lumped L², parsolve.post.projection); a name /fields
                                   has already gets ``_projected``: /fields/stress_projected
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import h5py
import numpy as np

from parsolve.fem import kernels
from parsolve.errors import InputError
from parsolve.io.xdmf import XdmfWriter, sidecar_path
from parsolve.post.result import NAN, Result


def full_tensor(sig: np.ndarray, dim: int, szz: np.ndarray | float = 0.0) -> np.ndarray:
    """Voigt stresses (..., 3, 4 or 6) → symmetric 3 × 3 tensors (..., 3, 3). Four components
    are axisymmetric (rr, zz, rz, θθ): the hoop stress is the third principal direction."""
    T = np.zeros(sig.shape[:-1] + (3, 3))
    if dim == 2:
        hoop = sig[..., 3] if sig.shape[-1] == 4 else szz
        T[..., 0, 0], T[..., 1, 1], T[..., 2, 2] = sig[..., 0], sig[..., 1], hoop
        T[..., 0, 1] = T[..., 1, 0] = sig[..., 2]
        return T
    for k in range(3):
        T[..., k, k] = sig[..., k]
    for row, (i, j) in zip((3, 4, 5), ((1, 2), (0, 2), (0, 1))):
        T[..., i, j] = T[..., j, i] = sig[..., row]
    return T


def von_mises(T: np.ndarray) -> np.ndarray:
    """sqrt(3/2 s : s) of 3 × 3 tensors (..., 3, 3)."""
    s = T - np.trace(T, axis1=-2, axis2=-1)[..., None, None] * np.eye(3) / 3.0
    return np.sqrt(1.5 * np.einsum("...ij,...ij->...", s, s))


def principal(T: np.ndarray) -> np.ndarray:
    """Principal values of 3 × 3 symmetric tensors, largest first (..., 3)."""
    return np.linalg.eigvalsh(T)[..., ::-1]


def out_of_plane(model, sig: np.ndarray) -> np.ndarray:
    """σzz of each cell (nsteps, ncells): 0 except in plane strain, ν (σxx + σyy); the hoop
    stress σθθ in an axisymmetric model (its 4th component)."""
    if model.scene.hypothesis == "axisymmetric":
        return sig[..., 3]
    if model.scene.hypothesis != "plane_strain":
        return np.zeros(sig.shape[:-1])
    nu = np.array([getattr(m, "nu", 0.0) for m in model.elasticity.models])[model.elasticity.cell_model]
    return nu * (sig[..., 0] + sig[..., 1])


def cell_strain(model, u: np.ndarray) -> np.ndarray:
    """Volume-weighted cell mean of ε (nsteps, ncells, nvoigt), engineering shear."""
    mesh = model.mesh
    cells = np.arange(mesh.num_cells)
    geo = model.elasticity.geometry(cells)
    B = geo.strain_operator()
    w = geo.wdet / geo.wdet.sum(axis=1, keepdims=True)
    return np.stack([(kernels.strains(B, us[mesh.cells].reshape(len(cells), -1)) * w[..., None]).sum(axis=1)
                     for us in u])


def region_nodal_stress(model, u: np.ndarray, cell_stress: np.ndarray) -> dict[str, np.ndarray]:
    """Nodal stress averaged (cell-volume weights) over each material entry's cells only.

    Linear elastic materials: σ = C ε evaluated at each cell's nodes (as the stored /fields/stress
    does, but per region); otherwise the stored cell-mean stresses are averaged."""
    mesh, el = model.mesh, model.elasticity
    cells = np.arange(mesh.num_cells)
    vol = el.geometry(cells).wdet.sum(axis=1)
    nen = mesh.cells.shape[1]
    if not el.nonlinear:
        Bn = el.geometry(cells, at_nodes=True).strain_operator()          # (nc, nen, nv, ndof)
        C = el.C[el.cell_model][:, None]
        at_nodes = np.stack([np.matmul(C, kernels.strains(Bn, us[mesh.cells].reshape(len(cells), -1))
                                       [..., None])[..., 0] for us in u])  # (ns, nc, nen, nv)
    else:
        at_nodes = np.repeat(cell_stress[:, :, None, :], nen, axis=2)
    out, names = {}, [spec.region for spec in model.scene.materials]
    for k in np.unique(el.cell_model):
        mine = np.flatnonzero(el.cell_model == k)
        nodes = mesh.cells[mine].ravel()
        weights = np.bincount(nodes, weights=np.repeat(vol[mine], nen), minlength=mesh.num_points)
        wsig = at_nodes[:, mine] * vol[mine][None, :, None, None]        # (ns, nm, nen, nv)
        ns, nv = wsig.shape[0], wsig.shape[-1]
        flat = wsig.transpose(0, 3, 1, 2).reshape(ns * nv, -1)
        # one bincount over (step, component, node) keys: no loop over nodes or cells
        keys = (np.arange(ns * nv)[:, None] * mesh.num_points + nodes[None, :]).ravel()
        sums = np.bincount(keys, weights=flat.ravel(), minlength=ns * nv * mesh.num_points)
        sums = sums.reshape(ns, nv, mesh.num_points).transpose(0, 2, 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            avg = np.where(weights[None, :, None] > 0, sums / weights[None, :, None], np.nan)
        name = names[k] if names.count(names[k]) == 1 else f"{names[k]}_{k}"
        out[f"stress_{name}"] = avg
    return out


def _write(src: str, out: Path, mesh, times: list, fields: dict, cell_fields: dict) -> None:
    """The copy with the derived datasets, and its XDMF. Written under a temporary name and
    renamed once whole: a failure (a full disk, a killed process aside) leaves nothing."""
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    written = [tmp]
    try:
        shutil.copyfile(src, tmp)
        with h5py.File(tmp, "r+") as f:
            for group, data in (("cell_fields", cell_fields), ("fields", fields)):
                for name, value in data.items():
                    if f"{group}/{name}" in f:
                        del f[f"{group}/{name}"]
                    f[f"{group}/{name}"] = value
                    if np.isnan(value).any():   # no value there (not damage): post.result.NAN
                        f[f"{group}/{name}"].attrs[NAN] = "no value at some nodes"
            all_fields = {n: f[f"fields/{n}"].shape[2] for n in f["fields"]}
            all_cells = {n: f[f"cell_fields/{n}"].shape[2] for n in f.get("cell_fields", {})}
        tmp.replace(out)
        written = [out, out.with_suffix(".xdmf"), sidecar_path(out)]
        xdmf = XdmfWriter(out, mesh)
        try:
            for step, t in enumerate(times):
                xdmf.append(step, t, all_fields, all_cells)
        finally:
            xdmf.close()
    except BaseException:
        for path in written:
            path.unlink(missing_ok=True)
        raise


def nodal_sources(res: Result, key: str) -> dict:
    """The stored cell fields to project, and under "taken" the names /fields has."""
    return {**{n: res.dataset(f"cell_fields/{n}", key) for n in res.names("cell_fields")},
            "taken": res.names("fields")}


def projected_fields(mesh: tuple, cell_fields: dict, taken: list[str]) -> dict[str, np.ndarray]:
    """Every cell field (but "taken") as a nodal field by lumped L² projection
    (parsolve.post.projection), named as ``projection.nodal_names`` says."""
    from parsolve.post.projection import nodal_names, project

    values = {n: v for n, v in cell_fields.items() if n != "taken"}
    names = nodal_names(list(values), taken)
    return {target: project(*mesh, values[n]) for n, target in names.items()}


def derive(src: str, out: str, key: str = "--derive") -> dict[str, list[str]]:
    """Copy ``src`` to ``out`` with the derived datasets and an XDMF beside it. Returns the
    names written: {"fields": [...], "cell_fields": [...]}."""
    from parsolve.post.scene_model import model_of

    with Result(src) as res:
        model = model_of(res, key)
        u = res.dataset("fields/displacement", key)
        sig = res.dataset("cell_fields/stress", key)
        times = res.times.tolist()
        stored, mesh = nodal_sources(res, key), (res.points, res.cells, res.cell_type)
    T = full_tensor(sig, model.mesh.dim, out_of_plane(model, sig))
    cell_fields = {"strain": cell_strain(model, u), "von_mises": von_mises(T)[..., None],
                   "principal_stress": principal(T)}
    fields = region_nodal_stress(model, u, sig)
    fields.update(projected_fields(mesh, {**stored, **cell_fields}, stored["taken"] + list(fields)))
    try:
        _write(src, Path(out), model.mesh, times, fields, cell_fields)
    except (OSError, RuntimeError) as exc:
        raise InputError(f"cannot write ({' '.join(str(exc).split())})", out, key) from None
    return {"fields": sorted(fields), "cell_fields": sorted(cell_fields)}
