"""Every bad-input family of the test suite at 2 and 3 ranks: ``parsolve check`` and ``parsolve
run`` exit 2 with one line naming the file and the key, within a time limit (a check that
raises on some ranks only would leave the others waiting in a collective call: a hang), with
nothing written and no lock left behind. The families are the tables the other tests use
(tests/test_cli.py, tests/effects/test_contact_bad_input.py, test_thermal_expansion.py,
test_diffusion_effect.py, test_springs.py, test_periodic.py, test_exchange.py,
tests/solvers/test_control.py, tests/loads/test_bad_input.py, tests/fem/test_axisymmetric.py),
plus checks that only some ranks' parts can fail (an axisymmetric mesh with r < 0 on one part,
a selector not finite on one part).

All cases of a rank count run in one mpirun (tests/helpers/bad_input_runner.py: one process
per rank, ``parsolve.cli.main`` per case), so the whole costs two start-ups."""

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT

pytestmark = pytest.mark.serial   # the runs start their own ranks
TESTS = ROOT / "tests"
LIMIT = 150   # seconds for every case of one rank count (about 15 s when nothing hangs)


def _module(path: str):
    spec = importlib.util.spec_from_file_location(Path(path).stem + "_table", TESTS / path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


AXISYMMETRIC = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 1.0
nx = 6
ny = 6
cell = "quad"
origin = [-0.2, 0.0]
[model]
hypothesis = "axisymmetric"
[[materials]]
E = 100.0
nu = 0.25
[[relations]]
name = "bottom"
type = "dirichlet"
region = "bottom"
components = ["y"]
"""


def families() -> dict[str, tuple[str, str, str]]:
    """name -> (scene text, file named, key named)."""
    cases = {}
    cli = _module("test_cli.py")
    for name, (text, source, key) in cli.BAD.items():
        if name == "bad selector":   # (as test_cli makes it: the bad region used)
            text = text.replace('region = "corner"', 'region = "odd"')
        if name not in ("output is the scene", "too large"):   # (run only; rank 0 only)
            cases[f"cli/{name}"] = (text, source, key)
    cases["cli/not finite on one part"] = (
        cli.GOOD.replace("[regions]", '[regions]\nodd = "1 / (x - 1) > 0"\n').replace(
            'region = "corner"', 'region = "odd"'), "scene.toml", "regions.odd")
    contact = _module("effects/test_contact_bad_input.py")
    for name, (text, key, _) in contact.BAD.items():
        cases[f"contact/{name}"] = (contact.SCENE.format(contact=text), "scene.toml", key)
    thermal = _module("effects/test_thermal_expansion.py")
    for name, (text, key) in thermal.BAD.items():
        cases[f"thermal_expansion/{name}"] = (text, "scene.toml", key)
    diffusion = _module("effects/test_diffusion_effect.py")
    for name, (overrides, key) in diffusion.BAD.items():
        cases[f"diffusion/{name}"] = (diffusion.poisson(4, "quad", "left", **overrides),
                                      "scene.toml", key)
    control = _module("solvers/test_control.py")
    for name, (text, key) in control.BAD.items():
        cases[f"control/{name}"] = (text, "scene.toml", key)
    cases["axisymmetric/r < 0 on some parts"] = (AXISYMMETRIC, "scene.toml", "mesh")
    axisymmetric = _module("fem/test_axisymmetric.py")
    for change, key in _table(axisymmetric.test_refused_inputs):
        cases[f"axisymmetric/{key}"] = (axisymmetric.cylinder(4, "quad").replace(*change),
                                        "scene.toml", key)
    loads = _module("loads/test_bad_input.py")   # (a serial table: its runs are on 1 rank)
    for name, (load, key, _) in loads.CASES.items():
        cases[f"loads/{name}"] = (_load_scene(loads, name, load), "scene.toml", key)
    springs = _module("effects/test_springs.py")
    supports = (ROOT / "configs" / "springs_bar_supports.toml").read_text()
    for k, (change, key, _) in enumerate(_table(springs.test_input_errors)):
        cases[f"springs/{k} {key}"] = (supports.replace(*change, 1), "scene.toml", key)
    exchange = _module("effects/test_exchange.py")
    for name, (_, key, _) in exchange.BAD.items():
        cases[f"exchange/{name}"] = (exchange.bad_scene(name), "scene.toml", key)
    periodic = _module("effects/test_periodic.py")
    for name, (extra, _) in periodic.REPEATED_TIES.items():
        relations = periodic.LAMINATE["relations"] + [extra]
        cases[f"periodic/{name}"] = (periodic.scene(periodic.LAMINATE, relations=relations),
                                     "scene.toml", "relations[4]")
    return cases


def _table(test) -> list:
    """The cases of a test's ``parametrize`` mark (a table written in its decorator)."""
    (_, values), = [m.args for m in test.pytestmark if m.name == "parametrize"]
    return values


def _load_scene(loads, name: str, load: str) -> str:
    """A case of tests/loads/test_bad_input.py as its test writes it."""
    own = "region" in load or "gravity" in load   # gravity acts on "all" by default
    text = loads.BASE.replace('region = "right"\n', "" if own else 'region = "right"\n')
    text = text.format(load=load)
    if name == "no density":
        text = text.replace("density = 1.0\n", "")
    if name == "bad density":
        text = text.replace("density = 1.0", "density = -1.0")
    return text + loads.CONTROL if name == "timed direction" else text


CASES = families()


@pytest.fixture(scope="module")
def cases_dir(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("bad_inputs")
    listed = []
    for k, (name, (text, _, _)) in enumerate(sorted(CASES.items())):
        directory = root / f"case{k:03d}"
        directory.mkdir()
        (directory / "scene.toml").write_text(text)
        listed.append((name, str(directory), ["check", "run"]))
    (root / "cases.json").write_text(json.dumps(listed))
    return root


@pytest.mark.parametrize("ranks", [2, 3])
def test_every_bad_input_family_exits_2_on_every_rank(ranks, cases_dir):
    results, progress = cases_dir / f"results{ranks}.json", cases_dir / f"progress{ranks}"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_"))}
    cmd = ["timeout", "-s", "KILL", str(LIMIT), "bash", str(ROOT / "scripts" / "mpirun.sh"),
           "-n", str(ranks), sys.executable, str(TESTS / "helpers" / "bad_input_runner.py"),
           str(cases_dir / "cases.json"), str(results), str(progress)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=cases_dir)
    hung = progress.read_text() if progress.exists() else "(none started)"
    assert proc.returncode == 0, f"exit {proc.returncode}; the last case started: {hung}\n" \
        f"{proc.stderr[-3000:]}"
    got = json.loads(results.read_text())
    assert len(got) == 2 * len(CASES)
    for name, (_, source, key) in CASES.items():
        for command in ("check", "run"):
            case = got[f"{name} {command}"]
            lines = [line for line in case["lines"] if line.startswith("parsolve:")]
            assert case["code"] == 2 and case["together"], (name, command, case)
            assert len(lines) == 1 and "Traceback" not in "".join(case["lines"]), (name, case)
            assert source in lines[0] and key in lines[0], (name, lines[0])
    for directory in cases_dir.glob("case[0-9]*"):
        assert sorted(p.name for p in directory.iterdir()) == ["scene.toml"], directory
