"""Scene validation (issue 6 §2): every float the scene reads is finite and sane, material
ranges, names, files that are not UTF-8 text. Errors name the file and the dotted key."""

import re
import tomllib

import pytest

from parsolve.errors import InputError
from parsolve.scene import load_scene, parse_scene

BASE = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 2
ny = 2
[model]
hypothesis = "plane_stress"
thickness = 1.0
[regions]
box = { box = [[0.0, 0.0], [0.5, 0.5]] }
[evolutions.cycle]
times = [0.0, 1.0]
values = [0.0, 1.0]
[[materials]]
E = 1.0
nu = 0.3
[[loads]]
name = "pull"
region = "right"
traction = [1.0, 0.0]
[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x", "y"]
value = 0.0
[steps]
count = 2
end = 1.0
[nonlinear]
rtol = 1e-8
"""


def parse(text: str):
    return parse_scene(tomllib.loads(text), "s.toml", text)


def error_of(old: str, new: str) -> InputError:
    assert old in BASE, old
    with pytest.raises(InputError) as info:
        parse(BASE.replace(old, new, 1))
    assert info.value.source == "s.toml"
    return info.value


def test_base_is_valid():
    """The base scene every case below breaks parses to what it says (so that each error
    below is the one edit's)."""
    scene = parse(BASE)
    assert (scene.hypothesis, scene.thickness, scene.dim) == ("plane_stress", 1.0, 2)
    assert scene.materials[0].params == {"E": 1.0, "nu": 0.3}
    assert scene.mesh.params == {"lx": 1.0, "ly": 1.0, "nx": 2, "ny": 2}
    assert scene.times == [0.5, 1.0]
    load, = scene.loads
    assert (load.pattern, load.region, load.kind, load.vector) == ("pull", "right", "traction",
                                                                   [1.0, 0.0])
    clamp, = scene.relations
    assert (clamp.name, clamp.type, clamp.region, clamp.components, clamp.value) == \
        ("clamp", "dirichlet", "left", [0, 1], 0.0)
    assert scene.regions["box"].value == [[0.0, 0.0], [0.5, 0.5]]
    assert scene.nonlinear.rtol == 1e-8


@pytest.mark.parametrize("old, new, key, words", [
    ("E = 1.0", "E = nan", "materials[0].E", "not a number"),
    ("E = 1.0", "E = inf", "materials[0].E", "must be finite"),
    ("E = 1.0", "E = 0.0", "materials[0].E", "must be positive"),
    ("E = 1.0", "E = -2", "materials[0].E", "must be positive"),
    ("nu = 0.3", "nu = 0.5", "materials[0].nu", "(-1, 0.5)"),
    ("nu = 0.3", "nu = -1.0", "materials[0].nu", "(-1, 0.5)"),
    ("nu = 0.3", "nu = -inf", "materials[0].nu", "must be finite"),
    ("thickness = 1.0", "thickness = 0.0", "model.thickness", "must be positive"),
    ("thickness = 1.0", "thickness = nan", "model.thickness", "not a number"),
    ("lx = 1.0", "lx = 1e308", "mesh.lx", "absurdly large"),
    ("lx = 1.0", "lx = 1e-320", "mesh.lx", "absurdly small"),
    ("nx = 2", "nx = 2\norigin = [0.0, nan]", "mesh.origin[1]", "not a number"),
    ("[0.5, 0.5]]", "[0.5, inf]]", "regions.box.box[1][1]", "must be finite"),
    ("values = [0.0, 1.0]", "values = [0.0, nan]", "evolutions.cycle.values[1]", "not a number"),
    ("times = [0.0, 1.0]", "times = [0.0, inf]", "evolutions.cycle.times[1]", "must be finite"),
    ("traction = [1.0, 0.0]", "traction = [1e308, 0.0]", "loads[0].traction[0]", "absurdly large"),
    ("value = 0.0", "value = nan", "relations[0].value", "not a number"),
    ("end = 1.0", "end = inf", "steps.end", "must be finite"),
    ("end = 1.0", "end = 1e60", "steps.end", "absurdly large"),
    ("count = 2", "count = 100000000", "steps.count", "absurd"),
    ("rtol = 1e-8", "rtol = nan", "nonlinear.rtol", "not a number"),
    ("rtol = 1e-8", "rtol = 0.0", "nonlinear.rtol", "(0, 1)"),
    ("rtol = 1e-8", "rtol = 1e-8\nstol = -1.0", "nonlinear.stol", "(0, 1)"),
    ('name = "clamp"', 'name = "a/b"', "relations[0].name", "not a plain name"),
    ('name = "clamp"', 'name = ".."', "relations[0].name", "not a plain name"),
    ('name = "clamp"', 'name = ""', "relations[0].name", "not a plain name"),
    ('name = "pull"', 'name = "x y"', "loads[0].name", "not a plain name"),
    ('name = "pull"', 'name = "' + "p" * 65 + '"', "loads[0].name", "at most 64"),
])
def test_bad_numbers_and_names(old, new, key, words):
    err = error_of(old, new)
    assert err.key == key and words in err.message, err.oneline()
    assert err.oneline().startswith(f"s.toml: {key}: ")


def test_material_parameters_name_their_key():
    text = BASE.replace('E = 1.0\nnu = 0.3', 'model = "mazars"\nE = 1.0\nnu = 0.3\neps_d0 = 1e-4\n'
                        'At = 1.0\nBt = -1.0\nAc = 1.0\nBc = 1.0')
    with pytest.raises(InputError) as info:
        parse(text)
    assert info.value.key == "materials[0].Bt"


def test_duplicate_relation_names():
    text = BASE + '[[relations]]\nname = "clamp"\ntype = "equal"\nregion = "top"\ncomponent = "y"\n'
    with pytest.raises(InputError, match="duplicate relation name") as info:
        parse(text)
    assert info.value.key == "relations[1].name"


@pytest.mark.parametrize("content, words", [
    (b"\x00\x01\x02binary", "binary file"),
    ('title = "d\u00e9formation"\n'.encode("latin-1"), "not UTF-8 text (byte 0xe9 on line 1)"),
    (None, "is a folder"),
])
def test_scene_files_that_are_not_text(tmp_path, content, words):
    path = tmp_path / "s.toml"
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    with pytest.raises(InputError, match=re.escape(words)) as info:
        load_scene(path)
    assert info.value.source == str(path)


@pytest.mark.parametrize("given, kind, vector, evolution", [
    ("traction = [1.0, 0.0]", "traction", [1.0, 0.0], "ramp"),
    ('traction = ["2 * y", 0.0]', "traction", ["2 * y", 0.0], "ramp"),
    ('traction = ["2 * t", 1]', "traction", ["2 * t", 1.0], "constant"),
    ("pressure = 3", "pressure", [3.0], "ramp"),
    ('pressure = "1 + t * x"', "pressure", ["1 + t * x"], "constant"),
    ('pressure = "1 + t * x"\nevolution = "cycle"', "pressure", ["1 + t * x"], "cycle"),
    ("gravity = [0, -9.81]", "gravity", [0.0, -9.81], "ramp"),
])
def test_load_entries_read_by_their_registry_entry(given, kind, vector, evolution):
    """Each load key is read as its entry says: numbers, expressions (a value naming t makes
    the evolution default "constant"), one value for a pressure, dim values for gravity."""
    load, = parse(BASE.replace("traction = [1.0, 0.0]", given)).loads
    assert (load.kind, load.vector, load.evolution, load.given) == (kind, vector, evolution, kind)


@pytest.mark.serial   # a subprocess: once, not once per rank
def test_effects_do_not_import_the_scene():
    """The scene reads the registries; no effect or load module imports the scene back."""
    import subprocess
    import sys

    code = ("import sys, parsolve.effects.registry, parsolve.loads.registry, "
            "parsolve.relation_kinds.registry, parsolve.relation_kinds.build; "
            "print('parsolve.scene' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={k: v for k, v in __import__("os").environ.items()
                              if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))})
    assert out.returncode == 0 and out.stdout.strip() == "False", out.stderr
