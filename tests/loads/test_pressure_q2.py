"""Pressure on the curved faces of Q2 quadrilaterals read from Gmsh files: Lamé's thick
cylinder (plane strain) and thick sphere (axisymmetric, the same mesh as a meridian section)
under internal pressure, on nine-node (Lagrange) and eight-node (serendipity) cells whose
every node lies on its circle (``helpers.curved_q2``); the pressure's resultant on a
half-cylinder; the result's XDMF read by VTK with the biquadratic cell type.

Measured (error of u_r at the nodes / max |u_r(a)|, L² error of u over the cells / ‖u‖, cell
stress error / p) on 4 × 8 then 8 × 16 cells:

  quad9 plane strain   nodes 6.6e-5 → 4.3e-6 (15.1)  L² 2.1e-4 → 2.7e-5 (7.8)  σ 7.9e-5 → 6.8e-6
  quad8 plane strain   nodes 7.3e-5 → 4.9e-6 (14.9)  L² 2.1e-4 → 2.7e-5 (7.8)  σ 8.2e-5 → 6.9e-6
  quad9 axisymmetric   nodes 3.8e-4 → 2.5e-5 (14.8)  L² 9.4e-4 → 1.3e-4 (7.5)  σ 2.9e-4 → 2.7e-5

The L² error falls as h³ (8 when h halves), the nodal values superconverge (h⁴: 16), the cell
means of the stress too (≈ 11, between h³ and h⁴); six-node triangles on 8 × 16 cells give
1.1e-4 at the nodes (tests/loads/test_pressure.py)."""

import numpy as np
import pytest
from mpi4py import MPI

from helpers.curved_q2 import quarter_tube_q2, ring_sector
from loads.test_pressure import (A, B, E, NU, P, SCENE, TUBE, cylinder, radial, sphere,
                                 stress_error)
from parsolve.fem.axisymmetric import Axisymmetric
from parsolve.fem.integrals import cell_rule


def l2_error(res, cell: str, exact, axisymmetric: bool) -> float:
    """‖u_h − u‖ / ‖u‖ over the (isoparametric) domain, u = u_r(r) e_r (r: |x|)."""
    pts, cells = res["mesh/points"], res[f"mesh/cells/{cell}"]
    rule = cell_rule(pts[cells], cell, Axisymmetric() if axisymmetric else 1.0)
    uh = np.einsum("qa,cad->cqd", rule.N, res["fields/displacement"][-1][cells])
    r = np.linalg.norm(rule.points, axis=-1, keepdims=True)
    u = exact(r) * rule.points / r
    return float(np.sqrt(np.einsum("cqd,cq->", (uh - u) ** 2, rule.weights)
                         / np.einsum("cqd,cq->", u ** 2, rule.weights)))


@pytest.mark.parametrize("cell, hypothesis, nodal, l2, stress", [
    ("quad9", "plane_strain", 6e-6, 3e-5, 8e-6),
    ("quad8", "plane_strain", 6e-6, 3e-5, 8e-6),
    ("quad9", "axisymmetric", 3e-5, 1.5e-4, 3e-5)])
def test_lame_internal_pressure_on_q2_cells(run, shared_tmp, cell, hypothesis, nodal, l2, stress):
    """The bounds are on 8 × 16 cells; halving the cells divides the L² error by more than 7
    (h³), the nodal error by more than 13 and the stress error by more than 8."""
    axisymmetric = hypothesis == "axisymmetric"
    exact, kind = (sphere, "sphere") if axisymmetric else (cylinder, "cylinder")
    errors = []
    for n in (4, 8):
        mesh = shared_tmp / f"ring_{cell}_{n}.msh"
        ring_sector(mesh, A, B, n, 2 * n, cell=cell)
        res = run(SCENE.format(mesh=mesh, hypothesis=hypothesis, E=E, NU=NU, pressure=P))
        assert f"mesh/cells/{cell}" in res
        r, ur = radial(res)
        errors.append((np.abs(ur - exact(r)).max() / exact(A), l2_error(res, cell, exact,
                       axisymmetric), stress_error(res, kind, axisymmetric)))
    (n0, l0, s0), (n1, l1, s1) = errors
    assert n1 < nodal and l1 < l2 and s1 < stress, errors
    assert l0 / l1 > 7.0 and n0 / n1 > 13.0 and s0 / s1 > 8.0, errors


@pytest.mark.parametrize("binary", [False, True])
def test_msh41_gives_the_msh22_answer(run, shared_tmp, binary):
    """The same quad9 ring written as MSH 4.1 (read by slices on every rank) and as 2.2:
    the same displacement to round-off."""
    import meshio

    from helpers.msh41 import blocks_of, write_msh41

    v22, v41 = shared_tmp / "ring22.msh", shared_tmp / f"ring41_{binary}.msh"
    ring_sector(v22, A, B, 3, 5)
    if MPI.COMM_WORLD.rank == 0:
        m = meshio.read(v22)
        write_msh41(v41, m.points, blocks_of(m), {(2, 1): "ring", (1, 10): "inner",
                                                   (1, 11): "outer"}, binary)
    MPI.COMM_WORLD.Barrier()
    a, b = (run(SCENE.format(mesh=m, hypothesis="plane_strain", E=E, NU=NU, pressure=P))
            for m in (v22, v41))
    np.testing.assert_array_equal(a["mesh/cells/quad9"], b["mesh/cells/quad9"])
    np.testing.assert_allclose(b["fields/displacement"], a["fields/displacement"], rtol=0,
                               atol=1e-12 * np.abs(a["fields/displacement"]).max())


HALF = """
[mesh]
file = "{mesh}"
[model]
hypothesis = "plane_strain"
[regions]
base = "y == 0"
top = "x == 0"
[[materials]]
E = 1000.0
nu = 0.3
[[loads]]
region = "inner"
pressure = {p}
[[relations]]
name = "base"
type = "dirichlet"
region = "base"
components = ["y"]
[[relations]]
name = "top"
type = "dirichlet"
region = "top"
components = ["x"]
"""


@pytest.mark.parametrize("cell", ["quad9", "quad8"])
def test_pressure_resultant_on_a_half_cylinder(run, shared_tmp, cell):
    """The bore of a half ring (0 ≤ θ ≤ π) under p: the pressure pushes the body by
    p ∫ e_r ds = (0, 2 p a) exactly whatever the cells (∫ n ds over a curved edge is its chord
    turned, integrated exactly): the base carries −2 p a to round-off, the x support nothing."""
    mesh = shared_tmp / f"half_{cell}.msh"
    ring_sector(mesh, A, B, 2, 6, angle=np.pi, cell=cell)
    res = run(HALF.format(mesh=mesh, p=P))
    np.testing.assert_allclose(res["relations/base/resultant"][-1][:2], [0.0, -2 * P * A],
                               rtol=1e-12, atol=1e-11 * P)
    np.testing.assert_allclose(res["relations/top/resultant"][-1][:2], 0.0, atol=1e-11 * P)


@pytest.mark.parametrize("cell, vtk_type", [("quad9", 28), ("quad8", 23)])
def test_xdmf_of_a_q2_result_reads_in_vtk(run, shared_tmp, cell, vtk_type):
    """VTK's XDMF reader (ParaView's) makes VTK_BIQUADRATIC_QUAD (28) / VTK_QUADRATIC_QUAD
    (23) cells of the result, with its nodes and displacement."""
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    mesh = shared_tmp / f"xdmf_{cell}.msh"
    ring_sector(mesh, A, B, 2, 3, cell=cell)
    res = run(SCENE.format(mesh=mesh, hypothesis="plane_strain", E=E, NU=NU, pressure=P))
    reader = vtk.vtkXdmfReader()
    reader.SetFileName(str(run.last.with_suffix(".xdmf")))
    reader.Update()
    grid = reader.GetOutputDataObject(0)
    assert grid.GetNumberOfCells() == 6 and grid.GetNumberOfPoints() == len(res["mesh/points"])
    assert {grid.GetCellType(k) for k in range(6)} == {vtk_type}
    cell_nodes = [[grid.GetCell(k).GetPointId(a) for a in range(9 if cell == "quad9" else 8)]
                  for k in range(6)]
    np.testing.assert_array_equal(cell_nodes, res[f"mesh/cells/{cell}"])
    u = vtk_to_numpy(grid.GetPointData().GetArray("displacement"))
    np.testing.assert_array_equal(u[:, :2], res["fields/displacement"][-1])


@pytest.mark.parametrize("cell, face, vtk_type", [("hexahedron27", "quad9", 29),
                                                  ("hexahedron20", "quad8", 25)])
def test_lame_tube_of_q2_hexahedra_is_the_plane_strain_answer(run, shared_tmp, cell, face,
                                                                vtk_type):
    """The quarter tube of one layer of Q2 hexahedra (u_z = 0 on both ends, the pressure on
    its curved quad9/quad8 faces) is the plane-strain ring of the same Q2 quadrilaterals:
    every node's displacement that of the 2D node at the same (x, y) to round-off (so the
    errors and rates above hold: 6.6e-5 on 4 × 8 cells for quad9), u_z = 0; its XDMF reads in
    VTK as triquadratic (29) / quadratic (25) hexahedra."""
    tube, ring = shared_tmp / f"tube_{cell}.msh", shared_tmp / f"ring_{face}.msh"
    quarter_tube_q2(tube, A, B, 0.25, 4, 8, 1, cell)
    ring_sector(ring, A, B, 4, 8, cell=face)
    res3 = run(TUBE.format(mesh=tube, E=E, NU=NU, P=P))
    xdmf = run.last.with_suffix(".xdmf")
    res2 = run(SCENE.format(mesh=ring, hypothesis="plane_strain", E=E, NU=NU, pressure=P))
    p3, p2 = res3["mesh/points"], res2["mesh/points"]
    u3, u2 = res3["fields/displacement"][-1], res2["fields/displacement"][-1]
    # each 3D node's 2D node at the same (x, y) (the middle layer holds some of them)
    index = {tuple(k): n for n, k in enumerate(np.round(p2, 9))}
    match = np.array([index[tuple(k)] for k in np.round(p3[:, :2], 9)])
    np.testing.assert_allclose(p3[:, :2], p2[match], atol=1e-14)
    np.testing.assert_allclose(u3[:, :2], u2[match], atol=1e-11 * np.abs(u2).max())
    np.testing.assert_allclose(u3[:, 2], 0.0, atol=1e-12 * np.abs(u2).max())
    r, ur = radial(res3)
    assert np.abs(ur - cylinder(r)).max() / cylinder(A) < 1e-4
    vtk = pytest.importorskip("vtk")
    reader = vtk.vtkXdmfReader()
    reader.SetFileName(str(xdmf))
    reader.Update()
    grid = reader.GetOutputDataObject(0)
    assert {grid.GetCellType(k) for k in range(grid.GetNumberOfCells())} == {vtk_type}
    assert grid.GetNumberOfCells() == 32 and grid.GetNumberOfPoints() == len(p3)


def test_contact_on_q2_hexahedra_is_refused(shared_tmp):
    """Contact has no rows on quad9/quad8 faces in 3D: the scene is refused with its key."""
    import tomllib

    from parsolve.errors import InputError
    from parsolve.model import build_model
    from parsolve.scene import parse_scene

    tube = shared_tmp / "tube_contact.msh"
    quarter_tube_q2(tube, A, B, 0.25, 1, 2, 1)
    text = TUBE.format(mesh=tube, E=E, NU=NU, P=P) + (
        '[[contact]]\nname = "wall"\nslave = "outer"\n'
        'obstacle = { plane = { origin = [0.0, 0.0, 0.0], normal = [1.0, 0.0, 0.0] } }\n')
    with pytest.raises(InputError, match="contact is not available on hexahedron27") as info:
        build_model(parse_scene(tomllib.loads(text), "s.toml", text), MPI.COMM_WORLD)
    assert info.value.key == "contact[0]"
