"""Thermal expansion: the temperature of a diffusion field as an eigenstrain of the elasticity,
a (u, T) block of the monolithic system, against closed forms (1, 2 and 3 ranks)."""

import subprocess
import sys
import tomllib

import numpy as np
import pytest
from mpi4py import MPI

from conftest import CONFIGS, rel_err
from helpers.scene import DROP, scene
from parsolve.errors import InputError

E, NU, ALPHA, T_REF, DT = 200.0, 0.3, 1e-3, 20.0, 50.0
A = ALPHA * DT   # the free thermal strain

BASE = {
    "mesh": {"generator": "rectangle", "lx": 2.0, "ly": 1.0, "nx": 4, "ny": 3, "cell": "quad"},
    "regions": {"boundary": "x == 0 or x == 2 or y == 0 or y == 1",
                "origin": {"point": [0.0, 0.0]}, "corner": {"point": [2.0, 0.0]}},
    "model": {"hypothesis": "plane_stress"},
    "materials": [{"E": 200.0, "nu": 0.3}],
    "diffusion": [{"field": "T", "materials": [{"conductivity": 1.5}]}],
    "thermal_expansion": [{"field": "T", "alpha": 1e-3, "reference": 20.0}],
}
EXPANSION = BASE["thermal_expansion"][0]


def plate(nx: int, ny: int, cell: str, hypothesis: str, relations: list, **overrides) -> str:
    """The 2 × 1 plate scene on an nx × ny mesh, with these relations and overrides."""
    return scene(BASE, mesh={"nx": nx, "ny": ny, "cell": cell}, model={"hypothesis": hypothesis},
                 relations=relations, **overrides)


def dirichlet(name, region, value, field=None, components=None, **extra) -> dict:
    rel = {"name": name, "type": "dirichlet", "region": region, "value": value,
           "evolution": "constant"}
    if field:
        rel["field"] = field
    if components:
        rel["components"] = list(components)
    return rel | extra


UNIFORM = [dirichlet("hot", "boundary", T_REF + DT, field="T")]
ROLLERS = [dirichlet("left", "left", 0.0, components=["x"]),
           dirichlet("bottom", "bottom", 0.0, components=["y"])]


def plane_factor(hypothesis: str) -> float:
    """The in-plane free strain per α ΔT: (1 + ν) in plane strain (ε_zz = 0 held)."""
    return 1.0 + NU if hypothesis == "plane_strain" else 1.0


def stresses(res):
    return res["fields/stress"][-1], res["cell_fields/stress"][-1]


@pytest.mark.parametrize("cell", ["quad", "triangle", "triangle6"])
@pytest.mark.parametrize("hypothesis", ["plane_stress", "plane_strain"])
def test_free_plate_uniform_rise(hypothesis, cell, run):
    """T = T_ref + ΔT on the whole boundary (steady: uniform inside), free expansion on
    rollers: u = f α ΔT x, stress zero."""
    res = run(plate(4, 3, cell, hypothesis, UNIFORM + ROLLERS), name=f"free_{hypothesis}_{cell}")
    p, u = res["mesh/points"], res["fields/displacement"][-1]
    np.testing.assert_allclose(res["fields/T"][-1][:, 0], T_REF + DT, rtol=1e-12)
    np.testing.assert_allclose(u, plane_factor(hypothesis) * A * p, rtol=0, atol=1e-12 * A)
    scale = E * A
    for sig in stresses(res):
        assert np.abs(sig).max() < 1e-10 * scale, np.abs(sig).max()


@pytest.mark.parametrize("cell", ["quad", "triangle"])
@pytest.mark.parametrize("hypothesis", ["plane_stress", "plane_strain"])
def test_bar_clamped_at_both_ends(hypothesis, cell, run):
    """u_x = 0 at both ends, free laterally: σ_xx = −E α ΔT in plane stress, −E α ΔT / (1 − ν)
    in plane strain; σ_yy = σ_xy = 0; the walls take σ_xx times the height."""
    relations = UNIFORM + [dirichlet("ends", "ends", 0.0, components=["x"]),
                           dirichlet("bottom", "bottom", 0.0, components=["y"])]
    text = plate(6, 2, cell, hypothesis, relations,
                 regions={"ends": {"expr": "x == 0 or x == 2"}})
    res = run(text, name=f"clamped_{hypothesis}_{cell}")
    plane_strain = hypothesis == "plane_strain"
    sxx = -E * A / (1 - NU) if plane_strain else -E * A
    lateral = (1 + NU) / (1 - NU) * A if plane_strain else (1 + NU) * A
    p, u = res["mesh/points"], res["fields/displacement"][-1]
    np.testing.assert_allclose(u[:, 0], 0.0, atol=1e-12 * A)
    np.testing.assert_allclose(u[:, 1], lateral * p[:, 1], rtol=0, atol=1e-12 * A)
    for sig in stresses(res):
        np.testing.assert_allclose(sig, np.tile([sxx, 0.0, 0.0], (len(sig), 1)), rtol=0,
                                   atol=1e-10 * abs(sxx))
    # the two walls' reactions: ±σ_xx · height each, opposite (the relation's resultant is 0)
    lam = res["relations/ends/multiplier"][-1]
    x_end = p[np.isclose(p[:, 0], 0) | np.isclose(p[:, 0], 2), 0]
    assert abs(lam[x_end == 0].sum()) == pytest.approx(abs(sxx) * 1.0, rel=1e-10)
    assert lam.sum() == pytest.approx(0.0, abs=1e-10 * abs(sxx))


def test_bar_expanding_into_a_gap(run):
    """Newton and the active set (a unilateral wall at a gap g = α ΔT L / 2 from the right end):
    the bar closes the gap, u_x = g x / L, σ_xx = −E α ΔT / 2 (plane stress), the stress
    output of a Newton run (quadrature-point stresses) less the eigenstrain too."""
    gap = 0.5 * A * 2.0
    relations = UNIFORM + ROLLERS + [dirichlet("wall", "right", gap, components=["x"], sense="<=")]
    res = run(plate(4, 2, "quad", "plane_stress", relations), name="gap")
    p, u = res["mesh/points"], res["fields/displacement"][-1]
    assert res["relations/wall/active"][-1].all()
    np.testing.assert_allclose(u[:, 0], gap * p[:, 0] / 2.0, rtol=0, atol=1e-12 * A)
    np.testing.assert_allclose(u[:, 1], (1 + NU / 2) * A * p[:, 1], rtol=0, atol=1e-12 * A)
    for sig in stresses(res):
        np.testing.assert_allclose(sig, np.tile([-E * A / 2, 0.0, 0.0], (len(sig), 1)), rtol=0,
                                   atol=1e-10 * E * A)


def test_alpha_per_region(run):
    """α = 1e-3, and 3e-3 on the right half (a [[thermal_expansion.regions]] entry), plane
    stress, u_x held at both ends and u_y on top and bottom: σ_xx = −E ᾱ ΔT / (1 − ν) with
    ᾱ the length-weighted mean α, σ_yy = ν σ_xx − E α ΔT in each half (cell values)."""
    relations = UNIFORM + [dirichlet("ends", "ends", 0.0, components=["x"]),
                           dirichlet("sides", "sides", 0.0, components=["y"])]
    text = plate(6, 2, "quad", "plane_stress", relations,
                 regions={"ends": {"expr": "x == 0 or x == 2"}, "sides": {"expr": "y == 0 or y == 1"},
                          "hot_half": {"expr": "x >= 1"}},
                 thermal_expansion=[EXPANSION | {"regions": [{"region": "hot_half", "alpha": 3e-3}]}])
    res = run(text, name="alpha_regions")
    centre = res["mesh/points"][res["mesh/cells/quad"]].mean(axis=1)[:, 0]
    alpha = np.where(centre > 1.0, 3e-3, 1e-3)
    sxx = -E * 2e-3 * DT / (1 - NU)
    expected = np.column_stack([np.full(len(alpha), sxx), NU * sxx - E * alpha * DT,
                                np.zeros(len(alpha))])
    np.testing.assert_allclose(res["cell_fields/stress"][-1], expected, rtol=0,
                               atol=1e-10 * abs(sxx))


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_transient_heating_by_a_source(mass, run):
    """θ = 1/2: an insulated plate heated by a uniform source s with capacity c warms
    uniformly, T = T_ref + s t / c (exact for the scheme); the displacements follow
    quasi-statically, u = f α (T − T_ref) x at every step (plane strain, f = 1 + ν)."""
    text = plate(4, 2, "quad", "plane_strain", ROLLERS,
                 diffusion=[{"field": "T", "initial": 20.0,
                             "materials": [{"conductivity": 1.5, "capacity": 2.0}]}],
                 loads=[{"name": "heater", "field": "T", "source": 4.0, "evolution": "constant"}],
                 time={"scheme": "theta", "theta": 0.5, "mass": mass},
                 steps={"count": 3, "end": 1.5})
    res = run(text, name=f"transient_{mass}")
    t, p = res["steps/time"], res["mesh/points"]
    rise = 4.0 * t / 2.0
    np.testing.assert_allclose(res["fields/T"][..., 0] - T_REF, np.repeat(rise[:, None], len(p), 1),
                               rtol=1e-12)
    for k, r in enumerate(rise):
        np.testing.assert_allclose(res["fields/displacement"][k], (1 + NU) * ALPHA * r * p, rtol=0,
                                   atol=1e-12 * ALPHA * r)
        assert np.abs(res["cell_fields/stress"][k]).max() < 1e-10 * E * ALPHA * r


LINEAR = [dirichlet("cold", "left", T_REF, field="T"),
          dirichlet("warm", "right", T_REF + DT, field="T"),
          dirichlet("pin", "origin", 0.0, components=["x", "y"]),
          dirichlet("roller", "corner", 0.0, components=["y"])]


@pytest.mark.parametrize("hypothesis", ["plane_stress", "plane_strain"])
def test_linear_profile_free_plate_p2_exact(hypothesis, run):
    """Steady conduction between the left (T_ref) and right (T_ref + ΔT) faces: T − T_ref = g x.
    A free plate takes the strain α g x I with no stress (it is compatible): u_x = f α g
    (x² − y²) / 2, u_y = f α g x y. Quadratic: P2 reproduces it to round-off."""
    res = run(plate(4, 2, "triangle6", hypothesis, LINEAR), name=f"linear_{hypothesis}")
    g = DT / 2.0
    p, u = res["mesh/points"], res["fields/displacement"][-1]
    x, y = p[:, 0], p[:, 1]
    np.testing.assert_allclose(res["fields/T"][-1][:, 0], T_REF + g * x, rtol=1e-12)
    f = plane_factor(hypothesis) * ALPHA * g
    exact = np.column_stack([f * (x ** 2 - y ** 2) / 2, f * x * y])
    assert rel_err(u, exact) < 1e-10
    for sig in stresses(res):
        assert np.abs(sig).max() < 1e-10 * E * A, np.abs(sig).max()


def test_linear_profile_q1_is_not_exact_but_converges(run):
    """The same plate on Q1 (bilinear u cannot hold x² − y²): the stress is not zero, and
    halving the cells divides its largest cell value by about 2 (first order)."""
    def worst(n):
        res = run(plate(2 * n, n, "quad", "plane_stress", LINEAR), name=f"linear_q1_{n}")
        return np.abs(res["cell_fields/stress"][-1]).max() / (E * A)

    coarse, fine = worst(2), worst(4)
    assert coarse > 1e-3 and 1.8 < coarse / fine < 2.2, (coarse, fine)


CUBE = {
    "mesh": {"generator": "box", "lx": 1.0, "ly": 1.0, "lz": 1.0, "nx": 2, "ny": 2, "nz": 2},
    "regions": {"boundary": "x == 0 or x == 1 or y == 0 or y == 1 or z == 0 or z == 1",
                "ends": "x == 0 or x == 1"},
    "model": {"hypothesis": "3d"},
    "materials": [{"E": 200.0, "nu": 0.3}],
    "diffusion": [{"field": "T", "materials": [{"conductivity": 1.0}]}],
    "thermal_expansion": [{"field": "T", "alpha": 1e-3, "reference": 20.0}],
}
CUBE_RELATIONS = UNIFORM + [dirichlet("y0", "ymin", 0.0, components=["y"]),
                            dirichlet("z0", "zmin", 0.0, components=["z"])]


def cube(cell: str, extra: dict) -> str:
    return scene(CUBE, mesh={"cell": cell}, relations=CUBE_RELATIONS + [extra])


@pytest.mark.parametrize("cell", ["hexahedron", "tetra"])
def test_free_cube_uniform_rise(cell, run):
    """3D: u = α ΔT x, no stress."""
    res = run(cube(cell, dirichlet("x0", "xmin", 0.0, components=["x"])), name=f"cube_{cell}")
    np.testing.assert_allclose(res["fields/displacement"][-1], A * res["mesh/points"], rtol=0,
                               atol=1e-12 * A)
    for sig in stresses(res):
        assert np.abs(sig).max() < 1e-10 * E * A, np.abs(sig).max()


def test_cube_clamped_in_x(run):
    """3D, u_x = 0 on both x faces, free laterally: σ_xx = −E α ΔT, u_y = (1 + ν) α ΔT y."""
    res = run(cube("hexahedron", dirichlet("ends", "ends", 0.0, components=["x"])),
              name="cube_clamped")
    p, u = res["mesh/points"], res["fields/displacement"][-1]
    np.testing.assert_allclose(u[:, 1:], (1 + NU) * A * p[:, 1:], rtol=0, atol=1e-12 * A)
    expected = np.array([-E * A, 0, 0, 0, 0, 0])
    for sig in stresses(res):
        np.testing.assert_allclose(sig, np.tile(expected, (len(sig), 1)), rtol=0,
                                   atol=1e-10 * E * A)


def test_unsymmetric_declared_and_lu_chosen():
    """The effect declares its block unsymmetric: the model says so and the direct preset is
    LU from the start (no switch by the numerical symmetry check)."""
    from parsolve.model import build_model
    from parsolve.scene import parse_scene
    from parsolve.solvers.setup import make_solver
    from parsolve.solvers.system import SaddleSystem

    text = plate(2, 1, "quad", "plane_stress", UNIFORM + ROLLERS)
    model = build_model(parse_scene(tomllib.loads(text), "t.toml", text), MPI.COMM_WORLD)
    assert not model.symmetric() and [e.name for e in model.effects][-1] == "thermal_expansion"
    system = SaddleSystem(MPI.COMM_WORLD, model)
    assert make_solver(MPI.COMM_WORLD, system, {}).settings["pc_type"] == "lu"
    without = plate(2, 1, "quad", "plane_stress", UNIFORM + ROLLERS, thermal_expansion=DROP)
    assert build_model(parse_scene(tomllib.loads(without), "t.toml", without), MPI.COMM_WORLD).symmetric()


def test_shipped_scene(run):
    """configs/thermal_expansion.toml: a plate between two walls heated from 20 to 120 in two
    steps (plane strain): σ_xx = −E α ΔT / (1 − ν), σ_yy = 0, u_y = (1 + ν)/(1 − ν) α ΔT y,
    each wall taking |σ_xx| times the height."""
    res = run(CONFIGS / "thermal_expansion.toml", name="thermal_shipped")
    scene = tomllib.loads((CONFIGS / "thermal_expansion.toml").read_text())
    mat, te = scene["materials"][0], scene["thermal_expansion"][0]
    e, nu, alpha = mat["E"], mat["nu"], te["alpha"]
    dT = res["fields/T"][:, :, 0] - te["reference"]
    rise = 100.0 * res["steps/time"]
    np.testing.assert_allclose(dT, np.repeat(rise[:, None], dT.shape[1], 1), rtol=1e-12)
    y = res["mesh/points"][:, 1]
    height = y.max()
    for k, r in enumerate(rise):
        sxx = -e * alpha * r / (1 - nu)
        for sig in (res["cell_fields/stress"][k], res["fields/stress"][k]):
            np.testing.assert_allclose(sig, np.tile([sxx, 0, 0], (len(sig), 1)), rtol=0,
                                       atol=1e-10 * abs(sxx))
        np.testing.assert_allclose(res["fields/displacement"][k][:, 1],
                                   (1 + nu) / (1 - nu) * alpha * r * y, rtol=0,
                                   atol=1e-12 * alpha * r)
        left = res["relations/left_wall/resultant"][k][0]
        right = res["relations/right_wall/resultant"][k][0]
        assert abs(left) == pytest.approx(abs(sxx) * height, rel=1e-10)
        assert left + right == pytest.approx(0.0, abs=1e-10 * abs(sxx) * height)


def bad(hypothesis: str = "plane_stress", **overrides) -> str:
    """The small plate with these overrides (each case one input error)."""
    return plate(2, 1, "quad", hypothesis, UNIFORM + ROLLERS, **overrides)


BAD = {
    "unknown field": (bad(thermal_expansion=[EXPANSION | {"field": "theta"}]),
                      "thermal_expansion[0].field"),
    "vector field": (bad(thermal_expansion=[EXPANSION | {"field": "u"}]),
                     "thermal_expansion[0].field"),
    "alpha inf": (bad(thermal_expansion=[EXPANSION | {"alpha": float("inf")}]),
                  "thermal_expansion[0].alpha"),
    "alpha nan in a region": (bad(thermal_expansion=[EXPANSION | {"regions": [
        {"region": "all", "alpha": float("nan")}]}]), "thermal_expansion[0].regions[0].alpha"),
    "unknown region": (bad(thermal_expansion=[EXPANSION | {"region": "nowhere"}]),
                       "thermal_expansion[0].region"),
    "nonlinear material": (bad(materials=[{"E": 200.0, "nu": 0.3, "model": "von_mises",
                                           "sigma_y": 1.0, "H": 10.0}],
                               hypothesis="plane_strain"), "materials[0].model"),
    "misspelt key": (bad(thermal_expansion=[{"field": "T", "alpha": 1e-3, "referense": 20.0}]),
                     "thermal_expansion[0].referense"),
    # their eigenstrains would add (σ doubled): one entry per field
    "two on one field": (bad(thermal_expansion=[EXPANSION, EXPANSION | {"alpha": 2e-5}]),
                         "thermal_expansion[1].field"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_in_process(case):
    """Every rank raises the same InputError naming the key (before any solve)."""
    from parsolve.model import build_model
    from parsolve.scene import parse_scene

    text, key = BAD[case]
    with pytest.raises(InputError) as info:
        build_model(parse_scene(tomllib.loads(text), "scene.toml", text), MPI.COMM_WORLD)
    assert info.value.key == key and info.value.source == "scene.toml", (info.value.key, str(info.value))


@pytest.mark.serial
@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_exit_2(case, tmp_path):
    """parsolve run: exit 2, one line naming the file and the key, nothing written."""
    text, key = BAD[case]
    (tmp_path / "scene.toml").write_text(text)
    env = {k: v for k, v in __import__("os").environ.items()
           if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    proc = subprocess.run([sys.executable, "-m", "parsolve", "run", "scene.toml", "-o", "out.h5"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "scene.toml" in lines[0] and key in lines[0], proc.stderr
    assert not list(tmp_path.glob("*.h5"))


def _assembled(text: str):
    """(operator values, known loads, cell stresses, nodal stress sums) of this rank, at a
    non-uniform u and T."""
    from parsolve.model import build_model
    from parsolve.scene import parse_scene
    from parsolve.solvers.system import SaddleSystem

    model = build_model(parse_scene(tomllib.loads(text), "t.toml", text), MPI.COMM_WORLD)
    system = SaddleSystem(MPI.COMM_WORLD, model)
    system.assemble()
    mech = model.effects[0]
    x = model.mesh.points
    values = {"u": np.stack([np.sin(x[:, 0] + 2 * x[:, 1]), np.cos(3 * x[:, 0] * x[:, 1])], 1),
              "T": (T_REF + 30 * x[:, 0] ** 2 - 10 * x[:, 1])[:, None]}
    nodal, cell = mech.outputs(system.local_cells, values, None, system.local_cells)
    return system.op.data.copy(), system.composition.known_loads(1.0, 1.0, None), cell["stress"], \
        nodal["stress"][0]


@pytest.mark.parametrize("cell", ["quad", "triangle6"])
def test_block_size_does_not_change_the_answer(cell, monkeypatch):
    """The coupling block is computed a block of cells at a time (CellKernel): blocks of 7
    cells give the operator, the loads and the stresses of one block, to 1e-14 (two α: the
    per-block contraction)."""
    import parsolve.effects.elasticity as elasticity
    import parsolve.fem.element_matrices as element_matrices

    text = plate(13, 7, cell, "plane_strain", UNIFORM + ROLLERS,
                 regions={"inner": {"expr": "x < 0.7"}},
                 thermal_expansion=[EXPANSION | {"regions": [{"region": "inner", "alpha": 4e-3}]}])
    whole = _assembled(text)
    monkeypatch.setattr(element_matrices, "block_cells", lambda *args: 7)
    monkeypatch.setattr(elasticity, "block_cells", lambda *args: 7)
    blocked = _assembled(text)
    for a, b in zip(whole, blocked):
        scale = MPI.COMM_WORLD.allreduce(float(np.abs(a).max(initial=0.0)), op=MPI.MAX)
        assert a.shape == b.shape and np.abs(a - b).max(initial=0.0) <= 1e-14 * scale
        assert scale > 0


def test_arc_length_pull_on_a_heated_plate(run):
    """Arc-length with thermal expansion (the effect's reference-state loads are among the
    loads the steps balance): a heated plate on rollers pulled at its right end by μ P,
    plane stress, unit height and thickness: σ_xx = μ, u_x = (α ΔT + μ / E) x,
    u_y = (α ΔT − ν μ / E) y at every step's load factor μ."""
    text = plate(4, 2, "quad", "plane_stress", UNIFORM + ROLLERS,
                 loads=[{"name": "pull", "region": "right", "total_force": [1.0, 0.0]}],
                 nonlinear={"method": "arc_length", "arc_length": {"pattern": "pull", "length": 0.05}},
                 steps={"count": 2})
    res = run(text, name="arc_heated")
    assert res["attrs"]["status"] == "complete"
    mu = res["steps/time"]
    assert np.all(mu > 0)
    p = res["mesh/points"]
    for k, m in enumerate(mu):
        u = res["fields/displacement"][k]
        np.testing.assert_allclose(u[:, 0], (A + m / E) * p[:, 0], rtol=0, atol=1e-10 * A)
        np.testing.assert_allclose(u[:, 1], (A - NU * m / E) * p[:, 1], rtol=0, atol=1e-10 * A)
        sig = res["cell_fields/stress"][k]
        np.testing.assert_allclose(sig, np.broadcast_to([m, 0.0, 0.0], sig.shape), rtol=0,
                                   atol=1e-9 * max(m, E * A))
