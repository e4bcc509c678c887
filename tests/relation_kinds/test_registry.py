"""Relation kinds are registry entries: each reads its own keys (the scene reads the common
ones and hands the rest to the entry), builds its rows, and names its regions for the checks
made before the mesh; bad values exit 2 naming the file and the key."""

import ast
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from parsolve.errors import InputError
from parsolve.relation_kinds import registry
from parsolve.relation_kinds.base import RelationSpec
from parsolve.scene import parse_scene

ROOT = Path(__file__).resolve().parents[2]

BASE = """
[mesh]
generator = "rectangle"
lx = 2.0
ly = 1.0
nx = 4
ny = 2
[model]
hypothesis = "plane_stress"
[regions]
tip = { point = [2.0, 1.0] }
[[materials]]
E = 100.0
nu = 0.25
[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x", "y"]
"""


def parse(text: str):
    return parse_scene(tomllib.loads(text), "scene.toml")


def test_the_type_choices_are_the_registry():
    with pytest.raises(InputError) as err:
        parse(BASE + '[[relations]]\nname = "r"\ntype = "bogus"\n')
    assert err.value.key == "relations[1].type"
    for kind in registry.RELATIONS:
        assert kind in err.value.message


@pytest.mark.serial   # the command line in this process, on one rank
@pytest.mark.parametrize("extra, key, words", [
    ('type = "equal"\nregion = "top"\ncomponent = "y"\nvalue = 1.0', "relations[1].value",
     "has no value"),
    ('type = "periodic"\nregion = "left"\ntarget = "right"\ntranslation = [2.0, 0.0]\n'
     'value = 1.0', "relations[1].value", "has no value"),
    ('type = "equal"\nregion = "top"\ncomponent = "y"\nminus = { region = "left", '
     'component = "y" }', "relations[1].minus", "only a 'mean'"),
    ('type = "mean"\nregion = "top"\ncomponent = "y"\nminus = { region = "nowhere", '
     'component = "y" }', "relations[1].minus.region", "unknown region"),
    ('type = "linear"\n[[relations.terms]]\nregion = "nowhere"\ncomponent = "x"',
     "relations[1].terms[0].region", "unknown region"),
    ('type = "periodic"\nregion = "left"\ntarget = "nowhere"\ntranslation = [2.0, 0.0]',
     "relations[1].target", "unknown region"),
    ('type = "strain"\nregion = "all"\ncomponent = "xy"', "relations[1].component",
     "through 'direction'"),
    ('type = "dirichlet"\nregion = "top"\ncomponent = "y"\nvalue = "x +"',
     "relations[1].value", None),
    ('type = "mean"\nregion = "top"\ncomponent = "y"\nmaximum = true\nsense = "<="',
     "relations[1].maximum", "per_cell"),
])
def test_bad_relation_values_name_their_key(extra, key, words, tmp_path, capfd, monkeypatch):
    """Through the command line: exit 2, one line with the file and the key, nothing
    written (errors found before the mesh and once it is read alike)."""
    from parsolve.cli import main

    (tmp_path / "scene.toml").write_text(BASE + '[[relations]]\nname = "r"\n' + extra + "\n")
    monkeypatch.chdir(tmp_path)
    capfd.readouterr()
    code = main(["run", "scene.toml", "-o", "out.h5"])
    err = capfd.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert f"scene.toml: {key}: " in err[0], err[0]
    assert words is None or words in err[0], err[0]
    assert not list(tmp_path.glob("*.h5"))


def test_an_entry_added_to_the_registry_is_read_and_built(monkeypatch):
    """A new kind is a module and an entry: the scene reads its keys through it and the
    model builds its rows through it (here: u_c at a region's nodes equal to twice a given
    value, a Dirichlet condition under another schema)."""
    from parsolve.model import build_model

    def parse_twice(t, spec, declared):
        spec.region = t.get("region", str)
        spec.components = [{"x": 0, "y": 1}[t.get("along", str, choices=("x", "y"))]]

    def build_twice(spec, where, evolution):
        from parsolve import relations as rel

        nodes, _ = where.owned_nodes(spec.region, spec.key + ".region")   # (one process)
        comp = where.fields.component(spec.field, spec.components[0])
        return rel.dirichlet(spec.name, nodes, [comp], where.fields.ncomp, 2 * spec.value,
                             evolution)

    monkeypatch.setitem(registry.RELATIONS, "twice",
                        registry.RelationEntry(parse_twice, build_twice, (float,)))
    scene = parse(BASE + '[[relations]]\nname = "lift"\ntype = "twice"\nregion = "right"\n'
                  'along = "y"\nvalue = 0.25\n')
    spec = scene.relations[1]
    assert isinstance(spec, RelationSpec) and (spec.type, spec.components) == ("twice", [1])
    model = build_model(scene)
    lift = next(r for r in model.relations if r.name == "lift")
    right = np.flatnonzero(np.isclose(model.mesh.points[:, 0], 2.0))
    assert sorted(lift.a_dofs) == sorted(right * 2 + 1)
    np.testing.assert_array_equal(lift.values, 0.5)
    with pytest.raises(InputError) as err:   # its own keys are checked as its schema says
        parse(BASE + '[[relations]]\nname = "lift"\ntype = "twice"\nregion = "right"\n'
              'along = "z"\n')
    assert err.value.key == "relations[1].along"


def test_a_relation_entrys_keys_appear_in_the_reference(monkeypatch):
    import runpy

    generator = runpy.run_path(str(ROOT / "scripts" / "docs_reference.py"))

    def parse_probe(t, spec, declared):
        spec.region = t.get("region", str)
        t.get("stiffest", bool, False)

    monkeypatch.setitem(registry.RELATIONS, "probe_kind",
                        replace(registry.RELATIONS["mean"], parse=parse_probe))
    found = generator["accepted"]()
    assert "stiffest" in found["relations[]"]


def _strings(path: Path) -> set[str]:
    return {n.value for n in ast.walk(ast.parse(path.read_text()))
            if isinstance(n, ast.Constant) and isinstance(n.value, str)}


def test_no_field_name_is_written_outside_the_effect_that_declares_it():
    """The displacement's name "u" is the elasticity's: springs, contact, loads and
    relations address it through the fields (``Field.displacement``, the scene's primary
    field), never by its name."""
    declaring = {ROOT / "parsolve" / "effects" / "elasticity.py"}
    modules = [ROOT / "parsolve" / "scene.py", ROOT / "parsolve" / "model.py",
               ROOT / "parsolve" / "relations.py"]
    for package in ("effects", "loads", "relation_kinds", "fem"):
        modules += sorted((ROOT / "parsolve" / package).rglob("*.py"))
    writing = [p.relative_to(ROOT) for p in modules if p not in declaring and "u" in _strings(p)]
    assert not writing, writing
