"""The scene reference (docs/reference/scene.md) is complete: every key the parser accepts is on
it with a meaning, checked three ways — the exploration of the parser that writes the page,
the literal key names the parsing modules read (``ast``), and the tables the parser reads its
keys from (material parameters, generator signatures) — and a registry entry's keys appear on
it without a change to the generator."""
import ast
import inspect
import re
import runpy
import tomllib
from dataclasses import replace
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "reference" / "scene.md"
MEANINGS = ROOT / "docs" / "reference" / "meanings.toml"


@pytest.fixture(scope="module")
def generator():
    return runpy.run_path(str(ROOT / "scripts" / "docs_reference.py"))


@pytest.fixture(scope="module")
def accepted(generator):
    return generator["accepted"]()


def page_sections() -> dict[str, set[str]]:
    """{section: keys} of the committed page's tables."""
    out: dict[str, set[str]] = {}
    section = None
    for line in PAGE.read_text().splitlines():
        m = re.match(r"^## `(.+)`$", line)
        if m:
            section = out.setdefault(m.group(1), set())
            continue
        m = re.match(r"^\| `([^`]+)` \|", line)
        if m and section is not None:
            section.add(m.group(1))
    return out


def test_every_key_the_parser_accepts_is_on_the_page(accepted):
    page = page_sections()
    missing = [f"{s}.{k}" for s, keys in accepted.items() for k in keys
               if k not in page.get(s, set())]
    assert not missing, missing
    extra = [f"{s}.{k}" for s, keys in page.items() for k in keys
             if k not in accepted.get(s, set())]
    assert not extra, extra


def test_the_issues_missing_keys_are_found(accepted):
    """Keys no shipped scene uses, which a reference recorded from scenes lacked."""
    for section, key in (("loads[]", "body"), ("loads[]", "nodal"), ("materials[]", "sigma_y"),
                         ("materials[]", "H"), ("contact[].obstacle", "sphere"),
                         ("contact[].obstacle.cylinder", "axis"), ("relations[].minus", "region"),
                         ("solver", "mesh"), ("steps.automatic", "max_steps")):
        assert key in accepted[section], (section, key)


def test_every_key_has_a_meaning_and_every_meaning_a_key(accepted, generator):
    meanings = generator["meanings"]()   # the file's and the registries' own
    without = [f"{s}.{k}" for s, keys in accepted.items() for k in keys
               if not meanings.get(s, {}).get(k, "").strip()]
    assert not without, f"add their meaning to {MEANINGS.relative_to(ROOT)}: {without}"
    stale = [f"{s}.{k}" for s, keys in meanings.items() for k in keys
             if k not in accepted.get(s, set())]
    assert not stale, f"keys the parser does not accept: {stale}"


def literal_keys() -> set[str]:
    """Literal names of Table reads (get, floats, table, tables, has) in the parsing modules:
    parsolve/scene.py, every module under parsolve/effects/, loads/ and relation_kinds/ (the
    registries' entries) and any schema module."""
    modules = [ROOT / "parsolve" / "scene.py"]
    for package in ("effects", "loads", "relation_kinds"):
        modules += sorted((ROOT / "parsolve" / package).rglob("*.py"))
    modules += [p for p in [ROOT / "parsolve" / "schema.py"] if p.exists()]
    keys = set()
    for path in modules:
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr in ("get", "floats", "table", "tables", "has")
                    and node.args and isinstance(node.args[0], ast.Constant)
                    and isinstance(node.args[0].value, str)
                    and not (node.func.attr == "get" and len(node.args) < 2)):   # dict.get
                keys.add(node.args[0].value)
    return keys


def test_every_literal_key_of_the_parsers_is_on_the_page(accepted):
    on_page = {k for keys in accepted.values() for k in keys}
    missing = sorted(k for k in literal_keys() if k not in on_page and "[" not in k)
    assert not missing, missing


def test_material_parameters_and_generator_parameters_are_on_the_page(accepted):
    """The parser reads these from tables (a model's PARAMETERS, a generator's signature)."""
    from parsolve.effects.elasticity import MODELS
    from parsolve.mesh.generators import GENERATORS

    for name, model in MODELS.items():
        assert set(model.PARAMETERS) <= accepted["materials[]"], name
    for name, function in GENERATORS.items():
        assert set(inspect.signature(function).parameters) <= accepted["mesh"], name


def test_a_registry_entrys_keys_appear_without_changing_the_generator(generator, monkeypatch):
    """A new entry in the effects registry (its parse reading a choice, a key under one of its
    answers, a sub-table): the exploration finds its section and keys."""
    from parsolve.effects import registry

    def parse(t, dim):
        kind = t.get("kind", str, "a", choices=("a", "b"))
        if kind == "b":
            t.get("only_b", float)
        sub = t.table("shape", None)
        if sub is not None:
            sub.floats("centre", dim)
            sub.done()
        t.done()
        return kind

    template = registry.EFFECTS["springs"]
    monkeypatch.setitem(registry.EFFECTS, "probe_effect",
                        replace(template, section="probe_effect", array=True, parse=parse))
    found = generator["accepted"]()
    assert found["probe_effect[]"] == {"kind", "only_b", "shape"}
    assert found["probe_effect[].shape"] == {"centre"}


def test_the_page_gives_types_defaults_and_conditions():
    text = PAGE.read_text()
    for row in ("| `sigma_y` | number | required |  | model = `von_mises` |",
                "| `body` | array of numbers (2) / array of numbers (3) | (none) |",
                "| `lz` |", "generator = `box`",
                "| `sphere` | table | (none) |"):
        assert row in text, row


def test_a_relation_kinds_description_is_its_meaning(generator, monkeypatch):
    """The meaning of a relation's ``type`` is read from the relation kinds' registry: every
    kind with its own description, a new kind's too, and none written by hand."""
    from parsolve.relation_kinds import registry

    assert "type" not in tomllib.loads(MEANINGS.read_text()).get("relations[]", {})
    text = generator["meanings"]()["relations[]"]["type"]
    for name, entry in registry.RELATIONS.items():
        assert entry.description and f"`{name}`: {entry.description}" in text
    monkeypatch.setitem(registry.RELATIONS, "probe_kind",
                        replace(registry.RELATIONS["equal"], description="a probe's rows"))
    assert "`probe_kind`: a probe's rows" in generator["meanings"]()["relations[]"]["type"]
