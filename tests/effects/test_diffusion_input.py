"""Bad diffusion tensors: an InputError naming the scene and the key (exit 2 on the command
line, checked once through ``parsolve check``), never a numpy traceback."""

import tomllib

import pytest

from helpers.scene import scene
from parsolve.errors import InputError
from parsolve.scene import parse_scene

SCENE = {
    "mesh": {"generator": "rectangle", "lx": 1.0, "ly": 1.0, "nx": 2, "ny": 2, "cell": "quad"},
    "model": {"dimension": 2},
    "diffusion": [{"field": "h", "materials": [{"conductivity": 1.0}]}],
    "relations": [{"name": "ends", "type": "dirichlet", "region": "left", "value": 0.0}],
}


def with_conductivity(value) -> str:
    return scene(SCENE, diffusion=[{"field": "h", "materials": [{"conductivity": value}]}])


KEY = "diffusion[0].materials[0].conductivity"

NAN, INF = float("nan"), float("inf")
# (the conductivity the scene holds, key, message fragment)
CASES = [
    ([[1.0, 0.0], [0.0]], KEY, "2×2 tensor of numbers"),           # ragged
    ([[1.0], [0.0, 1.0]], KEY, "2×2 tensor of numbers"),           # ragged the other way
    ([[1.0, 0.0], 1.0], KEY, "2×2 tensor of numbers"),             # a row that is a number
    ([["a", 0.0], [0.0, 1.0]], KEY, "2×2 tensor of numbers"),       # a string
    (["1.0", "2.0"], KEY, "2×2 tensor of numbers"),                 # strings, flat
    ([[True, 0.0], [0.0, 1.0]], KEY, "2×2 tensor of numbers"),      # a boolean
    ([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]], KEY, "2×2 tensor of numbers"),   # 3×2
    ([[[1.0]], [0.0, 1.0]], KEY, "2×2 tensor of numbers"),          # nested too deep
    ([], KEY, "2×2 tensor of numbers"),
    ([[NAN, 0.0], [0.0, 1.0]], KEY + "[0][0]", "not a number"),
    ([[1.0, 0.0], [0.0, INF]], KEY + "[1][1]", "must be finite"),
    ([[1.0, 1e300], [1e300, 1.0]], KEY + "[0][1]", "absurdly large"),
    ([[1.0, 2.0], [0.0, 1.0]], KEY, "symmetric positive semi-definite"),
    ("high", KEY, "expected float or list"),
]


@pytest.mark.parametrize("value, key, fragment", CASES)
def test_bad_conductivity(value, key, fragment):
    text = with_conductivity(value)
    with pytest.raises(InputError) as err:
        parse_scene(tomllib.loads(text), "scene.toml", text)
    assert err.value.source == "scene.toml" and err.value.key == key, err.value.oneline()
    assert fragment in err.value.message, err.value.message


def test_a_good_tensor_is_kept():
    text = with_conductivity([[2, 0.5], [0.5, 1]])
    parsed = parse_scene(tomllib.loads(text), "scene.toml", text)
    spec = parsed.effect_specs["diffusion"][0]
    assert spec.materials[0].conductivity.tolist() == [[2.0, 0.5], [0.5, 1.0]]
