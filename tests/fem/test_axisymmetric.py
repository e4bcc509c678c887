"""Axisymmetric hypothesis (x = r, y = z; every integral weighted by 2π r, forces for the whole
ring): Lamé's thick cylinder converging at the elements' rates, a uniform expansion patch test
exact to round-off (also on the axis), steady radial conduction, and the inputs refused."""

from pathlib import Path
import subprocess
import sys

import meshio
import numpy as np
import pytest
import tomllib
from mpi4py import MPI

from parsolve.errors import InputError
from parsolve.fem.materials.base import elastic_matrix
from parsolve.mesh.generators import make_quadratic, rectangle
from parsolve.model import build_model
from parsolve.scene import parse_scene

E, NU, P, A, B, H = 1000.0, 0.3, 1.0, 1.0, 2.0, 0.25   # inner radius A, outer B, height H

CYLINDER = """
[mesh]
generator = "rectangle"
lx = {lx}
ly = {ly}
nx = {nx}
ny = {ny}
cell = "{cell}"
origin = [{a}, 0.0]
[model]
hypothesis = "axisymmetric"
[[materials]]
model = "{model}"
E = {E}
nu = {nu}
{extra}
[[loads]]
name = "pressure"
region = "left"
traction = [{p}, 0.0]
[[relations]]
name = "bottom"
type = "dirichlet"
region = "bottom"
components = ["y"]
[[relations]]
name = "top"
type = "dirichlet"
region = "top"
components = ["y"]
"""


def cylinder(nx: int, cell: str, model: str = "elastic", extra: str = "") -> str:
    return CYLINDER.format(lx=B - A, ly=H, nx=nx, ny=max(nx // 4, 1), cell=cell, a=A, E=E, nu=NU,
                           p=P, model=model, extra=extra)


def lame(r: np.ndarray):
    """u_r, σ_rr, σ_θθ, σ_zz of the thick cylinder under inner pressure P, plane strain in z."""
    c1 = P * A * A / (B * B - A * A)
    c2 = c1 * B * B
    ur = (1 + NU) / E * ((1 - 2 * NU) * c1 * r + c2 / r)
    return ur, c1 - c2 / r ** 2, c1 + c2 / r ** 2, 2 * NU * c1


def rate(errors) -> np.ndarray:
    return np.log2(np.asarray(errors[:-1]) / np.asarray(errors[1:]))


@pytest.mark.parametrize("cell, u_rate, s_rate", [("quad", 1.9, 1.5), ("triangle6", 2.5, 1.4)])
def test_thick_cylinder_converges(cell, u_rate, s_rate, run):
    """u_r = c1' r + c2' / r: the nodal error falls as h² (Q1) and faster (P2) over three
    meshes; σ_rr and σ_θθ (nodal averages off the loaded and free faces) converge; the axial
    reaction of the held top is ∫ σ_zz 2π r dr = 2ν P π A² (the whole ring's) to round-off."""
    u_err, s_err, reaction = [], [], []
    for n in (4, 8, 16):
        res = run(cylinder(n, cell), name=f"lame_{cell}_{n}")
        r = res["mesh/points"][:, 0]
        ur, srr, stt, szz = lame(r)
        u = res["fields/displacement"][-1]
        u_err.append(np.abs(u[:, 0] - ur).max() / ur.max())
        assert np.abs(u[:, 1]).max() < (1e-15 if cell == "quad" else u_err[-1] * ur.max())
        s = res["fields/stress"][-1]
        assert s.shape[1] == 4                                     # rr, zz, rz, θθ
        inner = (r > A + 1e-9) & (r < B - 1e-9)
        s_err.append(max(np.abs(s[inner, 0] - srr[inner]).max(),
                         np.abs(s[inner, 3] - stt[inner]).max()) / P)
        reaction.append(res["relations/top/resultant"][-1][1])
        # the bottom and the top take equal and opposite axial forces
        assert abs(res["relations/bottom/resultant"][-1][1] + reaction[-1]) < 1e-12
    assert np.all(rate(u_err) > u_rate), u_err
    assert np.all(rate(s_err) > s_rate), s_err
    assert s_err[-1] < 5e-3
    # exact on every mesh: the virtual fields (r, 0) and (0, z/H) are in the element space,
    # and both reduce to ∫ ∂_r(r u_r) dr (integrated exactly), so the reaction is that identity
    exact = 2 * NU * P * np.pi * A * A
    np.testing.assert_allclose(reaction, exact, rtol=1e-12)


def test_von_mises_below_yield_is_elastic(run):
    """von Mises in the axisymmetric hypothesis (the 3D return on (rr, zz, θθ, γ_rz)), loaded
    below yield: the elastic answer, through the nonlinear path (Newton, internal forces)."""
    elastic = run(cylinder(8, "quad"), name="vm_ref")
    plastic = run(cylinder(8, "quad", "von_mises", "sigma_y = 100.0\nH = 10.0"), name="vm")
    np.testing.assert_allclose(plastic["fields/displacement"][-1],
                               elastic["fields/displacement"][-1], rtol=0, atol=1e-13)
    np.testing.assert_allclose(plastic["cell_fields/stress"][-1],
                               elastic["cell_fields/stress"][-1], rtol=0, atol=1e-11)
    assert np.all(plastic["cell_fields/plastic_strain"][-1] == 0.0)


# ---------------------------------------------------------------- patch test

EXPANSION = (2e-3, -1e-3)   # u_r = c r, u_z = d z: ε = (c, d, 0, c), constant


def distorted(cell: str, path: Path) -> None:
    """The unit square (0 ≤ r ≤ 1: it touches the axis) with its interior nodes moved."""
    base = "triangle" if cell == "triangle6" else cell
    mesh = rectangle(1.0, 1.0, 4, 3, cell=base)
    pts = mesh.points.copy()
    inner = np.all((pts > 1e-12) & (pts < 1 - 1e-12), axis=1)
    pts[inner] += np.random.default_rng(1).uniform(-0.06, 0.06, size=(inner.sum(), 2))
    mesh.points = pts
    if cell == "triangle6":   # straight edges: the midside nodes at the middle
        mesh = make_quadratic(mesh)
    if MPI.COMM_WORLD.rank == 0:
        meshio.write(str(path), meshio.Mesh(mesh.points, [(mesh.cell_type, mesh.cells)]))
    MPI.COMM_WORLD.Barrier()


def patch_scene(mesh_file: Path) -> str:
    c, d = EXPANSION
    return f"""
[mesh]
file = "{mesh_file}"
[model]
hypothesis = "axisymmetric"
[regions]
boundary = "x == 0 or x == 1 or y == 0 or y == 1"
bottom = "y == 0"
top = "y == 1"
[[materials]]
E = 200.0
nu = 0.3
[[relations]]
name = "radial"
type = "dirichlet"
region = "boundary"
components = ["x"]
value = "{c!r} * x"
[[relations]]
name = "bottom"
type = "dirichlet"
region = "bottom"
components = ["y"]
[[relations]]
name = "top"
type = "dirichlet"
region = "top"
components = ["y"]
value = {d!r}
"""


@pytest.mark.parametrize("cell", ["quad", "triangle", "triangle6"])
def test_uniform_expansion_patch(cell, run, shared_tmp):
    """u_r = c r, u_z = d z on a distorted mesh down to the axis: exact inside to round-off,
    the stress C ε in every cell and at every node (on the axis the hoop strain is the limit
    ε_θθ = ε_rr), and the top's axial reaction σ_zz π R² exactly (the whole ring's force)."""
    path = shared_tmp / f"axi_patch_{cell}.vtu"
    distorted(cell, path)
    res = run(patch_scene(path), name=f"axi_patch_{cell}")
    c, d = EXPANSION
    pts = res["mesh/points"]
    np.testing.assert_allclose(res["fields/displacement"][-1], pts * [c, d], rtol=0, atol=1e-15)
    sigma = elastic_matrix(200.0, 0.3, "axisymmetric") @ [c, d, 0.0, c]
    scale = np.abs(sigma).max()
    for where in ("cell_fields/stress", "fields/stress"):
        s = res[where][-1]
        np.testing.assert_allclose(s, np.tile(sigma, (len(s), 1)), rtol=0, atol=1e-12 * scale)
    assert abs(res["relations/top/resultant"][-1][1] - sigma[1] * np.pi) < 1e-12 * scale


# ---------------------------------------------------------------- diffusion

TUBE = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 0.5
nx = {n}
ny = {ny}
cell = "{cell}"
origin = [1.0, 0.0]
[model]
hypothesis = "axisymmetric"
[[diffusion]]
field = "T"
[[diffusion.materials]]
conductivity = 2.0
[[relations]]
name = "inner"
field = "T"
type = "dirichlet"
region = "left"
value = 10.0
[[relations]]
name = "outer"
field = "T"
type = "dirichlet"
region = "right"
value = 0.0
"""


@pytest.mark.parametrize("cell, expected", [("quad", 1.9), ("triangle6", 2.4)])
def test_radial_conduction(cell, expected, run):
    """T = T1 ln(r2 / r) / ln(r2 / r1) through a tube wall (1 ≤ r ≤ 3): the nodal error falls
    at the element's rate, the heat flow through the inner face (its multipliers, whole ring)
    tends to 2π k h T1 / ln 3."""
    errors, flows = [], []
    for n in (4, 8, 16):
        res = run(TUBE.format(n=n, ny=max(n // 4, 1), cell=cell), name=f"tube_{cell}_{n}")
        r = res["mesh/points"][:, 0]
        exact = 10.0 * np.log(3.0 / r) / np.log(3.0)
        errors.append(np.abs(res["fields/T"][-1][:, 0] - exact).max() / 10.0)
        flows.append(-res["relations/inner/multiplier"][-1].sum())
        outer = res["relations/outer/multiplier"][-1].sum()   # what goes in comes out
        assert abs(outer - flows[-1]) < 1e-12 * flows[-1]
    assert np.all(rate(errors) > expected), errors
    q = 2 * np.pi * 2.0 * 0.5 * 10.0 / np.log(3.0)
    flow_err = np.abs(np.array(flows) - q) / q
    assert flow_err[-1] < 1e-3 and np.all(np.diff(flow_err) < 0), flow_err


def test_uniform_heating(run):
    """Insulated tube, uniform source f t (the default ramp) and capacity c: backward Euler
    gives T_n = (f / c) Δt Σ_k≤n t_k at every node to round-off (capacity and source carry the
    same 2π r weight, consistent mass)."""
    text = TUBE.format(n=6, ny=2, cell="triangle6").split("[[relations]]")[0] + """
[[loads]]
name = "heat"
field = "T"
source = 3.0
[time]
mass = "consistent"
[steps]
count = 3
end = 0.3
"""
    text = text.replace("conductivity = 2.0", "conductivity = 2.0\ncapacity = 1.5")
    res = run(text, name="tube_heating")
    T = res["fields/T"][..., 0]
    t = res["steps/time"]
    expected = 3.0 / 1.5 * 0.1 * np.cumsum(t)
    np.testing.assert_allclose(T, np.tile(expected[:, None], (1, T.shape[1])), rtol=0, atol=1e-14)


# ---------------------------------------------------------------- inputs refused

def _model(text: str):
    return build_model(parse_scene(tomllib.loads(text), "scene.toml", text))


@pytest.mark.parametrize("change, key", [
    (("hypothesis = \"axisymmetric\"", "hypothesis = \"axisymmetric\"\nthickness = 2.0"),
     "model.thickness"),
    (('model = "elastic"', 'model = "mazars"\neps_d0 = 1e-4\nAt = 1.0\nBt = 1e4\nAc = 1.2\n'
      'Bc = 1e3'), "materials[0].model"),
])
def test_refused_inputs(change, key):
    with pytest.raises(InputError) as err:
        _model(cylinder(4, "quad").replace(*change))
    assert err.value.key == key and err.value.source == "scene.toml"


CONTACT = """
[[contact]]
name = "c"
slave = "right"
master = "left"
"""


def test_penalty_baseline_takes_obstacles_and_masters_as_in_plane_models():
    """The penalty baselines' areas are the rings' (2π r ds): accepted against a rigid obstacle
    (their answers: tests/effects/test_contact_baselines.py) and against a master region as a
    plane model takes it (tests/effects/test_contact_penalty_master.py); a master its slaves
    do not face (the cylinder's outer face against its inner one) is exit 2 naming the key,
    as for the multiplier contact."""
    with pytest.raises(InputError) as err:
        _model(cylinder(4, "quad") + CONTACT + 'formulation = "penalty"\n')
    assert err.value.key == "contact[0].slave" and err.value.source == "scene.toml"
    assert "no slave node faces the master surface" in str(err.value)
    obstacle = CONTACT.replace('master = "left"',
                               'obstacle = { plane = { origin = [5.0, 0.0], normal = [-1.0, 0.0] } }')
    _model(cylinder(4, "quad") + obstacle + 'formulation = "penalty"\n')


@pytest.mark.serial
def test_negative_radius_exit_2(tmp_path):
    """A mesh with nodes at x = r < 0: exit 2, one line naming the mesh file, nothing written."""
    mesh = rectangle(1.0, 1.0, 2, 2, origin=(-0.5, 0.0))
    meshio.write(str(tmp_path / "m.vtu"), meshio.Mesh(mesh.points, [("quad", mesh.cells)]))
    (tmp_path / "scene.toml").write_text(
        patch_scene(Path("m.vtu")).replace("x == 0 or x == 1", "x == -0.5 or x == 0.5"))
    proc = subprocess.run([sys.executable, "-m", "parsolve", "run", "scene.toml", "-o", "out.h5"],
                          cwd=tmp_path, capture_output=True, text=True)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert "m.vtu: mesh.file:" in lines[0] and "x < 0" in lines[0], lines[0]
    assert not list(tmp_path.glob("*.h5"))


COLUMN = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 2.0
nx = 3
ny = 5
cell = "{cell}"
[model]
hypothesis = "axisymmetric"
[[materials]]
E = 100.0
nu = 0.25
[[loads]]
name = "weight"
body = [0.0, -0.5]
[[loads]]
name = "lid"
region = "top"
total_force = [0.0, -3.0]
[[relations]]
name = "axis"
type = "dirichlet"
region = "left"
components = ["x"]
[[relations]]
name = "base"
type = "dirichlet"
region = "bottom"
components = ["y"]
"""


@pytest.mark.parametrize("cell", ["quad", "triangle", "triangle6"])
def test_loads_are_whole_ring_forces(cell, run):
    """A solid column (r ≤ 1, height 2) under its weight ρg = 0.5 per unit volume and a lid
    force of 3 (``total_force``: the whole ring's): the base carries 0.5 · 2π · 1² + 3, to
    round-off; the axis (u_r = 0) carries no axial force."""
    res = run(COLUMN.format(cell=cell), name=f"column_{cell}")
    base = res["relations/base/resultant"][-1]
    assert abs(base[1] - (0.5 * 2.0 * np.pi + 3.0)) < 1e-12 * base[1]
    assert abs(res["relations/axis/resultant"][-1][1]) < 1e-14


@pytest.mark.parametrize("cell", ["quad", "triangle"])
def test_strain_relation_mean_is_over_the_ring_volume(cell):
    """A strain relation's mean of n·ε·n in axisymmetry weights each cell by its ring volume
    (2π r): on u_r = r², whose Q1/P1 interpolant has ε_rr = r_i + r_(i+1) on the cells between
    r_i and r_(i+1), the row gives Σ s_i ∫r dr / Σ ∫r dr, not the plane mean (a + b here)."""
    nx = 6
    text = cylinder(nx, cell) + """
[[relations]]
name = "err"
type = "strain"
region = "all"
direction = [1.0, 0.0]
value = 0.0
"""
    model = build_model(parse_scene(tomllib.loads(text), "cyl.toml"))
    r = next(rel for rel in model.relations if rel.name == "err")
    x = model.mesh.points
    q = np.zeros((x.shape[0], model.ncomp))
    q[:, 0] = x[:, 0] ** 2
    q[:, 1] = 0.1 * x[:, 1]          # ε_zz: not in the row (n = e_r)
    value = float(np.sum(r.a_vals * q.ravel()[r.a_dofs]))
    ri = np.linspace(A, B, nx + 1)
    slopes, weights = ri[:-1] + ri[1:], (ri[1:] ** 2 - ri[:-1] ** 2) / 2
    assert value == pytest.approx(slopes @ weights / weights.sum(), rel=1e-12)
    assert abs(value - (A + B)) > 1e-2    # the plane mean would be A + B
