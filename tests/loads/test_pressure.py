"""Pressure on curved second-order faces: Lamé's thick cylinder (plane strain) and thick
sphere (axisymmetric) under internal pressure, from a Gmsh mesh of six-node triangles whose
edges follow the circles, and both in 3D from ten-node tetrahedra; the displacement and the
stresses to the element's order.

The stresses are the result's cell values (``cell_fields/stress``: each cell's mean, weighted
by 2π r in axisymmetry) against the mean of Lamé's stresses over the same cell (a quadrature
of the closed form on the cell's curved geometry): quadratic elements give stresses of order
h² (an error divided by 4 when the mesh is halved, once asymptotic)."""

import numpy as np
import pytest

from conftest import CONFIGS, rel_err
from helpers.curved import quarter_annulus, quarter_tube, sphere_octant
from parsolve.fem.axisymmetric import Axisymmetric
from parsolve.fem.integrals import cell_rule

A, B, P, E, NU = 1.0, 2.0, 10.0, 1000.0, 0.3

SCENE = """
[mesh]
file = "{mesh}"
[model]
hypothesis = "{hypothesis}"
[regions]
xaxis = "y == 0"
yaxis = "x == 0"
[[materials]]
E = {E}
nu = {NU}
[[loads]]
region = "inner"
pressure = {pressure}
[[relations]]
name = "xsym"
type = "dirichlet"
region = "yaxis"
components = ["x"]
[[relations]]
name = "ysym"
type = "dirichlet"
region = "xaxis"
components = ["y"]
"""


def cylinder(r):
    """Plane strain: u_r = (1+ν)/E ((1-2ν) C r + D / r), C = p a²/(b²-a²), D = C b²."""
    c = P * A**2 / (B**2 - A**2)
    return (1 + NU) / E * ((1 - 2 * NU) * c * r + c * B**2 / r)


def sphere(r):
    """u_r = ((1-2ν) C r + (1+ν) D / (2 r²)) / E, C = p a³/(b³-a³), D = C b³."""
    c = P * A**3 / (B**3 - A**3)
    return ((1 - 2 * NU) * c * r + (1 + NU) * c * B**3 / (2 * r**2)) / E


def cylinder_stress(x):
    """Lamé's (σ_rr, σ_θθ, σ_zz) at points x (plane strain: σ_zz = ν (σ_rr + σ_θθ))."""
    c = P * A**2 / (B**2 - A**2)
    r2 = x[..., 0] ** 2 + x[..., 1] ** 2
    return c * (1 - B**2 / r2), c * (1 + B**2 / r2), 2 * NU * c + 0 * r2


def sphere_stress(x):
    """Lamé's (σ_RR, σ_tt) at points x, R = |x|: σ_RR = C (1 − b³/R³), σ_tt = C (1 + b³/(2 R³))."""
    c = P * A**3 / (B**3 - A**3)
    R3 = np.linalg.norm(x, axis=-1) ** 3
    return c * (1 - B**3 / R3), c * (1 + B**3 / (2 * R3))


def lame_tensor(x, kind: str):
    """The closed-form stress tensor (..., d, d) at points x (..., d): radial σ_rr along
    e = x/|x| (in the plane for the cylinder), σ_tt across it; the cylinder's σ_zz in 3D."""
    d = x.shape[-1]
    in_plane = np.zeros(d)
    in_plane[:2] = 1.0
    radius_of = x * in_plane if kind == "cylinder" else x
    e = radius_of / np.linalg.norm(radius_of, axis=-1, keepdims=True)
    if kind == "cylinder":
        srr, stt, szz = cylinder_stress(x)
        across = np.diag(in_plane)
    else:
        srr, stt = sphere_stress(x)
        across = np.eye(d)
    sig = stt[..., None, None] * across + (srr - stt)[..., None, None] * e[..., :, None] * e[..., None, :]
    if kind == "cylinder" and d == 3:
        sig[..., 2, 2] = szz
    return sig


def stress_error(res, kind: str, axisymmetric: bool = False) -> float:
    """max over cells and components of |cell stress − Lamé's mean over the cell| / p."""
    pts = res["mesh/points"]
    (cell_type, cells), = ((k[len("mesh/cells/"):], v) for k, v in res.items()
                           if k.startswith("mesh/cells/"))
    rule = cell_rule(pts[cells], cell_type, Axisymmetric() if axisymmetric else 1.0)
    sig = lame_tensor(rule.points, kind)
    if pts.shape[1] == 2:   # (xx, yy, xy), and the hoop θθ = σ_tt (axisymmetric: sphere only)
        voigt = [sig[..., 0, 0], sig[..., 1, 1], sig[..., 0, 1]]
        voigt += [sphere_stress(rule.points)[1]] if axisymmetric else []
    else:
        voigt = [sig[..., 0, 0], sig[..., 1, 1], sig[..., 2, 2], sig[..., 1, 2], sig[..., 0, 2],
                 sig[..., 0, 1]]
    mean = np.einsum("cqv,cq->cv", np.stack(voigt, axis=-1), rule.weights) \
        / rule.weights.sum(axis=1)[:, None]
    return float(np.abs(res["cell_fields/stress"][-1] - mean).max() / P)


def radial(res):
    pts = res["mesh/points"]
    u = res["fields/displacement"][-1]
    r = np.hypot(pts[:, 0], pts[:, 1])
    return r, np.einsum("ni,ni->n", u[:, :2], pts[:, :2] / r[:, None])


@pytest.mark.parametrize("hypothesis, exact, bound, stress_bound",
                         [("plane_strain", cylinder, 2e-4, 2e-4),
                          ("axisymmetric", sphere, 1e-3, 5e-4)])
def test_lame_internal_pressure(run, shared_tmp, hypothesis, exact, bound, stress_bound):
    """Six-node triangles converge as h³ in displacement: halving the mesh divides the error
    by about 8 (measured: 7.4 and 6.5 from 4 × 8 to 8 × 16 cells, 7.2 for the sphere from
    8 × 16 to 16 × 32); 8 × 16 is within ``bound`` of Lamé's radial displacement (measured
    1.1e-4 and 8.2e-4). The stresses converge as h²: the error (of p) divided by 3.1 then 3.4
    for the cylinder (1.7e-3, 5.3e-4, 1.5e-4 on 4 × 8, 8 × 16, 16 × 32), by 2.8 then 3.3 for
    the sphere (3.7e-3, 1.3e-3, 3.9e-4), rising towards 4; 16 × 32 within ``stress_bound``."""
    errors, stresses = [], []
    kind = "cylinder" if hypothesis == "plane_strain" else "sphere"
    for n in (4, 8, 16):
        mesh = shared_tmp / f"ring{n}.msh"
        quarter_annulus(mesh, A, B, n, 2 * n)
        res = run(SCENE.format(mesh=mesh, hypothesis=hypothesis, E=E, NU=NU, pressure=P))
        r, ur = radial(res)
        errors.append(np.abs(ur - exact(r)).max() / exact(A))
        stresses.append(stress_error(res, kind, hypothesis == "axisymmetric"))
    assert errors[1] < bound
    assert errors[0] / errors[1] > 6.0
    assert stresses[2] < stress_bound, stresses
    assert stresses[0] / stresses[1] > 2.6 and stresses[1] / stresses[2] > 3.1, stresses


def test_pressure_as_expression_of_time(run, shared_tmp):
    """``pressure = "10 * t"`` with the default (constant) evolution is the ramp of 10."""
    mesh = shared_tmp / "ring.msh"
    quarter_annulus(mesh, A, B, 4, 8)
    text = SCENE.format(mesh=mesh, hypothesis="plane_strain", E=E, NU=NU, pressure=P)
    ramp = run(text + "[steps]\ncount = 2\n")
    timed = run(text.replace(f"pressure = {P}", '"pressure" = "10 * t"') + "[steps]\ncount = 2\n")
    np.testing.assert_allclose(timed["fields/displacement"], ramp["fields/displacement"],
                               rtol=1e-12, atol=1e-15)


def test_shipped_thick_cylinder(run):
    """configs/thick_cylinder_pressure.toml (E = 210e3, 8 × 16 curved cells): u_r within 2e-4
    of Lamé's; each symmetry plane carries p a (the bore's pressure projected on it) exactly,
    whatever the curved edges' discretisation (∫ n ds over an edge is its chord turned)."""
    res = run(CONFIGS / "thick_cylinder_pressure.toml")
    e, nu, p, a, b = 210e3, 0.3, 10.0, 1.0, 2.0
    c = p * a * a / (b * b - a * a)
    pts = res["mesh/points"]
    r = np.hypot(pts[:, 0], pts[:, 1])
    ur = np.einsum("ni,ni->n", res["fields/displacement"][-1], pts / r[:, None])
    assert rel_err(ur, (1 + nu) / e * ((1 - 2 * nu) * c * r + c * b * b / r)) < 2e-4
    np.testing.assert_allclose(res["relations/x_symmetry/resultant"][-1][:2], [0.0, -p * a],
                               atol=1e-9 * p)
    np.testing.assert_allclose(res["relations/y_symmetry/resultant"][-1][:2], [-p * a, 0.0],
                               atol=1e-9 * p)


TUBE = """
[mesh]
file = "{mesh}"
[model]
hypothesis = "3d"
[regions]
xaxis = "y == 0"
yaxis = "x == 0"
ends = "z == 0 or z == 0.25"
[[materials]]
E = {E}
nu = {NU}
[[loads]]
region = "inner"
pressure = {P}
[[relations]]
name = "xsym"
type = "dirichlet"
region = "yaxis"
components = ["x"]
[[relations]]
name = "ysym"
type = "dirichlet"
region = "xaxis"
components = ["y"]
[[relations]]
name = "ends"
type = "dirichlet"
region = "ends"
components = ["z"]
"""


def test_lame_tube_in_3d(run, shared_tmp):
    """The plane-strain cylinder as a 3D slice of ten-node tetrahedra (u_z = 0 on both ends):
    the pressure on the curved six-node faces of the bore gives Lamé's u_r within 5e-4 on
    8 × 16 × 1 cells; halving the mesh in the plane divides the error by 4.7 then 5.2
    (measured: 1.3e-3, 2.8e-4, 5.4e-5 on 4, 8, 16 radial cells), rising towards 8."""
    errors, stresses = [], []
    for n in (4, 8):
        mesh = shared_tmp / f"tube{n}.msh"
        quarter_tube(mesh, A, B, 0.25, n, 2 * n, 1)
        res = run(TUBE.format(mesh=mesh, E=E, NU=NU, P=P))
        r, ur = radial(res)
        errors.append(np.abs(ur - cylinder(r)).max() / cylinder(A))
        stresses.append(stress_error(res, "cylinder"))
    assert errors[1] < 3e-4 and errors[0] / errors[1] > 4.5, errors
    # σ (σ_zz = ν (σ_rr + σ_θθ) included) as h²: 5.7e-3 then 1.4e-3 of p (measured: 4.0)
    assert stresses[1] < 2e-3 and stresses[0] / stresses[1] > 3.5, stresses


SHELL = """
[mesh]
file = "{mesh}"
[model]
hypothesis = "3d"
[regions]
bore = "x*x + y*y + z*z < 1.0001"
xplane = "x == 0"
yplane = "y == 0"
zplane = "z == 0"
[[materials]]
E = {E}
nu = {NU}
[[loads]]
region = "bore"
pressure = {P}
[[relations]]
name = "x"
type = "dirichlet"
region = "xplane"
components = ["x"]
[[relations]]
name = "y"
type = "dirichlet"
region = "yplane"
components = ["y"]
[[relations]]
name = "z"
type = "dirichlet"
region = "zplane"
components = ["z"]
"""


def test_lame_thick_sphere_in_3d(run, shared_tmp):
    """An eighth of the thick sphere in ten-node tetrahedra on the exact spheres: the pressure
    on the curved bore gives Lamé's u_r within 6e-3 on 8² × 4 prism layers (measured 5.4e-3),
    the error divided by more than 5 from 4² × 2 (measured 3.3e-2: 6.1); the stresses too."""
    errors, stresses = [], []
    for n, layers in ((4, 2), (8, 4)):
        mesh = shared_tmp / f"shell{n}.msh"
        sphere_octant(mesh, A, B, n, layers)
        res = run(SHELL.format(mesh=mesh, E=E, NU=NU, P=P))
        pts = res["mesh/points"]
        r = np.linalg.norm(pts, axis=1)
        ur = np.einsum("ni,ni->n", res["fields/displacement"][-1], pts / r[:, None])
        errors.append(np.abs(ur - sphere(r)).max() / sphere(A))
        stresses.append(stress_error(res, "sphere"))
    assert errors[1] < 6e-3 and errors[0] / errors[1] > 5.0, errors
    # the stresses as h², still short of the asymptote on these meshes: 3.7e-2 then 1.65e-2
    # of p (2.2), 5.9e-3 on 16² × 8 (2.8; measured once, 20 s: not run here)
    assert stresses[1] < 2e-2 and stresses[0] / stresses[1] > 2.0, stresses
