"""Bad load values: exit 2, one line naming the scene file and the key, nothing written."""

import pytest

pytestmark = pytest.mark.serial   # the command line in this process, on one rank

BASE = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 2
ny = 2
[model]
hypothesis = "plane_strain"
[regions]
dot = {{ point = [0.5, 0.5] }}
[[materials]]
E = 1.0
nu = 0.3
density = 1.0
[[loads]]
name = "pull"
region = "right"
{load}
[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x", "y"]
"""

CASES = {
    "two kinds": ("traction = [1.0, 0.0]\npressure = 1.0", "loads[0].traction", "exactly one"),
    "unknown name": ('pressure = "2 * w"', "loads[0].pressure", "unknown name 'w'"),
    "syntax": ('traction = [0.0, "1 +"]', "loads[0].traction[1]", "syntax error"),
    "not finite": ('pressure = "1 / (x - x)"', "loads[0].pressure", "not finite"),
    "a call": ('traction = ["__import__(1)", 0.0]', "loads[0].traction[0]", "not allowed"),
    "too many": ('traction = [1.0, "x", 0.0]', "loads[0].traction", "expected 2 values"),
    "boolean": ("pressure = true", "loads[0].pressure", "got bool"),
    "gravity expression": ('gravity = [0.0, "-9.81 * t"]', "loads[0].gravity",
                           "list of numbers"),
    "gravity size": ("gravity = [0.0, -9.81, 0.0]", "loads[0].gravity", "expected 2 numbers"),
    "nan pressure": ("pressure = nan", "loads[0].pressure", "not a number"),
    "total force expression": ('total_force = ["x", 0.0]', "loads[0].total_force",
                               "list of numbers"),
    "pressure on no facet": ('pressure = 1.0\nregion = "dot"', "loads[0].region",
                             "no boundary facet"),
    "body on no cell": ('body = [1.0, 0.0]\nregion = "dot"', "loads[0].region", "no cell"),
    "no density": ("gravity = [0.0, -9.81]", "loads[0].gravity", "no density"),
    "bad density": ("gravity = [0.0, -9.81]", "materials[0].density", "must be positive"),
    "timed direction": ('traction = ["t", 0.0]', "loads[0].traction", "cannot name t"),
}

CONTROL = """
[[relations]]
name = "opening"
type = "mean"
region = "right"
component = "x"
value = 1e-3
dual = "pull"
"""


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_load_exits_2(case, tmp_path, capfd, monkeypatch):
    from parsolve.cli import main

    load, key, words = CASES[case]
    own = "region" in load or "gravity" in load   # gravity acts on "all" by default
    text = BASE.replace('region = "right"\n', "" if own else 'region = "right"\n')
    text = text.format(load=load)
    if case == "no density":
        text = text.replace("density = 1.0\n", "")
    if case == "bad density":
        text = text.replace("density = 1.0", "density = -1.0")
    if case == "timed direction":   # the pattern is a relation's dual: one fixed vector
        text += CONTROL
    (tmp_path / "scene.toml").write_text(text)
    monkeypatch.chdir(tmp_path)
    capfd.readouterr()
    code = main(["run", "scene.toml", "-o", "out.h5"])
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert f"scene.toml: {key}: " in err[0], err[0]
    assert words is None or words in err[0], err[0]
    assert not list(tmp_path.glob("*.h5"))
