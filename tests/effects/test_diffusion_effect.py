"""Diffusion as an effect: a scalar field with its own relations, loads and outputs, and no
displacement, stress or elasticity cost."""

import tomllib

import numpy as np
import pytest

from conftest import CONFIGS
from helpers.scene import DROP, merge, scene, shipped
from parsolve.errors import InputError

POISSON = {
    "mesh": {"generator": "rectangle", "lx": 2.0, "ly": 0.2, "nx": 4, "ny": 2, "cell": "quad"},
    "model": {"dimension": 2},
    "diffusion": [{"field": "h", "materials": [{"conductivity": 0.5}]}],
    "loads": [{"name": "rain", "field": "h", "source": 3.0}],
    "relations": [{"name": "ends", "type": "dirichlet", "region": "left", "value": 0.0}],
}
DRAINS = {"ends": "x == 0 or x == 2"}   # a region for both ends
RAIN, ENDS = POISSON["loads"][0], POISSON["relations"][0]


def poisson(nx: int, cell: str, ends: str, **overrides) -> str:
    """The strip on nx × 2 cells, h = 0 on the region ``ends``, with these overrides."""
    base = merge(POISSON, {"mesh": {"nx": nx, "cell": cell}, "relations": [ENDS | {"region": ends}]})
    return scene(base, **overrides)


@pytest.mark.parametrize("cell", ["quad", "triangle", "triangle6"])
def test_steady_source_between_two_drains(cell, run):
    """-k h'' = s, h(0) = h(L) = 0: h = s x (L - x) / (2k), exact at the nodes (P2: everywhere);
    each end takes half the source, the flux -k h' = s (x - L/2)."""
    text = poisson(16, cell, "ends", regions=DRAINS)
    res = run(text, name=f"poisson_{cell}")
    x = res["mesh/points"][:, 0]
    h = res["fields/h"][-1][:, 0]
    np.testing.assert_allclose(h, 3.0 * x * (2.0 - x) / 1.0, atol=1e-12)
    assert "fields/displacement" not in res and "cell_fields/stress" not in res
    np.testing.assert_allclose(res["relations/ends/multiplier"][-1].sum(), 3.0 * 2.0 * 0.2,
                               rtol=1e-12)  # λ = minus the reaction: what the drains take
    if cell == "quad":  # the Q1 flux of a nodally exact 1D field: exact at the cell centres
        cx = res["mesh/points"][res[f"mesh/cells/{cell}"]].mean(axis=1)[:, 0]
        np.testing.assert_allclose(res["cell_fields/h_flux"][-1][:, 0], 3.0 * (cx - 1.0),
                                   atol=1e-10)


def test_seepage_overflow_and_well_floor(run):
    """Both bounds become active: h0 = clip(q L / k, -0.5, 1), h linear; the multipliers are
    the spilled (overflow) and the missing (well floor) flow."""
    res = run(CONFIGS / "seepage_overflow.toml", name="seepage")
    t = res["steps/time"]
    q = np.interp(t, [0.0, 2.0, 4.0], [0.0, 3.0, -3.0])
    h0 = np.clip(q * 1.0 / 2.0, -0.5, 1.0)
    x = res["mesh/points"][:, 0]
    np.testing.assert_allclose(res["fields/h"][..., 0], h0[:, None] * (1.0 - x)[None, :], atol=1e-12)
    spill = res["relations/overflow/multiplier"].sum(axis=1)
    floor = res["relations/well_floor/multiplier"].sum(axis=1)
    np.testing.assert_allclose(spill, np.where(h0 >= 1.0, (q - 2.0) * 0.1, 0.0), atol=1e-12)
    np.testing.assert_allclose(floor, np.where(h0 <= -0.5, (q + 1.0) * 0.1, 0.0), atol=1e-12)
    assert res["relations/overflow/active"].any() and res["relations/well_floor/active"].any()
    assert not (res["relations/overflow/active"] & res["relations/well_floor/active"]).any()
    # the flux through the drain closes the balance: inflow = drained + spilled
    drained = res["relations/drain/multiplier"].sum(axis=1)
    np.testing.assert_allclose(q * 0.1, drained + spill + floor, atol=1e-12)


def test_transient_decay_of_a_mode(run):
    """Backward Euler with lumped capacity on a Q1 strip: h(x, 0) = sin(pi x) would decay by
    (1 + dt λ)^-n; here the mode is excited by a source over the first step only, then
    decays freely between two drains: the ratio of successive steps is 1 / (1 + dt λ_h)."""
    text = poisson(20, "quad", "ends", regions=DRAINS, loads=[RAIN | {"evolution": "pulse"}],
                   evolutions={"pulse": {"times": [0.0, 0.1, 0.1001], "values": [1.0, 1.0, 0.0]}},
                   time={"mass": "lumped"}, steps={"count": 12, "end": 1.2})
    res = run(text, name="decay")
    h = res["fields/h"][..., 0]
    mid = np.argmin(np.abs(res["mesh/points"][:, 0] - 1.0) + res["mesh/points"][:, 1])
    ratios = h[2:, mid] / h[1:-1, mid]
    # after a few steps the slowest mode dominates: constant ratio
    assert np.ptp(ratios[-4:]) < 1e-3 * ratios[-1]
    assert 0 < ratios[-1] < 1
    err = np.abs(res["balance/total/error"]).max()
    assert err <= 1e-13 * np.abs(res["balance/total/storage"]).max()


MATERIAL = POISSON["diffusion"][0]["materials"][0]
BAD = {  # overrides of the small strip (h = 0 on the left), each one input error
    "negative conductivity": ({"diffusion": [{"field": "h", "materials": [{"conductivity": -1.0}]}]},
                              "diffusion[0].materials[0].conductivity"),
    "relation on a missing field": ({"relations": [ENDS | {"field": "c"}]}, "relations[0].field"),
    "component of a scalar field": ({"relations": [ENDS | {"component": "x"}]},
                                    "relations[0].component"),
    "transient without steps": ({"time": {"mass": "lumped"}}, "steps"),
    "unknown mass matrix": ({"time": {"mass": "diagonal"}, "steps": {"count": 2}}, "time.mass"),
    "negative capacity": ({"diffusion": [{"field": "h", "materials": [MATERIAL | {"capacity": -2.0}]}]},
                          "diffusion[0].materials[0].capacity"),
}

OUTPUT_CLASHES = {  # a field named like another output would overwrite it in the result file
    "stress": 'field = "stress"',
    "displacement": 'field = "displacement"',
}


@pytest.mark.parametrize("name", sorted(OUTPUT_CLASHES))
def test_field_names_cannot_overwrite_outputs(name):
    from parsolve.model import build_model
    from parsolve.scene import parse_scene

    text = COUPLED + f"""
[[diffusion]]
{OUTPUT_CLASHES[name]}
[[diffusion.materials]]
conductivity = 1.0
"""
    with pytest.raises(InputError) as err:
        build_model(parse_scene(tomllib.loads(text), "scene.toml", text))
    assert err.value.key == "diffusion[0].field" and "written twice" in err.value.message


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_diffusion_input(case):
    from parsolve.scene import parse_scene

    overrides, key = BAD[case]
    text = poisson(4, "quad", "left", **overrides)
    with pytest.raises(InputError) as err:
        parse_scene(tomllib.loads(text), "scene.toml", text)
    assert err.value.key == key, err.value.oneline()


def test_bad_saturation():
    from parsolve.scene import parse_scene

    base = shipped("solubility_well_mixed.toml")
    assert base["solubility"]["saturation"] == 1.0
    text = scene(base, solubility={"saturation": -1.0})
    with pytest.raises(InputError) as err:
        parse_scene(tomllib.loads(text), "scene.toml", text)
    assert err.value.key == "solubility.saturation"


def test_initial_field_relaxes_to_its_mean(run):
    """A closed strip starting from h = x (an expression) relaxes to its mean 1 (over [0, 2]):
    the storage never changes (no source, no boundary), for backward Euler and Crank-Nicolson
    (which needs f_int of the initial field)."""
    # Crank-Nicolson is not L-stable: its shortest modes decay slowly at this step (|factor|
    # ≈ 0.92 per step), hence the looser uniformity check
    for scheme, atol in (({"scheme": "backward_euler"}, 1e-9), ({"scheme": "theta", "theta": 0.5}, 5e-3)):
        text = poisson(10, "quad", "left", relations=DROP, time=scheme, steps={"count": 40, "end": 40.0},
                       diffusion=[POISSON["diffusion"][0] | {"initial": "x"}],
                       loads=[RAIN | {"source": 0.0}])
        res = run(text, name="relax")
        storage = res["balance/total/storage"]
        np.testing.assert_allclose(storage, 2.0 * 0.2 * 1.0, rtol=1e-12)  # ∫ x over [0, 2] × 0.2
        np.testing.assert_allclose(res["fields/h"][-1][:, 0], 1.0, atol=atol)


def test_initial_expression_must_be_finite():
    from parsolve.model import build_model
    from parsolve.scene import parse_scene

    text = poisson(4, "quad", "left", diffusion=[POISSON["diffusion"][0] | {"initial": "sqrt(-1 - x)"}])
    with pytest.raises(InputError) as err:
        build_model(parse_scene(tomllib.loads(text), "scene.toml", text))
    assert err.value.key == "diffusion[0].initial"


COUPLED = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 0.2
nx = 8
ny = 2
cell = "quad"
[model]
hypothesis = "plane_stress"
[regions]
corner = { point = [0.0, 0.0] }
[[materials]]
E = 100.0
nu = 0.25
[[loads]]
name = "pull"
region = "right"
traction = [1.0, 0.0]
evolution = "constant"
[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x"]
[[relations]]
name = "corner"
type = "dirichlet"
region = "corner"
components = ["y"]
[steps]
times = [1.0, 2.0]
"""


@pytest.mark.parametrize("theta", [1.0, 0.5])
def test_displacements_stay_static_next_to_a_transient_field(theta, run):
    """θ weighs only fields with a capacity: the displacements of a transient scene are in
    equilibrium at every step, whatever θ (a θ-weighted elasticity would give 2× then 0)."""
    static = run(COUPLED, name="static")
    scheme = 'scheme = "theta"\ntheta = 0.5' if theta == 0.5 else 'scheme = "backward_euler"'
    transient = COUPLED + f"""
[[diffusion]]
field = "h"
initial = "x"
[[diffusion.materials]]
conductivity = 1.0
[time]
{scheme}
"""
    res = run(transient, name="coupled")
    np.testing.assert_allclose(res["fields/displacement"], static["fields/displacement"],
                               rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(res["balance/total/storage"], 0.5 * 0.2, rtol=1e-12)  # ∫ x


@pytest.mark.parametrize("field", ["h", "u"])
def test_a_field_is_declared_once(field):
    """Two [[diffusion]] sections on one field, or one named like the displacement: exit 2
    naming the second section's field key (the registry says which fields a section declares)."""
    from parsolve.scene import parse_scene

    section = f"""
[[diffusion]]
field = "{field}"
[[diffusion.materials]]
conductivity = 1.0
"""
    text = COUPLED + section * (2 if field == "h" else 1)
    with pytest.raises(InputError) as err:
        parse_scene(tomllib.loads(text), "scene.toml", text)
    assert "declared twice" in err.value.message
    assert err.value.key == ("diffusion[1].field" if field == "h" else "diffusion[0].field")
