"""The exchange (Robin) condition h (T − T∞) and fluxes given as expressions, against closed
forms: a wall between a fixed temperature and a convecting ambient that varies in time
(steady at each step, exact for linear elements), a fin cooled by convection (steady, the 1D
cosh solution) and a slab cooling through its face (transient, backward Euler, the series solution)."""

import numpy as np
import pytest
from scipy.optimize import brentq

from conftest import CONFIGS

WALL = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 0.2
nx = 6
ny = 1
cell = "{cell}"
[model]
dimension = 2
[[diffusion]]
field = "T"
[[diffusion.materials]]
conductivity = 0.5
[[exchange]]
field = "T"
region = "right"
coefficient = 2.0
ambient = "30 + 5 * t"
[[relations]]
name = "hot"
type = "dirichlet"
region = "left"
value = 100.0
evolution = "constant"
[steps]
times = [1.0, 2.0, 4.0]
"""


@pytest.mark.parametrize("cell", ["quad", "triangle", "triangle6"])
def test_wall_to_a_varying_ambient(cell, run):
    """T(0) = 100, -k T'(L) = h (T(L) - T∞(t)): T linear, T = 100 + (T∞ - 100) h x / (k + h L)
    at every step (T∞ = 30 + 5 t), exact at the nodes; the hot side's reaction is what the
    ambient takes, h (T(L) - T∞) × 0.2."""
    res = run(WALL.format(cell=cell))
    x = res["mesh/points"][:, 0]
    t = res["steps/time"]
    ambient = 30 + 5 * t[:, None]
    exact = 100 + (ambient - 100) * 2.0 * x[None, :] / (0.5 + 2.0 * 2.0)
    np.testing.assert_allclose(res["fields/T"][..., 0], exact, atol=1e-10)
    tip = 100 + (ambient[:, 0] - 100) * 4.0 / 4.5
    np.testing.assert_allclose(res["relations/hot/resultant"][:, 0],
                               2.0 * (tip - ambient[:, 0]) * 0.2, rtol=1e-10)


def test_fin_cooled_by_convection(run):
    """The shipped fin (configs/fin_convection.toml): thin (Biot h w / k = 1e-4), base at
    100, exchange on both faces, insulated tip: (T - T∞)/(T_b - T∞) = cosh(m (L - x)) /
    cosh(m L), m² = 2 h / (k w); the heat the base gives k w m tanh(m L) (T_b - T∞). Within
    2e-4 (the fin's own 2D effect is O(Biot))."""
    res = run(CONFIGS / "fin_convection.toml")
    x = res["mesh/points"][:, 0]
    m = np.sqrt(2 * 0.01 / (1.0 * 0.01))
    exact = 20 + 80 * np.cosh(m * (1 - x)) / np.cosh(m)
    np.testing.assert_allclose(res["fields/T"][-1][:, 0], exact, rtol=2e-4)
    np.testing.assert_allclose(res["relations/base/resultant"][-1][0],
                               1.0 * 0.01 * m * np.tanh(m) * 80, rtol=2e-4)


SLAB = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 0.1
nx = 40
ny = 1
cell = "triangle6"
[model]
dimension = 2
[time]
mass = "consistent"
[[diffusion]]
field = "T"
initial = 1.0
[[diffusion.materials]]
conductivity = 1.0
capacity = 1.0
[[exchange]]
field = "T"
region = "right"
coefficient = 2.0
ambient = 0.0
[steps]
count = {count}
end = 0.5
"""


def slab_series(x, t, biot, terms=60):
    """(T - T∞)/(T0 - T∞) of a slab 0 ≤ x ≤ 1 (k = c = 1) insulated at x = 0, exchanging at
    x = 1: Σ C_n exp(-ζ_n² t) cos(ζ_n x), ζ_n tan ζ_n = Bi, C_n = 4 sin ζ_n / (2 ζ_n + sin 2ζ_n)."""
    zeta = np.array([brentq(lambda z: z * np.tan(z) - biot, n * np.pi + 1e-12,
                            n * np.pi + np.pi / 2 - 1e-12) for n in range(terms)])
    c = 4 * np.sin(zeta) / (2 * zeta + np.sin(2 * zeta))
    return np.einsum("n,tn,xn->tx", c, np.exp(-np.outer(t, zeta**2)), np.cos(np.outer(x, zeta)))


def test_slab_cooling_through_its_face(run):
    """Backward Euler (first order in Δt: the space error of 40 six-node triangles is far
    below): from 50 to 100 steps the largest error past t = 0.05 halves (measured 0.0106 →
    0.0053) and the end state is within 1.1e-3 of the series solution (measured 1.03e-3)."""
    errors = []
    for count in (50, 100):
        res = run(SLAB.format(count=count))
        x, t = res["mesh/points"][:, 0], res["steps/time"]
        error = np.abs(res["fields/T"][..., 0] - slab_series(x, t, 2.0))
        errors.append(error[t >= 0.05].max())
    assert 1.9 < errors[0] / errors[1] < 2.1
    assert errors[1] < 6e-3 and error[-1].max() < 1.1e-3


def test_flux_as_an_expression_of_time_and_place(run):
    """T(0) = 0 and a flux q = 3 t (1 + y) per unit area into the right end of a strip
    0 ≤ y ≤ 0.2: the heat entering is ∫ q dy = 3 t × 0.22 at every step, all of it leaving
    through the fixed end."""
    text = WALL.format(cell="quad").replace('''[[exchange]]
field = "T"
region = "right"
coefficient = 2.0
ambient = "30 + 5 * t"''', '''[[loads]]
field = "T"
region = "right"
flux = "3 * t * (1 + y)"''')
    res = run(text)
    t = res["steps/time"]
    np.testing.assert_allclose(res["relations/hot/resultant"][:, 0], -3 * t * 0.22, rtol=1e-10)


THETA = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 0.1
nx = 5
ny = 1
cell = "triangle6"
[model]
dimension = 2
[time]
scheme = "theta"
theta = {theta}
mass = "consistent"
[[diffusion]]
field = "T"
initial = "x * x / 2"
[[diffusion.materials]]
conductivity = 1.0
capacity = 1.0
[[exchange]]
field = "T"
region = "right"
coefficient = 4.0
ambient = "t + 0.5 + 1 / 4"
[steps]
count = 4
end = 0.6
"""


@pytest.mark.parametrize("theta", [0.5, 0.75, 1.0])
def test_theta_scheme_exact_for_a_solution_linear_in_time(theta, run):
    """T = t + x²/2 solves T_t = T_xx with an insulated x = 0 and, at x = 1, the exchange
    -T_x = h (T - T∞) for T∞(t) = t + 1/2 + 1/h: quadratic in space (six-node triangles hold
    it) and linear in time (every θ-scheme integrates it exactly), so each step is exact to
    round-off only if the facet term and its load are both weighted by θ at t and t_n."""
    res = run(THETA.format(theta=theta))
    x, t = res["mesh/points"][:, 0], res["steps/time"]
    np.testing.assert_allclose(res["fields/T"][..., 0], t[:, None] + x[None, :] ** 2 / 2,
                               atol=1e-11)


# bad [[exchange]] values: (the entry's lines replaced, the key named, words of the message)
BAD = {
    "zero coefficient": (("coefficient = 2.0", "coefficient = 0.0"), "exchange[0].coefficient",
                         "must be positive"),
    "coefficient a string": (("coefficient = 2.0", 'coefficient = "h"'),
                             "exchange[0].coefficient", "expected float"),
    "ambient syntax": (('ambient = "30 + 5 * t"', 'ambient = "30 +"'), "exchange[0].ambient",
                       "syntax error"),
    "ambient unknown name": (('ambient = "30 + 5 * t"', 'ambient = "30 + w"'),
                             "exchange[0].ambient", "unknown name 'w'"),
    "ambient not finite": (('ambient = "30 + 5 * t"', 'ambient = "1 / (x - 2)"'),
                           "exchange[0].ambient", "not finite"),
    "not a field": (('field = "T"\nregion = "right"', 'field = "q"\nregion = "right"'),
                    "exchange[0].field", "not a scalar field"),
    "no facet": (('region = "right"\ncoefficient', 'region = "dot"\ncoefficient'),
                 "exchange[0].region", "no boundary facet"),
    "unknown region": (('region = "right"\ncoefficient', 'region = "nowhere"\ncoefficient'),
                       "exchange[0].region", "nowhere"),
    "unknown key": (("coefficient = 2.0", "coefficient = 2.0\nambiant = 3.0"),
                    "exchange[0].ambiant", "unknown key"),
    "no coefficient": (("coefficient = 2.0\n", ""), "exchange[0].coefficient", "required"),
}


def bad_scene(name: str) -> str:
    """The steady wall with one [[exchange]] value made bad (and a one-node region)."""
    change, _, _ = BAD[name]
    text = WALL.format(cell="quad").replace("[model]", '[regions]\ndot = { point = [0.0, 0.0] }'
                                            "\n[model]")
    assert change[0] in text, change
    return text.replace(change[0], change[1], 1)


@pytest.mark.serial   # the command line in this process (2, 3 ranks: test_bad_input_parallel)
@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_exchange_exits_2(name, tmp_path, capfd, monkeypatch):
    """Exit 2, one line naming the scene file and the key, nothing written."""
    from parsolve.cli import main

    _, key, words = BAD[name]
    (tmp_path / "scene.toml").write_text(bad_scene(name))
    monkeypatch.chdir(tmp_path)
    capfd.readouterr()
    code = main(["run", "scene.toml", "-o", "out.h5"])
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert f"scene.toml: {key}: " in err[0] and words in err[0], err[0]
    assert not list(tmp_path.glob("*.h5"))


@pytest.mark.parametrize("theta", [0.5, 0.75, 1.0])
def test_theta_scheme_with_a_flux_that_varies_in_time(theta, run):
    """The same T = t + x²/2 with the ambient at 0 and the heat coming in by a prescribed
    flux instead: -T_x(1) = h T(1) - q(t) holds for q(t) = 1 + h (t + 1/2), a flux linear in
    t (a load re-assembled at t and t_n); exact to round-off only if the flux is weighted by θ
    like the exchange's operator term."""
    text = THETA.format(theta=theta).replace('ambient = "t + 0.5 + 1 / 4"', "ambient = 0.0")
    text = text.replace("[steps]", '[[loads]]\nfield = "T"\nregion = "right"\n'
                        'flux = "1 + 4 * (t + 0.5)"\n[steps]')
    res = run(text)
    x, t = res["mesh/points"][:, 0], res["steps/time"]
    np.testing.assert_allclose(res["fields/T"][..., 0], t[:, None] + x[None, :] ** 2 / 2,
                               atol=1e-11)
